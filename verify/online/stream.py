# Over 500 lines: streaming nodes for every operator of the grammar over one shared retention scheme.
"""Streaming MITL evaluation: positions and atom values arriving in time order -> final sub-formula values and the
verdict of the formula at its first position, decided as soon as no future sample can change it.

input: a ``Track`` (position spans appended in time order, the end of observation, the observation ticks) and the
atoms' robustness bounds appended per position -> output: for every stream node its *final* values (those offline
analysis of any longer log would also give), and for the formula a ``Head`` whose interval only shrinks as data
arrives (monotone: a decided verdict never flips) and equals ``verify.monitor.engine`` on the whole log after ``close``.

The semantics is the offline one, computed by its own code: the windows of a batch of positions are
``verify.monitor.engine._windows`` over the retained slice of positions and their extrema ``range_reduce``; ``close``
runs ``_eventually`` (incomplete windows) on what is left. A node keeps only the positions its parent still needs:

* a bounded window ``[lo, hi]`` is final once ``stop + hi`` is observed, so a node retains ``hi`` x rate positions;
  before that its *provisional* bounds (and the time its verdict became certain) let the operators above it decide
  early -- a nested ``G`` is false at the first sample that shows its argument false;
* the top-level temporal operators are evaluated at the first position only (running extrema, nothing retained);
* an unbounded window *below* another temporal operator, and any ``Until`` / ``Next`` (evaluated at ``close`` by the
  offline engine), keep their positions until ``close`` (memory grows with the log for those formulas only).
"""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass
from typing import Any

import numpy as np
import numpy.typing as npt

from tubempc.mitl import Always, And, Atom, Const, Eventually, Formula, Implies, Interval, Next, Not, Or, Until
from verify.monitor.engine import (
    Positions,
    Truth,
    _eventually,
    _windows,
    bounds_ns,
    evaluate_at_points,
    explain,
    range_reduce,
)

__all__ = ["Buffer", "Evaluation", "Head", "Track", "build_head"]

FloatArray = npt.NDArray[np.float64]
IntArray = npt.NDArray[np.int64]
INF = math.inf
#: "never known" for the known-time arrays
_NEVER = np.iinfo(np.int64).max
#: a witness at the position's own start
_AT = np.iinfo(np.int64).min


class Buffer:
    """A growing 1-D array addressed by global index; the positions before ``base`` are dropped (amortised O(1))."""

    __slots__ = ("_a", "_off", "base", "stop")

    def __init__(self, dtype: type) -> None:
        self._a: npt.NDArray[np.generic] = np.empty(256, dtype=dtype)
        self._off = 0
        self.base = 0  # global index of the first retained element
        self.stop = 0  # global index past the last element

    def _room(self, k: int) -> int:
        """Room for ``k`` more elements (moving the retained ones to the front, or to a larger array, when the end
        is reached); returns where they go."""
        n = self.stop - self.base
        if self._off + n + k > self._a.shape[0]:
            cap = max(256, 2 * (n + k))
            new = np.empty(cap, dtype=self._a.dtype) if cap > self._a.shape[0] else self._a
            new[:n] = self._a[self._off : self._off + n]
            self._a, self._off = new, 0
        return self._off + n

    def extend(self, values: npt.NDArray[np.generic]) -> None:
        k = values.shape[0]
        at = self._off + self.stop - self.base
        if at + k > self._a.shape[0]:
            at = self._room(k)
        self._a[at : at + k] = values
        self.stop += k

    def fill(self, value: float | int, k: int) -> None:
        """``k`` copies of ``value``."""
        at = self._room(k)
        self._a[at : at + k] = value
        self.stop += k

    def view(self, g0: int, g1: int) -> npt.NDArray[np.generic]:
        if g0 < self.base or g1 > self.stop:
            raise IndexError(f"range [{g0}, {g1}) outside the retained [{self.base}, {self.stop})")
        return self._a[self._off + g0 - self.base : self._off + g1 - self.base]

    def at(self, g: int) -> float | int:
        return self._a[self._off + g - self.base].item()  # type: ignore[no-any-return]

    def drop_before(self, g: int) -> None:
        g = min(max(g, self.base), self.stop)
        self._off += g - self.base
        self.base = g


