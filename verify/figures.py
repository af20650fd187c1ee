"""Certification result + scenario -> PNG figures (matplotlib, Agg, no pyplot state).

input: the arrays of a certification (trajectory, nominal, inputs), its certificate (formula, timed run, failed
checks) and the scenario -> output: PNG bytes per figure, or ``None`` when the data for a figure is absent.

Figures, in report order: the workspace map (``verify.workspace_map``), one panel per obligation of the formula
(its verdict, margin, violation and decision as the certificate states them, and the curve of its target's margin
that the judging code computed with them, ``verify.judging``; nothing is judged here), the clearance of the robot
disc from obstacles and the workspace edge, the states x(t), y(t), theta(t) (unwrapped) with the workspace bounds
and the tube band (the paper's figures 6-8), the tube error, the inputs u1..u3 with their box (figures 9-11), and
the sampling intervals (data quality: dropouts and out-of-order stamps). matplotlib is confined to the figure
modules (this one and ``verify.workspace_map``).
"""

from __future__ import annotations

import math
import multiprocessing
import os
import threading
from collections.abc import Callable, Sequence
from dataclasses import dataclass
from functools import partial
from typing import Any

import numpy as np
import pandas as pd
from matplotlib.figure import Figure

from runkit.gcpause import gc_paused
from tubempc.scenario import Scenario
from verify.certificate import Certificate, ObligationEntry, Verdict
from verify.decimate import envelope
from verify.geometry import region_margins, workspace_margin
from verify.ingest.quality import DROPOUT_FACTOR
from verify.judging import FormulaJudgement, ObligationResult
from verify.workspace_map import nominal_layers, png_bytes, tube_radius_or_nan, workspace_caption, workspace_figure

__all__ = [
    "FigureSpec",
    "clearance_figure",
    "failed_checks",
    "figure_builders",
    "figure_workers",
    "inputs_figure",
    "obligations_figure",
    "pose_dropouts",
    "render_figures",
    "sampling_caption",
    "sampling_figure",
    "states_caption",
    "states_figure",
    "tube_figure",
    "workspace_figure",
]

_VERDICT_COLOURS = {"pass": "#2ca02c", "fail": "#d62728", "inconclusive": "#ff7f0e"}
_FAIL_COLOUR = "#d62728"


@dataclass(frozen=True, slots=True)
class FigureSpec:
    """One rendered figure: a file stem (``workspace``), a caption, and the PNG bytes."""

    stem: str
    caption: str
    png: bytes


def _png(fig: Figure) -> bytes:
    return png_bytes(fig)


def _envelope(frame: pd.DataFrame, columns: Sequence[str], certificate: Certificate | None = None) -> pd.DataFrame:
    """``verify.decimate.envelope``: every bucket's extremes and gaps, and the rows at the failed checks' first
    violations (the dotted lines) when ``certificate`` is given."""
    keep = [t for _, t in failed_checks(certificate)] if certificate is not None else []
    return envelope(frame, columns, keep_t_s=keep)


def _usable(frame: pd.DataFrame | None, columns: Sequence[str]) -> bool:
    return frame is not None and len(frame) > 0 and all(c in frame.columns for c in columns)


def failed_checks(certificate: Certificate) -> list[tuple[str, float]]:
    """(check name, first violation time in s) of every failed check."""
    return [(c.name, c.first_violation_time) for c in certificate.checks
            if c.verdict is Verdict.FAIL and c.first_violation_time is not None]


def _mark_violations(axes: Sequence[Any], certificate: Certificate, *,
                     names: Sequence[str] | None = None) -> None:
    """A dotted line at each failed check's first violation (only the checks in ``names`` when given)."""
    for ax in axes:
        for name, t_fail in failed_checks(certificate):
            if names is None or name in names:
                ax.axvline(t_fail, color=_FAIL_COLOUR, lw=0.8, ls=":", label=f"violation: {name} ({t_fail:.2f} s)")


