"""MITL monitor: formula + positions with 3-valued robustness intervals for the atoms -> the same for every sub-formula.

input: a parsed ``Formula``, a ``Positions`` value (time spans in integer nanoseconds) and, for every atom, a
``Truth`` (lower and upper bound of its robustness at every position) -> output: ``Truth`` for the formula and every
sub-formula (``evaluate``), a verdict with a witness (``explain``).

One engine serves both semantics of the certifier:

* timed-run (pointwise): every position is a point ``[t_i, t_i]``;
* trajectory: sample points alternate with the open gaps between samples, stored as closed integer spans
  ``[t_i + 1, t_{i+1} - 1]`` (ns); the value at a gap is a bound valid for *every* instant of the gap.

A position's value is an interval ``[lo, hi]`` that contains the robustness at every instant of its span. The verdict
is Kleene's 3-valued logic read off the interval: true iff ``lo > 0``, false iff ``hi < 0``, otherwise unknown
(``and``/``or`` are ``min``/``max`` of intervals, which is exactly Kleene's conjunction/disjunction).
Time windows use searchsorted over the span ends, and sliding max/min over the monotone index ranges are computed
with van Herk/Gil-Werman block scans per window-length class (O(n), vectorized), never a per-sample Python loop.
Regularly sampled trajectories take the faster, value-identical path of ``verify.monitor.grid``.

Finite logs (see docs/certifier.md): an unbounded interval ranges to the end of the log; a bounded window whose
upper end ``t + hi`` lies after the end of observation ``end_ns`` is incomplete: positions that could still come
are unknown.
"""

from __future__ import annotations

import math
from collections.abc import Mapping
from dataclasses import dataclass
from fractions import Fraction

import numpy as np
import numpy.typing as npt

from tubempc.mitl import Always, And, Atom, Const, Eventually, Formula, Implies, Interval, Next, Not, Or, Until

__all__ = [
    "UNTIL_ROBUSTNESS_LIMIT",
    "Explanation",
    "Positions",
    "Truth",
    "bounds_ns",
    "evaluate",
    "evaluate_at_points",
    "explain",
    "truth_from_bool",
    "verdict_of",
]

FloatArray = npt.NDArray[np.float64]
IntArray = npt.NDArray[np.int64]
BoolArray = npt.NDArray[np.bool_]

INF = math.inf
#: Until's robustness needs a prefix minimum per candidate; above this many positions only its verdict is exact and
#: its robustness is reported as +-inf (true/false) or [-inf, inf] (unknown).
UNTIL_ROBUSTNESS_LIMIT = 20_000


@dataclass(frozen=True, slots=True)
class Positions:
    """Time spans of the positions: ``start_ns[i] <= stop_ns[i] < start_ns[i+1]``; ``end_ns``: end of observation."""

    start_ns: IntArray
    stop_ns: IntArray
    is_point: BoolArray
    end_ns: int

    def __post_init__(self) -> None:
        n = self.start_ns.shape[0]
        if self.stop_ns.shape != (n,) or self.is_point.shape != (n,):
            raise ValueError("start_ns, stop_ns and is_point must have the same length")
        if n and (np.any(self.stop_ns < self.start_ns) or np.any(self.start_ns[1:] < self.stop_ns[:-1])):
            raise ValueError("position spans must be non-empty and sorted")
        gap = ~self.is_point
        if n > 1 and np.any((self.start_ns[1:] == self.stop_ns[:-1]) & (gap[1:] | gap[:-1])):
            raise ValueError("a gap span must not touch its neighbours")
        if n and self.end_ns < int(self.stop_ns[-1]):
            raise ValueError(f"end_ns={self.end_ns} is before the last position ({int(self.stop_ns[-1])})")

    @property
    def size(self) -> int:
        return int(self.start_ns.shape[0])

    @staticmethod
    def points(times_ns: IntArray, end_ns: int | None = None) -> Positions:
        t = np.asarray(times_ns, dtype=np.int64)
        end = int(t[-1]) if end_ns is None and t.size else (0 if end_ns is None else end_ns)
        return Positions(t, t, np.ones(t.shape, dtype=bool), end)