def _f(buf: Buffer, g0: int, g1: int) -> FloatArray:
    return buf.view(g0, g1)  # type: ignore[return-value]


def _i(buf: Buffer, g0: int, g1: int) -> IntArray:
    return buf.view(g0, g1)  # type: ignore[return-value]


class Track:
    """The positions of one semantics (sample points and gaps, or timed-run entries), in time order (ns).

    ``ticks``: the observation times (every sample), to say when a window was complete; ``end_ns``: the end of
    observation (the last tick)."""

    def __init__(self) -> None:
        self.start = Buffer(np.int64)
        self.stop_ns = Buffer(np.int64)
        self.is_point = Buffer(np.bool_)
        self.ticks = Buffer(np.int64)
        self.end_ns: int | None = None
        self.first_ns: int | None = None  # start of the first position (where the formula is evaluated)

    @property
    def count(self) -> int:
        return self.start.stop

    def append(self, start_ns: IntArray, stop_ns: IntArray, is_point: npt.NDArray[np.bool_]) -> None:
        if self.first_ns is None and start_ns.shape[0]:
            self.first_ns = int(start_ns[0])
        self.start.extend(start_ns)
        self.stop_ns.extend(stop_ns)
        self.is_point.extend(is_point)

    def tick(self, times_ns: IntArray) -> None:
        if times_ns.shape[0]:
            self.ticks.extend(times_ns)
            self.end_ns = int(times_ns[-1])

    def positions(self, g0: int, g1: int, end_ns: int) -> Positions:
        return Positions(_i(self.start, g0, g1), _i(self.stop_ns, g0, g1),
                         self.is_point.view(g0, g1), end_ns)  # type: ignore[arg-type]

    def first_tick_at_or_after(self, times_ns: IntArray, closing: bool) -> IntArray:
        ticks = _i(self.ticks, self.ticks.base, self.ticks.stop)
        k = np.searchsorted(ticks, times_ns, side="left")
        out = np.where(k < ticks.shape[0], ticks[np.minimum(k, max(ticks.shape[0] - 1, 0))] if ticks.size else 0,
                       self.end_ns if closing and self.end_ns is not None else _NEVER)
        return out.astype(np.int64)

    def drop_before(self, g: int) -> None:
        """Drop positions before ``g`` and the ticks before them (the last tick is always kept)."""
        g = min(max(g, self.start.base), self.count)
        ticks = _i(self.ticks, self.ticks.base, self.ticks.stop)
        cut = int(np.searchsorted(ticks, int(self.start.at(g)))) - 1 if g < self.count else ticks.shape[0] - 1
        self.start.drop_before(g)
        self.stop_ns.drop_before(g)
        self.is_point.drop_before(g)
        self.ticks.drop_before(self.ticks.base + max(cut, 0))


# ---- stream nodes: final values per position -------------------------------------------------------------------------
class Node:
    """Final values ``lo``, ``hi`` and the time each became known (``known``) for positions ``[0, final)``."""

    def __init__(self) -> None:
        self.lo = Buffer(np.float64)
        self.hi = Buffer(np.float64)
        self.known = Buffer(np.int64)
        self.wit = Buffer(np.int64)  # where a false value is shown (``verify.monitor.engine.explain``); _AT: its start
        self.final = 0
        self.keep_from = 0  # set by the consumers: the first position any of them still needs

    def children(self) -> tuple[Node, ...]:
        return ()

    def need_from(self) -> int:
        """The first position of the children this node still needs."""
        return self.final

    def update(self, track: Track, closing: bool) -> None:
        return

    def provisional(self, track: Track) -> tuple[FloatArray, FloatArray, FloatArray]:
        """Bounds of the positions ``[final, count)`` given the data so far (the final values lie within them) and,
        where their verdict is already certain, the time it became so (relative ns as float; inf: not yet)."""
        n = track.count - self.final
        return np.full(n, -INF), np.full(n, INF), np.full(n, INF)

    def values_from(self, track: Track, p: int) -> tuple[FloatArray, FloatArray, FloatArray]:
        """Final values then provisional ones for the positions ``[p, count)`` (known: float ns, inf = undecided
        for a provisional value; a final value is known at its time whatever its verdict)."""
        c = self.final
        lo, hi = _f(self.lo, p, c), _f(self.hi, p, c)
        known = _i(self.known, p, c).astype(np.float64)
        if c >= track.count:
            return lo, hi, known
        plo, phi, pkn = self.provisional(track)
        return np.concatenate((lo, plo)), np.concatenate((hi, phi)), np.concatenate((known, pkn))

    def emit(self, lo: FloatArray, hi: FloatArray, known: IntArray, wit: IntArray | None = None) -> None:
        self.lo.extend(lo)
        self.hi.extend(hi)
        self.known.extend(known)
        if wit is None:
            self.wit.fill(_AT, lo.shape[0])
        else:
            self.wit.extend(wit)
        self.final += lo.shape[0]

    def witness(self, track: Track, g0: int, g1: int) -> IntArray:
        """For the final positions ``[g0, g1)``: the time a false value is shown, as the offline ``explain`` walks
        down to it (a position's own start for an atom, a negation, an or; the earliest among the false conjuncts;
        an implication's conclusion; the end of an ``F``'s window; a ``G``'s first false argument)."""
        w = _i(self.wit, g0, g1)
        return np.where(w == _AT, _i(track.start, g0, g1), w)

    def trim(self) -> None:
        for b in (self.lo, self.hi, self.known, self.wit):
            b.drop_before(self.keep_from)