def _unwrapped(frame: pd.DataFrame) -> pd.DataFrame:
    """``theta_rad`` unwrapped (continuous through +-pi, not a sawtooth); NaN samples stay NaN and are skipped."""
    if "theta_rad" not in frame.columns:
        return frame
    theta = frame["theta_rad"].to_numpy(dtype=float).copy()
    ok = np.isfinite(theta)
    theta[ok] = np.unwrap(theta[ok])
    return frame.assign(theta_rad=theta)


def states_figure(certificate: Certificate, scenario: Scenario, trajectory: pd.DataFrame | None,
                  nominal: pd.DataFrame | None) -> bytes | None:
    """x(t), y(t), theta(t); nominal and its tube band; the bounds on the robot's centre from the workspace."""
    if trajectory is None or not _usable(trajectory, ("t_s", "x_m", "y_m", "theta_rad")):
        return None
    tr = _envelope(_unwrapped(trajectory), ("x_m", "y_m", "theta_rad"), certificate)
    drawn_nominal, drawn_band = nominal_layers(scenario, nominal)
    nom = (_envelope(_unwrapped(nominal), [c for c in ("x_m", "y_m", "theta_rad") if c in nominal.columns])
           if nominal is not None and drawn_nominal else None)
    fig = Figure(figsize=(8.0, 7.5))
    fig.subplots_adjust(left=0.13, right=0.97, bottom=0.07, top=0.95, hspace=0.12)
    axes = fig.subplots(3, 1, sharex=True)
    eta = scenario.robot.radius
    r_q = tube_radius_or_nan(scenario)
    bounds = {"x_m": scenario.workspace.x, "y_m": scenario.workspace.y}
    ylabels = ("x [m]", "y [m]", "theta [rad], unwrapped")
    for ax, col, ylabel in zip(axes, ("x_m", "y_m", "theta_rad"), ylabels, strict=True):
        ax.plot(tr["t_s"], tr[col], color="black", lw=1.0, label="measured")
        if nom is not None and col in nom.columns:
            ax.plot(nom["t_s"], nom[col], "--", color="#1f77b4", lw=1.0, label="nominal")
            if col in bounds and drawn_band:
                ax.fill_between(nom["t_s"], nom[col] - r_q, nom[col] + r_q, color="#1f77b4", alpha=0.25,
                                lw=0, label="tube")
        if col in bounds:
            lo, hi = bounds[col]
            ax.axhline(lo + eta, color="grey", ls="-.", lw=0.8, label="workspace bound (centre)")
            ax.axhline(hi - eta, color="grey", ls="-.", lw=0.8)
        ax.set_ylabel(ylabel)
        ax.grid(alpha=0.3)
    _mark_violations(axes, certificate)
    axes[0].legend(loc="upper right", fontsize=7)
    axes[-1].set_xlabel("t [s]")
    fig.align_ylabels(axes)
    axes[0].set_title("States over time")
    return _png(fig)


def states_caption(certificate: Certificate, scenario: Scenario, nominal: pd.DataFrame | None) -> str:
    """The states figure's caption: what ``states_figure`` draws for these data."""
    drawn_nominal, drawn_band = nominal_layers(scenario, nominal)
    with_nominal = (" the nominal with its tube band," if drawn_band else " the nominal," if drawn_nominal else "")
    marks = " and each failed check's first violation dotted" if failed_checks(certificate) else ""
    return (f"x(t), y(t), theta(t) (unwrapped) with{with_nominal} the bounds of the robot's centre from the "
            f"workspace{marks}.")


