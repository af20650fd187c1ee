"""Free-space guide paths: the intermediate targets that keep the short-horizon FHOCP feasible and moving.

input: start and goal points, obstacle discs (already grown by eta + r_q), the tightened workspace box ->
output: a frozen ``GuidePath`` (a polyline of shortest length in a visibility graph around the discs grown by a
margin), and ``references`` (the per-stage reference points the FHOCP tracks, a look-ahead along that polyline).
No free path raises ``NoGuidePathError`` (a ``DesignError``).
"""

from __future__ import annotations

import bisect
import heapq
import math
from collections.abc import Sequence
from dataclasses import dataclass, field

import numpy as np

from tubempc.errors import NoGuidePathError

__all__ = ["GuidePath", "NoGuidePathError", "guide_path", "references"]

_RING_POINTS = 16


@dataclass(frozen=True, slots=True)
class GuidePath:
    points: np.ndarray  # k x 2, from start to goal
    cum_length_m: np.ndarray  # k, arc length at each vertex
    # per-call constants, derived once: contiguous coordinate columns and plain-float copies for ``project``
    _x: np.ndarray = field(init=False, repr=False, compare=False)
    _y: np.ndarray = field(init=False, repr=False, compare=False)
    _floats: tuple[list[float], list[float], list[float]] = field(init=False, repr=False, compare=False)

    def __post_init__(self) -> None:
        object.__setattr__(self, "_x", np.ascontiguousarray(self.points[:, 0], dtype=float))
        object.__setattr__(self, "_y", np.ascontiguousarray(self.points[:, 1], dtype=float))
        object.__setattr__(self, "_floats", (self._x.tolist(), self._y.tolist(), self.cum_length_m.tolist()))

    @property
    def length_m(self) -> float:
        return float(self.cum_length_m[-1])

    def point_at(self, s_m: float) -> np.ndarray:
        s = min(max(s_m, 0.0), self.length_m)
        i = int(np.searchsorted(self.cum_length_m, s, side="right")) - 1
        i = min(max(i, 0), len(self.points) - 2) if len(self.points) > 1 else 0
        if len(self.points) == 1:
            return np.array(self.points[0], dtype=float)
        seg = self.cum_length_m[i + 1] - self.cum_length_m[i]
        a = 0.0 if seg <= 0 else (s - self.cum_length_m[i]) / seg
        return np.asarray(self.points[i] + a * (self.points[i + 1] - self.points[i]), dtype=float)

    def project(self, p: np.ndarray, s_from_m: float, window_m: float) -> float:
        """Arc length of the point of the path nearest to ``p`` within ``[s_from, s_from + window]``.

        Called once per MPC step on a polyline of a handful of vertices: plain float arithmetic is several times
        faster than numpy here (the candidates and the tie-breaking, first minimum, are the same).
        """
        xs, ys, cum = self._floats
        n = len(xs)
        if n < 2:
            return s_from_m
        length = cum[-1]
        px, py = float(p[0]), float(p[1])
        lo, hi = s_from_m, s_from_m + window_m
        best_s, best_d = s_from_m, math.inf
        for i in range(n - 1):
            dx, dy = xs[i + 1] - xs[i], ys[i + 1] - ys[i]
            seg2 = dx * dx + dy * dy
            t = ((px - xs[i]) * dx + (py - ys[i]) * dy) / seg2 if seg2 > 0 else 0.0
            t = min(max(t, 0.0), 1.0)
            s = min(max(cum[i] + t * (cum[i + 1] - cum[i]), lo), hi)
            s = min(max(s, 0.0), length)
            j = min(max(bisect.bisect_right(cum, s) - 1, 0), n - 2)
            span = cum[j + 1] - cum[j]
            a = (s - cum[j]) / span if span > 0 else 0.0
            qx, qy = xs[j] + a * (xs[j + 1] - xs[j]), ys[j] + a * (ys[j + 1] - ys[j])
            d = math.hypot(qx - px, qy - py)
            if d < best_d:
                best_s, best_d = s, d
        return max(best_s, s_from_m)


def _visible(a: np.ndarray, ends: np.ndarray, centers: np.ndarray, radii: np.ndarray) -> np.ndarray:
    """For each segment a -> ends[j]: does it keep every disc (centers, radii) at a distance >= its radius?"""
    if len(centers) == 0:
        return np.ones(len(ends), dtype=bool)
    ab = ends - a  # J x 2
    denom = np.einsum("ij,ij->i", ab, ab)  # J
    ac = centers - a  # K x 2
    t = np.divide(ab @ ac.T, denom[:, None], out=np.zeros((len(ends), len(centers))), where=denom[:, None] > 0)
    t = np.clip(t, 0.0, 1.0)  # J x K
    nearest = a + t[..., None] * ab[:, None, :]  # J x K x 2
    gap = np.linalg.norm(centers[None, :, :] - nearest, axis=2) - radii[None, :]
    return np.asarray(np.all(gap >= -1e-12, axis=1))


