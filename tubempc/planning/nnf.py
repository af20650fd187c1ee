"""MITL -> negation normal form: the nodes the timed automaton (``tubempc.planning.automaton``) works on.

input: a ``Formula`` (``tubempc.mitl``) and the tick (seconds per integer time unit) -> output: the list of
``Node`` values (hash-consed: one node per distinct sub-formula), the root's index and, per node, the sub-formula of
the input it came from (for messages). ``->`` and ``!`` are pushed to the atoms; the temporal operators are
``F_I, G_I, U_I, R_I`` (release, the dual of until), strong ``X_I`` and weak ``Xw_I`` (the dual of next), each with
its interval in ticks (every endpoint must be an exact multiple of the tick; ``tick_of`` finds the largest that
works). Conjunctions and disjunctions are flattened, sorted and simplified against ``true``/``false``.
"""

from __future__ import annotations

from collections.abc import Iterable
from dataclasses import dataclass
from fractions import Fraction
from math import gcd, lcm

from tubempc.mitl import (
    Always,
    And,
    Atom,
    Const,
    Eventually,
    Formula,
    Implies,
    Interval,
    Next,
    Not,
    Or,
    Until,
)

__all__ = ["ALW", "AND", "ATOM", "EV", "FALSE", "KIND_NAMES", "NATOM", "NXT", "OR", "REL", "TRUE", "UNT", "WNXT",
           "Node", "negation_normal_form", "tick_of"]

# Node kinds of the negation normal form.
TRUE, FALSE, ATOM, NATOM, AND, OR, EV, ALW, UNT, REL, NXT, WNXT = range(12)
KIND_NAMES = ("true", "false", "atom", "!atom", "and", "or", "F", "G", "U", "R", "X", "Xw")


def tick_of(values: Iterable[Fraction], *, refine: int = 1) -> Fraction:
    """Largest ``q`` such that every value is an integer multiple of ``q``, divided by ``refine``.

    ``refine = 2`` makes every constant even, so that "strictly after a constant" is one tick after it.
    """
    nums = [v for v in values if v != 0]
    if refine < 1:
        raise ValueError(f"refine={refine} must be a positive integer")
    if not nums:
        return Fraction(1, refine)
    if any(v < 0 for v in nums):
        raise ValueError("times must not be negative")
    den = lcm(*(v.denominator for v in nums))
    g = 0
    for v in nums:
        g = gcd(g, int(v * den))
    return Fraction(g, den) / refine


@dataclass(frozen=True, slots=True)
class Node:
    """One node of the negation normal form. Interval endpoints in ticks; ``hi is None`` means unbounded."""

    kind: int
    text: str
    atom: str = ""
    children: tuple[int, ...] = ()
    lo: int = 0
    hi: int | None = None
    lo_closed: bool = True
    hi_closed: bool = False

    def inside(self, age: int) -> bool:
        if age < self.lo or (age == self.lo and not self.lo_closed):
            return False
        return self.hi is None or age < self.hi or (age == self.hi and self.hi_closed)

    def before(self, age: int) -> bool:
        return age < self.lo or (age == self.lo and not self.lo_closed)

    def reached(self, age: int) -> bool:
        """At or past the lower end: the copy is 'inside its window' for subsumption and acceptance."""
        return not self.before(age)

    def future(self, age: int) -> bool:
        """Whether a later position (at least one tick later) can have an age inside the interval."""
        if self.hi is None:
            return True
        nxt = age + 1
        return nxt < self.hi or (nxt == self.hi and self.hi_closed)

    @property
    def cap(self) -> int:
        """Ages at or above the cap behave alike."""
        return (self.lo if self.hi is None else self.hi) + 1


