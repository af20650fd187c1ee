"""Trajectory semantics (the stricter one): formula + sampled positions -> verdict, robustness signal and witness.

input: an MITL formula, sample times (int ns, strictly increasing), positions ``x_m, y_m`` (NaN = missing), the
scenario and the speed bound -> output: a ``TrajectoryVerdict``.

Positions of the monitor are the samples *and* the open gaps between them. An atom's value at a sample is its exact
margin (``[-inf, inf]`` when the sample is NaN); at a gap it is the bound of the margin over every instant of the gap
(``geometry.gap_bounds``), so a disc that may have touched an obstacle between two samples makes ``G !obs``
undecided, never true, and a sample inside an obstacle makes it false with that sample as evidence.
"""

from __future__ import annotations

import math
from collections.abc import Mapping
from dataclasses import dataclass

import numpy as np
import numpy.typing as npt

from tubempc.mitl import Formula, atoms
from tubempc.scenario import Scenario
from verify.geometry import gap_bounds, label_margins, step_bound_m, step_bound_regular_m
from verify.monitor.engine import Positions, Truth, evaluate_at_points, explain, verdict_of
from verify.monitor.grid import Grid, GridResult, UnsupportedFormulaError, evaluate_grid, evaluate_root, regular_grid
from verify.signals import SignalBounds

__all__ = ["NEAR_ZERO_MARGIN_M", "TrajectoryValues", "TrajectoryVerdict", "check_trajectory", "interleave",
           "reported_margin", "trajectory_positions", "trajectory_values"]

#: the fast path computes distances with sqrt(dx*dx + dy*dy) (a few ulps from hypot); a root margin closer to 0
#: than this is recomputed with hypot, so the verdict is the one of the exact margins
NEAR_ZERO_MARGIN_M = 1e-6

FloatArray = npt.NDArray[np.float64]
IntArray = npt.NDArray[np.int64]


@dataclass(frozen=True, slots=True)
class TrajectoryVerdict:
    """Verdict at time 0, guaranteed margin (m), witness, and the margin signal at the samples."""

    verdict: str
    margin_m: float
    margin_hi_m: float
    subformula: str | None
    time_ns: int | None
    reason: str | None
    signal_t_ns: IntArray
    signal_rho_m: FloatArray


def reported_margin(verdict: str, lo_m: float, hi_m: float) -> float | None:
    """The margin a certificate states for the formula (certify and the online monitor alike): on a pass the
    guaranteed one (``lo_m``); on a fail the optimistic one (``hi_m`` < 0: violated by at least that much), or the
    guaranteed one where the optimistic one is unbounded, so a failed formula always states by how much; None when
    undecided, or when no finite margin exists (a formula failing on constants)."""
    if verdict == "inconclusive":
        return None
    if verdict == "pass":
        return lo_m
    for value in (hi_m, lo_m):
        if math.isfinite(value):
            return value
    return None


def trajectory_positions(t_ns: IntArray) -> tuple[Positions, IntArray, IntArray]:
    """Interleaved sample points and gaps; returns positions, the index of each sample, the index of each gap
    (-1 where two samples are 1 ns apart and leave no instant between them)."""
    n = t_ns.shape[0]
    has_gap = np.diff(t_ns) >= 2
    before = np.concatenate(([0], np.cumsum(has_gap)))
    point_at = np.arange(n, dtype=np.int64) + before
    gap_at = np.where(has_gap, point_at[:-1] + 1, -1)
    m = n + int(before[-1]) if n else 0
    start = np.empty(m, dtype=np.int64)
    stop = np.empty(m, dtype=np.int64)
    is_point = np.zeros(m, dtype=bool)
    start[point_at] = t_ns
    stop[point_at] = t_ns
    is_point[point_at] = True
    g = gap_at[has_gap]
    start[g] = t_ns[:-1][has_gap] + 1
    stop[g] = t_ns[1:][has_gap] - 1
    end = int(t_ns[-1]) if n else 0
    return Positions(start, stop, is_point, end), point_at, gap_at


