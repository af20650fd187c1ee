"""Reading a judged formula: when each verdict was decided and which atom value a margin is.

input: a formula, its ``Positions`` and the ``Truth`` of every sub-formula (``verify.monitor.engine.evaluate`` or
``evaluate_at_points``; the regular-grid path's values interleaved) -> output:

* ``decided_times``: for every sub-formula and position, the observation time (ns, on the positions' clock) at
  which the data seen so far settled its verdict there (``inf``: undecided by the end of the log). An atom's value
  at a sample is known at the sample, over a gap at the next sample; ``F_I a`` is true as soon as ``a`` is
  certainly true at a position of its window, false once the window has been observed to its end (the first
  sample at or after it; an unbounded window: the end of the log) with ``a`` false throughout; ``G_I`` dually;
  ``and``/``or`` settle at their first deciding argument, else when the last one is decided; ``X`` when the next
  sample shows it; ``U`` at its witness (true) or when its window closes or ``a`` fails (false).
* ``margin_source``: the atom and the position whose value *is* a given bound of a sub-formula at a position (the
  semantics only takes minima, maxima and negations of atom values, so the value is found by equality), or None when
  the bound is a constant's ``+-inf``.

These are the facts the certificate states per obligation (``verify.judging``); they are computed from the values
the verdict was computed from, never by judging again.
"""

from __future__ import annotations

import math
from collections.abc import Mapping

import numpy as np
import numpy.typing as npt

from tubempc.mitl import Always, And, Atom, Const, Eventually, Formula, Implies, Next, Not, Or, Until
from verify.monitor.engine import Positions, Truth, _first_at_or_after, _windows, bounds_ns, range_reduce

__all__ = ["decided_times", "margin_source"]

FloatArray = npt.NDArray[np.float64]
INF = math.inf


def decided_times(formula: Formula, pos: Positions, values: Mapping[Formula, Truth]) -> dict[Formula, FloatArray]:
    """Per sub-formula, the time (ns as float, on the positions' clock) its verdict at each position was settled by
    the data; ``inf`` where it is undecided (or not evaluated there)."""
    memo: dict[Formula, FloatArray] = {}
    ticks = pos.start_ns[pos.is_point]
    known = np.where(pos.is_point, pos.start_ns, pos.stop_ns + 1).astype(np.float64)

    def window_end(hi_ns: int | None) -> FloatArray:
        """The first sample at or after each position's window end (the end of the log for unbounded windows)."""
        if hi_ns is None or ticks.size == 0:
            return np.full(pos.size, float(pos.end_ns))
        k = np.searchsorted(ticks, pos.stop_ns + hi_ns, side="left")
        return np.where(k < ticks.size, ticks[np.minimum(k, ticks.size - 1)], pos.end_ns).astype(np.float64)

    def rec(f: Formula) -> FloatArray:
        if f in memo:
            return memo[f]
        v = values[f]
        with np.errstate(invalid="ignore"):
            true, false = v.lo > 0, v.hi < 0
        d: FloatArray
        if isinstance(f, Atom):
            d = known.copy()
        elif isinstance(f, Const):
            d = known.copy()  # a gap exists (and a constant holds over it) once the sample after it arrives
        elif isinstance(f, Not):
            d = rec(f.arg).copy()
        elif isinstance(f, And | Or | Implies):
            if isinstance(f, Implies):
                kids = [(values[f.left], rec(f.left), True), (values[f.right], rec(f.right), False)]
            else:
                kids = [(values[g], rec(g), False) for g in f.args]
            settle_true = isinstance(f, Or | Implies)  # or: one true argument settles it; and: one false one
            d = _junction_times(kids, settle_true=settle_true, settled=true if settle_true else false)
        elif isinstance(f, Eventually | Always):
            w = _windows(pos, f.interval)
            a, ad = values[f.arg], rec(f.arg)
            with np.errstate(invalid="ignore"):
                shown = (a.lo > 0) if isinstance(f, Eventually) else (a.hi < 0)
            first = range_reduce(np.where(shown, ad, INF), w.in0, w.in1, np.minimum, INF)
            closed = np.maximum(window_end(w.hi_ns), range_reduce(ad, w.out0, w.out1, np.maximum, -INF))
            settled_early = true if isinstance(f, Eventually) else false
            d = np.where(settled_early, first, closed)
        elif isinstance(f, Next):
            d = _next_times(f, pos, ad=rec(f.arg))
        elif isinstance(f, Until):
            d = _until_times(f, pos, values, da=rec(f.left), db=rec(f.right), window_end=window_end)
        else:
            raise TypeError(f"unknown formula node {f!r}")
        d = np.where(true | false, d, INF)
        memo[f] = d
        return d

    rec(formula)
    return memo


def _junction_times(kids: list[tuple[Truth, FloatArray, bool]], *, settle_true: bool,
                    settled: npt.NDArray[np.bool_]) -> FloatArray:
    """``and`` / ``or`` (``settle_true``) / ``->`` over ``(values, decided times, negated)`` per argument: where the
    verdict is ``settled`` (false for ``and``, true for ``or``), the first argument that decides it; elsewhere when
    the last argument is decided."""
    n = settled.shape[0]
    settle = np.full(n, INF)
    last = np.full(n, -INF)
    with np.errstate(invalid="ignore"):
        for kv, kd, negated in kids:
            k_true, k_false = (kv.hi < 0, kv.lo > 0) if negated else (kv.lo > 0, kv.hi < 0)
            decisive = k_true if settle_true else k_false
            settle = np.minimum(settle, np.where(decisive, kd, INF))
            last = np.maximum(last, np.where(k_true | k_false, kd, INF))
    result: FloatArray = np.where(settled, settle, last)
    return result


