"""MITL -> an on-the-fly alternating timed automaton with clock copies, made nondeterministic state by state.

input: a ``Formula`` (``tubempc.mitl``) and the tick (seconds per integer time unit) -> output: a ``TimedAutomaton``
whose states are canonical sets of *obligations* ``(node, age)``: "the sub-formula ``node`` was anchored ``age``
ticks ago and is still pending". ``step(state, delta, label_class)`` gives the successor states (a disjunction)
after ``delta`` ticks, at a new position whose labels are ``label_class``.

Construction (documented with its complexity in ``docs/planner.md``):

* the formula is put in negation normal form over ``F_I, G_I, U_I, R_I`` (release, the dual of until), strong
  ``X_I`` and weak ``Xw_I`` (the dual of next); ``->`` and ``!`` on temporal operators are pushed to the atoms
  (``tubempc.planning.nnf``: the nodes, their kinds and windows in ticks);
* a temporal node anchored at the current position has age 0 and is *processed* at once (pointwise semantics:
  ``F_I a`` at ``i`` can be met at ``i`` itself when ``0 in I``); at each later position its age grows by the
  elapsed ticks and it is processed again: ``in`` (age in ``I``), ``before`` (age below ``I``), ``future`` (a later
  tick age can still lie in ``I``) decide whether it is met, stays pending or fails;
* each pending obligation is a clock copy; ages are capped one tick above the largest constant that matters (an
  unbounded interval's lower end), so a state is a finite value and the product with a WTS is a finite graph;
* canonical form (hash-consed sorted tuples) with subsumption: two copies of the same ``F``/``U`` node that are both
  inside their window keep only the older one (it implies the younger); two such ``G``/``R`` copies keep the
  younger; a disjunct that is implied by another disjunct of the same successor set is dropped;
* generalized Büchi acceptance: one set per unbounded ``F_[l,inf)`` / ``U_[l,inf)`` node; a state is in the set
  when no copy of that node *inside its window* is pending. Copies still too young (age below ``l``) are ignored,
  which is what makes ``G(p -> F[2,inf) q)`` acceptable on a run that keeps alternating ``p`` and ``q``.

Times are integers (ticks); the caller scales every weight and interval endpoint exactly (``fractions.Fraction``).
"""

from __future__ import annotations

from collections.abc import Iterable
from fractions import Fraction

from tubempc.mitl import Formula
from tubempc.planning.nnf import (
    ALW,
    AND,
    ATOM,
    EV,
    FALSE,
    KIND_NAMES,
    NATOM,
    NXT,
    OR,
    REL,
    TRUE,
    UNT,
    WNXT,
    Node,
    negation_normal_form,
    tick_of,
)

__all__ = [  # the node kinds, ``Node`` and ``tick_of`` are ``tubempc.planning.nnf``'s, named here too
    "ALW",
    "AND",
    "ATOM",
    "EV",
    "FALSE",
    "KIND_NAMES",
    "NATOM",
    "NXT",
    "OR",
    "REL",
    "TRUE",
    "UNT",
    "WNXT",
    "Node",
    "Obligation",
    "State",
    "TimedAutomaton",
    "compile_formula",
    "tick_of",
]

_TEMPORAL = frozenset({EV, ALW, UNT, REL, NXT, WNXT})
_EXISTENTIAL = frozenset({EV, UNT})  # in-window copies: the older implies the younger
_UNIVERSAL = frozenset({ALW, REL})  # in-window copies: the younger implies the older
_FINAL_OK = frozenset({ALW, REL, WNXT})  # pending obligations that a run ending here meets

Obligation = tuple[int, int]  # (node id, age in ticks)
State = tuple[Obligation, ...]  # sorted, canonical; () = nothing pending (accepting, absorbing)
Dnf = tuple[State, ...]
_TRUE: Dnf = ((),)  # one disjunct with no pending obligation
_FALSE: Dnf = ()  # no disjunct


