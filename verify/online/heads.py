"""Streaming MITL evaluation, the heads: the formula's value at its first position, refined as the stream nodes'
values arrive, and the evaluation that steps nodes and heads together.

input: the formula, its atoms' stream nodes (``verify.online.stream``) over one ``Track`` -> output: a ``Head``
whose interval only shrinks as data arrives (monotone: a decided verdict never flips), with the time it was decided
and where a false verdict is shown; equal to ``verify.monitor.engine`` on the whole log after ``close``. The
top-level temporal operators are evaluated at the first position only (running extrema, nothing retained); a formula
with ``Until`` / ``Next`` keeps its atoms and is evaluated at ``close`` by the offline engine.
"""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass

import numpy as np
import numpy.typing as npt

from tubempc.mitl import Always, And, Atom, Const, Eventually, Formula, Implies, Next, Not, Or, Until, subformulas
from tubempc.mitl import atoms as atoms_of
from verify.monitor.engine import Truth, bounds_ns, evaluate_at_points, explain
from verify.online.stream import AtomNode, BoolNode, ConstNode, Node, NotNode, WindowNode
from verify.online.track import NEVER_NS, Track, floats, ints
from verify.semantics.analysis import decided_times

__all__ = ["BoolHead", "Evaluation", "Head", "OfflineHead", "StreamHead", "WindowHead", "build_head"]

INF = math.inf
IntArray = npt.NDArray[np.int64]


# ---- the formula at its first position -------------------------------------------------------------------------------
@dataclass(slots=True)
class Head:
    """The value of a formula at the first position, refined as data arrives: ``lo`` only grows, ``hi`` only
    shrinks. ``decided_ns``: when the verdict became final; ``witness_ns``: where a false verdict was shown;
    ``final_ns``: the time of the sample since which ``lo`` and ``hi`` are final (no later sample can change them;
    None while one can), whatever the batching."""

    formula: Formula
    lo: float = -INF
    hi: float = INF
    decided_ns: int | None = None
    witness_ns: int | None = None
    closed: bool = False
    final_ns: int | None = None

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
        return self.closed or self.final_ns is not None

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

    def need_from(self) -> int:
        return 0 if self.node.final == 0 else 1

    def update(self, track: Track, closing: bool) -> None:
        if self.node.final and self.node.lo.base == 0 and self.decided_ns is None:
            self.lo, self.hi = float(self.node.lo.at(0)), float(self.node.hi.at(0))
            self.decided_ns = self.final_ns = int(self.node.known.at(0))
            self.witness_ns = track.first_ns if self.hi < 0 else None
        if closing:
            self.closed = True
            if self.decided_ns is None:
                self.decided_ns = self.final_ns = track.end_ns


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
        start, stop = ints(track.start, p, track.count), ints(track.stop_ns, p, track.count)
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

    def need_from(self) -> int:
        return self.used

    def update(self, track: Track, closing: bool) -> None:
        if track.first_ns is None or track.end_ns is None:
            if closing:
                self.closed = True
                self.decided_ns = track.end_ns
            return
        t0 = track.first_ns
        if self.complete:  # later positions cannot change it
            self.used = self.node.final
        if self.node.final > self.used:
            self._consume(track, t0)
        if self.decided_ns is None and not self.complete and self.node.final < track.count:
            self._early(track, t0)
        if not self.complete:
            self._complete(track, t0, track.end_ns, closing)
        lo, hi = max(self.acc_lo, self.early_lo), (self.acc_hi if self.complete else INF)
        self.lo, self.hi = (-hi, -lo) if self.always else (lo, hi)
        if closing:
            self.closed = True
            if self.final_ns is None:
                self.final_ns = track.end_ns
            if self.decided_ns is None:
                self.decided_ns = track.end_ns
                if not self.always and self.hi < 0:  # an unbounded F never met: shown at the end of the log
                    self.witness_ns = track.end_ns

    def _consume(self, track: Track, t0: int) -> None:
        """The argument's new final values: those inside the window update the running extrema (and decide the
        head at the first position that makes the argument true, false for G)."""
        p, c = self.used, self.node.final
        self.used = c
        track_start, track_stop = track.start, track.stop_ns
        first, last = t0 + self.lo_ns, None if self.hi_ns is None else t0 + self.hi_ns
        # positions are in time order (starts and stops rising): all of them may meet the window, or none of them
        # (the timed run's entries are points: a window may also fall between two)
        if track_stop.at(c - 1) < first or (last is not None and track_start.at(p) > last):
            return
        start = ints(track_start, p, c)
        sel: slice | IntArray
        if track_stop.at(p) >= first and (last is None or track_start.at(c - 1) <= last):
            sel = slice(None)
        else:
            inside = ints(track_stop, p, c) >= first
            if last is not None:
                inside &= start <= last
            sel = np.flatnonzero(inside)
            if not sel.size:
                return
        lo_a, hi_a = floats(self.node.lo, p, c)[sel], floats(self.node.hi, p, c)[sel]
        known = ints(self.node.known, p, c)[sel]
        # the (negated for G) argument's extrema over these positions
        best, worst = (-float(hi_a.min()), -float(lo_a.min())) if self.always else (float(lo_a.max()),
                                                                                     float(hi_a.max()))
        if self.acc_lo <= 0 < best:  # the argument decides it in this batch: at its first position that does
            j = int(np.argmax(-hi_a > 0 if self.always else lo_a > 0))
            k = j if isinstance(sel, slice) else int(sel[j])
            where = int(self.node.witness(track, p + k, p + k + 1)[0]) if self.always else int(start[k])
            self._decide(int(known[j]), where)
        self.acc_lo = max(self.acc_lo, best)
        self.acc_hi = max(self.acc_hi, worst)
        self.acc_known = max(self.acc_known, int(known.max()))

    def _complete(self, track: Track, t0: int, end: int, closing: bool) -> None:
        """Whether the window has been observed to its end with every value in it final (then a head not yet
        decided is decided by its extrema: false, since true would have decided it before)."""
        if self.hi_ns is None:
            self.complete = closing
            return
        bound = t0 + self.hi_ns
        covered = self.used >= track.count or int(track.start.at(self.used)) > bound
        self.complete = bound <= end and covered
        if self.complete:
            when = int(track.first_tick_at_or_after(np.array([bound], dtype=np.int64), closing)[0])
            # final since the first sample at or after the window's end, once every value in it is final: the same
            # time however the samples were batched (the update that sees it may come later)
            self.final_ns = max(min(when, end), self.acc_known)
            if self.acc_lo <= 0 and self.acc_hi < 0:  # decided once the window and its values are seen
                self._decide(self.final_ns, min(bound, end))

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

    def need_from(self) -> int:
        return NEVER_NS  # reads no positions itself

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
        if self.final_ns is None and all(k.final_ns is not None for k in self.kids):  # final once every part is
            self.final_ns = max(_d(k, final=True) for k in self.kids)
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


