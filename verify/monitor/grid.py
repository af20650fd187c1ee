"""Trajectory monitor on a regular sample grid: formula + per-atom sample margins -> robustness at samples and gaps.

input: an MITL formula, a ``Grid`` (first time, period ``dt_ns`` >= 2, sample count), every atom's margin at the
samples (finite or -inf, no NaN) and the path-length bound of every gap -> output: for the formula and each
sub-formula a ``SplitTruth`` (robustness bounds at the n samples and, where needed, at the n - 1 gaps).

This is the same semantics as ``verify.monitor.engine`` on the interleaved positions of ``verify.semantics.trajectory``
(sample points and the open gaps ``[t_i + 1, t_{i+1} - 1]`` ns) and gives bit-identical values (min/max are exact; the
only arithmetic is the gap bound ``(m_i + m_{i+1}) / 2 -+ D / 2``, done in the same order). It is faster because

* samples and gaps are kept in separate arrays (no interleaving of 2n positions, no searchsorted): on a regular grid
  every window ``t + I`` covers samples ``i + a .. i + b`` and gaps ``i + a' .. i + b'`` with constant offsets;
* propositional sub-formulas are evaluated once on the gap mid-points: every atom's gap bound is
  ``mid -+ half`` with the same ``half`` for all atoms, and rounding is monotone, so ``min``/``max``/negation commute
  with ``-+ half`` exactly;
* a sub-formula needed only at the samples (the formula itself and boolean nodes above its temporal operators)
  skips the gaps.

``Until`` is not handled here (``UnsupportedFormulaError``; the caller uses the general engine). The window
reductions on the grid (which samples and gaps a window covers, blocked sliding min/max) are
``verify.monitor.gridwindows``.
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass

import numpy as np
import numpy.typing as npt

from tubempc.mitl import Always, And, Atom, Const, Eventually, Formula, Implies, Next, Not, Or, Until
from verify.errors import UnsupportedFormulaError
from verify.monitor.engine import bounds_ns
from verify.monitor.gridwindows import WindowRange, reduce_window, sliding_clipped, window_range

__all__ = [
    "Grid",
    "GridResult",
    "RootBounds",
    "SplitTruth",
    "UnsupportedFormulaError",
    "evaluate_grid",
    "evaluate_root",
    "regular_grid",
    "sliding_clipped",
]

FloatArray = npt.NDArray[np.float64]
IntArray = npt.NDArray[np.int64]
INF = np.inf


@dataclass(frozen=True, slots=True)
class Grid:
    """Sample times ``t0_ns + i * dt_ns`` for ``i < n``; ``dt_ns >= 2`` so every pair of samples leaves a gap."""

    t0_ns: int
    dt_ns: int
    n: int

    def __post_init__(self) -> None:
        if self.dt_ns < 2 or self.n < 2:
            raise ValueError(f"a grid needs dt_ns >= 2 and n >= 2, got dt_ns={self.dt_ns}, n={self.n}")

    @property
    def end_ns(self) -> int:
        return self.t0_ns + (self.n - 1) * self.dt_ns


def regular_grid(t_ns: IntArray) -> Grid | None:
    """The grid of ``t_ns`` if its samples are exactly evenly spaced by >= 2 ns, else None."""
    n = int(t_ns.shape[0])
    if n < 2:
        return None
    dt = int(t_ns[1]) - int(t_ns[0])
    if dt < 2 or int(t_ns[-1]) - int(t_ns[0]) != (n - 1) * dt:
        return None
    if not np.all(np.diff(t_ns) == dt):
        return None
    return Grid(int(t_ns[0]), dt, n)


@dataclass(frozen=True, slots=True)
class SplitTruth:
    """Robustness bounds at the samples (``p_*``, length n) and at the gaps (``g_*``, length n - 1, or None when
    the sub-formula was only needed at the samples). ``p_lo`` and ``p_hi`` may be the same array."""

    p_lo: FloatArray
    p_hi: FloatArray
    g_lo: FloatArray | None
    g_hi: FloatArray | None


@dataclass(slots=True)
class _Val:
    """Internal value: gaps either explicit (``g_lo``/``g_hi``) or centred (``g_mid -+ half``)."""

    p_lo: FloatArray
    p_hi: FloatArray
    g_lo: FloatArray | None = None
    g_hi: FloatArray | None = None
    g_mid: FloatArray | None = None

    def gaps(self, half: FloatArray) -> tuple[FloatArray, FloatArray]:
        return self.gap_lo(half), self.gap_hi(half)

    def _mid(self) -> FloatArray:
        if self.g_mid is None:
            raise ValueError("gap values were not computed")
        return self.g_mid

    def gap_lo(self, half: FloatArray) -> FloatArray:
        if self.g_lo is None:
            self.g_lo = self._mid() - half
        return self.g_lo

    def gap_hi(self, half: FloatArray) -> FloatArray:
        if self.g_hi is None:
            self.g_hi = self._mid() + half
        return self.g_hi

    def gap_slice(self, bound: str, half: FloatArray, a: int, b: int | None) -> FloatArray:
        """``gap_lo``/``gap_hi`` (``bound``) at the gaps ``a .. b`` only (the same operations, on the slice)."""
        explicit = self.g_lo if bound == "lo" else self.g_hi
        end = None if b is None else b + 1
        if explicit is not None:
            return explicit[a:end]
        mid = self._mid()[a:end]
        return mid - half[a:end] if bound == "lo" else mid + half[a:end]


# ---- evaluation -----------------------------------------------------------------------------------------------------
@dataclass(frozen=True, slots=True)
class _Ctx:
    grid: Grid
    margins: Mapping[str, FloatArray]
    half: FloatArray


@dataclass(frozen=True, slots=True)
class GridResult:
    """The formula's values at the samples (``root``) and, on demand, every sub-formula's (``values``)."""

    root: SplitTruth
    _ctx: _Ctx
    _full: dict[Formula, _Val]
    _part: dict[Formula, _Val]

    def values(self) -> dict[Formula, SplitTruth]:
        """Every evaluated sub-formula; values computed at samples and gaps override samples-only ones."""
        out: dict[Formula, SplitTruth] = {}
        for memo in (self._part, self._full):
            for f, v in memo.items():
                has_gaps = v.g_lo is not None or v.g_mid is not None
                g_lo, g_hi = v.gaps(self._ctx.half) if has_gaps else (None, None)
                out[f] = SplitTruth(v.p_lo, v.p_hi, g_lo, g_hi)
        return out


def evaluate_grid(formula: Formula, grid: Grid, margins: Mapping[str, FloatArray], step_m: FloatArray
                  ) -> GridResult:
    """Values of ``formula`` (at the samples only) and of its sub-formulas (samples and, below a temporal operator,
    gaps). ``margins``: every atom's margin at the samples (finite or -inf); ``step_m``: path-length bound of every
    gap (finite). Same values as ``monitor.evaluate_at_points`` on the interleaved positions."""
    if step_m.shape != (grid.n - 1,):
        raise ValueError(f"step_m has shape {step_m.shape}, expected ({grid.n - 1},)")
    ctx = _Ctx(grid, margins, 0.5 * step_m)
    full: dict[Formula, _Val] = {}
    part: dict[Formula, _Val] = {}
    root = _eval(formula, ctx, full, part, need_gaps=False)
    return GridResult(SplitTruth(root.p_lo, root.p_hi, None, None), ctx, full, part)


@dataclass(frozen=True, slots=True)
class RootBounds:
    """The formula's lower bound at every sample and its upper bound at the first sample."""

    lo: FloatArray
    hi_first: float