@dataclass(frozen=True, slots=True)
class Truth:
    """Robustness bounds per position; true iff ``lo > 0``, false iff ``hi < 0``, else unknown."""

    lo: FloatArray
    hi: FloatArray


def truth_from_bool(value: BoolArray, known: BoolArray | None = None) -> Truth:
    """Boolean atom values as robustness +-1 (unknown positions get ``[-1, 1]``)."""
    lo = np.where(value, 1.0, -1.0)
    hi = lo.copy()
    if known is not None:
        lo[~known] = -1.0
        hi[~known] = 1.0
    return Truth(lo, hi)


def verdict_of(lo: float, hi: float) -> str:
    if lo > 0:
        return "pass"
    if hi < 0:
        return "fail"
    return "inconclusive"


# ---- interval arithmetic on nanoseconds ----------------------------------------------------------------------------
_NS = 10**9


#: interval bounds are capped here (ns, about 146 years): every log is shorter, so a window reaching further is the
#: same window, and times plus offsets stay inside int64 (a bound of 1e11 s overflowed)
MAX_OFFSET_NS = 2**62


def bounds_ns(interval: Interval) -> tuple[int, int | None]:
    """Integer-ns offsets ``[lo, hi]`` (closed) such that ``t + d`` (ns) is in ``t + interval``; hi None: unbounded.
    Both are capped at ``MAX_OFFSET_NS``."""
    lo = Fraction(interval.lo) * _NS
    lo_ns = min(math.ceil(lo) if interval.lo_closed else math.floor(lo) + 1, MAX_OFFSET_NS)
    if interval.hi is None:
        return lo_ns, None
    hi = Fraction(interval.hi) * _NS
    hi_ns = min(math.floor(hi) if interval.hi_closed else math.ceil(hi) - 1, MAX_OFFSET_NS)
    return lo_ns, hi_ns


@dataclass(frozen=True, slots=True)
class _Windows:
    """Index ranges [j0, j1) of the positions overlapping the inner and outer windows, and completeness."""

    in0: IntArray
    in1: IntArray
    out0: IntArray
    out1: IntArray
    complete: BoolArray
    lo_ns: int
    hi_ns: int | None


def _windows(pos: Positions, interval: Interval, at: IntArray | None = None) -> _Windows:
    """Windows of the positions ``at`` (default: all). Index ranges are clipped to ``j >= i`` (pointwise semantics:
    positions with equal timestamps are distinct and only later ones count)."""
    lo_ns, hi_ns = bounds_ns(interval)
    s_all, e_all = pos.start_ns, pos.stop_ns
    idx = np.arange(pos.size, dtype=np.int64) if at is None else at
    s, e = s_all[idx], e_all[idx]
    points_only = bool(np.all(pos.is_point[idx]))
    end = pos.end_ns

    def first_end_at_least(a: IntArray) -> IntArray:
        if lo_ns == 0 and a is s:
            return idx.copy()  # the position itself is the first one ending at or after its own start
        return np.searchsorted(e_all, a, side="left").astype(np.int64, copy=False)

    def first_start_after(b: IntArray) -> IntArray:
        return np.searchsorted(s_all, b, side="right").astype(np.int64, copy=False)

    if hi_ns is None:
        out0 = first_end_at_least(s + lo_ns if lo_ns else s)
        out1 = np.full(idx.shape[0], pos.size, dtype=np.int64)
        in0 = out0 if points_only else first_end_at_least(e + lo_ns)
        in1 = out1
        complete = np.ones(idx.shape[0], dtype=bool)
    else:
        out0 = first_end_at_least(s + lo_ns if lo_ns else s)
        out1 = first_start_after(e + hi_ns)
        if points_only:
            in0, in1 = out0, out1
        else:
            in_a, in_b = e + lo_ns, s + hi_ns
            in0 = first_end_at_least(in_a)
            in1 = np.where(in_a <= in_b, first_start_after(in_b), in0)  # empty when the gap outlasts the interval
        complete = e + hi_ns <= end
    out0, in0 = np.maximum(out0, idx), np.maximum(in0, idx)
    return _Windows(in0, np.maximum(in1, in0), out0, np.maximum(out1, out0), complete, lo_ns, hi_ns)


