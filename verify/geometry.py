"""Region geometry of the certifier (its own, independent of the planner): positions -> signed margins in metres.

input: sample positions ``x_m, y_m`` (arrays) and a scenario -> output: margins that are 1-Lipschitz in the position
(so the motion between two samples bounds them), the region containing the robot disc, and the conservative bounds
of a margin over the gap between two samples given the largest distance the robot can travel in that gap.

Regions are discs or simple polygons. Let ``sd(p)`` be the signed distance of p to the region's boundary, positive
inside (disc: ``r - |p - c|``; polygon: the distance to the nearest edge, signed by the even-odd rule). Both are
exact and 1-Lipschitz. Conventions (metres; positive = the proposition holds):
* safe region R: the disc ``M(p, eta)`` is inside R: margin ``sd(p) - eta``;
* unsafe region R: the disc intersects R: margin ``sd(p) + eta``;
* workspace box: the disc is inside the box: margin ``min(x - x0, x1 - x, y - y0, y1 - y) - eta``; workspace
  polygon: ``sd(p) - eta``.
A margin of exactly 0 is reported as undecided by the monitor (see docs/certifier.md).
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np
import numpy.typing as npt

from tubempc.scenario import Scenario

__all__ = [
    "GapBounds",
    "containing_region",
    "containment",
    "gap_bounds",
    "label_margins",
    "polygon_signed_distance",
    "region_margins",
    "step_bound_m",
    "step_bound_regular_m",
    "workspace_margin",
]

FloatArray = npt.NDArray[np.float64]
IntArray = npt.NDArray[np.int64]


def region_margins(x_m: FloatArray, y_m: FloatArray, scenario: Scenario,
                   indices: Sequence[int] | None = None) -> FloatArray:
    """``(n_regions, n)`` margins, one row per region in scenario order (NaN where the position is NaN); with
    ``indices``, one row per listed region, in that order."""
    eta = scenario.robot.radius
    regions = scenario.regions if indices is None else [scenario.regions[i] for i in indices]
    out = np.empty((len(regions), x_m.shape[0]), dtype=np.float64)
    for k, r in enumerate(regions):
        if r.polygon is not None:
            sd = polygon_signed_distance(x_m, y_m, r.polygon)
            out[k] = sd + eta if r.unsafe else sd - eta
            continue
        d = np.hypot(x_m - r.center[0], y_m - r.center[1])
        out[k] = (r.radius + eta - d) if r.unsafe else (r.radius - eta - d)
    return out


def _axis_rectangle(vertices: tuple[tuple[float, float], ...]) -> tuple[float, float, float, float] | None:
    """``(x0, y0, x1, y1)`` when the polygon is an axis-aligned rectangle (either vertex order), else None."""
    if len(vertices) != 4:
        return None
    xs = sorted({v[0] for v in vertices})
    ys = sorted({v[1] for v in vertices})
    if len(xs) != 2 or len(ys) != 2:
        return None
    for (ax, ay), (bx, by) in zip(vertices, (*vertices[1:], vertices[0]), strict=True):
        if ax != bx and ay != by:  # a diagonal edge: not a rectangle's ring
            return None
    return xs[0], ys[0], xs[1], ys[1]


def polygon_signed_distance(x_m: FloatArray, y_m: FloatArray,
                            vertices: tuple[tuple[float, float], ...]) -> FloatArray:
    """Signed distance of each point to a simple polygon's boundary: positive inside, negative outside, 0 on it,
    NaN for a NaN point. Exact up to rounding: the distance to each edge segment (clamped projection), the sign
    from the even-odd crossing rule, block by block so the temporaries stay in cache. An axis-aligned rectangle
    (rooms, tables) takes a closed form: inside ``min(x - x0, x1 - x, y - y0, y1 - y)``, outside minus the
    distance to the nearest point of the box."""
    rect = _axis_rectangle(vertices)
    if rect is not None:
        return _rectangle_signed_distance(x_m, y_m, rect)
    n = x_m.shape[0]
    out = np.empty(n, dtype=np.float64)
    vx = np.array([v[0] for v in vertices], dtype=np.float64)
    vy = np.array([v[1] for v in vertices], dtype=np.float64)
    vy_next = np.roll(vy, -1)  # the crossing rule compares the vertices themselves (vy + ey may round)
    ex, ey = np.roll(vx, -1) - vx, vy_next - vy
    inv_len2 = 1.0 / (ex * ex + ey * ey)  # a simple polygon has no zero-length edge
    for s in range(0, n, _BLOCK):
        e = min(n, s + _BLOCK)
        px, py = x_m[s:e], y_m[s:e]
        best = np.full(e - s, np.inf)
        inside = np.zeros(e - s, dtype=bool)
        for k in range(vx.shape[0]):
            wx, wy = px - vx[k], py - vy[k]
            t = np.clip((wx * ex[k] + wy * ey[k]) * inv_len2[k], 0.0, 1.0)
            wx -= t * ex[k]
            wy -= t * ey[k]
            np.minimum(best, wx * wx + wy * wy, out=best)
            if ey[k] != 0.0:  # a horizontal edge never crosses the ray
                y0, y1 = vy[k], vy_next[k]
                straddle = (y0 > py) != (y1 > py)
                x_cross = vx[k] + (py - y0) * (ex[k] / ey[k])
                inside ^= straddle & (px < x_cross)
        np.sqrt(best, out=best)
        out[s:e] = np.where(inside, best, -best)
    nan = np.isnan(x_m) | np.isnan(y_m)
    if nan.any():
        out[nan] = np.nan
    return out


def _rectangle_signed_distance(x_m: FloatArray, y_m: FloatArray,
                               rect: tuple[float, float, float, float]) -> FloatArray:
    x0, y0, x1, y1 = rect
    n = x_m.shape[0]
    out = np.empty(n, dtype=np.float64)
    for s in range(0, n, _BLOCK):
        e = min(n, s + _BLOCK)
        px, py = x_m[s:e], y_m[s:e]
        dx = np.maximum(x0 - px, px - x1)  # > 0 outside the slab, -(distance to the nearer side) inside
        dy = np.maximum(y0 - py, py - y1)
        inside = np.minimum(-dx, -dy)
        ox = np.maximum(dx, 0.0)
        oy = np.maximum(dy, 0.0)
        outside = np.sqrt(ox * ox + oy * oy)
        out[s:e] = np.where((dx <= 0.0) & (dy <= 0.0), inside, -outside)
    return out


#: elements per block of the fast margin computation: the temporaries of a block stay in the CPU cache
_BLOCK = 1 << 15


def _region_margin(x_m: FloatArray, y_m: FloatArray, center: tuple[float, float], offset_m: float,
                   exact: bool) -> FloatArray:
    """``offset_m - |p - c|``; ``exact=False`` computes the distance as ``sqrt(dx*dx + dy*dy)`` block by block
    (about 4x faster than ``hypot``, within a few ulps of it)."""
    if exact:
        return offset_m - np.hypot(x_m - center[0], y_m - center[1])
    n = x_m.shape[0]
    out = np.empty(n)
    dx = np.empty(min(n, _BLOCK))
    dy = np.empty(min(n, _BLOCK))
    for s in range(0, n, _BLOCK):
        e = min(n, s + _BLOCK)
        a, b = dx[: e - s], dy[: e - s]
        np.subtract(x_m[s:e], center[0], out=a)
        np.multiply(a, a, out=a)
        np.subtract(y_m[s:e], center[1], out=b)
        np.multiply(b, b, out=b)
        np.add(a, b, out=a)
        np.sqrt(a, out=a)
        np.subtract(offset_m, a, out=out[s:e])
    return out


def label_margins(x_m: FloatArray, y_m: FloatArray, scenario: Scenario, names: set[str] | frozenset[str], *,
                  exact: bool = True) -> dict[str, FloatArray]:
    """Margin of each atomic proposition in ``names``: the largest margin among the regions carrying the label
    (-inf for a label no region carries). Only those regions are computed. ``exact=False``: distances via
    ``sqrt(dx*dx + dy*dy)`` instead of ``hypot`` (a few ulps apart; callers that need a verdict near a zero margin
    recompute with ``exact=True``)."""
    eta = scenario.robot.radius
    cache: dict[int, FloatArray] = {}

    def margin(k: int) -> FloatArray:
        if k not in cache:
            r = scenario.regions[k]
            if r.polygon is not None:  # always the exact polygon distance
                sd = polygon_signed_distance(x_m, y_m, r.polygon)
                cache[k] = sd + eta if r.unsafe else sd - eta
            else:
                offset = (r.radius + eta) if r.unsafe else (r.radius - eta)
                cache[k] = _region_margin(x_m, y_m, r.center, offset, exact)
        return cache[k]

    out: dict[str, FloatArray] = {}
    for name in sorted(names):
        rows = [k for k, r in enumerate(scenario.regions) if name in r.labels]
        if not rows:
            out[name] = np.full(x_m.shape[0], -np.inf)
            continue
        value = margin(rows[0])
        for k in rows[1:]:
            value = np.maximum(value, margin(k))
        out[name] = value
    return out


def containment(x_m: FloatArray, y_m: FloatArray, scenario: Scenario) -> npt.NDArray[np.bool_]:
    """``(n_regions, n)``: whether the region contains the whole robot disc (Definition 3); False where NaN.
    Disc: ``|p - c| + eta <= r``; polygon: ``sd(p) >= eta``. Regions may overlap or nest, so a sample may be in
    several regions at once."""
    eta = scenario.robot.radius
    out = np.zeros((len(scenario.regions), x_m.shape[0]), dtype=bool)
    for k, r in enumerate(scenario.regions):
        if r.polygon is not None:
            out[k] = polygon_signed_distance(x_m, y_m, r.polygon) >= eta
        else:
            out[k] = np.hypot(x_m - r.center[0], y_m - r.center[1]) + eta <= r.radius
    return out


def containing_region(x_m: FloatArray, y_m: FloatArray, scenario: Scenario) -> IntArray:
    """Index of a region whose shape contains the whole robot disc, -1 if none or NaN (the last one in scenario
    order when regions nest; ``containment`` gives them all)."""
    inside = containment(x_m, y_m, scenario)
    idx = np.full(x_m.shape[0], -1, dtype=np.int64)
    for k in range(inside.shape[0]):
        idx[inside[k]] = k
    return idx


def workspace_margin(x_m: FloatArray, y_m: FloatArray, scenario: Scenario) -> FloatArray:
    ws, eta = scenario.workspace, scenario.robot.radius
    if ws.polygon is not None:
        return polygon_signed_distance(x_m, y_m, ws.polygon) - eta
    return np.minimum(np.minimum(x_m - ws.x[0], ws.x[1] - x_m), np.minimum(y_m - ws.y[0], ws.y[1] - y_m)) - eta


def step_bound_m(t_ns: IntArray, x_m: FloatArray, y_m: FloatArray, max_speed_mps: float) -> FloatArray:
    """Largest path length between consecutive samples: ``max(v_max * dt, |p_{i+1} - p_i|)`` (NaN-safe: inf).

    ``hypot`` is only evaluated where the squared step is not clearly below ``(v_max * dt)^2`` (relative slack 1e-9,
    far above the rounding of ``dx*dx + dy*dy``), so the result is the same as with ``hypot`` everywhere."""
    dt_s = np.diff(t_ns).astype(np.float64) * 1e-9
    dx = np.diff(x_m)
    dy = np.diff(y_m)
    speed_bound = max_speed_mps * dt_s
    d2 = dx * dx
    d2 += dy * dy
    near = ~(d2 < (speed_bound * speed_bound) * (1.0 - 1e-9))  # also True where NaN
    if np.count_nonzero(near) > d2.shape[0] // 4:
        step = np.hypot(dx, dy)
        bound = np.fmax(speed_bound, step)
        return np.where(np.isnan(step), np.inf, bound)
    bound = np.array(speed_bound, dtype=np.float64, copy=True)
    k = np.flatnonzero(near)
    if k.size:
        step_k = np.hypot(dx[k], dy[k])
        bound[k] = np.where(np.isnan(step_k), np.inf, np.fmax(speed_bound[k], step_k))
    return bound


def step_bound_regular_m(dt_ns: int, x_m: FloatArray, y_m: FloatArray, max_speed_mps: float) -> FloatArray:
    """``step_bound_m`` for samples exactly ``dt_ns`` apart (the same values, fewer passes): squared steps block by
    block in cache; a block whose largest squared step is clearly below ``(v_max * dt)^2`` keeps the speed bound,
    elsewhere ``hypot`` is evaluated where the step is not clearly below it (a NaN block takes that path too)."""
    speed_bound = max_speed_mps * (float(dt_ns) * 1e-9)
    limit = (speed_bound * speed_bound) * (1.0 - 1e-9)
    n = max(x_m.shape[0] - 1, 0)
    bound = np.full(n, speed_bound)
    sq_x = np.empty(min(n, _BLOCK))
    sq_y = np.empty_like(sq_x)
    for s in range(0, n, _BLOCK):
        e = min(n, s + _BLOCK)
        a, b = sq_x[: e - s], sq_y[: e - s]
        np.subtract(x_m[s + 1 : e + 1], x_m[s:e], out=a)
        np.multiply(a, a, out=a)
        np.subtract(y_m[s + 1 : e + 1], y_m[s:e], out=b)
        np.multiply(b, b, out=b)
        np.add(a, b, out=a)
        if a.max() < limit:  # False when the block holds a NaN
            continue
        near = np.flatnonzero(~(a < limit)) + s
        bound[near] = np.fmax(speed_bound, np.hypot(x_m[near + 1] - x_m[near], y_m[near + 1] - y_m[near]))
    return bound


@dataclass(frozen=True, slots=True)
class GapBounds:
    """Bounds of a 1-Lipschitz margin over every instant of each open gap between consecutive samples."""

    lo: FloatArray
    hi: FloatArray


def gap_bounds(margin: FloatArray, step_m: FloatArray) -> GapBounds:
    """A path of length <= D from p_i to p_{i+1}: any point is within s of p_i and D - s of p_{i+1}, so a
    1-Lipschitz margin m stays in ``[(m_i + m_{i+1} - D) / 2, (m_i + m_{i+1} + D) / 2]``. NaN -> ``[-inf, inf]``."""
    mid = 0.5 * (margin[:-1] + margin[1:])
    half = 0.5 * step_m
    lo = mid - half
    hi = mid + half
    nan = np.isnan(lo)
    lo[nan] = -np.inf
    hi[np.isnan(hi)] = np.inf
    return GapBounds(lo, hi)