class AtomNode(Node):
    """Values appended by the feeder (``push``)."""

    def push(self, lo: FloatArray, hi: FloatArray, known: IntArray) -> None:
        self.emit(lo, hi, known)


class ConstNode(Node):
    def __init__(self, value: bool) -> None:
        super().__init__()
        self.value = INF if value else -INF

    def update(self, track: Track, closing: bool) -> None:
        k = track.count - self.final
        if k > 0:
            v = np.full(k, self.value)
            known = _i(track.start, self.final, track.count)
            self.emit(v, v, known)


class NotNode(Node):
    def __init__(self, arg: Node) -> None:
        super().__init__()
        self.arg = arg

    def children(self) -> tuple[Node, ...]:
        return (self.arg,)

    def update(self, track: Track, closing: bool) -> None:
        c = self.arg.final
        if c > self.final:
            p = self.final
            self.emit(-_f(self.arg.hi, p, c), -_f(self.arg.lo, p, c), _i(self.arg.known, p, c))

    def provisional(self, track: Track) -> tuple[FloatArray, FloatArray, FloatArray]:
        lo, hi, known = self.arg.values_from(track, self.final)
        return -hi, -lo, known


class BoolNode(Node):
    """And / Or of several children (min / max of the intervals: Kleene's logic)."""

    def __init__(self, args: list[Node], op: np.ufunc, *, implies: bool = False) -> None:
        super().__init__()
        self.args = args
        self.op = op
        self.implies = implies  # [!left, right]: a false implication is shown where its conclusion is

    def children(self) -> tuple[Node, ...]:
        return tuple(self.args)

    def update(self, track: Track, closing: bool) -> None:
        c = min(a.final for a in self.args)
        p = self.final
        if c <= p:
            return
        lo = _f(self.args[0].lo, p, c)
        hi = _f(self.args[0].hi, p, c)
        known = _i(self.args[0].known, p, c)
        for a in self.args[1:]:
            lo = self.op(lo, _f(a.lo, p, c))
            hi = self.op(hi, _f(a.hi, p, c))
            known = np.maximum(known, _i(a.known, p, c))
        wit = None
        if self.implies:
            wit = self.args[1].witness(track, p, c)
        elif self.op is np.minimum:  # and: the earliest witness among the false conjuncts
            wit = np.full(c - p, _NEVER, dtype=np.int64)
            for a in self.args:
                wit = np.where(_f(a.hi, p, c) < 0, np.minimum(wit, a.witness(track, p, c)), wit)
            wit = np.where(wit == _NEVER, _AT, wit)
        self.emit(lo, hi, known, wit)  # copied into the buffers

    def provisional(self, track: Track) -> tuple[FloatArray, FloatArray, FloatArray]:
        """Kleene's and/or; decided false (and) as soon as one argument is, true once all are (or: the dual)."""
        parts = [a.values_from(track, self.final) for a in self.args]
        lo, hi = parts[0][0], parts[0][1]
        for plo, phi, _ in parts[1:]:
            lo, hi = self.op(lo, plo), self.op(hi, phi)
        is_and = self.op is np.minimum
        # the argument verdict that settles the result alone (false for and), and the one all must share
        settle = [np.where(((phi < 0) if is_and else (plo > 0)) & np.isfinite(pk), pk, INF) for plo, phi, pk in parts]
        every = [np.where(((plo > 0) if is_and else (phi < 0)) & np.isfinite(pk), pk, INF) for plo, phi, pk in parts]
        known = np.minimum.reduce(settle)
        known = np.minimum(known, np.maximum.reduce(every))
        return lo, hi, known