def _next_times(f: Next, pos: Positions, *, ad: FloatArray) -> FloatArray:
    """``X_I a``: settled when the next sample is seen (and ``a`` is decided there, when the sample is inside the
    window); the end of the log where there is no next sample."""
    start = pos.start_ns.astype(np.float64)
    point_idx = np.flatnonzero(pos.is_point)
    nxt = np.searchsorted(point_idx, np.arange(pos.size), side="right")
    has = nxt < point_idx.size
    j = point_idx[np.minimum(nxt, max(point_idx.size - 1, 0))] if point_idx.size else np.zeros(pos.size, np.int64)
    lo_ns, hi_ns = bounds_ns(f.interval)
    dt = pos.start_ns[j] - pos.start_ns
    inside = (dt >= lo_ns) & (True if hi_ns is None else dt <= hi_ns)
    result: FloatArray = np.where(has, np.where(inside, np.maximum(start[j], ad[j]), start[j]), float(pos.end_ns))
    return result


def _until_times(f: Until, pos: Positions, values: Mapping[Formula, Truth], *, da: FloatArray, db: FloatArray,
                 window_end: object) -> FloatArray:
    """``a U_I b``: true at its first witness (``b`` true at a point of the window, ``a`` true before it), settled
    when both are known there; false when ``a`` fails before any ``b`` could hold, or when the window closes."""
    n = pos.size
    a, b = values[f.left], values[f.right]
    w = _windows(pos, f.interval)
    idx = np.arange(n, dtype=np.int64)
    with np.errstate(invalid="ignore"):
        b_true = (b.lo > 0) & pos.is_point
        a_false = a.hi < 0
    j = _first_at_or_after(b_true)[np.minimum(np.maximum(idx, w.in0), n - 1)] if n else idx
    j = np.where(np.maximum(idx, w.in0) < n, j, n)
    jj = np.minimum(j, n - 1)
    a_before = range_reduce(da, idx, np.maximum(j, idx), np.maximum, -INF)
    true_at = np.maximum(db[jj], a_before)
    k = _first_at_or_after(a_false) if n else idx
    kk = np.minimum(k, n - 1)
    blocked = k < w.out1
    end = window_end(w.hi_ns)  # type: ignore[operator]
    b_seen = range_reduce(db, np.maximum(idx, w.out0), np.maximum(np.minimum(w.out1, k + 1), np.maximum(idx, w.out0)),
                          np.maximum, -INF)
    false_at = np.maximum(np.where(blocked, da[kk], end), b_seen)
    with np.errstate(invalid="ignore"):
        true = values[f].lo > 0
    return np.where(true, true_at, false_at)


def margin_source(f: Formula, i: int, bound: str, pos: Positions, values: Mapping[Formula, Truth], *,
                  infinite: bool = False) -> tuple[str, int] | None:
    """The atom and position whose value is ``values[f].<bound>[i]`` (``bound``: "lo" or "hi"); None when it comes
    from a constant or from timing (a window or a next sample the log does not have). ``infinite``: trace an
    infinite value too (to an atom whose margin overflowed); otherwise None for it."""
    v = float(getattr(values[f], bound)[i])
    if math.isnan(v) or (math.isinf(v) and not infinite):
        return None
    other = "hi" if bound == "lo" else "lo"

    def val(g: Formula, b: str, k: int) -> float:
        return float(getattr(values[g], b)[k])

    def first(candidates: list[tuple[Formula, int, str]]) -> tuple[str, int] | None:
        for g, k, b in candidates[:_TRIES]:
            found = margin_source(g, k, b, pos, values, infinite=infinite)
            if found is not None:
                return found
        return None

    def in_range(g: Formula, j0: int, j1: int) -> list[tuple[Formula, int, str]]:
        hits = np.flatnonzero(getattr(values[g], bound)[j0:j1] == v)
        return [(g, j0 + int(h), bound) for h in hits[:_TRIES]]

    if isinstance(f, Atom):
        return f.name, i
    if isinstance(f, Not):
        return margin_source(f.arg, i, other, pos, values, infinite=infinite)
    if isinstance(f, And | Or):
        return first([(g, i, bound) for g in f.args if val(g, bound, i) == v])
    if isinstance(f, Implies):
        return first([c for c, ok in (((f.left, i, other), -val(f.left, other, i) == v),
                                      ((f.right, i, bound), val(f.right, bound, i) == v)) if ok])
    if isinstance(f, Eventually | Always):
        w = _windows(pos, f.interval, np.array([i], dtype=np.int64))
        inner = isinstance(f, Eventually) == (bound == "lo")
        j0, j1 = (int(w.in0[0]), int(w.in1[0])) if inner else (int(w.out0[0]), int(w.out1[0]))
        return first(in_range(f.arg, j0, j1))
    if isinstance(f, Next):
        later = np.flatnonzero(pos.is_point[i + 1:])
        if later.size == 0:
            return None
        j = i + 1 + int(later[0])
        return first([(f.arg, j, bound)] if val(f.arg, bound, j) == v else [])
    if isinstance(f, Until):
        w = _windows(pos, f.interval, np.array([i], dtype=np.int64))
        return first(in_range(f.right, i, int(w.out1[0])) + in_range(f.left, i, int(w.out1[0])))
    return None  # a constant


#: candidates tried per node when several positions or arguments carry the value (an infinite one, usually)
_TRIES = 8