def interleave(point_lo: FloatArray, point_hi: FloatArray, gap_lo: FloatArray, gap_hi: FloatArray, *,
               point_at: IntArray, gap_at: IntArray, size: int) -> Truth:
    n = point_at.shape[0]
    if size == 2 * n - 1:  # every pair of samples leaves a gap: strided interleave, no scatter
        lo = np.empty(2 * n, dtype=np.float64)
        hi = np.empty(2 * n, dtype=np.float64)
        lo[0::2], hi[0::2] = point_lo, point_hi
        lo[1:-1:2], hi[1:-1:2] = gap_lo, gap_hi
        return Truth(lo[:size], hi[:size])
    lo = np.empty(size, dtype=np.float64)
    hi = np.empty(size, dtype=np.float64)
    lo[point_at] = point_lo
    hi[point_at] = point_hi
    ok = gap_at >= 0
    lo[gap_at[ok]] = gap_lo[ok]
    hi[gap_at[ok]] = gap_hi[ok]
    return Truth(lo, hi)


def _sample_truth(margin: FloatArray) -> tuple[FloatArray, FloatArray]:
    nan = np.isnan(margin)
    if not nan.any():
        return margin, margin
    return np.where(nan, -np.inf, margin), np.where(nan, np.inf, margin)


def _atom_values(formula: Formula, t_ns: IntArray, x_m: FloatArray, y_m: FloatArray, *, scenario: Scenario,
                 max_speed_mps: float, sig: Mapping[str, SignalBounds], point_at: IntArray, gap_at: IntArray,
                 size: int) -> dict[str, Truth]:
    """Each atom's truth at the samples and over the gaps between them: region atoms from their margins (the motion
    between samples bounded by ``max_speed_mps``), signal atoms from their bounds."""
    step = step_bound_m(t_ns, x_m, y_m, max_speed_mps)
    values: dict[str, Truth] = {}
    for name, margin in label_margins(x_m, y_m, scenario, atoms(formula) - set(sig)).items():
        plo, phi = _sample_truth(margin)
        gb = gap_bounds(margin, step)
        values[name] = interleave(plo, phi, gb.lo, gb.hi, point_at=point_at, gap_at=gap_at, size=size)
    for name, b in sig.items():
        values[name] = interleave(b.point_lo, b.point_hi, b.gap_lo, b.gap_hi, point_at=point_at, gap_at=gap_at,
                                  size=size)
    return values


def check_trajectory(formula: Formula, t_ns: IntArray, x_m: FloatArray, y_m: FloatArray, scenario: Scenario, *,
                     max_speed_mps: float, signals: Mapping[str, SignalBounds] | None = None) -> TrajectoryVerdict:
    """Evaluate ``formula`` at the first sample under the trajectory semantics (times: ns, strictly increasing).

    ``signals``: bounds of the signal atoms at these samples and gaps (``verify.signals.signal_bounds``); a formula
    that uses one is evaluated by the general engine (the regular-grid path bounds only position margins)."""
    sig = {k: v for k, v in (signals or {}).items() if k in atoms(formula)}
    n = t_ns.shape[0]
    if n == 0:
        empty_i = np.zeros(0, dtype=np.int64)
        return TrajectoryVerdict("inconclusive", -np.inf, np.inf, str(formula), None, "no pose samples",
                                 empty_i, np.zeros(0))
    grid = regular_grid(t_ns)
    if grid is not None and not sig and bool(np.isfinite(x_m).all()) and bool(np.isfinite(y_m).all()):
        fast = _check_on_grid(formula, grid, t_ns, x_m, y_m, scenario=scenario, max_speed_mps=max_speed_mps)
        if fast is not None:
            return fast
    pos, point_at, gap_at = trajectory_positions(t_ns)
    values = _atom_values(formula, t_ns, x_m, y_m, scenario=scenario, max_speed_mps=max_speed_mps, sig=sig,
                          point_at=point_at, gap_at=gap_at, size=pos.size)
    result = evaluate_at_points(formula, pos, values)
    root = result[formula]
    lo0, hi0 = float(root.lo[0]), float(root.hi[0])
    verdict = verdict_of(lo0, hi0)
    signal = root.lo[point_at]
    if verdict == "pass":
        return TrajectoryVerdict(verdict, lo0, hi0, None, None, None, t_ns, signal)
    why = explain(formula, 0, pos, result)
    return TrajectoryVerdict(verdict, lo0, hi0, why.subformula, why.time_ns, why.reason, t_ns, signal)