class WindowNode(Node):
    """``F_I arg`` (or ``G_I arg`` = ``!F_I !arg``) at every position: final once the window is observed."""

    def __init__(self, arg: Node, interval: Interval, always: bool) -> None:
        super().__init__()
        self.arg = arg
        self.interval = interval
        self.always = always
        self.hi_ns = bounds_ns(interval)[1]

    def children(self) -> tuple[Node, ...]:
        return (self.arg,)

    def update(self, track: Track, closing: bool) -> None:
        p, c, n = self.final, self.arg.final, track.count
        end = track.end_ns
        if p >= n or end is None:
            return
        if closing:
            k = n
        elif self.hi_ns is None:
            return
        else:
            limit = end if c >= n else min(end, track.start.at(c) - 1)
            k = p + int(np.searchsorted(_i(track.stop_ns, p, n), limit - self.hi_ns, side="right"))
            k = min(k, c)
        if k <= p:
            return
        pos = track.positions(p, c, end)
        lo_a, hi_a = _f(self.arg.lo, p, c), _f(self.arg.hi, p, c)
        arg = Truth(-hi_a, -lo_a) if self.always else Truth(lo_a, hi_a)
        if closing:
            w = _windows(pos, self.interval)
            val = _eventually(arg, w, None, pos.size)
            lo, hi = val.lo, val.hi
        else:
            w = _windows(pos, self.interval, np.arange(k - p, dtype=np.int64))
            lo = range_reduce(arg.lo, w.in0, w.in1, np.maximum, -INF)
            hi = range_reduce(arg.hi, w.out0, w.out1, np.maximum, -INF)
        if self.always:
            lo, hi = -hi, -lo
        arg_known = _i(self.arg.known, p, c)
        last = np.maximum(w.out1 - 1, 0)
        known = np.where(w.out1 > w.out0, arg_known[np.minimum(last, max(c - p - 1, 0))], np.iinfo(np.int64).min)
        if self.hi_ns is not None:
            known = np.maximum(known, track.first_tick_at_or_after(pos.stop_ns[: k - p] + self.hi_ns, closing))
        elif closing:
            known = np.maximum(known, end)
        if closing:
            known = np.minimum(known, end)
        self.emit(lo, hi, known.astype(np.int64), self._witness(track, pos, w, hi_a=hi_a, span=(p, c)))

    def _witness(self, track: Track, pos: Positions, w: Any, *, hi_a: FloatArray, span: tuple[int, int]
                 ) -> IntArray:
        """Where each of the ``k`` new values is shown false (``explain``): ``F``, the end of its window (clipped to
        the log's end); ``G``, the witness of its argument at the first false position of the window."""
        p, c = span
        k = w.in0.shape[0]
        stop = pos.stop_ns[:k]
        ends = (np.full(k, pos.end_ns, dtype=np.int64) if self.hi_ns is None
                else np.minimum(stop + self.hi_ns, pos.end_ns))
        if not self.always:
            return ends.astype(np.int64)
        fail = np.flatnonzero(hi_a < 0)  # the argument false (its own bounds, not negated)
        if fail.size == 0:
            return ends.astype(np.int64)
        j = np.searchsorted(fail, w.in0[:k])  # the first false argument at or after each window's start
        first = fail[np.minimum(j, fail.size - 1)]
        hit = (j < fail.size) & (first < w.in1[:k])
        arg_wit = self.arg.witness(track, p, c)
        return np.where(hit, arg_wit[first], ends).astype(np.int64)

    def provisional(self, track: Track) -> tuple[FloatArray, FloatArray, FloatArray]:
        """A window not yet observed to its end: ``F`` is certain once its argument is certainly true at a position
        of the window (then), never false before its end; ``G`` dually. An unbounded window stays open."""
        p, n, end = self.final, track.count, track.end_ns
        lo_a, hi_a, kn = self.arg.values_from(track, p)
        if end is None or n <= p:
            return np.zeros(0), np.zeros(0), np.zeros(0)
        arg = Truth(-hi_a, -lo_a) if self.always else Truth(lo_a, hi_a)
        pos = track.positions(p, n, max(end, int(track.stop_ns.at(n - 1))))
        w = _windows(pos, self.interval)
        lo = range_reduce(arg.lo, w.in0, w.in1, np.maximum, -INF)
        hi = np.full(n - p, INF)  # F may still come true later in the window (or after the end, if unbounded)
        certain = np.where((arg.lo > 0) & np.isfinite(kn), kn, INF)
        known = range_reduce(certain, w.in0, w.in1, np.minimum, INF)
        if self.always:
            lo, hi = -hi, -lo
        return lo, hi, known


