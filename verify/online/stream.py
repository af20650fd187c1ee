"""Streaming MITL evaluation, the stream nodes: positions and atom values arriving in time order -> final
sub-formula values per position, and provisional bounds for those not final yet.

input: a ``Track`` (``verify.online.track``: position spans appended in time order, the end of observation, the
observation ticks) and the atoms' robustness bounds appended per position -> output: for every node its *final*
values (those offline analysis of any longer log would also give), the time each became known, and where a false
value is shown. The formula's verdict at its first position is read from these by the heads
(``verify.online.heads``).

The semantics is the offline one, computed by its own code: the windows of a batch of positions are
``verify.monitor.engine._windows`` over the retained slice of positions and their extrema ``range_reduce``; ``close``
runs ``_eventually`` (incomplete windows) on what is left. A node keeps only the positions its parent still needs:

* a bounded window ``[lo, hi]`` is final once ``stop + hi`` is observed, so a node retains ``hi`` x rate positions;
  before that its *provisional* bounds (and the time its verdict became certain) let the operators above it decide
  early -- a nested ``G`` is false at the first sample that shows its argument false;
* an unbounded window *below* another temporal operator keeps its positions until ``close`` (memory grows with the
  log for those formulas only).
"""

from __future__ import annotations

import math
from typing import Any

import numpy as np
import numpy.typing as npt

from tubempc.mitl import Interval
from verify.monitor.engine import Positions, Truth, _eventually, _windows, bounds_ns, range_reduce
from verify.online.track import AT_START, NEVER_NS, Buffer, Track, floats, ints

__all__ = ["AtomNode", "BoolNode", "ConstNode", "Node", "NotNode", "WindowNode"]

FloatArray = npt.NDArray[np.float64]
IntArray = npt.NDArray[np.int64]
INF = math.inf


class Node:
    """Final values ``lo``, ``hi`` and the time each became known (``known``) for positions ``[0, final)``."""

    def __init__(self) -> None:
        self.lo = Buffer(np.float64)
        self.hi = Buffer(np.float64)
        self.known = Buffer(np.int64)
        self.wit = Buffer(np.int64)  # where a false value is shown (``engine.explain``); AT_START: its start
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
        lo, hi = floats(self.lo, p, c), floats(self.hi, p, c)
        known = ints(self.known, p, c).astype(np.float64)
        if c >= track.count:
            return lo, hi, known
        plo, phi, pkn = self.provisional(track)
        return np.concatenate((lo, plo)), np.concatenate((hi, phi)), np.concatenate((known, pkn))

    def emit(self, lo: FloatArray, hi: FloatArray, known: IntArray, wit: IntArray | None = None) -> None:
        self.lo.extend(lo)
        self.hi.extend(hi)
        self.known.extend(known)
        if wit is None:
            self.wit.fill(AT_START, lo.shape[0])
        else:
            self.wit.extend(wit)
        self.final += lo.shape[0]

    def witness(self, track: Track, g0: int, g1: int) -> IntArray:
        """For the final positions ``[g0, g1)``: the time a false value is shown, as the offline ``explain`` walks
        down to it (a position's own start for an atom, a negation, an or; the earliest among the false conjuncts;
        an implication's conclusion; the end of an ``F``'s window; a ``G``'s first false argument)."""
        w = ints(self.wit, g0, g1)
        return np.where(w == AT_START, ints(track.start, g0, g1), w)

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
            # as an atom's (and verify.semantics.analysis): a gap exists once the sample after it arrives
            p, c = self.final, track.count
            known = np.where(track.is_point.view(p, c), ints(track.start, p, c), ints(track.stop_ns, p, c) + 1)
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
            self.emit(-floats(self.arg.hi, p, c), -floats(self.arg.lo, p, c), ints(self.arg.known, p, c))

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
        lo = floats(self.args[0].lo, p, c)
        hi = floats(self.args[0].hi, p, c)
        known = ints(self.args[0].known, p, c)
        for a in self.args[1:]:
            lo = self.op(lo, floats(a.lo, p, c))
            hi = self.op(hi, floats(a.hi, p, c))
            known = np.maximum(known, ints(a.known, p, c))
        wit = None
        if self.implies:
            wit = self.args[1].witness(track, p, c)
        elif self.op is np.minimum:  # and: the earliest witness among the false conjuncts
            wit = np.full(c - p, NEVER_NS, dtype=np.int64)
            for a in self.args:
                wit = np.where(floats(a.hi, p, c) < 0, np.minimum(wit, a.witness(track, p, c)), wit)
            wit = np.where(wit == NEVER_NS, AT_START, wit)
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
            k = p + int(np.searchsorted(ints(track.stop_ns, p, n), limit - self.hi_ns, side="right"))
            k = min(k, c)
        if k <= p:
            return
        pos = track.positions(p, c, end)
        lo_a, hi_a = floats(self.arg.lo, p, c), floats(self.arg.hi, p, c)
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
        arg_known = ints(self.arg.known, p, c)
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
