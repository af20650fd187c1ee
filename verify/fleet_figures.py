"""Figures of a multi-robot certificate: the map with one path per robot, the obligations, the separation over time,
and each robot's own clearance and sampling panels.

input: a certificate with ``robots`` (``verify.fleet``), the scenario and the result's tables (``trajectory/<robot>``,
``separation/<a>-<b>``) -> output: ``FigureSpec`` values for ``verify.report`` (PNG bytes). Nothing is judged here:
verdicts, margins and times are the certificate's; the separation band is the bound the judging code computed.
"""

from __future__ import annotations

from collections.abc import Mapping
from typing import Any

import numpy as np
import pandas as pd
from matplotlib.figure import Figure
from matplotlib.patches import Circle, Polygon, Rectangle

from tubempc.scenario import Scenario
from verify.certificate import Certificate
from verify.figures import FigureSpec, clearance_figure, obligations_figure, sampling_figure
from verify.judging import FormulaJudgement
from verify.workspace_map import _draw_regions

__all__ = ["ROBOT_COLOURS", "fleet_map_figure", "render_fleet_figures", "separation_figure"]

#: one colour per robot, in the scenario's order (colour-blind safe, distinct from the regions' fills)
ROBOT_COLOURS = ("#1f77b4", "#d95f02", "#7570b3", "#e7298a", "#66a61e", "#a6761d")
_FAIL_COLOUR = "#d62728"
_DPI = 110


def _png(fig: Figure) -> bytes:
    import io

    buf = io.BytesIO()
    fig.savefig(buf, format="png", dpi=_DPI)
    return buf.getvalue()


def _frame(tables: Mapping[str, Any], key: str) -> pd.DataFrame | None:
    cols = tables.get(key)
    return None if cols is None else pd.DataFrame(cols)


def _at(frame: pd.DataFrame, t_s: float) -> tuple[float, float] | None:
    t = frame["t_s"].to_numpy(dtype=float)
    if not t.size:
        return None
    k = int(np.clip(np.searchsorted(t, t_s), 0, t.size - 1))
    x, y = float(frame["x_m"].iloc[k]), float(frame["y_m"].iloc[k])
    return (x, y) if np.isfinite(x) and np.isfinite(y) else None


def fleet_map_figure(cert: Certificate, scenario: Scenario, paths: Mapping[str, pd.DataFrame]) -> bytes:
    """Workspace, regions (named), one path per robot in its colour with its disc at the start and the end, each
    robot's timed-run entries, and the first violation of every failed check (the separation: both discs)."""
    ws = scenario.workspace
    w, h = ws.x[1] - ws.x[0], ws.y[1] - ws.y[0]
    fig = Figure(figsize=(9.0, float(np.clip(9.0 * h / w, 3.5, 8.0)) + 0.8))
    ax = fig.add_subplot()
    if ws.polygon is not None:
        ax.add_patch(Polygon(np.asarray(ws.polygon, dtype=float), closed=True, fill=False, lw=1.5, ec="black"))
    else:
        ax.add_patch(Rectangle((ws.x[0], ws.y[0]), w, h, fill=False, lw=1.5, ec="black"))
    _draw_regions(ax, scenario, with_legend=False)
    for region in scenario.regions:
        x0, _, x1, y1 = region.bounds
        ax.annotate(region.name, ((x0 + x1) / 2, y1), ha="center", va="bottom", fontsize=7, color="#444444")
    robots = [r.name for r in cert.robots or []]
    colour = {name: ROBOT_COLOURS[i % len(ROBOT_COLOURS)] for i, name in enumerate(robots)}
    radius = {r.name: r.radius_m for r in cert.robots or []}
    for name in robots:
        frame = paths.get(name)
        if frame is None or frame.empty:
            continue
        x, y = frame["x_m"].to_numpy(dtype=float), frame["y_m"].to_numpy(dtype=float)
        ax.plot(x, y, color=colour[name], lw=1.6, label=name, zorder=4)
        ok = np.isfinite(x) & np.isfinite(y)
        if ok.any():
            i0, i1 = int(np.argmax(ok)), int(len(ok) - 1 - np.argmax(ok[::-1]))
            ax.add_patch(Circle((x[i0], y[i0]), radius[name], fill=False, ec=colour[name], ls="--", lw=1.0))
            ax.add_patch(Circle((x[i1], y[i1]), radius[name], fc=colour[name], ec=colour[name], alpha=0.35))
            ax.annotate(f"{name} start", (x[i0], y[i0]), xytext=(4, -10), textcoords="offset points", fontsize=7,
                        color=colour[name])
        for entry in cert.timed_run:
            if entry.robot == name:
                pos = _at(frame, entry.time)
                if pos is not None:
                    ax.plot(*pos, "o", ms=4, color=colour[name], mec="black", mew=0.5, zorder=5)
                    ax.annotate(f"{entry.region} {entry.time:.1f} s", pos, xytext=(4, 4),
                                textcoords="offset points", fontsize=6, color=colour[name])
    for check in cert.checks:
        t = check.first_violation_time
        if check.verdict.value != "fail" or t is None:
            continue
        who = [check.name.split("/", 1)[0]] if "/" in check.name else (
            str(check.details.get("pair", "")).split("-") if check.name == "separation" else [])
        spots = [p for n in who if n in paths and (p := _at(paths[n], t)) is not None]
        for p in spots:
            ax.plot(*p, "x", ms=9, mew=2.0, color=_FAIL_COLOUR, zorder=6)
        if len(spots) == 2:
            ax.plot([spots[0][0], spots[1][0]], [spots[0][1], spots[1][1]], color=_FAIL_COLOUR, lw=1.2, zorder=6)
        if spots:
            ax.annotate(f"{check.name} fails at {t:.2f} s", spots[0], xytext=(6, -12), textcoords="offset points",
                        fontsize=7, color=_FAIL_COLOUR)
    pad = 0.02 * max(w, h)
    ax.set_xlim(ws.x[0] - pad, ws.x[1] + pad)
    ax.set_ylim(ws.y[0] - pad, ws.y[1] + pad)
    ax.set_aspect("equal")
    ax.set_xlabel("x [m]")
    ax.set_ylabel("y [m]")
    ax.set_title("Workspace map: one path per robot (dashed disc: start, filled disc: end)")
    ax.grid(alpha=0.2)
    ax.legend(loc="upper left", bbox_to_anchor=(1.01, 1.0), fontsize=8, title="robots")
    fig.tight_layout()
    return _png(fig)