def evaluate_root(formula: Formula, grid: Grid, margins: Mapping[str, FloatArray], step_m: FloatArray
                  ) -> RootBounds:
    """``evaluate_grid(...).root.p_lo`` and ``.p_hi[0]`` (the same values) without computing the upper bounds
    elsewhere: the verdict at time 0 and the margin signal need nothing more when the verdict is a pass."""
    if step_m.shape != (grid.n - 1,):
        raise ValueError(f"step_m has shape {step_m.shape}, expected ({grid.n - 1},)")
    ctx = _Ctx(grid, margins, 0.5 * step_m)
    full: dict[Formula, _Val] = {}
    memo: dict[tuple[Formula, str], FloatArray] = {}
    lo = _samples_bound(formula, "lo", ctx, full, memo)
    return RootBounds(lo, float(_first_bound(formula, "hi", ctx, full, memo)))


def _other(bound: str) -> str:
    return "hi" if bound == "lo" else "lo"


def _samples_bound(f: Formula, bound: str, ctx: _Ctx, full: dict[Formula, _Val],
                   memo: dict[tuple[Formula, str], FloatArray]) -> FloatArray:
    """One bound of ``f`` at every sample, computing only what that bound needs (same operations as ``_eval``)."""
    key = (f, bound)
    if key in memo:
        return memo[key]
    out: FloatArray
    if f in full or isinstance(f, Atom | Const | Next):
        v = full[f] if f in full else _eval(f, ctx, full, {}, need_gaps=False)
        out = v.p_lo if bound == "lo" else v.p_hi
    elif isinstance(f, Not):
        out = -_samples_bound(f.arg, _other(bound), ctx, full, memo)
    elif isinstance(f, Implies):
        out = np.maximum(-_samples_bound(f.left, _other(bound), ctx, full, memo),
                         _samples_bound(f.right, bound, ctx, full, memo))
    elif isinstance(f, And | Or):
        out = _fold([_samples_bound(g, bound, ctx, full, memo) for g in f.args],
                    np.minimum if isinstance(f, And) else np.maximum)
    elif isinstance(f, Eventually | Always):
        a = _eval(f.arg, ctx, full, {}, need_gaps=True)
        out = _temporal_bound(a, f, ctx, _windows(f, ctx.grid, False, False), bound)
    elif isinstance(f, Until):
        raise UnsupportedFormulaError(f"{f} (until) is evaluated by the general engine")
    else:
        raise TypeError(f"unknown formula node {f!r}")
    memo[key] = out
    return out