@dataclass(frozen=True, slots=True)
class TrajectoryValues:
    """Every sub-formula's robustness bounds on the interleaved positions (samples and gaps), with exact margins."""

    pos: Positions
    point_at: IntArray
    gap_at: IntArray
    values: dict[Formula, Truth]


def trajectory_values(formula: Formula, t_ns: IntArray, x_m: FloatArray, y_m: FloatArray, scenario: Scenario, *,
                      max_speed_mps: float, signals: Mapping[str, SignalBounds] | None = None) -> TrajectoryValues:
    """The values ``check_trajectory`` reads its verdict from, for every sub-formula (at least one sample): the
    regular-grid evaluator's interleaved when it applies, else the general engine's (bit-identical values)."""
    sig = {k: v for k, v in (signals or {}).items() if k in atoms(formula)}
    pos, point_at, gap_at = trajectory_positions(t_ns)
    grid = regular_grid(t_ns)
    if grid is not None and not sig and bool(np.isfinite(x_m).all()) and bool(np.isfinite(y_m).all()):
        step = step_bound_regular_m(grid.dt_ns, x_m, y_m, max_speed_mps)
        if bool(np.isfinite(step).all()):
            try:
                res = evaluate_grid(formula, grid, label_margins(x_m, y_m, scenario, atoms(formula), exact=True),
                                    step)
            except UnsupportedFormulaError:
                pass
            else:
                return TrajectoryValues(pos, point_at, gap_at, _interleaved(res, point_at, gap_at, pos.size))
    values = _atom_values(formula, t_ns, x_m, y_m, scenario=scenario, max_speed_mps=max_speed_mps, sig=sig,
                          point_at=point_at, gap_at=gap_at, size=pos.size)
    return TrajectoryValues(pos, point_at, gap_at, evaluate_at_points(formula, pos, values))


def _check_on_grid(formula: Formula, grid: Grid, t_ns: IntArray, x_m: FloatArray, y_m: FloatArray, *,
                   scenario: Scenario, max_speed_mps: float) -> TrajectoryVerdict | None:
    """Regularly sampled, NaN-free trajectory: ``verify.monitor.grid`` (same values as the interleaved engine). A pass
    far from a zero margin keeps the fast distances; otherwise the margins are recomputed with ``hypot`` and the
    witness is found on the interleaved positions. None: the formula needs the general engine (``Until``)."""
    step = step_bound_regular_m(grid.dt_ns, x_m, y_m, max_speed_mps)
    if not bool(np.isfinite(step).all()):
        return None
    names = atoms(formula)
    try:
        root = evaluate_root(formula, grid, label_margins(x_m, y_m, scenario, names, exact=False), step)
    except UnsupportedFormulaError:
        return None
    lo0, hi0 = float(root.lo[0]), root.hi_first
    if verdict_of(lo0, hi0) == "pass" and lo0 > NEAR_ZERO_MARGIN_M:
        return TrajectoryVerdict("pass", lo0, hi0, None, None, None, t_ns, root.lo)
    res = evaluate_grid(formula, grid, label_margins(x_m, y_m, scenario, names, exact=True), step)
    lo0, hi0 = float(res.root.p_lo[0]), float(res.root.p_hi[0])
    verdict = verdict_of(lo0, hi0)
    if verdict == "pass":
        return TrajectoryVerdict("pass", lo0, hi0, None, None, None, t_ns, res.root.p_lo)
    pos, point_at, gap_at = trajectory_positions(t_ns)
    why = explain(formula, 0, pos, _interleaved(res, point_at, gap_at, pos.size))
    return TrajectoryVerdict(verdict, lo0, hi0, why.subformula, why.time_ns, why.reason, t_ns, res.root.p_lo)


def _interleaved(res: GridResult, point_at: IntArray, gap_at: IntArray, size: int) -> dict[Formula, Truth]:
    """Split values -> values on the interleaved positions (NaN at the gaps of samples-only sub-formulas)."""
    out: dict[Formula, Truth] = {}
    for f, v in res.values().items():
        nan_gaps = np.full(gap_at.shape[0], np.nan)
        g_lo = nan_gaps if v.g_lo is None else v.g_lo
        g_hi = nan_gaps if v.g_hi is None else v.g_hi
        out[f] = interleave(v.p_lo, v.p_hi, g_lo, g_hi, point_at=point_at, gap_at=gap_at, size=size)
    return out