def inputs_figure(certificate: Certificate, scenario: Scenario, inputs: pd.DataFrame | None) -> bytes | None:
    """u1, u2, u3 over time with the input box ``|u_i| <= max_abs[i]``."""
    if inputs is None or not _usable(inputs, ("t_s", "u1", "u2", "u3")):
        return None
    data = _envelope(inputs, ("u1", "u2", "u3"), certificate)
    fig = Figure(figsize=(8.0, 7.5))
    fig.subplots_adjust(left=0.13, right=0.97, bottom=0.07, top=0.95, hspace=0.12)
    axes = fig.subplots(3, 1, sharex=True)
    units = ("m/s", "m/s", "rad/s")
    lim = scenario.inputs
    # columns: linear.x, linear.y, angular.z; a unicycle bounds (v, w) and allows linear.y up to a tolerance
    bounds = lim.max_abs if lim.model == "holonomic" else (lim.max_abs[0], lim.lateral_tolerance, lim.max_abs[1])
    for i, ax in enumerate(axes):
        col = f"u{i + 1}"
        bound = bounds[i]
        ax.step(data["t_s"], data[col], where="post", color="black", lw=1.0, label=col)
        ax.axhline(bound, color="grey", ls="-.", lw=0.8, label=f"|{col}| <= {bound:g}")
        ax.axhline(-bound, color="grey", ls="-.", lw=0.8)
        ax.set_ylabel(f"{col} [{units[i]}]")
        ax.grid(alpha=0.3)
        ax.legend(loc="upper right", fontsize=7)
    _mark_violations(axes, certificate)
    axes[-1].set_xlabel("t [s]")
    axes[0].set_title("Inputs over time (body frame, as commanded)")
    return _png(fig)


def tube_figure(certificate: Certificate, scenario: Scenario, trajectory: pd.DataFrame | None,
                nominal: pd.DataFrame | None) -> bytes | None:
    """Tube error ``|p - p_hat|`` over time (nominal interpolated at the pose stamps) against ``r_q``."""
    cols = ("t_s", "x_m", "y_m")
    if trajectory is None or nominal is None or not (_usable(trajectory, cols) and _usable(nominal, cols)):
        return None
    nom = nominal.sort_values("t_s")
    t_nom = nom["t_s"].to_numpy(dtype=float)
    t = trajectory["t_s"].to_numpy(dtype=float)
    inside = (t >= t_nom[0]) & (t <= t_nom[-1])
    if not inside.any():
        return None
    t = t[inside]
    dx = trajectory["x_m"].to_numpy(dtype=float)[inside] - np.interp(t, t_nom, nom["x_m"].to_numpy(dtype=float))
    dy = trajectory["y_m"].to_numpy(dtype=float)[inside] - np.interp(t, t_nom, nom["y_m"].to_numpy(dtype=float))
    env = _envelope(pd.DataFrame({"t_s": t, "err_m": np.hypot(dx, dy)}), ("err_m",), certificate)
    t, err_m = env["t_s"].to_numpy(), env["err_m"].to_numpy()
    r_q = tube_radius_or_nan(scenario)
    fig = Figure(figsize=(8.0, 3.2))
    fig.subplots_adjust(left=0.1, right=0.97, bottom=0.16, top=0.89)
    ax = fig.add_subplot()
    ax.plot(t, err_m, color="black", lw=1.0, label="|p - p_hat|")
    ax.axhline(r_q, color="#1f77b4", ls="--", lw=1.0, label=f"r_q = {r_q:.3g} m")
    outside = err_m > r_q  # the envelope keeps every bucket's maximum: no excursion is dropped
    if outside.any():
        ax.plot(t[outside], err_m[outside], ".", ms=3, color=_FAIL_COLOUR, label="outside the tube")
    _mark_violations([ax], certificate)
    ax.set_xlabel("t [s]")
    ax.set_ylabel("tube error [m]")
    ax.set_title("Distance to the nominal against the tube radius")
    ax.grid(alpha=0.3)
    ax.legend(loc="upper right", fontsize=7)
    return _png(fig)


def _window_label(window: Sequence[float | None]) -> str:
    hi = window[1]
    return f"window [{window[0]:g}, {'inf' if hi is None or math.isinf(hi) else f'{hi:g}'}] s"