def _first_bound(f: Formula, bound: str, ctx: _Ctx, full: dict[Formula, _Val],
                 memo: dict[tuple[Formula, str], FloatArray]) -> np.float64:
    """One bound of ``f`` at the first sample (same values as ``_samples_bound(...)[0]``)."""
    if (f, bound) in memo:
        return np.float64(memo[(f, bound)][0])
    if f in full or isinstance(f, Atom | Const | Next):
        return np.float64(_samples_bound(f, bound, ctx, full, memo)[0])
    if isinstance(f, Not):
        return np.float64(-_first_bound(f.arg, _other(bound), ctx, full, memo))
    if isinstance(f, Implies):
        return np.float64(np.maximum(-_first_bound(f.left, _other(bound), ctx, full, memo),
                                     _first_bound(f.right, bound, ctx, full, memo)))
    if isinstance(f, And | Or):
        op: np.ufunc = np.minimum if isinstance(f, And) else np.maximum
        vals = [_first_bound(g, bound, ctx, full, memo) for g in f.args]
        acc = vals[0]
        for v in vals[1:]:
            acc = op(acc, v)
        return np.float64(acc)
    if isinstance(f, Eventually | Always):
        return _temporal_first(_eval(f.arg, ctx, full, {}, need_gaps=True), f, ctx, bound)
    if isinstance(f, Until):
        raise UnsupportedFormulaError(f"{f} (until) is evaluated by the general engine")
    raise TypeError(f"unknown formula node {f!r}")