class _Compiler:
    def __init__(self, tick: Fraction) -> None:
        self.tick = tick
        self.nodes: list[Node] = []
        self.index: dict[Node, int] = {}
        self.sources: dict[int, Formula] = {}

    def add(self, node: Node, source: Formula) -> int:
        nid = self.index.get(node)
        if nid is None:
            nid = len(self.nodes)
            self.nodes.append(node)
            self.index[node] = nid
            self.sources[nid] = source
        return nid

    def ticks(self, value: Fraction, what: Interval) -> int:
        q = value / self.tick
        if q.denominator != 1:
            raise ValueError(f"interval {what}: endpoint {value} is not a multiple of the tick {self.tick} s")
        return int(q)

    def _temporal(self, kind: int, text: str, kids: tuple[int, ...], f: Next | Eventually | Always | Until) -> int:
        iv = f.interval
        hi = None if iv.hi is None else self.ticks(iv.hi, iv)
        node = Node(kind, text, children=kids, lo=self.ticks(iv.lo, iv), hi=hi, lo_closed=iv.lo_closed,
                    hi_closed=iv.hi_closed)
        return self.add(node, f)

    def nnf(self, f: Formula, positive: bool) -> int:
        if isinstance(f, Const):
            val = f.value == positive
            return self.add(Node(TRUE if val else FALSE, "true" if val else "false"), f)
        if isinstance(f, Atom):
            if positive:
                return self.add(Node(ATOM, f.name, atom=f.name), f)
            return self.add(Node(NATOM, "!" + f.name, atom=f.name), f)
        if isinstance(f, Not):
            return self.nnf(f.arg, not positive)
        if isinstance(f, Implies):
            return self._junction(OR if positive else AND, (self.nnf(f.left, not positive),
                                                           self.nnf(f.right, positive)), f)
        if isinstance(f, And | Or):
            kind = (AND if isinstance(f, And) else OR) if positive else (OR if isinstance(f, And) else AND)
            return self._junction(kind, tuple(self.nnf(a, positive) for a in f.args), f)
        text = str(f) if positive else "!" + _paren(str(f))
        if isinstance(f, Next):
            return self._temporal(NXT if positive else WNXT, text, (self.nnf(f.arg, positive),), f)
        if isinstance(f, Eventually):
            return self._temporal(EV if positive else ALW, text, (self.nnf(f.arg, positive),), f)
        if isinstance(f, Always):
            return self._temporal(ALW if positive else EV, text, (self.nnf(f.arg, positive),), f)
        if isinstance(f, Until):
            # !(a U_I b) = (!a) R_I (!b)
            kids = (self.nnf(f.left, positive), self.nnf(f.right, positive))
            return self._temporal(UNT if positive else REL, text, kids, f)
        raise TypeError(f"formula={f!r} is not an MITL formula")

    def _junction(self, kind: int, kids: tuple[int, ...], source: Formula) -> int:
        neutral, absorbing = (TRUE, FALSE) if kind == AND else (FALSE, TRUE)
        flat: list[int] = []
        for k in kids:
            node = self.nodes[k]
            if node.kind == absorbing:
                return k
            if node.kind == neutral:
                continue
            if node.kind == kind:
                flat.extend(c for c in node.children if c not in flat)
            elif k not in flat:
                flat.append(k)
        if not flat:
            return self.add(Node(neutral, "true" if neutral == TRUE else "false"), source)
        if len(flat) == 1:
            return flat[0]
        flat.sort()
        sep = " & " if kind == AND else " | "
        text = sep.join(_paren(self.nodes[c].text) for c in flat)
        return self.add(Node(kind, text, children=tuple(flat)), source)


def _paren(text: str) -> str:
    return text if text.replace("_", "").isalnum() else f"({text})"


def negation_normal_form(formula: Formula, tick: Fraction) -> tuple[list[Node], int, dict[int, Formula]]:
    """The nodes of ``formula`` in negation normal form, the root's index and each node's source sub-formula."""
    comp = _Compiler(tick)
    root = comp.nnf(formula, True)
    return comp.nodes, root, comp.sources