def obligations_figure(obligations: Sequence[ObligationEntry], duration_s: float | None,
                       curves: Sequence[ObligationResult] = ()) -> bytes | None:
    """One panel per obligation (``Certificate.panels``): its verdict, margin, violation and decision as the
    certificate states them, the curve of its target's margin (``curves``: the judging code's, matched by formula
    text; absent when the report is made from a certificate alone), and its window shaded."""
    if not obligations:
        return None
    by_text = {c.formula: c for c in curves}
    n = len(obligations)
    fig = Figure(figsize=(8.0, 1.2 + 2.0 * n))
    fig.subplots_adjust(left=0.1, right=0.97, bottom=0.5 / (1.2 + 2.0 * n), top=1 - 0.75 / (1.2 + 2.0 * n),
                        hspace=0.7)
    axes = fig.subplots(n, 1, sharex=True, squeeze=False)[:, 0]
    end = duration_s if duration_s is not None and math.isfinite(duration_s) else None
    for ax, ob in zip(axes, obligations, strict=True):
        curve = by_text.get(ob.formula)
        if curve is not None and curve.curve_t_ns.size:
            env = envelope(pd.DataFrame({"t_s": curve.curve_t_ns * 1e-9, "rho": curve.curve}), ("rho",),
                           keep_t_s=[] if ob.first_violation_time is None else [ob.first_violation_time])
            t, rho = env["t_s"].to_numpy(dtype=float), env["rho"].to_numpy(dtype=float)
        else:
            t, rho = np.zeros(0), np.zeros(0)
        last = end if end is not None else (float(t[-1]) if t.size else 0.0)
        in_window = np.ones_like(t, dtype=bool)
        if ob.window is not None:
            lo = float(ob.window[0] or 0.0)
            hi = math.inf if ob.window[1] is None else float(ob.window[1])
            if lo < last:
                ax.axvspan(lo, min(hi, last), color="#1f77b4", alpha=0.12, lw=0, label=_window_label(ob.window))
            # an unbounded window ranges to the end of the log (finite-log semantics): nothing to say about it
            note = ("" if hi <= last or math.isinf(hi) else f"{_window_label(ob.window)} opens after the log ends"
                    if lo >= last else "the window continues past the log end: undecided there")
            if note:
                ax.annotate(note, (0.995, 0.96), xycoords="axes fraction", ha="right", va="top", fontsize=7,
                            color="#1f77b4", bbox={"boxstyle": "round,pad=0.2", "fc": "white", "ec": "none"})
            in_window = (t >= lo) & (t <= hi)
        if t.size:
            ax.plot(t, rho, color="black", lw=1.0, label=f"margin of {_short(curve.body if curve else ob.formula)}")
            if ob.verdict is Verdict.FAIL:  # where the failed obligation's target was missed inside its window
                ax.fill_between(t, rho, 0.0, where=in_window & (rho < 0), color=_FAIL_COLOUR, alpha=0.25, lw=0)
        else:
            ax.annotate("no margin curve (report made from the certificate alone)", (0.5, 0.5),
                        xycoords="axes fraction", ha="center", va="center", fontsize=8, color="#555555")
        ax.axhline(0.0, color="grey", lw=0.8)
        if ob.first_violation_time is not None:
            tv = ob.first_violation_time
            ax.axvline(tv, color=_FAIL_COLOUR, lw=1.2, ls="--")
            ax.plot([tv], [0.0], "X", color=_FAIL_COLOUR, ms=9, label=f"violated at {tv:.2f} s")
        if ob.decided_at is not None and ob.verdict is not Verdict.FAIL:
            ax.axvline(ob.decided_at, color=_VERDICT_COLOURS["pass"], lw=0.8, ls=":",
                       label=f"decided at {ob.decided_at:.2f} s")
        colour = _VERDICT_COLOURS.get(ob.verdict.value, "#555555")
        margin = ("" if ob.margin is None else f", margin {ob.margin:.4g} {ob.margin_unit or ''}".rstrip())
        ax.set_title(f"{_short(ob.formula, 70)}: {ob.verdict.value.upper()}{margin}", fontsize=9, color=colour,
                     loc="left", weight="bold")
        if ob.explanation:
            ax.annotate(_short(ob.explanation, 120), (0.005, 0.04), xycoords="axes fraction", ha="left",
                        va="bottom", fontsize=6.5, color=colour,
                        bbox={"boxstyle": "round,pad=0.2", "fc": "white", "ec": "none", "alpha": 0.8})
        unit = curve.body_unit if curve is not None else ob.margin_unit
        ax.set_ylabel(f"margin [{unit}]" if unit and not unit.startswith("mixed") else "margin", fontsize=8)
        ax.grid(alpha=0.3)
        if ax.get_legend_handles_labels()[0]:
            ax.legend(loc="best", fontsize=7)
        if end is not None:
            ax.set_xlim(min(0.0, float(t[0])) if t.size else 0.0, end)
    axes[-1].set_xlabel("t [s]")
    fig.suptitle("Obligations: margin of each obligation's target over time (> 0: satisfied there)", fontsize=10)
    return _png(fig)