def guide_path(start: Sequence[float], goal: Sequence[float], discs: Sequence[tuple[float, float, float]], *,
               box_x: tuple[float, float], box_y: tuple[float, float], margin_m: float = 0.05) -> GuidePath:
    """Shortest polyline from ``start`` to ``goal`` avoiding ``discs`` (cx, cy, r) grown by ``margin_m``.

    Vertices are the start, the goal and ``_RING_POINTS`` points on a circumscribed polygon around each grown
    disc (so polygon edges stay outside it), kept when inside the box. A disc's margin is reduced where the start
    or the goal lies within it, so that a start on the edge of the free space still connects.
    """
    s = np.asarray(start, dtype=float)[:2]
    g = np.asarray(goal, dtype=float)[:2]
    centers = np.array([[d[0], d[1]] for d in discs], dtype=float).reshape(-1, 2)
    base = np.array([d[2] for d in discs], dtype=float)
    room = np.minimum(np.linalg.norm(centers - s, axis=1), np.linalg.norm(centers - g, axis=1)) - base
    margins = np.clip(np.minimum(margin_m, room), 0.0, None)
    check = base + 0.5 * margins  # the polygon edges stay at >= base + margin; the check allows half of it
    nodes = [s, g]
    step = 2 * math.pi / _RING_POINTS
    for c, r0, m in zip(centers, base, margins, strict=True):
        ring = (r0 + m) / math.cos(step / 2)
        for k in range(_RING_POINTS):
            p = c + ring * np.array([math.cos(k * step), math.sin(k * step)])
            inside_box = box_x[0] <= p[0] <= box_x[1] and box_y[0] <= p[1] <= box_y[1]
            if inside_box and bool(np.all(np.linalg.norm(centers - p, axis=1) >= check)):
                nodes.append(p)
    pts = np.array(nodes)
    n = len(pts)
    dist = np.full(n, math.inf)
    prev = np.full(n, -1, dtype=int)
    dist[0] = 0.0
    heap: list[tuple[float, int]] = [(0.0, 0)]
    done = np.zeros(n, dtype=bool)
    while heap:
        d, i = heapq.heappop(heap)
        if done[i]:
            continue
        done[i] = True
        if i == 1:
            break
        cand = np.flatnonzero(~done)
        w = np.linalg.norm(pts[cand] - pts[i], axis=1)
        better = d + w < dist[cand]
        cand, w = cand[better], w[better]
        if len(cand) == 0:
            continue
        clear = _visible(pts[i], pts[cand], centers, check)
        for j, wj in zip(cand[clear].tolist(), w[clear].tolist(), strict=True):
            dist[j] = d + wj
            prev[j] = i
            heapq.heappush(heap, (d + wj, j))
    if not math.isfinite(dist[1]):
        raise NoGuidePathError(f"no collision-free path from ({s[0]:.3f}, {s[1]:.3f}) to ({g[0]:.3f}, {g[1]:.3f}) "
                               f"around {len(discs)} obstacle disc(s) inside the tightened workspace")
    order = [1]
    while order[-1] != 0:
        order.append(int(prev[order[-1]]))
    poly = pts[order[::-1]]
    cum = np.concatenate([[0.0], np.cumsum(np.linalg.norm(np.diff(poly, axis=0), axis=1))])
    return GuidePath(points=poly, cum_length_m=cum)


def references(path: GuidePath, s_m: float, *, lookahead_m: float, step_m: float, stages: int,
               out: np.ndarray | None = None) -> np.ndarray:
    """``stages`` planar reference points at arc length ``s + lookahead + k * step`` (clamped at the goal).

    With ``out`` (stages x >= 2) the points are written into its first two columns and ``out`` is returned.
    """
    # np.minimum(np.maximum(.)) is np.clip without its Python-level dispatch (the same values)
    s = np.minimum(np.maximum(s_m + lookahead_m + step_m * np.arange(stages), 0.0), path.length_m)
    if out is None:
        out = np.empty((stages, 2))
    out[:, 0] = np.interp(s, path.cum_length_m, path._x)
    out[:, 1] = np.interp(s, path.cum_length_m, path._y)
    return out