def _d(h: Head, *, final: bool = False) -> int:
    """When ``h`` was decided (``final``: since when its margin is final); never if not yet."""
    t = h.final_ns if final else h.decided_ns
    return t if t is not None else NEVER_NS


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
        atoms = {name: Truth(floats(node.lo, 0, n), floats(node.hi, 0, n)) for name, node in self.atom_nodes.items()}
        values = evaluate_at_points(self.formula, pos, atoms)
        root = values[self.formula]
        self.lo, self.hi = float(root.lo[0]), float(root.hi[0])
        # when the data decided it, as the certificate's decided_at (verify.semantics.analysis), not when judged
        d = float(decided_times(self.formula, pos, values)[self.formula][0])
        self.decided_ns = int(d) if math.isfinite(d) and (self.lo > 0 or self.hi < 0) else track.end_ns
        if self.hi < 0:  # where the certificate shows the violation
            self.witness_ns = explain(self.formula, 0, pos, values).time_ns
        self.closed = True
        self.final_ns = track.end_ns


# ---- building --------------------------------------------------------------------------------------------------------
def _temporal(f: Formula) -> bool:
    return any(isinstance(g, Eventually | Always | Until | Next) for g in subformulas(f))


def _offline_only(f: Formula) -> bool:
    return any(isinstance(g, Until | Next) for g in subformulas(f))


def _new_node(f: Formula, child: Callable[[Formula], Node], atom: Callable[[str], AtomNode]) -> Node:
    """The stream node of ``f`` over its children's (``child``) and the atom nodes (``atom``)."""
    if isinstance(f, Atom):
        return atom(f.name)
    if isinstance(f, Const):
        return ConstNode(f.value)
    if isinstance(f, Not):
        return NotNode(child(f.arg))
    if isinstance(f, And | Or):
        return BoolNode([child(g) for g in f.args], np.minimum if isinstance(f, And) else np.maximum)
    if isinstance(f, Implies):
        return BoolNode([NotNode(child(f.left)), child(f.right)], np.maximum, implies=True)
    if isinstance(f, Eventually | Always):
        return WindowNode(child(f.arg), f.interval, isinstance(f, Always))
    raise TypeError(f"no stream node for {f}")


def build_head(formula: Formula, atom: Callable[[str], AtomNode]) -> Head:
    """The head of ``formula`` over the atom nodes ``atom(name)`` (shared stream nodes per distinct sub-formula)."""
    memo: dict[Formula, Node] = {}

    def stream(f: Formula) -> Node:
        if f not in memo:
            memo[f] = _new_node(f, stream, atom)
        return memo[f]

    def head(f: Formula) -> Head:
        if _offline_only(f):
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


#: steps between two drops of the positions no consumer needs (dropping is cheap but not free) ...
_TRIM_EVERY = 8
#: ... or sooner, once this many positions and ticks were appended since the last drop (large batches)
_TRIM_AFTER = 1024


class Evaluation:
    """Stream nodes (children first) and heads of one semantics over one track; ``step`` advances them and drops
    what no consumer needs any more."""

    def __init__(self, track: Track, heads: list[Head]) -> None:
        self.track = track
        self.heads = heads
        self.nodes: list[Node] = []
        self._steps = 0
        self._trimmed_at = 0  # positions and ticks appended when the last drop ran
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
        appended = self.track.count + self.track.ticks.stop
        if closing or (self._steps % _TRIM_EVERY and appended - self._trimmed_at < _TRIM_AFTER):
            return
        self._trimmed_at = appended
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