class TimedAutomaton:
    """The compiled formula and the memo tables of its progression (real state: caches, no behaviour change)."""

    def __init__(self, nodes: list[Node], root: int, tick: Fraction, formula: Formula,
                 sources: dict[int, Formula]) -> None:
        self.nodes = nodes
        self.root = root
        self.tick = tick
        self.formula = formula
        self.sources = sources  # node id -> the sub-formula of the input it came from (for messages)
        self.label_classes: list[frozenset[str]] = []
        self._class_ids: dict[frozenset[str], int] = {}
        self._expand_memo: dict[tuple[int, int, int], Dnf] = {}
        self._step_memo: dict[tuple[State, int, int], Dnf] = {}
        self._accept_memo: dict[State, tuple[bool, ...]] = {}
        self.buchi = tuple(i for i, n in enumerate(nodes) if n.kind in _EXISTENTIAL and n.hi is None)
        # per node: 0 = not subsumable, 1 = existential (keep the older), 2 = universal (keep the younger)
        self._mode = [1 if n.kind in _EXISTENTIAL else 2 if n.kind in _UNIVERSAL else 0 for n in nodes]
        self._reach = [n.lo if n.lo_closed else n.lo + 1 for n in nodes]  # first age at or past the lower end
        self._caps = [n.cap for n in nodes]
        self._trigger_memo: dict[tuple[int, int], bool] = {}
        self._age_memo: dict[tuple[State, int], State] = {}
        self._silent_memo: dict[tuple[State, int, bool], tuple[int, ...]] = {}
        self.atoms = frozenset(n.atom for n in nodes if n.kind in (ATOM, NATOM))

    # ---- labels -------------------------------------------------------------------------------------------
    def label_class(self, labels: Iterable[str]) -> int:
        """Id of the class of label sets that agree on the formula's atoms."""
        key = frozenset(labels) & self.atoms
        cid = self._class_ids.get(key)
        if cid is None:
            cid = len(self.label_classes)
            self.label_classes.append(key)
            self._class_ids[key] = cid
        return cid

    # ---- progression --------------------------------------------------------------------------------------
    def initial(self, label_class: int) -> Dnf:
        """States after the first position (age 0 of the root), one per disjunct; ``()`` if none."""
        return self._minimize(self._canon(d) for d in self._expand(self.root, 0, label_class))

    def step(self, state: State, delta: int, label_class: int) -> Dnf:
        """Successor states after ``delta >= 1`` ticks at a new position with the given label class."""
        key = (state, delta, label_class)
        hit = self._step_memo.get(key)
        if hit is not None:
            return hit
        caps = self._caps
        single: list[Obligation] = []  # obligations of the conjuncts that have exactly one disjunct
        multi: list[Dnf] = []
        for node_id, age in state:
            new_age = age + delta
            cap = caps[node_id]
            part = self._expand(node_id, new_age if new_age < cap else cap, label_class)
            if not part:
                self._step_memo[key] = ()
                return ()
            if len(part) == 1:
                single.extend(part[0])
            else:
                multi.append(part)
        if not multi:
            out: Dnf = (self._canon(single),)
        else:
            acc: Dnf = (tuple(single),)
            for part in multi:
                acc = self._and(acc, part)
            out = self._minimize(self._canon(d) for d in acc)
        self._step_memo[key] = out
        return out

    def expand(self, node_id: int, age: int, cls: int) -> Dnf:
        """Obligation ``node_id`` processed at a position of ``cls`` at ``age`` ticks (at most its cap): the states
        it leaves, one per disjunct (its own pending copy keeps ``age``; obligations it anchors here have age 0)."""
        return self._expand(node_id, age, cls)

    @property
    def subsumption_modes(self) -> list[int]:
        """Per node: 0 not subsumable, 1 existential (of two in-window copies keep the older), 2 universal (the
        younger)."""
        return self._mode

    def _expand(self, node_id: int, age: int, cls: int) -> Dnf:
        key = (node_id, age, cls)
        out = self._expand_memo.get(key)
        if out is None:
            raw = self._expand_uncached(node_id, age, cls)
            out = raw if len(raw) <= 1 else self._minimize(self._canon(d) for d in raw)
            self._expand_memo[key] = out
        return out

    def _expand_uncached(self, node_id: int, age: int, cls: int) -> Dnf:
        n = self.nodes[node_id]
        if n.kind not in _TEMPORAL:  # true, false, an atom or its negation, and, or: decided at this position
            return self._expand_propositional(n, cls)
        pending: Dnf = (((node_id, age),),)  # the obligation stays, one tick older at the next position
        if n.kind in (NXT, WNXT):
            return self._expand_next(n, age, cls, pending)
        return self._expand_temporal(n, age, cls, pending)

    def _expand_propositional(self, n: Node, cls: int) -> Dnf:
        """A boolean node at a position of label class ``cls``: true ``((),)``, false ``()`` or its children's."""
        k = n.kind
        if k == TRUE:
            return _TRUE
        if k == FALSE:
            return _FALSE
        if k == ATOM:
            return _TRUE if n.atom in self.label_classes[cls] else _FALSE
        if k == NATOM:
            return _FALSE if n.atom in self.label_classes[cls] else _TRUE
        if k == AND:
            acc = _TRUE
            for c in n.children:
                acc = self._and(acc, self._expand(c, 0, cls))
            return acc
        return self._or(*(self._expand(c, 0, cls) for c in n.children))  # OR

    def _expand_next(self, n: Node, age: int, cls: int, pending: Dnf) -> Dnf:
        """Strong ``X_I`` / weak ``Xw_I``: pending where anchored, decided at the next position by its age."""
        if age == 0:
            return pending
        if n.inside(age):
            return self._expand(n.children[0], 0, cls)
        return _FALSE if n.kind == NXT else _TRUE

    def _expand_temporal(self, n: Node, age: int, cls: int, pending: Dnf) -> Dnf:
        """``F_I``, ``G_I``, ``U_I``, ``R_I`` at ``age``: met, still pending (``later``) or failed, by the window."""
        k = n.kind
        later = pending if n.future(age) else None
        if k == EV:
            a = self._expand(n.children[0], 0, cls) if n.inside(age) else _FALSE
            return self._or(a, later or _FALSE)
        if k == ALW:
            if n.inside(age):
                return self._and(self._expand(n.children[0], 0, cls), later or _TRUE)
            return pending if n.before(age) else _TRUE
        left = self._expand(n.children[0], 0, cls)
        right = self._expand(n.children[1], 0, cls)
        if k == UNT:
            if n.inside(age):
                return self._or(right, self._and(left, later or _FALSE))
            return self._and(left, pending) if n.before(age) else _FALSE
        # REL: for all j with age in I: right(j) or left(k) for some k in [anchor, j)
        if n.inside(age):
            return self._and(right, self._or(left, later or _TRUE))
        return self._or(left, pending) if n.before(age) else _TRUE

    # ---- boolean algebra on DNFs --------------------------------------------------------------------------
    @staticmethod
    def _and(a: Dnf, b: Dnf) -> Dnf:
        if not a or not b:
            return ()
        if a == ((),):
            return b
        if b == ((),):
            return a
        return tuple(tuple(sorted(set(x) | set(y))) for x in a for y in b)

    @staticmethod
    def _or(*parts: Dnf) -> Dnf:
        out: list[State] = []
        for p in parts:
            out.extend(p)
        return tuple(out)

    def _canon(self, disjunct: Iterable[Obligation]) -> State:
        """Subsumption inside one conjunction: keep the strongest in-window copy of each F/U/G/R node."""
        best: dict[int, int] = {}
        rest: set[Obligation] = set()
        mode, reach = self._mode, self._reach
        for node_id, age in disjunct:
            m = mode[node_id]
            if m and age >= reach[node_id]:
                old = best.get(node_id)
                if old is None:
                    best[node_id] = age
                elif m == 1:
                    best[node_id] = old if old > age else age
                else:
                    best[node_id] = old if old < age else age
            else:
                rest.add((node_id, age))
        rest.update(best.items())
        return tuple(sorted(rest))

    def implies(self, strong: Obligation, weak: Obligation) -> bool:
        """Whether meeting obligation ``strong`` also meets ``weak`` (same node, both in window, or equal)."""
        if strong == weak:
            return True
        if strong[0] != weak[0]:
            return False
        n = self.nodes[strong[0]]
        if not (n.reached(strong[1]) and n.reached(weak[1])):
            return False
        if n.kind in _EXISTENTIAL:
            return strong[1] >= weak[1]
        if n.kind in _UNIVERSAL:
            return strong[1] <= weak[1]
        return False

    def weaker(self, weak: State, strong: State) -> bool:
        """Whether every obligation of ``weak`` is implied by one of ``strong`` (so ``weak`` is at least as easy)."""
        if len(weak) > len(strong):
            # subsumption keeps one in-window copy per node, so a weaker state cannot have more obligations
            return False
        sset = set(strong)
        for o in weak:
            if o in sset:
                continue
            if not any(self.implies(s, o) for s in strong if s[0] == o[0]):
                return False
        return True

    def _minimize(self, disjuncts: Iterable[State]) -> Dnf:
        """Drop duplicates and every disjunct that is harder than another one."""
        uniq = sorted(set(disjuncts), key=len)
        kept: list[State] = []
        for d in uniq:
            if not any(self.weaker(k, d) for k in kept):
                kept.append(d)
        return tuple(kept)

    # ---- acceptance and events ----------------------------------------------------------------------------
    def accepting(self, state: State) -> tuple[bool, ...]:
        """Membership of ``state`` in each generalized Büchi set (one per unbounded F/U node)."""
        out = self._accept_memo.get(state)
        if out is None:
            pending = {nid for nid, age in state if self.nodes[nid].reached(age)}
            out = tuple(b not in pending for b in self.buchi)
            self._accept_memo[state] = out
        return out

    def event_delays(self, state: State, label_class: int) -> set[int]:
        """Dwell durations (ticks) after which a pending obligation whose child can change value in the dwell
        region (``label_class``), or a pending next, changes status at the dwell position; and one tick."""
        out = {1}
        for nid, age in state:
            n = self.nodes[nid]
            if n.kind not in (NXT, WNXT) and not self._triggers(nid, label_class):
                continue
            ends: tuple[int, ...] = (n.lo,) if n.hi is None else (n.lo, n.hi)
            base = 0 if n.kind in (NXT, WNXT) else age
            for c in ends:
                for d in (c - base, c - base + 1):
                    if d >= 1:
                        out.add(d)
        return out

    def targeted_delays(self, state: State, arrivals: Iterable[tuple[int, int]]) -> set[int]:
        """Dwell durations that make the *next arrival* (after ``weight`` ticks, into ``label_class``) land on the
        lower end of a pending F/U window (or just after the upper end of a G/R window) whose child can change
        value in that class. ``arrivals`` yields ``(weight, label_class)``."""
        targets: list[tuple[int, int, int]] = []  # (node, age, target age)
        for nid, age in state:
            n = self.nodes[nid]
            if n.kind in _EXISTENTIAL and n.before(age):
                targets.append((nid, age, n.lo if n.lo_closed else n.lo + 1))
            elif n.kind in _UNIVERSAL and n.hi is not None:
                targets.append((nid, age, n.hi + 1 if n.hi_closed else n.hi))
        out: set[int] = set()
        if not targets:
            return out
        for weight, cls in arrivals:
            for nid, age, goal in targets:
                if self._triggers(nid, cls):
                    d = goal - age - weight
                    if d >= 1:
                        out.add(d)
        return out

    # ---- silent waits ---------------------------------------------------------------------------------------
    def final(self, state: State) -> bool:
        """Whether ``state`` is met by a run that ends here (no further position): only ``G``, ``R`` and weak
        ``X`` obligations are pending (a silent stay forever in the last region)."""
        nodes = self.nodes
        return all(nodes[nid].kind in _FINAL_OK for nid, _ in state)

    def age(self, state: State, delta: int) -> State:
        """``state`` after ``delta`` ticks without any position (a silent wait): every age grows, capped."""
        caps = self._caps
        aged = tuple((nid, age + delta if age + delta < caps[nid] else caps[nid]) for nid, age in state)
        if len({nid for nid, _ in state}) == len(state):
            return aged  # one copy per node: still sorted, nothing to subsume
        key = (state, delta)
        out = self._age_memo.get(key)
        if out is None:
            out = self._canon(aged)
            self._age_memo[key] = out
        return out

    def silent_goals(self, state: State, label_class: int, *, direct: bool = True) -> tuple[int, ...]:
        """Elapsed times (ticks from now, sorted) at which an arrival into ``label_class`` lands where a pending
        obligation changes status there: on the lower end of an ``F``/``U`` window (or one tick past an open one)
        whose child can hold in that class, one tick past the end of a ``G``/``R`` window whose child can fail
        there, and (``direct``: the arrival is the next position) on either end of a pending next's interval.

        A silent wait before a move of ``w`` ticks is event-driven when ``w + wait`` is one of these goals
        (``silent_delays``); with ``direct=False`` the arrival is the last of several moves."""
        key = (state, label_class, direct)
        out = self._silent_memo.get(key)
        if out is not None:
            return out
        found: set[int] = set()
        for nid, age in state:
            n = self.nodes[nid]
            k = n.kind
            if k in (NXT, WNXT):
                if direct:
                    found.add(self._reach[nid] - age)
                    if n.hi is not None:
                        found.add(n.hi + (1 if n.hi_closed else 0) - age)
            elif k in _EXISTENTIAL:
                if n.before(age) and self._triggers(nid, label_class):
                    found.add(self._reach[nid] - age)
            elif k in _UNIVERSAL and n.hi is not None and self._triggers(nid, label_class):
                found.add(n.hi + (1 if n.hi_closed else 0) - age)
        out = tuple(sorted(g for g in found if g > 0))
        self._silent_memo[key] = out
        return out

    def silent_delays(self, state: State, weight: int, label_class: int, *, direct: bool = True) -> list[int]:
        """Silent waits (ticks, >= 1, sorted) before a move (or, ``direct=False``, a path of moves) of ``weight``
        ticks into ``label_class`` after which the arrival lands on a goal of ``silent_goals``."""
        return [g - weight for g in self.silent_goals(state, label_class, direct=direct) if g > weight]

    def triggers(self, node_id: int, label_class: int) -> bool:
        """Whether the child of temporal node ``node_id`` can change value at a position of ``label_class`` (an
        ``F``/``U`` obligation can be met there; a ``G``/``R`` one can fail there)."""
        return self._triggers(node_id, label_class)

    def _triggers(self, node_id: int, cls: int) -> bool:
        key = (node_id, cls)
        out = self._trigger_memo.get(key)
        if out is None:
            out = self._triggers_uncached(node_id, cls)
            self._trigger_memo[key] = out
        return out

    def _triggers_uncached(self, node_id: int, cls: int) -> bool:
        n = self.nodes[node_id]
        child = n.children[-1]
        val = self._expand(child, 0, cls)
        if n.kind in _EXISTENTIAL:
            return val != ()
        if n.kind == REL:
            return val != ((),) or self._expand(n.children[0], 0, cls) != ()
        return val != ((),)

    # ---- inspection ---------------------------------------------------------------------------------------
    def describe(self, state: State) -> str:
        """Readable text of a state: ``{F[30,50] mission_2 @12, ...}`` with ages in seconds."""
        parts = [f"{self.nodes[nid].text} @{float(age * self.tick):g}s" for nid, age in state]
        return "{" + ", ".join(parts) + "}"


def compile_formula(formula: Formula, tick: Fraction) -> TimedAutomaton:
    """Negation normal form of ``formula`` with every interval endpoint in ticks (they must be exact multiples)."""
    if tick <= 0:
        raise ValueError(f"tick={tick} must be positive")
    nodes, root, sources = negation_normal_form(formula, tick)
    return TimedAutomaton(nodes, root, tick, formula, sources)