# ---- the formula at its first position -------------------------------------------------------------------------------
@dataclass(slots=True)
class Head:
    """The value of a formula at the first position, refined as data arrives: ``lo`` only grows, ``hi`` only
    shrinks. ``decided_ns``: when the verdict became final; ``witness_ns``: where a false verdict was shown."""

    formula: Formula
    lo: float = -INF
    hi: float = INF
    decided_ns: int | None = None
    witness_ns: int | None = None
    closed: bool = False

    @property
    def verdict(self) -> str:
        return "pass" if self.lo > 0 else ("fail" if self.hi < 0 else "inconclusive")

    @property
    def decided(self) -> bool:
        return self.closed or self.lo > 0 or self.hi < 0

    @property
    def margin_final(self) -> bool:
        """Whether ``lo`` and ``hi`` are final: no later sample can change them (the verdict may be final earlier,
        while a window is still open: an ``F`` already true can still become more so)."""
        return self.closed

    def children(self) -> tuple[Head, ...]:
        return ()

    def nodes(self) -> tuple[Node, ...]:
        """The stream nodes this head reads."""
        return ()

    def need_from(self) -> int:
        return 0

    def update(self, track: Track, closing: bool) -> None:
        raise NotImplementedError


class StreamHead(Head):
    """A sub-formula without temporal operators: its value at the first position."""

    def __init__(self, formula: Formula, node: Node) -> None:
        super().__init__(formula)
        self.node = node

    def nodes(self) -> tuple[Node, ...]:
        return (self.node,)

    @property
    def margin_final(self) -> bool:
        return self.closed or self.decided_ns is not None

    def need_from(self) -> int:
        return 0 if self.node.final == 0 else 1

    def update(self, track: Track, closing: bool) -> None:
        if self.node.final and self.node.lo.base == 0 and self.decided_ns is None:
            self.lo, self.hi = float(self.node.lo.at(0)), float(self.node.hi.at(0))
            self.decided_ns = int(self.node.known.at(0))
            self.witness_ns = track.first_ns if self.hi < 0 else None
        if closing:
            self.closed = True
            if self.decided_ns is None:
                self.decided_ns = track.end_ns