def _eval(f: Formula, ctx: _Ctx, full: dict[Formula, _Val], part: dict[Formula, _Val], *, need_gaps: bool) -> _Val:
    if f in full:
        return full[f]
    if not need_gaps and f in part:
        return part[f]
    n = ctx.grid.n
    out: _Val
    if isinstance(f, Atom):
        if f.name not in ctx.margins:
            raise KeyError(f"atom={f.name!r} has no valuation")
        m = ctx.margins[f.name]
        mid = None
        if need_gaps:
            mid = m[:-1] + m[1:]
            mid *= 0.5  # the same operations as geometry.gap_bounds
        out = _Val(m, m, g_mid=mid)
    elif isinstance(f, Const):
        v = INF if f.value else -INF
        p = np.full(n, v)
        out = _Val(p, p, g_mid=np.full(n - 1, v) if need_gaps else None)
    elif isinstance(f, Not):
        a = _eval(f.arg, ctx, full, part, need_gaps=need_gaps)
        out = _negate(a)
    elif isinstance(f, And | Or | Implies):
        if isinstance(f, Implies):
            parts = [_negate(_eval(f.left, ctx, full, part, need_gaps=need_gaps)),
                     _eval(f.right, ctx, full, part, need_gaps=need_gaps)]
            op: np.ufunc = np.maximum
        else:
            parts = [_eval(g, ctx, full, part, need_gaps=need_gaps) for g in f.args]
            op = np.minimum if isinstance(f, And) else np.maximum
        out = _combine(parts, op, ctx.half, need_gaps)
    elif isinstance(f, Eventually | Always):
        a = _eval(f.arg, ctx, full, part, need_gaps=True)
        out = _temporal(a, f, ctx, need_gaps)
    elif isinstance(f, Next):
        out = _next(_eval(f.arg, ctx, full, part, need_gaps=True), f, ctx)
    elif isinstance(f, Until):
        raise UnsupportedFormulaError(f"{f} (until) is evaluated by the general engine")
    else:
        raise TypeError(f"unknown formula node {f!r}")
    (full if need_gaps else part)[f] = out
    return out


def _negate(a: _Val) -> _Val:
    if a.p_lo is a.p_hi:
        neg = -a.p_lo
        p_lo = p_hi = neg
    else:
        p_lo, p_hi = -a.p_hi, -a.p_lo
    if a.g_mid is None and a.g_lo is not None and a.g_hi is not None:
        return _Val(p_lo, p_hi, g_lo=-a.g_hi, g_hi=-a.g_lo)
    return _Val(p_lo, p_hi, g_mid=None if a.g_mid is None else -a.g_mid)


def _combine(parts: list[_Val], op: np.ufunc, half: FloatArray, need_gaps: bool) -> _Val:
    shared = all(p.p_lo is p.p_hi for p in parts)
    lo = _fold([p.p_lo for p in parts], op)
    hi = lo if shared else _fold([p.p_hi for p in parts], op)
    if not need_gaps:
        return _Val(lo, hi)
    mids = [p.g_mid for p in parts if p.g_mid is not None]  # a centred value keeps g_mid (g_lo/g_hi: caches)
    if len(mids) == len(parts):
        return _Val(lo, hi, g_mid=_fold(mids, op))
    gaps = [p.gaps(half) for p in parts]
    return _Val(lo, hi, g_lo=_fold([g[0] for g in gaps], op), g_hi=_fold([g[1] for g in gaps], op))


def _fold(xs: list[FloatArray], op: np.ufunc) -> FloatArray:
    """``op`` over the arrays (a new array unless there is only one; inputs untouched)."""
    if len(xs) == 1:
        return xs[0]
    out: FloatArray = op(xs[0], xs[1])
    for x in xs[2:]:
        op(out, x, out=out)
    return out


@dataclass(frozen=True, slots=True)
class _Windows:
    """Windows of a temporal node for one kind of query position: the ranges its lo and hi bounds reduce over, and
    the first query index whose window reaches past the end (``nq``: none)."""

    lo: WindowRange
    hi: WindowRange
    nq: int
    first_incomplete: int


