"""Certification result + scenario -> PNG figures (matplotlib, Agg, no pyplot state).

input: the arrays of a certification (trajectory, nominal, inputs, robustness), its certificate (timed run, failed
checks) and the scenario -> output: PNG bytes per figure, or ``None`` when the data for a figure is absent.

Figures: the workspace map (regions coloured by kind, trajectory, tube band around the nominal, reconstructed
timed run, violations marked), the states x(t), y(t), theta(t) with workspace bounds and the tube band (the paper's
figures 6-8), the inputs u1..u3 with their box (figures 9-11), robustness over time, and the sampling intervals
(data quality: dropouts and out-of-order stamps). matplotlib is confined to this module.
"""

from __future__ import annotations

import io
import math
from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np
import pandas as pd
from matplotlib.figure import Figure
from matplotlib.patches import Circle, Polygon, Rectangle

from tubempc.scenario import Scenario, ScenarioError

__all__ = [
    "MAX_PLOT_POINTS",
    "FigureSpec",
    "inputs_figure",
    "render_figures",
    "robustness_figure",
    "sampling_figure",
    "states_figure",
    "tube_figure",
    "workspace_figure",
]

MAX_PLOT_POINTS = 5_000  # map paths are decimated to this many points; markers (violations, run) stay exact
ENVELOPE_BUCKETS = 1_000  # time series keep the min and max of each of this many time buckets: spikes stay
MAX_BAND_POINTS = 2_000  # the tube band outline (a polygon: costly to draw) per side
_DPI = 110
_KIND_COLOURS = {"unsafe": "#d62728", "labelled": "#2ca02c", "free": "#7f7f7f"}
_FAIL_COLOUR = "#d62728"


@dataclass(frozen=True, slots=True)
class FigureSpec:
    """One rendered figure: a file stem (``workspace``), a caption, and the PNG bytes."""

    stem: str
    caption: str
    png: bytes


def _png(fig: Figure) -> bytes:
    buf = io.BytesIO()
    fig.savefig(buf, format="png", dpi=_DPI)
    return buf.getvalue()


def _envelope(frame: pd.DataFrame, columns: Sequence[str]) -> pd.DataFrame:
    """Rows holding the min and the max of every column in each of ``ENVELOPE_BUCKETS`` consecutive buckets.

    Drawing 1e6 samples into 800 pixels shows nothing more than this, and no excursion is lost.
    """
    n = len(frame)
    if n <= 4 * ENVELOPE_BUCKETS:
        return frame
    k = math.ceil(n / ENVELOPE_BUCKETS)
    pad = (-n) % k
    keep = [np.array([0, n - 1])]
    for col in columns:
        v = frame[col].to_numpy(dtype=float)
        blocks = np.concatenate([v, np.full(pad, v[-1])]).reshape(-1, k)
        offsets = np.arange(blocks.shape[0]) * k
        nan = np.isnan(blocks)
        keep.append(np.where(nan, np.inf, blocks).argmin(axis=1) + offsets)
        keep.append(np.where(nan, -np.inf, blocks).argmax(axis=1) + offsets)
    return frame.iloc[np.unique(np.clip(np.concatenate(keep), 0, n - 1))]


def _decimate(frame: pd.DataFrame) -> pd.DataFrame:
    n = len(frame)
    if n <= MAX_PLOT_POINTS:
        return frame
    step = math.ceil(n / MAX_PLOT_POINTS)
    return frame.iloc[::step]


def _usable(frame: pd.DataFrame | None, columns: Sequence[str]) -> bool:
    return frame is not None and len(frame) > 0 and all(c in frame.columns for c in columns)


def _region_kind(labels: Sequence[str], unsafe: bool) -> str:
    if unsafe:
        return "unsafe"
    return "labelled" if labels else "free"


def failed_checks(certificate: Mapping[str, Any]) -> list[tuple[str, float]]:
    """(check name, first violation time in s) of every failed check that states a time."""
    out: list[tuple[str, float]] = []
    for check in certificate.get("checks", []) or []:
        if not isinstance(check, Mapping) or check.get("verdict") != "fail":
            continue
        t = check.get("first_violation_time")
        if isinstance(t, int | float) and math.isfinite(float(t)):
            out.append((str(check.get("name", "?")), float(t)))
    return out


def _position_at(trajectory: pd.DataFrame, t_s: float) -> tuple[float, float] | None:
    if not _usable(trajectory, ("t_s", "x_m", "y_m")):
        return None
    t = trajectory["t_s"].to_numpy(dtype=float)
    i = int(np.clip(np.searchsorted(t, t_s), 0, len(t) - 1))
    return float(trajectory["x_m"].iloc[i]), float(trajectory["y_m"].iloc[i])