def _short(text: str, limit: int = 40) -> str:
    return text if len(text) <= limit else text[: limit - 3] + "..."


def clearance_figure(certificate: Certificate, scenario: Scenario,
                     trajectory: pd.DataFrame | None) -> bytes | None:
    """Distance from the robot disc to the nearest unsafe region and to the workspace edge (negative: touching)."""
    if trajectory is None or not _usable(trajectory, ("t_s", "x_m", "y_m")):
        return None
    x = trajectory["x_m"].to_numpy(dtype=float)
    y = trajectory["y_m"].to_numpy(dtype=float)
    frame = pd.DataFrame({"t_s": trajectory["t_s"].to_numpy(dtype=float),
                          "edge_m": workspace_margin(x, y, scenario)})
    unsafe = [k for k, r in enumerate(scenario.regions) if r.unsafe]
    if unsafe:
        frame["obstacle_m"] = -np.max(region_margins(x, y, scenario, unsafe), axis=0)
    env = _envelope(frame, [c for c in ("edge_m", "obstacle_m") if c in frame.columns], certificate)
    fig = Figure(figsize=(8.0, 3.2))
    fig.subplots_adjust(left=0.1, right=0.97, bottom=0.16, top=0.89)
    ax = fig.add_subplot()
    if "obstacle_m" in env.columns:
        ax.plot(env["t_s"], env["obstacle_m"], color=_FAIL_COLOUR, lw=1.0, label="to the nearest unsafe region")
    ax.plot(env["t_s"], env["edge_m"], color="black", lw=1.0, label="to the workspace edge")
    ax.axhline(0.0, color="grey", lw=0.8)
    _mark_violations([ax], certificate, names=("obstacle_clearance", "workspace"))
    ax.set_xlabel("t [s]")
    ax.set_ylabel("clearance of the disc [m]")
    ax.set_title("Clearance over time (robot disc; < 0: touching)")
    ax.grid(alpha=0.3)
    ax.legend(loc="upper right", fontsize=7)
    return _png(fig)


def pose_dropouts(certificate: Certificate) -> tuple[float | None, int]:
    """(gap threshold in s, dropout count) of the pose stream as the certificate's data quality states them: the
    data-quality rule (``verify.ingest.quality``: a gap longer than ``DROPOUT_FACTOR`` median periods); (None, 0)
    when the certificate states none."""
    pose = certificate.data_quality.get("pose")
    dropouts = pose.get("dropouts") if isinstance(pose, dict) else None
    if not isinstance(dropouts, dict):
        return None, 0
    threshold, count = dropouts.get("threshold_s"), dropouts.get("count")
    return (float(threshold) if isinstance(threshold, int | float) else None,
            int(count) if isinstance(count, int) else 0)