def _windows(f: Eventually | Always, grid: Grid, gap_query: bool, need_gaps: bool) -> _Windows:
    """``F_I a``: lo = max of a.lo over the inner window, hi = max of a.hi over the outer one (+inf if the window
    reaches past the end). ``G_I a``: lo = min of a.lo over the outer window (-inf if incomplete), hi = min of
    a.hi over the inner one."""
    dt, n = grid.dt_ns, grid.n
    lo_ns, hi_ns = bounds_ns(f.interval)
    s, e = (1, dt - 1) if gap_query else (0, 0)
    nq = n - 1 if gap_query else n
    outer = window_range(s + lo_ns, None if hi_ns is None else e + hi_ns, dt, gap_query, False)
    # inner window [e + lo, s + hi]; on samples queried alone it is the outer one (as in monitor._windows)
    if not gap_query and not need_gaps:
        inner = outer
    else:
        empty = hi_ns is not None and e + lo_ns > s + hi_ns
        inner = window_range(e + lo_ns, None if hi_ns is None else s + hi_ns, dt, gap_query, empty)
    first_incomplete = nq
    if hi_ns is not None:
        # complete iff t_i + e + hi <= end, i.e. i * dt <= span - e - hi
        first_incomplete = min(nq, max(0, ((n - 1) * dt - e - hi_ns) // dt + 1))
    lo_rng, hi_rng = (outer, inner) if isinstance(f, Always) else (inner, outer)
    return _Windows(lo_rng, hi_rng, nq, first_incomplete)


def _temporal_bound(a: _Val, f: Eventually | Always, ctx: _Ctx, w: _Windows, bound: str) -> FloatArray:
    """One bound (``"lo"`` or ``"hi"``) of ``f`` at every query position of ``w``."""
    always = isinstance(f, Always)
    op: np.ufunc = np.minimum if always else np.maximum
    ident = INF if always else -INF
    if bound == "lo":
        out = reduce_window(a.p_lo, a.gap_lo(ctx.half), w.lo, nq=w.nq, op=op, identity=ident)
        if always:
            out[w.first_incomplete:] = -INF
    else:
        out = reduce_window(a.p_hi, a.gap_hi(ctx.half), w.hi, nq=w.nq, op=op, identity=ident)
        if not always:
            out[w.first_incomplete:] = INF
    return out


def _temporal(a: _Val, f: Eventually | Always, ctx: _Ctx, need_gaps: bool) -> _Val:
    """``f`` at the samples and, if ``need_gaps``, at the gaps (see ``_windows``)."""
    w = _windows(f, ctx.grid, False, need_gaps)
    p_lo, p_hi = _temporal_bound(a, f, ctx, w, "lo"), _temporal_bound(a, f, ctx, w, "hi")
    if not need_gaps:
        return _Val(p_lo, p_hi)
    wg = _windows(f, ctx.grid, True, need_gaps)
    return _Val(p_lo, p_hi, g_lo=_temporal_bound(a, f, ctx, wg, "lo"), g_hi=_temporal_bound(a, f, ctx, wg, "hi"))


def _temporal_first(a: _Val, f: Eventually | Always, ctx: _Ctx, bound: str) -> np.float64:
    """One bound of ``f`` at the first sample only: the reduction over that sample's window (gap bounds computed
    on the window only)."""
    w = _windows(f, ctx.grid, False, False)
    always = isinstance(f, Always)
    if w.first_incomplete == 0 and always == (bound == "lo"):
        return np.float64(-INF if always else INF)
    r = w.lo if bound == "lo" else w.hi
    ident = INF if always else -INF
    p = a.p_lo if bound == "lo" else a.p_hi
    parts = []
    if r.pb is None or r.pa <= r.pb:
        parts.append(p[r.pa: None if r.pb is None else r.pb + 1])
    if r.gb is None or r.ga <= r.gb:
        parts.append(a.gap_slice(bound, ctx.half, r.ga, r.gb))
    red = np.min if always else np.max
    vals = [red(x) for x in parts if x.shape[0]]
    if not vals:
        return np.float64(ident)
    return np.float64(min(vals) if always else max(vals))


def _next(a: _Val, f: Next, ctx: _Ctx) -> _Val:
    """``X_I a`` at sample i: a at sample i + 1 if ``dt`` is in I; at the last sample undecided while ``t + hi``
    lies after the end; at gaps ``[-inf, inf]``."""
    n, dt = ctx.grid.n, ctx.grid.dt_ns
    lo_ns, hi_ns = bounds_ns(f.interval)
    p_lo = np.full(n, -INF)
    p_hi = np.full(n, -INF)
    if lo_ns <= dt and (hi_ns is None or dt <= hi_ns):
        p_lo[:-1] = a.p_lo[1:]
        p_hi[:-1] = a.p_hi[1:]
    if hi_ns is not None and hi_ns > 0:
        p_hi[-1] = INF
    return _Val(p_lo, p_hi, g_lo=np.full(n - 1, -INF), g_hi=np.full(n - 1, INF))