class WindowHead(Head):
    """``F_I arg`` / ``G_I arg`` at the first position (a point): running extrema over the window's positions."""

    def __init__(self, formula: Eventually | Always, node: Node) -> None:
        super().__init__(formula)
        self.node = node
        self.always = isinstance(formula, Always)
        self.lo_ns, self.hi_ns = bounds_ns(formula.interval)
        self.used = 0  # positions of the argument consumed
        self.acc_lo = -INF  # max of the (negated for G) argument's lo over the window so far
        self.acc_hi = -INF
        self.complete = False
        self.early_lo = -INF  # the (negated for G) argument certainly true at a position not final yet
        self.acc_known = -(2**63)  # the latest time an argument value in the window became final

    def _early(self, track: Track, t0: int) -> None:
        """The argument's provisional values settle the window before they are final (a nested window that is
        already certainly true, or false for G)."""
        p = self.used
        lo_a, hi_a, kn = self.node.values_from(track, p)
        if self.always:
            lo_a, hi_a = -hi_a, -lo_a
        start, stop = _i(track.start, p, track.count), _i(track.stop_ns, p, track.count)
        inside = stop >= t0 + self.lo_ns
        if self.hi_ns is not None:
            inside &= start <= t0 + self.hi_ns
        certain = np.flatnonzero(inside & (lo_a > 0) & np.isfinite(kn))
        if certain.size:
            k = int(certain[int(np.argmin(kn[certain]))])
            self.early_lo = float(lo_a[certain].max())
            self._decide(int(kn[k]), int(kn[k]))  # shown by the sample that made the argument certain

    def nodes(self) -> tuple[Node, ...]:
        return (self.node,)

    @property
    def margin_final(self) -> bool:
        return self.closed or self.complete

    def need_from(self) -> int:
        return self.used

    def update(self, track: Track, closing: bool) -> None:
        c = self.node.final
        if track.first_ns is None or track.end_ns is None:
            if closing:
                self.closed = True
                self.decided_ns = track.end_ns
            return
        t0 = track.first_ns
        if self.complete:  # later positions cannot change it
            self.used = c
        if c > self.used:
            p = self.used
            start, stop = _i(track.start, p, c), _i(track.stop_ns, p, c)
            lo_a, hi_a = _f(self.node.lo, p, c), _f(self.node.hi, p, c)
            if self.always:
                lo_a, hi_a = -hi_a, -lo_a
            inside = stop >= t0 + self.lo_ns
            if self.hi_ns is not None:
                inside &= start <= t0 + self.hi_ns
            if inside.any():
                sel = np.flatnonzero(inside)
                run_lo = np.maximum.accumulate(lo_a[sel])
                if self.acc_lo <= 0 < run_lo[-1]:  # the argument decides it in this batch: at which position
                    k = int(sel[int(np.argmax(run_lo > 0))])
                    where = int(self.node.witness(track, p + k, p + k + 1)[0]) if self.always else int(start[k])
                    self._decide(int(_i(self.node.known, p, c)[k]), where)
                self.acc_lo = max(self.acc_lo, float(run_lo[-1]))
                self.acc_hi = max(self.acc_hi, float(hi_a[sel].max()))
                self.acc_known = max(self.acc_known, int(_i(self.node.known, p, c)[sel].max()))
            self.used = c
        if self.decided_ns is None and not self.complete and self.node.final < track.count:
            self._early(track, t0)
        if not self.complete:
            if self.hi_ns is not None:
                bound = t0 + self.hi_ns
                covered = self.used >= track.count or int(track.start.at(self.used)) > bound
                self.complete = bound <= track.end_ns and covered
                if self.complete:
                    when = int(track.first_tick_at_or_after(np.array([bound], dtype=np.int64), closing)[0])
                    if self.acc_lo <= 0 and self.acc_hi < 0:  # decided once the window and its values are seen
                        self._decide(max(min(when, track.end_ns), self.acc_known), min(bound, track.end_ns))
            elif closing:
                self.complete = True
        lo, hi = max(self.acc_lo, self.early_lo), (self.acc_hi if self.complete else INF)
        self.lo, self.hi = (-hi, -lo) if self.always else (lo, hi)
        if closing:
            self.closed = True
            if self.decided_ns is None:
                self.decided_ns = track.end_ns
                if not self.always and self.hi < 0:  # an unbounded F never met: shown at the end of the log
                    self.witness_ns = track.end_ns

    def _decide(self, when_ns: int, where_ns: int | None) -> None:
        """``where_ns``: the position that shows a violation (G) or the end of the window (F), if false."""
        if self.decided_ns is None:
            self.decided_ns = when_ns
            if self.always or where_ns is not None:
                self.witness_ns = where_ns if where_ns is not None else when_ns


