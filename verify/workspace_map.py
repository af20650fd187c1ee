"""Certificate + scenario + trajectory -> the workspace map, legible from a 5 m lab to a 150 m field.

input: the certificate (timed run, failed checks and the sub-formula they name), the scenario, the trajectory and
nominal tables -> output: a matplotlib ``Figure`` (``workspace_map``) or its PNG bytes (``workspace_figure``).

What a reader needs from the map, whatever its scale:
- every region visible (a marker where its disc would be smaller than a few pixels), named once (``pond``, not
  ``pond/pond``: labels equal to the name are not repeated), its name *beside* it;
- the path coloured by time (colour bar), arrows for the direction of travel, start and end marked;
- at each first violation, what failed: the obligation (``F[30,50] mission_2 violated``) or the check
  (``obstacle_clearance: R8``) and the time;
- when the map is large against the robot, one zoomed panel around each violation (A, B, ...), boxed on the map.

Text is placed by ``place_texts``: each label tries candidate offsets around its anchor, in order, and takes the
first whose rendered extent (matplotlib's text extents) overlaps no text placed before it and stays inside the axes;
a label with no free place is hidden (the report's tables still list it) and counted in ``hidden_labels``.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass
from typing import Any, Literal

import numpy as np
import pandas as pd
from matplotlib.axes import Axes
from matplotlib.backends.backend_agg import FigureCanvasAgg
from matplotlib.collections import LineCollection
from matplotlib.colors import Normalize
from matplotlib.figure import Figure
from matplotlib.patches import Circle, FancyArrowPatch, Polygon, Rectangle
from matplotlib.text import Annotation, Text
from matplotlib.transforms import Bbox

from tubempc.scenario import Region, Scenario, ScenarioError
from verify.certificate import Certificate, CheckEntry, Verdict
from verify.decimate import envelope

__all__ = ["LARGE_MAP_RATIO", "MapFigure", "Violation", "map_texts", "nominal_layers", "place_texts", "png_bytes",
           "region_caption", "text_box", "violations_of", "workspace_caption", "workspace_figure", "workspace_map"]

#: a map whose larger side exceeds this many robot radii gets zoomed panels around the violations
LARGE_MAP_RATIO = 40.0
MAX_ZOOMS = 3
MAX_PATH_POINTS = 5_000
_DPI = 110
_FIG_W_IN = 9.0
_KIND_COLOURS = {"unsafe": "#d62728", "labelled": "#2ca02c", "free": "#7f7f7f"}
_FAIL_COLOUR = "#d62728"
_RUN_COLOUR = "#ff7f0e"
_MIN_REGION_PX = 4.0  # a region disc smaller than this (radius, pixels) gets a marker at its centre
_DIRECTIONS = ((1, 0), (0, 1), (-1, 0), (0, -1), (1, 1), (-1, 1), (-1, -1), (1, -1))


@dataclass(frozen=True, slots=True)
class MapFigure:
    """The rendered map and how many labels ``place_texts`` had to hide."""

    figure: Figure
    hidden_labels: int


@dataclass(frozen=True, slots=True)
class Violation:
    """A first violation to mark: its time, the checks that report it, and what failed in words."""

    t_s: float
    checks: tuple[str, ...]
    what: str


def _region_kind(labels: Sequence[str], unsafe: bool) -> str:
    if unsafe:
        return "unsafe"
    return "labelled" if labels else "free"


def region_caption(name: str, labels: Sequence[str]) -> str:
    """``R3: mission_2``; a label equal to the name is not repeated (``pond``, not ``pond/pond``)."""
    extra = [lab for lab in labels if lab != name]
    return f"{name}: {', '.join(extra)}" if extra else name


def _describe(check: CheckEntry) -> str:
    if check.subformula:
        return f"{check.subformula} violated"
    region = check.details.get("region")
    if isinstance(region, str) and region:
        return f"{check.name}: {region}"
    return check.name


def violations_of(certificate: Certificate) -> list[Violation]:
    """First violations of the failed checks, grouped by time (to the hundredth of a second)."""
    groups: dict[float, tuple[list[str], list[str]]] = {}
    for check in certificate.checks:
        t = check.first_violation_time
        if check.verdict is not Verdict.FAIL or t is None or not math.isfinite(t):
            continue
        names, whats = groups.setdefault(round(t, 2), ([], []))
        names.append(check.name)
        what = _describe(check)
        if what not in whats:
            whats.append(what)
    return [Violation(t, tuple(n), "\n".join(w)) for t, (n, w) in sorted(groups.items())]


def _position_at(trajectory: pd.DataFrame, t_s: float) -> tuple[float, float] | None:
    t = trajectory["t_s"].to_numpy(dtype=float)
    if t.size == 0:
        return None
    i = int(np.clip(np.searchsorted(t, t_s), 0, len(t) - 1))
    x, y = float(trajectory["x_m"].iloc[i]), float(trajectory["y_m"].iloc[i])
    return (x, y) if math.isfinite(x) and math.isfinite(y) else None


def _decimate(frame: pd.DataFrame, keep_t_s: Sequence[float] = ()) -> pd.DataFrame:
    """At most about ``MAX_PATH_POINTS`` rows of a path: every bucket's extremes of x and y, its gaps, and the
    rows at ``keep_t_s`` (``verify.decimate.envelope``: an excursion or a violation of a long log stays drawn)."""
    return envelope(frame, ("x_m", "y_m"), buckets=MAX_PATH_POINTS // 4, keep_t_s=keep_t_s)


def _tube_polygon(nominal: pd.DataFrame, radius_m: float) -> np.ndarray | None:
    """Outline of the band of half-width ``radius_m`` around the nominal path (left side, then right reversed)."""
    xy = _decimate(nominal)[["x_m", "y_m"]].to_numpy(dtype=float)
    xy = xy[np.all(np.isfinite(xy), axis=1)]
    if len(xy) < 2 or not (math.isfinite(radius_m) and radius_m > 0):
        return None
    xy = xy[np.concatenate([[True], np.any(np.diff(xy, axis=0) != 0, axis=1)])]
    if len(xy) < 2:
        return None
    tangent = np.gradient(xy, axis=0)
    norm = np.linalg.norm(tangent, axis=1, keepdims=True)
    norm[norm == 0] = 1.0
    normal = np.column_stack([-tangent[:, 1], tangent[:, 0]]) / norm
    return np.vstack([xy + radius_m * normal, (xy - radius_m * normal)[::-1]])


def _usable(frame: pd.DataFrame | None, columns: Sequence[str]) -> bool:
    return frame is not None and len(frame) > 0 and all(c in frame.columns for c in columns)


# ---- text placement ------------------------------------------------------------------------------------------------
_HA = Literal["left", "center", "right"]
_VA = Literal["bottom", "center", "top"]
_Offset = tuple[float, float, _HA, _VA]  # (dx, dy) in points, alignments


@dataclass
class _Label:
    text: Annotation
    offsets: list[_Offset]  # tried in order


def _ring(radius_pt: float, pad_pt: float = 3.0, *, far: bool = False) -> list[_Offset]:
    """Candidate offsets just outside a disc of ``radius_pt`` points, then further out (much further: ``far``)."""
    out: list[_Offset] = []
    for extra_pt in (0.0, 10.0, 24.0, *((45.0, 80.0, 130.0) if far else ())):
        r = radius_pt + pad_pt + extra_pt
        for dx, dy in _DIRECTIONS:
            norm = math.hypot(dx, dy)
            ha: _HA = "left" if dx > 0 else ("right" if dx < 0 else "center")
            va: _VA = "bottom" if dy > 0 else ("top" if dy < 0 else "center")
            out.append((r * dx / norm, r * dy / norm, ha, va))
    return out


def text_box(text: Text, renderer: Any) -> Bbox:
    """The extent of the characters of ``text`` (an annotation's arrow is not part of it), with a small margin."""
    if isinstance(text, Annotation):
        text.update_positions(renderer)
    return Text.get_window_extent(text, renderer).expanded(1.04, 1.1)


def _hits(boxes: np.ndarray, box: Bbox) -> bool:
    if boxes.size == 0:
        return False
    return bool(np.any((boxes[:, 0] < box.x1) & (boxes[:, 2] > box.x0) & (boxes[:, 1] < box.y1)
                       & (boxes[:, 3] > box.y0)))


def _crossed(boxes: np.ndarray, a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """Which boxes (x0, y0, x1, y1 rows, pixels) the segment a-b meets (Liang-Barsky clipping, all boxes at once)."""
    if boxes.size == 0:
        return np.zeros(0, dtype=bool)
    d = b - a
    lo, hi = np.zeros(len(boxes)), np.ones(len(boxes))
    ok = np.ones(len(boxes), dtype=bool)
    for p, q in ((-d[0], a[0] - boxes[:, 0]), (d[0], boxes[:, 2] - a[0]), (-d[1], a[1] - boxes[:, 1]),
                 (d[1], boxes[:, 3] - a[1])):
        if p == 0:
            ok &= q >= 0
            continue
        r = q / p
        if p < 0:
            lo = np.maximum(lo, r)
        else:
            hi = np.minimum(hi, r)
    return ok & (lo <= hi)


def _leader(box: Bbox, end: np.ndarray) -> tuple[np.ndarray, np.ndarray] | None:
    """The leader line of a call-out whose text occupies ``box``: from where the line from the box's centre to
    ``end`` (its marker, pixels) leaves the box, to ``end``; None when the marker is inside the box."""
    centre = np.array([(box.x0 + box.x1) / 2, (box.y0 + box.y1) / 2])
    d = end - centre
    exits = [(hi - c) / v if v > 0 else (lo - c) / v for v, c, lo, hi in
             ((d[0], centre[0], box.x0, box.x1), (d[1], centre[1], box.y0, box.y1)) if v != 0]
    t_exit = min(exits, default=math.inf)
    return None if t_exit >= 1.0 else (centre + t_exit * d, end)


def place_texts(fig: Figure, ax: Axes, labels: Sequence[_Label], *, keep_out: np.ndarray | None = None,
                prefer_out: np.ndarray | None = None, lines_keep_out: np.ndarray | None = None) -> int:
    """Give each label the first candidate offset whose extent stays inside the axes and overlaps no text placed
    before it nor a ``keep_out`` box (x0, y0, x1, y1 in pixels: markers); candidates that also miss every
    ``prefer_out`` box (the path) are tried first. A call-out (an annotation with an arrow) also wants its leader
    line (``_leader``) to cross no text placed before it and no ``lines_keep_out`` box that does not hold its marker
    (the zoom boxes), and every label wants to stay off the leader lines placed before it: candidates that keep
    these apart are tried before those that do not. A label with no free place is hidden. Returns the hidden
    count."""
    canvas = fig.canvas if isinstance(fig.canvas, FigureCanvasAgg) else FigureCanvasAgg(fig)
    renderer = canvas.get_renderer()  # type: ignore[no-untyped-call]
    ax.apply_aspect()
    inside = ax.get_window_extent(renderer)
    hard = np.zeros((0, 4)) if keep_out is None else keep_out
    soft = np.zeros((0, 4)) if prefer_out is None else prefer_out
    line_boxes = np.zeros((0, 4)) if lines_keep_out is None else lines_keep_out
    texts = np.zeros((0, 4))  # the text boxes placed so far
    leaders: list[tuple[np.ndarray, np.ndarray]] = []  # the leader lines placed so far

    def lines_clear(label: _Label, box: Bbox) -> tuple[bool, tuple[np.ndarray, np.ndarray] | None]:
        row = np.array([[box.x0, box.y0, box.x1, box.y1]])
        if any(_crossed(row, a, b)[0] for a, b in leaders):
            return False, None
        if not isinstance(label.text, Annotation) or label.text.arrow_patch is None:
            return True, None
        end = np.asarray(ax.transData.transform(label.text.xy), dtype=float)
        leader = _leader(box, end)
        if leader is None:
            return True, None
        holds = ((line_boxes[:, 0] <= end[0]) & (end[0] <= line_boxes[:, 2]) & (line_boxes[:, 1] <= end[1])
                 & (end[1] <= line_boxes[:, 3]))
        clear = not _crossed(texts, *leader).any() and not (_crossed(line_boxes, *leader) & ~holds).any()
        return clear, leader

    hidden = 0
    for label in labels:
        chosen = None
        for strict, apart in ((True, True), (False, True), (False, False)):
            for offset in label.offsets:
                dx, dy, ha, va = offset
                label.text.set_position((dx, dy))
                label.text.set_horizontalalignment(ha)
                label.text.set_verticalalignment(va)
                box = text_box(label.text, renderer)
                if (box.x0 >= inside.x0 and box.x1 <= inside.x1 and box.y0 >= inside.y0 and box.y1 <= inside.y1
                        and not _hits(hard, box) and not (strict and _hits(soft, box))):
                    clear, leader = lines_clear(label, box)
                    if clear or not apart:
                        chosen = offset, box, leader
                        break
            if chosen is not None:
                break
        if chosen is None:
            label.text.set_visible(False)
            hidden += 1
            continue
        (dx, dy, ha, va), box, leader = chosen
        label.text.set_position((dx, dy))
        label.text.set_horizontalalignment(ha)
        label.text.set_verticalalignment(va)
        hard = np.vstack([hard, [box.x0, box.y0, box.x1, box.y1]])
        texts = np.vstack([texts, [box.x0, box.y0, box.x1, box.y1]])
        if leader is not None:
            leaders.append(leader)
    return hidden


def _point_boxes(ax: Axes, points: np.ndarray, half_px: float) -> np.ndarray:
    """(x0, y0, x1, y1) pixel boxes of half-width ``half_px`` around data points (NaN rows dropped)."""
    if points.size == 0:
        return np.zeros((0, 4))
    pts = points[np.all(np.isfinite(points), axis=1)]
    px = ax.transData.transform(pts) if len(pts) else np.zeros((0, 2))
    return np.column_stack([px - half_px, px + half_px])


def _path_points(ax: Axes, trajectory: pd.DataFrame, spacing_px: float = 6.0) -> np.ndarray:
    """Points of the path about ``spacing_px`` apart on screen (what labels should rather not cover)."""
    xy = _decimate(trajectory)[["x_m", "y_m"]].to_numpy(dtype=float)
    xy = xy[np.all(np.isfinite(xy), axis=1)]
    if len(xy) < 2:
        return xy
    px = ax.transData.transform(xy)
    arc = np.concatenate([[0.0], np.cumsum(np.hypot(*np.diff(px, axis=0).T))])
    if arc[-1] <= 0:
        return xy[:1]
    s = np.arange(0.0, arc[-1] + spacing_px, spacing_px)
    return np.column_stack([np.interp(s, arc, xy[:, 0]), np.interp(s, arc, xy[:, 1])])


def map_texts(fig: Figure) -> list[Annotation]:
    """The visible, non-empty annotations on every axes of a map (what ``place_texts`` keeps apart)."""
    return [t for ax in fig.axes for t in ax.texts
            if isinstance(t, Annotation) and t.get_visible() and t.get_text().strip()]


# ---- drawing -------------------------------------------------------------------------------------------------------
def tube_radius_or_nan(scenario: Scenario) -> float:
    """r_q, or NaN when the scenario gives none (the tube is then not checked and no nominal is plotted)."""
    try:
        return scenario.tube_radius_m
    except ScenarioError:
        return math.nan


def _draw_regions(ax: Axes, scenario: Scenario, *, with_legend: bool) -> None:
    seen: set[str] = set()
    for region in scenario.regions:
        kind = _region_kind(region.labels, region.unsafe)
        colour = _KIND_COLOURS[kind]
        name = {"unsafe": "unsafe region", "labelled": "labelled region", "free": "unlabelled region"}[kind]
        legend = name if with_legend and kind not in seen else None
        if region.polygon is not None:
            ax.add_patch(Polygon(np.asarray(region.polygon, dtype=float), closed=True, fc=colour, ec=colour,
                                 alpha=0.25, label=legend))
        else:
            ax.add_patch(Circle(region.center, region.radius, fc=colour, ec=colour, alpha=0.25, label=legend))
        seen.add(kind)


def _anchor(region: Region) -> tuple[tuple[float, float], float]:
    """Where a region's label goes around: a disc's centre and radius; a polygon's bounding-box centre and half
    its larger side."""
    if region.polygon is None:
        return region.center, region.radius
    x0, y0, x1, y1 = region.bounds
    return ((x0 + x1) / 2, (y0 + y1) / 2), max(x1 - x0, y1 - y0) / 2


def _draw_small_region_markers(ax: Axes, scenario: Scenario, px_per_m: float) -> None:
    for region in scenario.regions:
        center, size_m = _anchor(region)
        if size_m * px_per_m < _MIN_REGION_PX:
            colour = _KIND_COLOURS[_region_kind(region.labels, region.unsafe)]
            ax.plot(*center, "o", ms=5, mfc=colour, mec="black", mew=0.5, zorder=3)


def _draw_path(ax: Axes, trajectory: pd.DataFrame, norm: Normalize, *, arrows: int,
               keep_t_s: Sequence[float] = ()) -> LineCollection:
    tr = _decimate(trajectory, keep_t_s)
    xy = tr[["x_m", "y_m"]].to_numpy(dtype=float)
    t = tr["t_s"].to_numpy(dtype=float)
    segments = np.stack([xy[:-1], xy[1:]], axis=1)
    lc = LineCollection(list(segments), cmap="viridis", norm=norm, lw=1.6, zorder=4)
    lc.set_array(0.5 * (t[:-1] + t[1:]))
    ax.add_collection(lc)
    finite = np.all(np.isfinite(xy), axis=1)
    if arrows and finite.sum() > 2:
        pts = xy[finite]
        step = np.hypot(*np.diff(pts, axis=0).T)
        arc = np.concatenate([[0.0], np.cumsum(step)])
        if arc[-1] > 0:
            for s in np.linspace(0, arc[-1], arrows + 2)[1:-1]:
                i = int(np.clip(np.searchsorted(arc, s), 1, len(pts) - 1))
                j = max(i - 1, 0)
                while j > 0 and np.allclose(pts[j], pts[i]):
                    j -= 1
                if np.allclose(pts[j], pts[i]):
                    continue
                ax.add_patch(FancyArrowPatch(tuple(pts[j]), tuple(pts[i]), arrowstyle="-|>", mutation_scale=12,
                                             color="black", lw=0, zorder=5))
    return lc


def nominal_layers(scenario: Scenario, nominal: pd.DataFrame | None) -> tuple[bool, bool]:
    """(the nominal path is drawn, its tube band is drawn): what the map and the states figure draw for these data,
    and what their captions say."""
    if nominal is None or not _usable(nominal, ("t_s", "x_m", "y_m")):
        return False, False
    return True, _tube_polygon(nominal, tube_radius_or_nan(scenario)) is not None


def _draw_nominal(ax: Axes, nominal: pd.DataFrame | None, r_q: float, *, with_legend: bool) -> None:
    if not _usable(nominal, ("t_s", "x_m", "y_m")) or nominal is None:
        return
    poly = _tube_polygon(nominal, r_q)
    if poly is not None:  # add_artist: the axes' limits are the workspace's (add_patch walks every vertex for them)
        ax.add_artist(Polygon(poly, closed=True, fc="#1f77b4", ec="none", alpha=0.3,
                              label=f"tube r_q = {r_q:.3g} m" if with_legend else None))
    nom = _decimate(nominal)
    ax.plot(nom["x_m"], nom["y_m"], "--", color="#1f77b4", lw=0.9, label="nominal" if with_legend else None)


def _px_per_m(fig: Figure, ax: Axes) -> float:
    ax.apply_aspect()
    box = ax.get_window_extent()
    x0, x1 = ax.get_xlim()
    return float(box.width / (x1 - x0)) if x1 > x0 else 1.0


#: room kept between the y axis' label and the figure's left edge (inches)
_LEFT_MARGIN_IN = 0.08


def _keep_left_labels_inside(fig: Figure, ax: Axes, cax: Axes) -> None:
    """Move the map (and the colour bar under it) right until the y tick labels and the y label fit inside the
    figure: a wide workspace fills the map's box, whose fixed left edge leaves too little room for "-1000"."""
    renderer = fig.canvas.get_renderer()  # type: ignore[attr-defined]
    fig_w_px = fig.get_figwidth() * fig.dpi
    for _ in range(3):  # the tick labels can change with the axes' size: settle in a few steps
        box = ax.yaxis.get_tightbbox(renderer)
        if box is None:
            return
        short = _LEFT_MARGIN_IN * fig.dpi - float(box.x0)
        if short <= 0.5:
            return
        shift = short / fig_w_px
        for a in (ax, cax):
            x0, y0, w, h = a.get_position(original=True).bounds
            a.set_position((x0 + shift, y0, w - shift, h))


def _letter(i: int) -> str:
    return chr(ord("A") + i)


def _draw_run(fig: Figure, ax: Axes, cax: Axes, *, certificate: Certificate, trajectory: pd.DataFrame,
              violations: Sequence[Violation], zooms: Sequence[tuple[Violation, tuple[float, float]]],
              eta: float, px_per_m: float) -> tuple[list[_Label], list[_Label], list[tuple[float, float]]]:
    """The path (coloured by time, with its colour bar), its start and end, the timed run's entries and the first
    violations on the map: their labels (start, end and violations; the run's numbers apart) still to be placed and
    the points that labels must not cover."""
    pt_per_px = 72.0 / fig.dpi
    labels: list[_Label] = []
    run_labels: list[_Label] = []
    markers: list[tuple[float, float]] = []
    t = trajectory["t_s"].to_numpy(dtype=float)
    norm = Normalize(vmin=float(np.nanmin(t)), vmax=float(np.nanmax(t)) if t.size > 1 else float(t[0]) + 1.0)
    lc = _draw_path(ax, trajectory, norm, arrows=8, keep_t_s=[v.t_s for v in violations])
    fig.colorbar(lc, cax=cax, orientation="horizontal", label="time along the path t [s]")
    ax.plot([], [], "-", color="#21918c", lw=1.6, label="trajectory (colour: time)")
    first, last = _position_at(trajectory, float(t[0])), _position_at(trajectory, float(t[-1]))
    markers += [p for p in (first, last) if p is not None]
    if first is not None:
        ax.add_patch(Circle(first, eta, fill=False, ec="black", ls=":", zorder=5))
        ax.plot(*first, "o", ms=7, mfc="white", mec="black", zorder=6, label="start (robot disc dotted)")
        labels.append(_Label(ax.annotate(f"start, t = {t[0]:.2f} s", first, xytext=(0, 0),
                                         textcoords="offset points", fontsize=8),
                             _ring(max(eta * px_per_m, 5.0) * pt_per_px)))
    if last is not None:
        ax.plot(*last, "s", ms=6, mfc="black", mec="black", zorder=6, label="end")
        # kept off the robot's disc at the end, as the start label is (it covered the disc)
        labels.append(_Label(ax.annotate(f"end, t = {t[-1]:.2f} s", last, xytext=(0, 0), textcoords="offset points",
                                         fontsize=8), _ring(max(eta * px_per_m, 5.0) * pt_per_px)))
    for i, entry in enumerate(certificate.timed_run):
        pos = _position_at(trajectory, entry.time)
        if pos is None:
            continue
        markers.append(pos)
        ax.plot(*pos, "o", color=_RUN_COLOUR, ms=5, zorder=6, label="timed run entry (#)" if i == 0 else None)
        run_labels.append(_Label(ax.annotate(str(i), pos, xytext=(0, 0), textcoords="offset points", fontsize=8,
                                             color=_RUN_COLOUR, weight="bold"), _ring(4.0 * pt_per_px)))
    for j, v in enumerate(violations):
        pos = _position_at(trajectory, v.t_s)
        if pos is None:
            continue
        markers.append(pos)
        ax.plot(*pos, "X", color=_FAIL_COLOUR, ms=11, mec="white", mew=0.8, zorder=7,
                label="first violation" if j == 0 else None)
        zoom_tag = next((f"[{_letter(k)}] " for k, (z, _) in enumerate(zooms) if z is v), "")
        text = f"{zoom_tag}{v.what}\nt = {v.t_s:.2f} s"
        labels.insert(j, _Label(ax.annotate(text, pos, xytext=(0, 0), textcoords="offset points", fontsize=8,
                                            color=_FAIL_COLOUR, weight="bold",
                                            bbox={"boxstyle": "round,pad=0.2", "fc": "white", "ec": _FAIL_COLOUR,
                                                  "alpha": 0.9},
                                            arrowprops={"arrowstyle": "-", "color": _FAIL_COLOUR, "lw": 0.8}),
                                _ring(8.0 * pt_per_px, pad_pt=10.0, far=True)))
    return labels, run_labels, markers


def workspace_map(certificate: Certificate, scenario: Scenario, trajectory: pd.DataFrame | None,
                  nominal: pd.DataFrame | None) -> MapFigure:
    """The map (see the module docstring) and the number of labels that found no free place."""
    ws = scenario.workspace
    width_m, height_m = ws.x[1] - ws.x[0], ws.y[1] - ws.y[0]
    eta = scenario.robot.radius
    has_path = _usable(trajectory, ("t_s", "x_m", "y_m")) and trajectory is not None
    violations = violations_of(certificate) if has_path else []
    zooms = _zooms(scenario, trajectory, violations)
    pad = 0.02 * max(width_m, height_m)
    # layout in inches, bottom up: zoom row, colour bar (label below it), map (height from the workspace's aspect)
    map_w_in = 0.64 * _FIG_W_IN
    map_h_in = float(np.clip(map_w_in * (height_m + 2 * pad) / (width_m + 2 * pad), 3.2, 7.0))
    zoom_in = 2.9 if zooms else 0.0
    cbar_in = zoom_in + 0.6
    map_in = cbar_in + 0.8
    fig_h_in = map_in + map_h_in + 0.45
    fig = Figure(figsize=(_FIG_W_IN, fig_h_in), dpi=_DPI)
    FigureCanvasAgg(fig)
    ax = fig.add_axes((0.07, map_in / fig_h_in, 0.64, map_h_in / fig_h_in))
    cax = fig.add_axes((0.07, cbar_in / fig_h_in, 0.64, 0.16 / fig_h_in))
    if ws.polygon is not None:
        ax.add_patch(Polygon(np.asarray(ws.polygon, dtype=float), closed=True, fill=False, lw=1.5, ec="black",
                             label="workspace"))
    else:
        ax.add_patch(Rectangle((ws.x[0], ws.y[0]), width_m, height_m, fill=False, lw=1.5, ec="black",
                               label="workspace"))
    _draw_regions(ax, scenario, with_legend=True)
    _draw_nominal(ax, nominal, tube_radius_or_nan(scenario), with_legend=True)
    ax.set_xlim(ws.x[0] - pad, ws.x[1] + pad)
    ax.set_ylim(ws.y[0] - pad, ws.y[1] + pad)
    ax.set_aspect("equal")
    ax.set_xlabel("x [m]")
    ax.set_ylabel("y [m]")
    _keep_left_labels_inside(fig, ax, cax)  # before the labels are placed: they are placed for the final axes
    px_per_m = _px_per_m(fig, ax)
    pt_per_px = 72.0 / fig.dpi
    _draw_small_region_markers(ax, scenario, px_per_m)
    labels: list[_Label] = []
    run_labels: list[_Label] = []
    markers: list[tuple[float, float]] = []  # points that labels must not cover
    if has_path and trajectory is not None:
        labels, run_labels, markers = _draw_run(fig, ax, cax, certificate=certificate, trajectory=trajectory,
                                                violations=violations, zooms=zooms, eta=eta, px_per_m=px_per_m)
    else:
        cax.set_visible(False)
    for region in scenario.regions:
        center, size_m = _anchor(region)
        r_pt = max(size_m * px_per_m, _MIN_REGION_PX) * pt_per_px
        labels.append(_Label(ax.annotate(region_caption(region.name, region.labels), center,
                                         xytext=(0, 0), textcoords="offset points", fontsize=8), _ring(r_pt)))
    path = (_path_points(ax, trajectory, 6.0) if has_path and trajectory is not None else np.zeros((0, 2)))
    half_m = max(8.0 * eta, 0.03 * max(width_m, height_m))  # of each zoom box, boxed on the map below
    zoom_px = np.array([[*ax.transData.transform((c[0] - half_m, c[1] - half_m)),
                         *ax.transData.transform((c[0] + half_m, c[1] + half_m))]
                        for c in (_inside_limits(ax, pos, half_m) for _, pos in zooms)]).reshape(-1, 4)
    hidden = place_texts(fig, ax, [*labels, *run_labels], keep_out=_point_boxes(ax, np.array(markers), 6.0),
                         prefer_out=np.vstack([_point_boxes(ax, path, 3.0), zoom_px]), lines_keep_out=zoom_px)
    ax.set_title("Workspace, trajectory and timed run")
    ax.legend(loc="upper left", bbox_to_anchor=(1.02, 1.0), fontsize=8, borderaxespad=0.0)
    for k, (v, pos) in enumerate(zooms):
        _zoom_panel(fig, ax, _Zoom(k, len(zooms), v, pos, half_m), scenario, trajectory=trajectory, nominal=nominal)
    return MapFigure(fig, hidden)


def _zooms(scenario: Scenario, trajectory: pd.DataFrame | None,
           violations: Sequence[Violation]) -> list[tuple[Violation, tuple[float, float]]]:
    """The violations that get a zoomed panel (a map large against the robot; one per place, at most
    ``MAX_ZOOMS``) with their positions."""
    ws = scenario.workspace
    if trajectory is None or max(ws.x[1] - ws.x[0], ws.y[1] - ws.y[0]) <= LARGE_MAP_RATIO * scenario.robot.radius:
        return []
    zooms: list[tuple[Violation, tuple[float, float]]] = []
    for v in violations:
        pos = _position_at(trajectory, v.t_s)
        if pos is not None and all(math.dist(pos, p) > 1e-9 for _, p in zooms):
            zooms.append((v, pos))
    return zooms[:MAX_ZOOMS]


def workspace_caption(certificate: Certificate, scenario: Scenario, trajectory: pd.DataFrame | None,
                      nominal: pd.DataFrame | None) -> str:
    """The map's caption: it names what ``workspace_map`` draws for these data, and nothing it does not."""
    has_path = trajectory is not None and _usable(trajectory, ("t_s", "x_m", "y_m"))
    parts = ["regions"]
    if has_path:
        parts.append("the path coloured by time with its direction")
    drawn_nominal, drawn_band = nominal_layers(scenario, nominal)
    if drawn_nominal:
        parts.append("the nominal path with its tube band" if drawn_band else "the nominal path")
    if has_path and certificate.timed_run:
        parts.append("the timed run (numbered)")
    violations = violations_of(certificate) if has_path else []
    if violations:
        parts.append("each first violation with what failed")
    text = "Workspace map: " + ", ".join(parts[:-1]) + (" and " if len(parts) > 1 else "") + parts[-1]
    zooms = _zooms(scenario, trajectory, violations) if has_path else []
    if zooms:
        text += f"; below, a zoomed panel around {'each violation' if len(zooms) > 1 else 'the violation'}"
    return text + "."


@dataclass(frozen=True, slots=True)
class _Zoom:
    index: int
    count: int
    violation: Violation
    pos: tuple[float, float]
    half_m: float


def _zoom_panel(fig: Figure, main: Axes, zoom: _Zoom, scenario: Scenario, *, trajectory: pd.DataFrame | None,
                nominal: pd.DataFrame | None) -> None:
    """Panel ``zoom.index`` of the row under the map: the neighbourhood of one violation, boxed on the map."""
    k, v, pos, half_m = zoom.index, zoom.violation, zoom.pos, zoom.half_m
    centre = _inside_limits(main, pos, half_m)  # the box stays inside the map's frame; the panel shows the box
    width = 0.86 / zoom.count
    fig_h_in = fig.get_figheight()
    ax = fig.add_axes((0.07 + k * width, 0.35 / fig_h_in, width - 0.05, 2.2 / fig_h_in))
    _draw_regions(ax, scenario, with_legend=False)
    _draw_nominal(ax, nominal, tube_radius_or_nan(scenario), with_legend=False)
    if trajectory is not None:
        t = trajectory["t_s"].to_numpy(dtype=float)
        near = (np.abs(trajectory["x_m"].to_numpy(dtype=float) - centre[0]) <= 2 * half_m) & (
            np.abs(trajectory["y_m"].to_numpy(dtype=float) - centre[1]) <= 2 * half_m)
        part = trajectory[near]
        if len(part) > 1:
            _draw_path(ax, part, Normalize(vmin=float(np.nanmin(t)), vmax=float(np.nanmax(t))), arrows=0,
                       keep_t_s=[v.t_s])
    for region in scenario.regions:
        (cx, cy), _ = _anchor(region)
        if abs(cx - centre[0]) < half_m and abs(cy - centre[1]) < half_m:
            ax.text(cx, cy, region.name, ha="center", va="center", fontsize=7,
                    clip_on=True)
    ax.add_patch(Circle(pos, scenario.robot.radius, fill=False, ec=_FAIL_COLOUR, lw=1.2, zorder=6))
    ax.plot(*pos, "X", color=_FAIL_COLOUR, ms=9, mec="white", mew=0.8, zorder=7)
    ax.set_xlim(centre[0] - half_m, centre[0] + half_m)
    ax.set_ylim(centre[1] - half_m, centre[1] + half_m)
    ax.set_aspect("equal")
    ax.tick_params(labelsize=7)
    ax.set_title(f"[{_letter(k)}] t = {v.t_s:.2f} s (robot disc in red)", fontsize=8)
    main.add_patch(Rectangle((centre[0] - half_m, centre[1] - half_m), 2 * half_m, 2 * half_m, fill=False,
                             ec=_FAIL_COLOUR, lw=1.0, ls="--", zorder=8))


def _inside_limits(ax: Axes, pos: tuple[float, float], half_m: float) -> tuple[float, float]:
    """The centre nearest ``pos`` of a square of half-side ``half_m`` inside the axes' limits (``pos`` itself when
    the square fits around it; the limits' centre on an axis shorter than the square)."""
    out = []
    for p, (lo, hi) in ((pos[0], ax.get_xlim()), (pos[1], ax.get_ylim())):
        out.append((lo + hi) / 2 if hi - lo <= 2 * half_m else min(max(p, lo + half_m), hi - half_m))
    return out[0], out[1]


def workspace_figure(certificate: Certificate, scenario: Scenario, trajectory: pd.DataFrame | None,
                     nominal: pd.DataFrame | None) -> bytes:
    """The map as PNG bytes."""
    return png_bytes(workspace_map(certificate, scenario, trajectory, nominal).figure)


def _title_needs_placing(ax: Axes) -> bool:
    """Whether matplotlib's automatic title placement could move ``ax``'s title off its plain place (``y = 1``, its
    pad above the axes): only when the x axis has tick labels or its label on top, when the y axis shows an offset
    text (``1e-5``, ``+1e3``) for the ticks it will draw, or when other axes are attached to it (child axes, a twin).
    The y ticks are computed as a draw computes them (locator, then formatter)."""
    xaxis = ax.xaxis
    if xaxis.get_label_position() == "top" or xaxis.get_ticks_position() in ("top", "default") or \
            any(tick.label2.get_visible() for tick in (*xaxis.majorTicks[:1], *xaxis.minorTicks[:1])):
        return True
    fig = ax.get_figure()
    box = ax.get_position().bounds
    if ax.child_axes or fig is None or any(other is not ax and other.get_position().bounds == box
                                           for other in fig.axes):  # a twin shares its axes' place
        return True
    formatter = ax.yaxis.get_major_formatter()
    formatter.format_ticks([float(v) for v in ax.yaxis.get_majorticklocs()])
    return bool(ax.yaxis.offsetText.get_visible() and formatter.get_offset())


def _fix_title_positions(fig: Figure) -> None:
    """Keep each title at its plain place where automatic placement would leave it there (``_title_needs_placing``).
    matplotlib otherwise re-places every titled axes' title at each draw by measuring the tick labels of its axes
    (about an eighth of drawing a report's figures); fixed where nothing can move it, the pixels are the same."""
    for ax in fig.axes:
        if any(ax.get_title(loc) for loc in ("center", "left", "right")) and not _title_needs_placing(ax):
            ax._autotitlepos = False  # type: ignore[attr-defined]  # what set_title(y=1.0) sets: not re-placed


def png_bytes(fig: Figure) -> bytes:
    """A figure as PNG at the reports' resolution. zlib level 3 instead of Pillow's default 6: the same pixels,
    files about 7 % larger, encoded in about half the time. Titles that nothing can move are not re-placed at the
    draw (``_fix_title_positions``)."""
    import io

    _fix_title_positions(fig)
    buf = io.BytesIO()
    fig.savefig(buf, format="png", dpi=_DPI, pil_kwargs={"compress_level": 3})
    return buf.getvalue()