def _tube_polygon(nominal: pd.DataFrame, radius_m: float) -> np.ndarray | None:
    """Outline of the band of half-width ``radius_m`` around the nominal path (left side, then right reversed)."""
    xy = nominal[["x_m", "y_m"]].to_numpy(dtype=float)
    xy = xy[np.all(np.isfinite(xy), axis=1)]
    if len(xy) > MAX_BAND_POINTS:
        xy = xy[np.unique(np.r_[np.arange(0, len(xy), math.ceil(len(xy) / MAX_BAND_POINTS)), len(xy) - 1])]
    if len(xy) < 2 or radius_m <= 0:
        return None
    keep = np.concatenate([[True], np.any(np.diff(xy, axis=0) != 0, axis=1)])
    xy = xy[keep]
    if len(xy) < 2:
        return None
    tangent = np.gradient(xy, axis=0)
    norm = np.linalg.norm(tangent, axis=1, keepdims=True)
    norm[norm == 0] = 1.0
    normal = np.column_stack([-tangent[:, 1], tangent[:, 0]]) / norm
    left = xy + radius_m * normal
    right = xy - radius_m * normal
    return np.vstack([left, right[::-1]])


def _tube_radius(scenario: Scenario) -> float:
    """r_q, or NaN when the scenario gives none (the tube is then not checked and no nominal is plotted)."""
    try:
        return scenario.tube_radius_m
    except ScenarioError:
        return math.nan


def workspace_figure(certificate: Mapping[str, Any], scenario: Scenario, trajectory: pd.DataFrame | None,
                     nominal: pd.DataFrame | None) -> bytes:
    """The map: workspace box, regions by kind, trajectory, tube band, timed run, violations."""
    fig = Figure(figsize=(8.5, 6.2))
    fig.subplots_adjust(left=0.08, right=0.70, bottom=0.08, top=0.94)  # fixed margins: 2x cheaper than a layout
    ax = fig.add_subplot()
    ws = scenario.workspace
    if ws.polygon is not None:
        ax.add_patch(Polygon(ws.polygon, closed=True, fill=False, lw=1.5, ec="black", label="workspace"))
    else:
        ax.add_patch(Rectangle((ws.x[0], ws.y[0]), ws.x[1] - ws.x[0], ws.y[1] - ws.y[0], fill=False, lw=1.5,
                               ec="black", label="workspace"))
    seen: set[str] = set()
    for region in scenario.regions:
        kind = _region_kind(region.labels, region.unsafe)
        colour = _KIND_COLOURS[kind]
        label = {"unsafe": "unsafe region", "labelled": "labelled region", "free": "unlabelled region"}[kind]
        legend = None if kind in seen else label
        if region.polygon is not None:
            ax.add_patch(Polygon(region.polygon, closed=True, fc=colour, ec=colour, alpha=0.25, label=legend))
            x0, y0, x1, y1 = region.bounds
            anchor = (0.5 * (x0 + x1), y1 - 0.15 * (y1 - y0))
        else:
            ax.add_patch(Circle(region.center, region.radius, fc=colour, ec=colour, alpha=0.25, label=legend))
            anchor = (region.center[0], region.center[1] + 0.45 * region.radius)
        seen.add(kind)
        text = region.name + (f"\n{', '.join(region.labels)}" if region.labels else "")
        ax.annotate(text, anchor, ha="center", va="center", fontsize=8)
    r_q = _tube_radius(scenario)
    if _usable(nominal, ("x_m", "y_m")) and nominal is not None:
        poly = _tube_polygon(nominal, r_q)
        if poly is not None:
            ax.add_patch(Polygon(poly, closed=True, fc="#1f77b4", ec="none", alpha=0.3,
                                 label=f"tube r_q = {r_q:.3g} m"))
        nom = _decimate(nominal)
        ax.plot(nom["x_m"], nom["y_m"], "--", color="#1f77b4", lw=1.0, label="nominal")
    if _usable(trajectory, ("x_m", "y_m")) and trajectory is not None:
        tr = _decimate(trajectory)
        ax.plot(tr["x_m"], tr["y_m"], "-", color="black", lw=1.2, label="trajectory")
        first = trajectory.iloc[0]
        ax.add_patch(Circle((float(first["x_m"]), float(first["y_m"])), scenario.robot.radius, fill=False,
                            ec="black", ls=":", label="robot disc at t = 0"))
        listing: list[str] = []
        for i, entry in enumerate(certificate.get("timed_run", []) or []):
            if not isinstance(entry, Mapping):
                continue
            t = entry.get("time")
            if not isinstance(t, int | float):
                continue
            pos = _position_at(trajectory, float(t))
            if pos is None:
                continue
            ax.plot(*pos, "o", color="#ff7f0e", ms=6, label="timed run" if i == 0 else None)
            ax.annotate(str(i), pos, xytext=(5, -11), textcoords="offset points", fontsize=8, color="#ff7f0e",
                        weight="bold")
            listing.append(f"{i}: {entry.get('region', '?')} @ {float(t):.2f} s")
        if listing:
            shown = listing if len(listing) <= 20 else [*listing[:19], f"... ({len(listing) - 19} more)"]
            ax.text(1.02, 0.0, "timed run\n" + "\n".join(shown), transform=ax.transAxes, va="bottom", ha="left",
                    fontsize=8, color="#ff7f0e")
        by_time: dict[float, list[str]] = {}
        for name, t_fail in failed_checks(certificate):
            by_time.setdefault(round(t_fail, 6), []).append(name)
        for j, (t_fail, names) in enumerate(sorted(by_time.items())):
            pos = _position_at(trajectory, t_fail)
            if pos is None:
                continue
            ax.plot(*pos, "X", color=_FAIL_COLOUR, ms=10, label="first violation" if j == 0 else None)
            ax.annotate(f"{', '.join(names)} @ {t_fail:.2f} s", pos, xytext=(6, 6 + 10 * j),
                        textcoords="offset points", fontsize=8, color=_FAIL_COLOUR)
    pad = 0.1
    ax.set_xlim(ws.x[0] - pad, ws.x[1] + pad)
    ax.set_ylim(ws.y[0] - pad, ws.y[1] + pad)
    ax.set_aspect("equal")
    ax.set_xlabel("x [m]")
    ax.set_ylabel("y [m]")
    ax.set_title("Workspace, trajectory and timed run")
    ax.legend(loc="upper left", bbox_to_anchor=(1.02, 1.0), fontsize=8)
    return _png(fig)