class BoolHead(Head):
    """Not / And / Or / Implies of heads (Kleene's logic on the intervals)."""

    def __init__(self, formula: Formula, kids: list[Head], kind: str) -> None:
        super().__init__(formula)
        self.kids = kids
        self.kind = kind  # "and" | "or" | "not" | "implies"

    def children(self) -> tuple[Head, ...]:
        return tuple(self.kids)

    @property
    def margin_final(self) -> bool:
        return self.closed or all(k.margin_final for k in self.kids)

    def need_from(self) -> int:
        return _NEVER  # reads no positions itself

    def update(self, track: Track, closing: bool) -> None:
        for k in self.kids:
            k.update(track, closing)
        parts = [(k.lo, k.hi, k) for k in self.kids]
        if self.kind == "not":
            (lo, hi, _), = parts
            self.lo, self.hi = -hi, -lo
        elif self.kind == "implies":
            (alo, ahi, _), (blo, bhi, _) = parts
            self.lo, self.hi = max(-ahi, blo), max(-alo, bhi)
        else:
            op = min if self.kind == "and" else max
            self.lo, self.hi = op(p[0] for p in parts), op(p[1] for p in parts)
        if self.decided_ns is None and (self.lo > 0 or self.hi < 0):
            self.decided_ns, self.witness_ns = self._when(track)
        if closing:
            self.closed = True
            if self.decided_ns is None:
                self.decided_ns = track.end_ns
            if self.kind == "and" and self.hi < 0:  # every conjunct is settled now: the earliest witness
                self.witness_ns = min((k.witness_ns for k in self.kids if k.hi < 0 and k.witness_ns is not None),
                                      default=self.witness_ns)

    def _when(self, track: Track) -> tuple[int | None, int | None]:
        """The decision time: the earliest deciding child for a decisive one, else the last child decided; and
        where a false one is shown, as ``verify.monitor.engine.explain``: a negation or a disjunction at the first
        position, an implication where its conclusion is, a conjunction at the earliest false conjunct's."""
        true = self.lo > 0
        signs = [(k, k.lo > 0, k.hi < 0) for k in self.kids]
        if self.kind == "not":
            return self.kids[0].decided_ns, None if true else track.first_ns
        if self.kind == "implies":
            (a, _a_t, a_f), (b, b_t, _b_f) = signs
            decisive = [k for k, ok in ((a, a_f), (b, b_t)) if ok] if true else []
            if not true:
                return max(_d(a), _d(b)), b.witness_ns
            return min(_d(k) for k in decisive), None
        short = (self.kind == "and" and not true) or (self.kind == "or" and true)
        if short:
            deciding = [k for k, t, f in signs if (f if self.kind == "and" else t)]
            first = min(deciding, key=_d)
            if true:
                return _d(first), None
            return _d(first), min((k.witness_ns for k in deciding if k.witness_ns is not None), default=None)
        return max(_d(k) for k in self.kids), None if true else track.first_ns


def _d(h: Head) -> int:
    return h.decided_ns if h.decided_ns is not None else _NEVER


class OfflineHead(Head):
    """A formula with ``Until`` / ``Next``: its atoms are kept and it is evaluated by the offline engine at close."""

    def __init__(self, formula: Formula, atom_nodes: dict[str, Node]) -> None:
        super().__init__(formula)
        self.atom_nodes = atom_nodes

    def nodes(self) -> tuple[Node, ...]:
        return tuple(self.atom_nodes.values())

    def update(self, track: Track, closing: bool) -> None:
        if not closing or track.end_ns is None or track.count == 0:
            return
        n = track.count
        pos = track.positions(0, n, track.end_ns)
        atoms = {name: Truth(_f(node.lo, 0, n), _f(node.hi, 0, n)) for name, node in self.atom_nodes.items()}
        values = evaluate_at_points(self.formula, pos, atoms)
        root = values[self.formula]
        self.lo, self.hi = float(root.lo[0]), float(root.hi[0])
        self.decided_ns = track.end_ns
        if self.hi < 0:  # where the certificate shows the violation
            self.witness_ns = explain(self.formula, 0, pos, values).time_ns
        self.closed = True


# ---- building --------------------------------------------------------------------------------------------------------
def _temporal(f: Formula) -> bool:
    if isinstance(f, Eventually | Always | Until | Next):
        return True
    if isinstance(f, Not):
        return _temporal(f.arg)
    if isinstance(f, And | Or):
        return any(_temporal(g) for g in f.args)
    if isinstance(f, Implies):
        return _temporal(f.left) or _temporal(f.right)
    return False