def sampling_caption(certificate: Certificate) -> str:
    """The sampling figure's caption: what ``sampling_figure`` draws for this certificate."""
    threshold_s, n_dropouts = pose_dropouts(certificate)
    if threshold_s is None:
        return "Pose stamp intervals against the MoCap period (data quality)."
    circled = f"; the {n_dropouts} dropout(s) the data-quality table counts are circled" if n_dropouts else ""
    return f"Pose stamp intervals against the MoCap period and the dropout threshold (data quality){circled}."


def sampling_figure(certificate: Certificate, scenario: Scenario, trajectory: pd.DataFrame | None) -> bytes | None:
    """Intervals between pose stamps against the MoCap period; the gaps the data-quality table counts as dropouts
    (its threshold, read from the certificate) circled; non-increasing stamps (never in a cleaned stream) too."""
    if trajectory is None or not _usable(trajectory, ("t_s",)) or len(trajectory) < 2:
        return None
    t = trajectory["t_s"].to_numpy(dtype=float)
    dt_s = np.diff(t)
    period_s = 1.0 / scenario.mocap.rate_hz
    threshold_s, n_dropouts = pose_dropouts(certificate)
    fig = Figure(figsize=(8.0, 3.2))
    fig.subplots_adjust(left=0.1, right=0.97, bottom=0.16, top=0.89)
    ax = fig.add_subplot()
    env = _envelope(pd.DataFrame({"t_s": t[1:], "dt_s": dt_s}), ("dt_s",))  # keeps each bucket's min and max
    t_env, dt_env = env["t_s"].to_numpy(), env["dt_s"].to_numpy()
    ax.plot(t_env, dt_env, ".", ms=2, color="black", label="stamp interval")
    if threshold_s is not None:
        ax.axhline(threshold_s, color=_FAIL_COLOUR, ls=":", lw=0.8,
                   label=f"dropout threshold {threshold_s * 1e3:.3g} ms ({DROPOUT_FACTOR:g} median periods)")
        gaps = dt_env > threshold_s
        if gaps.any():
            ax.plot(t_env[gaps], dt_env[gaps], "o", ms=5, mfc="none", color=_FAIL_COLOUR,
                    label=f"dropouts ({n_dropouts}, as the data-quality table counts)")
    bad = (dt_env <= 0) | ~np.isfinite(dt_env)
    if bad.any():
        n_bad = int(np.count_nonzero((dt_s <= 0) | ~np.isfinite(dt_s)))
        ax.plot(t_env[bad], dt_env[bad], "s", ms=5, mfc="none", color=_FAIL_COLOUR,
                label=f"non-increasing stamps ({n_bad})")
    ax.axhline(period_s, color="#1f77b4", ls="--", lw=0.8, label=f"MoCap period {period_s * 1e3:.3g} ms")
    ax.set_xlabel("t [s]")
    ax.set_ylabel("dt [s]")
    ax.set_title("Pose sampling intervals")
    ax.grid(alpha=0.3)
    ax.legend(loc="upper right", fontsize=7)
    return _png(fig)


_OBLIGATIONS_CAPTION = ("Each obligation of the formula on its own panel, as the certificate states it: its verdict, "
                        "margin, where it was violated or when it was decided, the margin of its target over time "
                        "(> 0 satisfied there; metres, or the signal's unit) and its window shaded.")
_CLEARANCE_CAPTION = "Clearance of the robot disc from the nearest unsafe region and from the workspace edge."
_TUBE_CAPTION = "Tube error |p - p_hat| over time against the tube radius r_q."
_INPUTS_CAPTION = "u1, u2, u3 over time with the input box."

#: the figure builders of the report being rendered, read by forked workers by index (``_render_one``)
_PENDING: list[Callable[[], FigureSpec | None]] = []


def _spec(stem: str, caption: str, draw: Callable[[], bytes | None]) -> FigureSpec | None:
    png = draw()
    return None if png is None else FigureSpec(stem, caption, png)


