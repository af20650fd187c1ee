"""The joint run of several robots: each robot's samples -> bounds of its atoms on one merged time axis.

input: per robot its pose samples (absolute ns, strictly increasing), per-sample margins and the bound on its motion
between samples -> output: ``SignalBounds`` (``verify.signals``) at every instant of the joint axis and over every
open gap between two of its instants, so the formula's engine judges robots' atoms exactly as it judges signal atoms.

The joint axis is the union of the robots' sample times inside the joint span (the stretch every robot was observed
in). An instant of the axis that is one of a robot's samples takes that sample's exact margin; any other instant,
and any open gap of the axis, lies inside one gap of that robot's own samples and takes that gap's bound
(``geometry.gap_bounds``: a 1-Lipschitz margin over a path of length at most ``D`` from ``p_i`` to ``p_{i+1}`` stays
in ``[(m_i + m_{i+1} - D) / 2, (m_i + m_{i+1} + D) / 2]``) -- the rule a single robot's gaps follow today. Outside
a robot's samples its margins are unknown (``[-inf, inf]``).

The distance between two robot discs (edges, metres) is 1-Lipschitz in each robot's position, so over a stretch in
which robot a moves along a path of length ``Da`` from ``A0`` to ``A1`` and robot b of length ``Db`` from ``B0`` to
``B1`` it stays within ``mean_ij(d(Ai, Bj)) -+ (Da + Db) / 2`` (``pair_distance_bounds``).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import numpy.typing as npt

from verify.geometry import gap_bounds
from verify.signals import SignalBounds

__all__ = ["RobotTrack", "joint_axis", "margin_bounds", "pair_distance_bounds"]

FloatArray = npt.NDArray[np.float64]
IntArray = npt.NDArray[np.int64]


@dataclass(frozen=True, slots=True)
class RobotTrack:
    """One robot's judged pose samples (absolute ns, strictly increasing), its disc and its path-length bound
    between consecutive samples (``geometry.step_bound_m``)."""

    name: str
    t_ns: IntArray
    x_m: FloatArray
    y_m: FloatArray
    radius_m: float
    step_m: FloatArray

    @property
    def span_ns(self) -> tuple[int, int] | None:
        return (int(self.t_ns[0]), int(self.t_ns[-1])) if self.t_ns.size else None


def joint_axis(tracks: list[RobotTrack]) -> tuple[IntArray, tuple[int, int] | None]:
    """The joint axis (absolute ns) and the joint span: the robots' sample times inside the stretch every robot was
    observed in (empty, with span None, when some robot has no sample or the spans do not overlap)."""
    spans = [t.span_ns for t in tracks]
    if not spans or any(s is None for s in spans):
        return np.zeros(0, dtype=np.int64), None
    start = max(s[0] for s in spans if s is not None)
    end = min(s[1] for s in spans if s is not None)
    if start > end:
        return np.zeros(0, dtype=np.int64), None
    every = np.unique(np.concatenate([t.t_ns for t in tracks]))
    return every[(every >= start) & (every <= end)], (start, end)


def _where(track_t: IntArray, joint_t: IntArray) -> tuple[IntArray, IntArray, IntArray]:
    """For each joint instant: the robot's sample there (-1 if none) and the robot gap it lies in (-1 if none);
    for each open gap of the axis: the robot gap it lies in (-1: outside the robot's samples)."""
    n = track_t.shape[0]
    j = np.searchsorted(track_t, joint_t, side="left")
    jc = np.minimum(j, max(n - 1, 0))
    exact = (j < n) & (track_t[jc] == joint_t) if n else np.zeros(joint_t.shape[0], dtype=bool)
    sample = np.where(exact, jc, -1)
    inside = ~exact & (j > 0) & (j < n)
    point_gap = np.where(inside, j - 1, -1)
    k = np.searchsorted(track_t, joint_t[:-1], side="right")
    gap = np.where((k > 0) & (k < n), k - 1, -1)
    return sample, point_gap, gap


def margin_bounds(track: RobotTrack, margin: FloatArray, joint_t: IntArray) -> SignalBounds:
    """Bounds of one robot's margin (per sample of the robot) at the joint axis's instants and over its gaps."""
    gb = gap_bounds(margin, track.step_m) if margin.size > 1 else None
    sample, point_gap, gap = _where(track.t_ns, joint_t)
    m = joint_t.shape[0]
    point_lo = np.full(m, -np.inf)
    point_hi = np.full(m, np.inf)
    at = sample >= 0
    exact = margin[sample[at]]
    point_lo[at] = np.where(np.isnan(exact), -np.inf, exact)
    point_hi[at] = np.where(np.isnan(exact), np.inf, exact)
    gap_lo = np.full(max(m - 1, 0), -np.inf)
    gap_hi = np.full(max(m - 1, 0), np.inf)
    if gb is not None:
        ins = point_gap >= 0
        point_lo[ins] = gb.lo[point_gap[ins]]
        point_hi[ins] = gb.hi[point_gap[ins]]
        g = gap >= 0
        gap_lo[g] = gb.lo[gap[g]]
        gap_hi[g] = gb.hi[gap[g]]
    return SignalBounds(point_lo, point_hi, gap_lo, gap_hi)


def _segments(track: RobotTrack, sample: IntArray, gap: IntArray) -> tuple[FloatArray, FloatArray, FloatArray,
                                                                                FloatArray, FloatArray]:
    """Per joint position: the robot's path ends ``(x0, y0)``, ``(x1, y1)`` and its length bound (a sample: both
    ends at it, length 0); NaN where the robot is not observed around it."""
    size = sample.shape[0]
    x0, y0, x1, y1 = (np.full(size, np.nan) for _ in range(4))
    d = np.full(size, np.nan)
    at = sample >= 0
    s = sample[at]
    x0[at], y0[at], x1[at], y1[at], d[at] = track.x_m[s], track.y_m[s], track.x_m[s], track.y_m[s], 0.0
    ins = gap >= 0
    g = gap[ins]
    if g.size:
        x0[ins], y0[ins] = track.x_m[g], track.y_m[g]
        x1[ins], y1[ins] = track.x_m[g + 1], track.y_m[g + 1]
        d[ins] = track.step_m[g]
    return x0, y0, x1, y1, d


def _pair_bounds(a: tuple[FloatArray, ...], b: tuple[FloatArray, ...], radii_m: float) -> tuple[FloatArray,
                                                                                                FloatArray]:
    ax0, ay0, ax1, ay1, da = a
    bx0, by0, bx1, by1, db = b
    mean = 0.25 * (np.hypot(ax0 - bx0, ay0 - by0) + np.hypot(ax0 - bx1, ay0 - by1)
                   + np.hypot(ax1 - bx0, ay1 - by0) + np.hypot(ax1 - bx1, ay1 - by1)) - radii_m
    half = 0.5 * (da + db)
    lo, hi = mean - half, mean + half
    nan = np.isnan(lo) | np.isnan(hi)
    return np.where(nan, -np.inf, lo), np.where(nan, np.inf, hi)


def pair_distance_bounds(a: RobotTrack, b: RobotTrack, joint_t: IntArray) -> SignalBounds:
    """Bounds of the distance between the two robots' discs (edge to edge, metres; negative: overlapping) at the
    joint axis's instants and over its open gaps."""
    sa, pa, ga = _where(a.t_ns, joint_t)
    sb, pb, gb = _where(b.t_ns, joint_t)
    radii = a.radius_m + b.radius_m
    point_lo, point_hi = _pair_bounds(_segments(a, sa, pa), _segments(b, sb, pb), radii)
    none = np.full(ga.shape[0], -1, dtype=np.int64)
    gap_lo, gap_hi = _pair_bounds(_segments(a, none, ga), _segments(b, none, gb), radii)
    return SignalBounds(point_lo, point_hi, gap_lo, gap_hi)