def _offline_only(f: Formula) -> bool:
    if isinstance(f, Until | Next):
        return True
    if isinstance(f, Not | Eventually | Always):
        return _offline_only(f.arg)
    if isinstance(f, And | Or):
        return any(_offline_only(g) for g in f.args)
    if isinstance(f, Implies):
        return _offline_only(f.left) or _offline_only(f.right)
    return False


def build_head(formula: Formula, atom: Callable[[str], AtomNode]) -> Head:
    """The head of ``formula`` over the atom nodes ``atom(name)`` (shared stream nodes per distinct sub-formula)."""
    memo: dict[Formula, Node] = {}

    def stream(f: Formula) -> Node:
        if f in memo:
            return memo[f]
        node: Node
        if isinstance(f, Atom):
            node = atom(f.name)
        elif isinstance(f, Const):
            node = ConstNode(f.value)
        elif isinstance(f, Not):
            node = NotNode(stream(f.arg))
        elif isinstance(f, And | Or):
            node = BoolNode([stream(g) for g in f.args], np.minimum if isinstance(f, And) else np.maximum)
        elif isinstance(f, Implies):
            node = BoolNode([NotNode(stream(f.left)), stream(f.right)], np.maximum, implies=True)
        elif isinstance(f, Eventually | Always):
            node = WindowNode(stream(f.arg), f.interval, isinstance(f, Always))
        else:
            raise TypeError(f"no stream node for {f}")
        memo[f] = node
        return node

    def head(f: Formula) -> Head:
        if _offline_only(f):
            from tubempc.mitl import atoms as atoms_of

            return OfflineHead(f, {name: atom(name) for name in sorted(atoms_of(f))})
        if not _temporal(f):
            return StreamHead(f, stream(f))
        if isinstance(f, Eventually | Always):
            return WindowHead(f, stream(f.arg))
        if isinstance(f, Not):
            return BoolHead(f, [head(f.arg)], "not")
        if isinstance(f, Implies):
            return BoolHead(f, [head(f.left), head(f.right)], "implies")
        if isinstance(f, And | Or):
            return BoolHead(f, [head(g) for g in f.args], "and" if isinstance(f, And) else "or")
        raise TypeError(f"no head for {f}")

    return head(formula)


#: steps between two drops of the positions no consumer needs (dropping is cheap but not free)
_TRIM_EVERY = 8


class Evaluation:
    """Stream nodes (children first) and heads of one semantics over one track; ``step`` advances them and drops
    what no consumer needs any more."""

    def __init__(self, track: Track, heads: list[Head]) -> None:
        self.track = track
        self.heads = heads
        self.nodes: list[Node] = []
        self._steps = 0
        self.consumers: dict[int, list[Node | Head]] = {}
        seen: set[int] = set()

        def visit(node: Node, parent: Node | Head) -> None:
            self.consumers.setdefault(id(node), []).append(parent)
            if id(node) in seen:
                return
            seen.add(id(node))
            for child in node.children():
                visit(child, node)
            self.nodes.append(node)

        def visit_head(h: Head) -> None:
            for node in h.nodes():
                visit(node, h)
            for k in h.children():
                visit_head(k)

        for h in heads:
            visit_head(h)

    def step(self, closing: bool = False) -> None:
        for node in self.nodes:
            node.update(self.track, closing)
        for h in self.heads:
            h.update(self.track, closing)
        self._steps += 1
        if closing or self._steps % _TRIM_EVERY:
            return
        keep = self.track.count
        for node in self.nodes:
            node.keep_from = min(c.need_from() for c in self.consumers[id(node)])
            node.trim()
            keep = min(keep, node.need_from(), node.keep_from)
        for h in self.heads:
            keep = min(keep, _head_need(h))
        self.track.drop_before(keep)

    def retained(self) -> int:
        """Positions, ticks and values held (for the memory bound)."""
        tr = self.track
        return (tr.count - tr.start.base) + (tr.ticks.stop - tr.ticks.base) + sum(n.lo.stop - n.lo.base
                                                                                    for n in self.nodes)


def _head_need(h: Head) -> int:
    return min([h.need_from(), *(_head_need(k) for k in h.children())])