def figure_builders(certificate: Certificate, scenario: Scenario, *, trajectory: pd.DataFrame | None,
                    nominal: pd.DataFrame | None, inputs: pd.DataFrame | None,
                    judgement: FormulaJudgement | None = None) -> list[Callable[[], FigureSpec | None]]:
    """One builder per figure, in report order; each returns its ``FigureSpec`` (caption beside the drawing), or
    ``None`` when its data are absent. Nothing is drawn until a builder is called."""
    curves = judgement.panels if judgement is not None else ()
    return [
        partial(_spec, "workspace", workspace_caption(certificate, scenario, trajectory, nominal),
                partial(workspace_figure, certificate, scenario, trajectory, nominal)),
        partial(_spec, "obligations", _OBLIGATIONS_CAPTION,
                partial(obligations_figure, certificate.panels, certificate.duration_s, curves)),
        partial(_spec, "clearance", _CLEARANCE_CAPTION, partial(clearance_figure, certificate, scenario, trajectory)),
        partial(_spec, "states", states_caption(certificate, scenario, nominal),
                partial(states_figure, certificate, scenario, trajectory, nominal)),
        partial(_spec, "tube", _TUBE_CAPTION, partial(tube_figure, certificate, scenario, trajectory, nominal)),
        partial(_spec, "inputs", _INPUTS_CAPTION, partial(inputs_figure, certificate, scenario, inputs)),
        partial(_spec, "sampling", sampling_caption(certificate),
                partial(sampling_figure, certificate, scenario, trajectory)),
    ]


def figure_workers() -> int:
    """Processes that render a report's figures: 2 where this process may fork safely (a machine with 2 or more
    cores, the only thread of a process that is not a pool's worker), else 1 (drawn here)."""
    if (os.cpu_count() or 1) < 2 or threading.active_count() > 1 or multiprocessing.current_process().daemon:
        return 1
    return 2


def _render_one(index: int) -> FigureSpec | None:
    return _PENDING[index]()


def render_figures(certificate: Certificate, scenario: Scenario, *, trajectory: pd.DataFrame | None,
                   nominal: pd.DataFrame | None, inputs: pd.DataFrame | None,
                   robustness: pd.DataFrame | None, judgement: FormulaJudgement | None = None,
                   workers: int | None = None) -> list[FigureSpec]:
    """Every figure that the data allows, in the order a reader asks: the map and the obligations, clearance, then
    states, tube and inputs, then data quality. (``robustness``, the whole formula's signal, is not drawn: one
    curve for a conjunction hides which obligation failed; each obligation gets its own panel instead.) The
    obligation panels read the certificate's ``obligations`` and the curves of ``judgement`` (the judging code's).

    ``workers`` (default ``figure_workers()``): processes drawing the figures; above 1 the figures are drawn by
    forked processes (the data are inherited, only the PNG bytes come back), the same figures as drawn here."""
    del robustness
    builders = figure_builders(certificate, scenario, trajectory=trajectory, nominal=nominal, inputs=inputs,
                               judgement=judgement)
    count = min(figure_workers() if workers is None else workers, len(builders))
    with gc_paused():
        specs = _render_forked(builders, count) if count > 1 else None
        if specs is None:
            specs = [build() for build in builders]
    return [spec for spec in specs if spec is not None]


def _render_forked(builders: list[Callable[[], FigureSpec | None]], count: int) -> list[FigureSpec | None] | None:
    """The builders' results drawn by ``count`` forked processes; None when no process can be started (then the
    caller draws them itself). An error inside a builder is raised here, as it would be when drawn here."""
    global _PENDING  # noqa: PLW0603 (the table the forked workers inherit)
    _PENDING = builders
    try:
        try:
            pool = multiprocessing.get_context("fork").Pool(count)
        except OSError:
            return None
        with pool:
            return pool.map(_render_one, range(len(builders)), chunksize=1)
    finally:
        _PENDING = []