# ---- sliding extrema over monotone index ranges ---------------------------------------------------------------------
def sliding_reduce(x: FloatArray, width: int, op: np.ufunc, identity: float) -> FloatArray:
    """``op`` over every window ``x[i:i+width]`` (van Herk / Gil-Werman: block prefix and suffix scans, O(n))."""
    n = x.shape[0]
    if width <= 1:
        return x
    m = -(-n // width)
    xp = np.concatenate((x, np.full(m * width - n, identity))).reshape(m, width)
    prefix = op.accumulate(xp, axis=1).ravel()
    suffix = op.accumulate(xp[:, ::-1], axis=1)[:, ::-1].ravel()
    return op(suffix[: n - width + 1], prefix[width - 1 : n])  # type: ignore[no-any-return]


def range_reduce(x: FloatArray, j0: IntArray, j1: IntArray, op: np.ufunc, empty: float) -> FloatArray:
    """``op``-reduction (``np.maximum``/``np.minimum``) of ``x[j0[i]:j1[i]]`` for every i; ``empty`` where j0 >= j1.

    Ranges ending at the end of ``x`` use one suffix scan; the others are grouped by length class
    ``w <= length <= 2w`` and answered from one fixed-width sliding reduction per class as ``op(M[j0], M[j1 - w])``.
    O(n) per length class (usually one), no per-sample Python loop.
    """
    n = x.shape[0]
    out = np.full(j0.shape[0], empty, dtype=np.float64)
    length = j1 - j0
    nonempty = length > 0
    if n == 0 or not np.any(nonempty):
        return out
    to_end = nonempty & (j1 == n)
    if np.any(to_end):
        suffix = op.accumulate(x[::-1])[::-1]
        out[to_end] = suffix[j0[to_end]]
    todo = np.flatnonzero(nonempty & ~to_end)
    while todo.size:
        lengths = length[todo]
        w = int(lengths.min())
        sel = lengths <= 2 * w
        q = todo[sel]
        windows = sliding_reduce(x, w, op, empty)
        out[q] = op(windows[j0[q]], windows[j1[q] - w])
        todo = todo[~sel]
    return out


def _first_at_or_after(cond: BoolArray) -> IntArray:
    """For each i, the first k >= i with cond[k] (len(cond) if none)."""
    n = cond.shape[0]
    idx = np.where(cond, np.arange(n, dtype=np.int64), n)
    return np.minimum.accumulate(idx[::-1])[::-1] if n else idx


# ---- evaluation ------------------------------------------------------------------------------------------------------
def evaluate(formula: Formula, pos: Positions, atoms: Mapping[str, Truth]) -> dict[Formula, Truth]:
    """Truth of ``formula`` and of each of its sub-formulas at every position (memoized per distinct sub-formula)."""
    memo: dict[Formula, Truth] = {}
    _eval(formula, pos, atoms, memo, part={}, at=None)
    return memo


def evaluate_at_points(formula: Formula, pos: Positions, atoms: Mapping[str, Truth]) -> dict[Formula, Truth]:
    """Like ``evaluate`` but the formula itself (and boolean nodes above its temporal operators) is only needed at
    the point positions: its values at gaps are NaN. Temporal operators below it are evaluated everywhere."""
    memo: dict[Formula, Truth] = {}
    part: dict[Formula, Truth] = {}
    _eval(formula, pos, atoms, memo, part=part, at=np.flatnonzero(pos.is_point))
    return {**part, **memo}  # values computed at every position override the points-only ones


def _eval(f: Formula, pos: Positions, atoms: Mapping[str, Truth], memo: dict[Formula, Truth], *,
          part: dict[Formula, Truth], at: IntArray | None) -> Truth:
    """``at``: the positions where this node's value is needed (None: all); elsewhere the result may be NaN.
    ``memo`` holds values valid at every position, ``part`` values valid only at the ``at`` positions (a
    sub-formula needed at the top level and again under a temporal operator is computed in full for the latter)."""
    if f in memo:
        return memo[f]
    if at is not None and f in part:
        return part[f]
    n = pos.size
    out: Truth
    if isinstance(f, Atom):
        if f.name not in atoms:
            raise KeyError(f"atom={f.name!r} has no valuation")
        out = atoms[f.name]
    elif isinstance(f, Const):
        v = INF if f.value else -INF
        out = Truth(np.full(n, v), np.full(n, v))
    elif isinstance(f, Not):
        a = _eval(f.arg, pos, atoms, memo, part=part, at=at)
        out = Truth(-a.hi, -a.lo)
    elif isinstance(f, And | Or):
        op = np.minimum if isinstance(f, And) else np.maximum
        parts = [_eval(g, pos, atoms, memo, part=part, at=at) for g in f.args]
        lo, hi = parts[0].lo, parts[0].hi
        for p in parts[1:]:
            lo, hi = op(lo, p.lo), op(hi, p.hi)
        out = Truth(lo, hi)
    elif isinstance(f, Implies):
        a = _eval(f.left, pos, atoms, memo, part=part, at=at)
        b = _eval(f.right, pos, atoms, memo, part=part, at=at)
        out = Truth(np.maximum(-a.hi, b.lo), np.maximum(-a.lo, b.hi))
    elif isinstance(f, Eventually):
        out = _eventually(_eval(f.arg, pos, atoms, memo, part=part, at=None), _windows(pos, f.interval, at), at, n)
    elif isinstance(f, Always):
        a = _eval(f.arg, pos, atoms, memo, part=part, at=None)
        neg = _eventually(Truth(-a.hi, -a.lo), _windows(pos, f.interval, at), at, n)
        out = Truth(-neg.hi, -neg.lo)
    elif isinstance(f, Next):
        out = _next(_eval(f.arg, pos, atoms, memo, part=part, at=None), pos, f.interval)
    else:
        left = _eval(f.left, pos, atoms, memo, part=part, at=None)
        out = _until(left, _eval(f.right, pos, atoms, memo, part=part, at=None), pos, f.interval)
    (memo if at is None else part)[f] = out
    return out


def _eventually(a: Truth, w: _Windows, at: IntArray | None, n: int) -> Truth:
    lo = range_reduce(a.lo, w.in0, w.in1, np.maximum, -INF)
    hi = range_reduce(a.hi, w.out0, w.out1, np.maximum, -INF)
    hi[~w.complete] = INF
    if at is None:
        return Truth(lo, hi)
    full_lo = np.full(n, np.nan)
    full_hi = np.full(n, np.nan)
    full_lo[at] = lo
    full_hi[at] = hi
    return Truth(full_lo, full_hi)


def _next(a: Truth, pos: Positions, interval: Interval) -> Truth:
    n = pos.size
    lo = np.full(n, -INF)
    hi = np.full(n, -INF)
    if n == 0:
        return Truth(lo, hi)
    lo_ns, hi_ns = bounds_ns(interval)
    point_idx = np.flatnonzero(pos.is_point)
    # next point strictly after each position
    nxt = np.searchsorted(point_idx, np.arange(n), side="right")
    has = nxt < point_idx.size
    j = point_idx[np.minimum(nxt, max(point_idx.size - 1, 0))] if point_idx.size else np.zeros(n, dtype=np.int64)
    dt = pos.start_ns[j] - pos.start_ns
    in_iv = (dt >= lo_ns) & (True if hi_ns is None else dt <= hi_ns)
    ok = has & in_iv & pos.is_point
    lo[ok] = a.lo[j[ok]]
    hi[ok] = a.hi[j[ok]]
    if hi_ns is not None:
        pending = ~has & pos.is_point & (pos.start_ns + hi_ns > pos.end_ns)
        hi[pending] = INF
    gaps = ~pos.is_point
    lo[gaps], hi[gaps] = -INF, INF
    return Truth(lo, hi)


def _until(a: Truth, b: Truth, pos: Positions, interval: Interval) -> Truth:
    n = pos.size
    w = _windows(pos, interval)
    idx = np.arange(n, dtype=np.int64)
    # verdict part, exact and vectorized ---------------------------------------------------------------------------
    b_true = (b.lo > 0) & pos.is_point
    a_not_true = ~(a.lo > 0)
    a_false = a.hi < 0
    first_not_true = _first_at_or_after(a_not_true)  # a holds on [i, first_not_true)
    first_false = _first_at_or_after(a_false)  # k*
    cnt_bt = np.concatenate(([0], np.cumsum(b_true)))
    t0 = np.maximum(idx, w.in0)
    t1 = np.maximum(np.minimum(w.in1, first_not_true + 1), t0)
    is_true = (cnt_bt[t1] - cnt_bt[t0]) > 0
    b_not_false = ~(b.hi < 0)
    cnt_bnf = np.concatenate(([0], np.cumsum(b_not_false)))
    f0 = np.maximum(idx, w.out0)
    f1 = np.maximum(np.minimum(w.out1, first_false + 1), f0)
    blocked = first_false < w.out1
    is_false = ((cnt_bnf[f1] - cnt_bnf[f0]) == 0) & (blocked | w.complete)
    if n <= UNTIL_ROBUSTNESS_LIMIT:
        lo, hi = _until_robustness(a, b, pos, w)
        # the loop and the counting rule agree on the verdict; keep the interval consistent with it in any case
        lo = np.where(is_true, np.maximum(lo, np.nextafter(0.0, 1.0)), np.minimum(lo, 0.0))
        hi = np.where(is_false, np.minimum(hi, -np.nextafter(0.0, 1.0)), np.maximum(hi, 0.0))
        return Truth(lo, hi)
    lo = np.where(is_true, INF, -INF)
    hi = np.where(is_false, -INF, INF)
    return Truth(lo, hi)


def _until_robustness(a: Truth, b: Truth, pos: Positions, w: _Windows) -> tuple[FloatArray, FloatArray]:
    n = pos.size
    lo = np.full(n, -INF)
    hi = np.full(n, -INF)
    b_lo_pt = np.where(pos.is_point, b.lo, -INF)
    for i in range(n):
        # lower bound: witnesses are points in the inner window; a must hold on [i, j)
        j0, j1 = max(i, int(w.in0[i])), int(w.in1[i])
        if j1 > j0:
            pre = np.minimum.accumulate(a.lo[i:j1])  # pre[m] = min a.lo[i .. i+m]
            prefix = np.concatenate(([INF], pre[:-1]))[j0 - i :]  # min a.lo over [i, j)
            lo[i] = float(np.max(np.minimum(b_lo_pt[j0:j1], prefix)))
        # upper bound: candidates in the outer window; beyond the end of the log, bounded by a's observed minimum
        k0, k1 = max(i, int(w.out0[i])), int(w.out1[i])
        best = -INF
        if k1 > k0:
            pre = np.minimum.accumulate(a.hi[i:k1])
            prefix = np.concatenate(([INF], pre[:-1]))[k0 - i :]
            best = float(np.max(np.minimum(b.hi[k0:k1], prefix)))
        if not w.complete[i]:
            best = max(best, float(np.min(a.hi[i:])) if i < n else INF)
        hi[i] = best
    return lo, hi


# ---- witnesses ------------------------------------------------------------------------------------------------------
@dataclass(frozen=True, slots=True)
class Explanation:
    """Why a formula is false or unknown at a position: the responsible sub-formula, a time (ns) and a reason."""

    subformula: str
    time_ns: int
    reason: str
    node: Formula | None = None  # the responsible sub-formula itself
    index: int = -1  # the position at which it is false or unknown


def explain(f: Formula, i: int, pos: Positions, values: Mapping[Formula, Truth]) -> Explanation:
    """Walk down from ``f`` at position ``i`` (false or unknown there) to the sub-formula that decides it."""
    failing = bool(values[f].hi[i] < 0)
    t_i = int(pos.start_ns[i])
    if isinstance(f, And | Or | Implies):
        return _explain_connective(f, i, pos, values, failing=failing)
    if isinstance(f, Not):
        reason = "its negation holds" if failing else "its argument is undecided"
        if not failing and f.arg in values and _state(values, f.arg, i) == "unknown" and not isinstance(f.arg, Atom):
            return explain(f.arg, i, pos, values)
        return Explanation(str(f), t_i, reason, f, i)
    if isinstance(f, Always | Eventually):
        return _explain_window(f, i, pos, values, failing=failing)
    if isinstance(f, Until | Next):
        w = _windows(pos, f.interval, np.array([i], dtype=np.int64))
        return Explanation(str(f), _window_end(pos, w, i) if not failing else t_i,
                           "violated" if failing else "undecided at the end of the log", f, i)
    return Explanation(str(f), t_i, "false here" if failing else "unknown here (missing or ambiguous data)", f, i)


def _state(values: Mapping[Formula, Truth], g: Formula, k: int) -> str:
    t = values[g]
    return "fail" if t.hi[k] < 0 else ("pass" if t.lo[k] > 0 else "unknown")


def _explain_connective(f: And | Or | Implies, i: int, pos: Positions, values: Mapping[Formula, Truth], *,
                        failing: bool) -> Explanation:
    """``explain`` of a conjunction, disjunction or implication: the operand that decides it."""
    want = "fail" if failing else "unknown"
    # an implication's premise is undecided exactly when its negation is (and it is always among the values)
    kids = list(f.args) if isinstance(f, And | Or) else [f.left, f.right]
    if isinstance(f, And) and failing:  # the first violation: the earliest witness among the false conjuncts
        found = [explain(g, i, pos, values) for g in kids if g in values and _state(values, g, i) == "fail"]
        if found:
            return min(found, key=lambda e: e.time_ns)
    if isinstance(f, And) or not failing:
        for g in kids:
            if g in values and _state(values, g, i) == want:
                return explain(g, i, pos, values)
    if isinstance(f, Implies) and failing:
        return explain(f.right, i, pos, values)
    return Explanation(str(f), int(pos.start_ns[i]), "every alternative is false" if failing else
                       "no alternative decided", f, i)


def _explain_window(f: Always | Eventually, i: int, pos: Positions, values: Mapping[Formula, Truth], *,
                    failing: bool) -> Explanation:
    """``explain`` of a windowed Always or Eventually: the position in its window that decides it."""
    w = _windows(pos, f.interval, np.array([i], dtype=np.int64))
    arg_v = values[f.arg]
    if isinstance(f, Always):
        rng = (int(w.in0[0]), int(w.in1[0])) if failing else (int(w.out0[0]), int(w.out1[0]))
        seg_state = (arg_v.hi[rng[0] : rng[1]] < 0) if failing else ~(arg_v.lo[rng[0] : rng[1]] > 0)
        hits = np.flatnonzero(seg_state)
        if hits.size:
            return explain(f.arg, rng[0] + int(hits[0]), pos, values)
        return Explanation(str(f), _window_end(pos, w, i), "the window reaches past the end of the log", f, i)
    rng = (int(w.out0[0]), int(w.out1[0]))
    if failing:
        return Explanation(str(f), _window_end(pos, w, i), "never satisfied within its window", f, i)
    unk = np.flatnonzero(~(arg_v.hi[rng[0] : rng[1]] < 0))
    if unk.size:
        return explain(f.arg, rng[0] + int(unk[0]), pos, values)
    return Explanation(str(f), _window_end(pos, w, i), "the window reaches past the end of the log", f, i)


def _window_end(pos: Positions, w: _Windows, i: int) -> int:
    """End of the window of position ``i`` (``w`` computed for that position only), clipped to the log's end."""
    if w.hi_ns is None:
        return pos.end_ns
    return min(int(pos.stop_ns[i]) + w.hi_ns, pos.end_ns)