def _mark_violations(axes: Sequence[Any], certificate: Mapping[str, Any]) -> None:
    for ax in axes:
        for name, t_fail in failed_checks(certificate):
            ax.axvline(t_fail, color=_FAIL_COLOUR, lw=0.8, ls=":", label=f"violation: {name}")


def states_figure(certificate: Mapping[str, Any], scenario: Scenario, trajectory: pd.DataFrame | None,
                  nominal: pd.DataFrame | None) -> bytes | None:
    """x(t), y(t), theta(t); nominal and its tube band; the bounds on the robot's centre from the workspace."""
    if trajectory is None or not _usable(trajectory, ("t_s", "x_m", "y_m", "theta_rad")):
        return None
    tr = _envelope(trajectory, ("x_m", "y_m", "theta_rad"))
    nom = (_envelope(nominal, [c for c in ("x_m", "y_m", "theta_rad") if c in nominal.columns])
           if nominal is not None and _usable(nominal, ("t_s", "x_m", "y_m")) else None)
    fig = Figure(figsize=(8.0, 7.5))
    fig.subplots_adjust(left=0.13, right=0.97, bottom=0.07, top=0.95, hspace=0.12)
    axes = fig.subplots(3, 1, sharex=True)
    eta = scenario.robot.radius
    r_q = _tube_radius(scenario)
    bounds = {"x_m": scenario.workspace.x, "y_m": scenario.workspace.y}
    for ax, col, ylabel in zip(axes, ("x_m", "y_m", "theta_rad"), ("x [m]", "y [m]", "theta [rad]"), strict=True):
        ax.plot(tr["t_s"], tr[col], color="black", lw=1.0, label="measured")
        if nom is not None and col in nom.columns:
            ax.plot(nom["t_s"], nom[col], "--", color="#1f77b4", lw=1.0, label="nominal")
            if col in bounds:
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


def inputs_figure(certificate: Mapping[str, Any], scenario: Scenario, inputs: pd.DataFrame | None) -> bytes | None:
    """u1, u2, u3 over time with the input box ``|u_i| <= max_abs[i]``."""
    if inputs is None or not _usable(inputs, ("t_s", "u1", "u2", "u3")):
        return None
    data = _envelope(inputs, ("u1", "u2", "u3"))
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