def separation_figure(cert: Certificate, tables: Mapping[str, Any]) -> bytes | None:
    """Per pair: the band the separation margin (distance between the discs minus ``min_m``) lies in at the joint
    samples; below 0 for certain is a violation, a band reaching below 0 is undecided."""
    keys = sorted(k for k in tables if k.startswith("separation/"))
    if not keys:
        return None
    fig = Figure(figsize=(8.0, 1.2 + 1.9 * len(keys)))
    axes = fig.subplots(len(keys), 1, sharex=True, squeeze=False)[:, 0]
    check = cert.check("separation")
    for ax, key in zip(axes, keys, strict=True):
        frame = pd.DataFrame(tables[key])
        pair = key.split("/", 1)[1]
        t = frame["t_s"].to_numpy(dtype=float)
        lo, hi = frame["lo_m"].to_numpy(dtype=float), frame["hi_m"].to_numpy(dtype=float)
        lo_c, hi_c = np.clip(lo, -5.0, None), np.clip(hi, None, 1e3)
        ax.fill_between(t, lo_c, hi_c, color="#1f77b4", alpha=0.35, lw=0, label="margin bounds")
        ax.plot(t, 0.5 * (lo_c + hi_c), color="#1f77b4", lw=0.8)
        ax.axhline(0.0, color="black", lw=0.8)
        bad = hi < 0
        if bad.any():
            ax.fill_between(t, hi_c, 0.0, where=bad, color=_FAIL_COLOUR, alpha=0.4, lw=0, label="violated")
        doubt = (lo < 0) & ~bad
        if doubt.any():
            ax.plot(t[doubt], np.zeros(int(doubt.sum())), "|", color="#ff7f0e", ms=8, label="may be violated")
        entry = next((p for p in (check.details.get("pairs", []) if check else [])
                      if "-".join(p.get("robots", [])) == pair), None)
        verdict = entry.get("verdict", "?") if entry else "?"
        min_m = float(frame["min_m"].iloc[0]) if len(frame) else float("nan")
        ax.set_title(f"{pair}: distance between the discs - {min_m:g} m ({verdict})", fontsize=9)
        ax.set_ylabel("margin [m]")
        ax.grid(alpha=0.3)
        ax.legend(loc="upper right", fontsize=7)
        if entry and entry.get("first_violation_time") is not None:
            ax.axvline(entry["first_violation_time"], color=_FAIL_COLOUR, ls="--", lw=1.0)
    axes[-1].set_xlabel("t [s]")
    fig.tight_layout()
    return _png(fig)


def render_fleet_figures(cert: Certificate, scenario: Scenario, tables: Mapping[str, Any], *,
                         judgement: FormulaJudgement | None = None) -> list[FigureSpec]:
    """The figures of a multi-robot report, in reading order."""
    robots = [r.name for r in cert.robots or []]
    paths = {n: f for n in robots if (f := _frame(tables, f"trajectory/{n}")) is not None}
    out = [FigureSpec("workspace", "Workspace map: each robot's path in its own colour, its timed-run entries, and "
                                   "the first violation of every failed check.",
                      fleet_map_figure(cert, scenario, paths))]
    panels = obligations_figure(cert.panels, cert.duration_s, judgement.panels if judgement is not None else ())
    if panels is not None:
        out.append(FigureSpec("obligations", "Each obligation of the formula over the joint run, as the certificate "
                                             "states it.", panels))
    sep = separation_figure(cert, tables)
    if sep is not None:
        out.append(FigureSpec("separation", "Separation over time: for each pair of robots the distance between "
                                            "their discs minus min_m (bounds at the joint samples).", sep))
    for name in robots:
        if name not in paths or name not in scenario.robot_names:
            continue
        own = scenario.robot_scenario(name)
        entry = next((r for r in cert.robots or () if r.name == name), None)
        # the robot's own data quality states its dropout threshold and count (the sampling figure reads them)
        own_cert = cert if entry is None else cert.model_copy(update={"data_quality": entry.data_quality})
        for stem, caption, png in (
                (f"clearance-{name}", f"{name}: clearance of its disc from unsafe regions and the workspace edge.",
                 clearance_figure(cert, own, paths[name])),
                (f"sampling-{name}", f"{name}: pose stamp intervals (data quality).",
                 sampling_figure(own_cert, own, paths[name]))):
            if png is not None:
                out.append(FigureSpec(stem, caption, png))
    return out