def tube_figure(certificate: Mapping[str, Any], scenario: Scenario, trajectory: pd.DataFrame | None,
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
    env = _envelope(pd.DataFrame({"t_s": t, "err_m": np.hypot(dx, dy)}), ("err_m",))
    t, err_m = env["t_s"].to_numpy(), env["err_m"].to_numpy()
    r_q = _tube_radius(scenario)
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


def robustness_figure(certificate: Mapping[str, Any], robustness: pd.DataFrame | None) -> bytes | None:
    """The formula's robustness rho(t) in metres; negative means violated at that time."""
    if robustness is None or not _usable(robustness, ("t_s", "rho_m")):
        return None
    data = _envelope(robustness, ("rho_m",))
    t = data["t_s"].to_numpy(dtype=float)
    rho = data["rho_m"].to_numpy(dtype=float)
    fig = Figure(figsize=(8.0, 3.2))
    fig.subplots_adjust(left=0.1, right=0.97, bottom=0.16, top=0.89)
    ax = fig.add_subplot()
    ax.plot(t, rho, color="black", lw=1.0, label="robustness")
    ax.fill_between(t, rho, 0.0, where=rho < 0, color=_FAIL_COLOUR, alpha=0.3, lw=0, label="violated")
    ax.axhline(0.0, color="grey", lw=0.8)
    # Where a bounded window of the formula reaches past the end of the log, rho(t) is undecided (no finite bound):
    # show that span instead of letting the curve stop without explanation.
    duration = certificate.get("duration_s")
    decided = t[np.isfinite(rho)]
    if isinstance(duration, int | float) and math.isfinite(duration) and len(t):
        last = float(decided[-1]) if len(decided) else 0.0
        if last < duration - 1e-9:
            ax.axvspan(last, duration, color="grey", alpha=0.15, lw=0,
                       label="undecided: a window reaches past the end of the log")
        ax.set_xlim(min(0.0, float(t[0])), duration)
    _mark_violations([ax], certificate)
    ax.set_xlabel("t [s]")
    ax.set_ylabel("rho [m]")
    ax.set_title("Robustness of the formula over time")
    ax.grid(alpha=0.3)
    ax.legend(loc="upper right", fontsize=7)
    return _png(fig)


def sampling_figure(scenario: Scenario, trajectory: pd.DataFrame | None) -> bytes | None:
    """Intervals between pose stamps against the MoCap period: dropouts stand out, out-of-order is negative."""
    if trajectory is None or not _usable(trajectory, ("t_s",)) or len(trajectory) < 2:
        return None
    t = trajectory["t_s"].to_numpy(dtype=float)
    dt_s = np.diff(t)
    period_s = 1.0 / scenario.mocap.rate_hz
    fig = Figure(figsize=(8.0, 3.2))
    fig.subplots_adjust(left=0.1, right=0.97, bottom=0.16, top=0.89)
    ax = fig.add_subplot()
    env = _envelope(pd.DataFrame({"t_s": t[1:], "dt_s": dt_s}), ("dt_s",))  # keeps each bucket's min and max
    t_env, dt_env = env["t_s"].to_numpy(), env["dt_s"].to_numpy()
    n_anomalies = int(np.count_nonzero((dt_s > 2.0 * period_s) | (dt_s <= 0) | ~np.isfinite(dt_s)))
    anomalies = (dt_env > 2.0 * period_s) | (dt_env <= 0) | ~np.isfinite(dt_env)
    ax.plot(t_env, dt_env, ".", ms=2, color="black", label="stamp interval")
    if anomalies.any():
        ax.plot(t_env[anomalies], dt_env[anomalies], "o", ms=5, mfc="none", color=_FAIL_COLOUR,
                label=f"gaps > 2 periods or non-increasing ({n_anomalies})")
    ax.axhline(period_s, color="#1f77b4", ls="--", lw=0.8, label=f"MoCap period {period_s * 1e3:.3g} ms")
    ax.set_xlabel("t [s]")
    ax.set_ylabel("dt [s]")
    ax.set_title("Pose sampling intervals")
    ax.grid(alpha=0.3)
    ax.legend(loc="upper right", fontsize=7)
    return _png(fig)


def render_figures(certificate: Mapping[str, Any], scenario: Scenario, *, trajectory: pd.DataFrame | None,
                   nominal: pd.DataFrame | None, inputs: pd.DataFrame | None,
                   robustness: pd.DataFrame | None) -> list[FigureSpec]:
    """Every figure that the data allows, in report order."""
    out: list[FigureSpec] = [FigureSpec(
        "workspace", "Workspace map: regions by kind, trajectory, tube band around the nominal, timed run and "
        "first violations.", workspace_figure(certificate, scenario, trajectory, nominal))]
    optional = (
        ("states", "x(t), y(t), theta(t) with the nominal, the tube band and the workspace bounds.",
         states_figure(certificate, scenario, trajectory, nominal)),
        ("tube", "Tube error |p - p_hat| over time against the tube radius r_q.",
         tube_figure(certificate, scenario, trajectory, nominal)),
        ("inputs", "u1, u2, u3 over time with the input box.", inputs_figure(certificate, scenario, inputs)),
        ("robustness", "Robustness of the formula over time (metres).", robustness_figure(certificate, robustness)),
        ("sampling", "Pose stamp intervals (data quality).", sampling_figure(scenario, trajectory)),
    )
    out.extend(FigureSpec(stem, caption, png) for stem, caption, png in optional if png is not None)
    return out
