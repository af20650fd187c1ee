"""Exact product search with delay transitions: a time-optimal accepting run on the tick grid, or a proof of none.

input: the WTS as region indices (label class, out-edges in ticks), the formula's ``TimedAutomaton``, the initial
region, the wait mode (``silent``, ``observed`` or ``none``) and an upper bound on the cost (the cost of a run
already found, or none) -> output: a run strictly cheaper than the bound (``Found``), or ``None``: no run cheaper
than the bound exists on the tick grid (with no bound: no accepting run exists at all).

The graph searched is the product of the WTS and the automaton with waiting as *delay transitions* of one tick:
a state is ``(region, automaton state, position flag)``; its successors are
* a move ``r -> j`` of weight ``w``: a new position in ``j``, the automaton stepped by ``w`` ticks
  (silent mode: from any state; observed and none: only from a position);
* a delay of one tick (silent and observed): every obligation ages by one tick, no position
  (``TimedAutomaton.age``); a delay that changes nothing (every age at its cap) is not generated;
* an observed dwell (observed mode): a new position in the same region one tick later.
Every wait of ``d`` ticks is ``d`` delays, so every run on the tick grid is a path of this graph and every path is
a run: the search loses nothing. Ages are capped, so the graph is finite.

Cost: a finite run (silent mode: the robot stays in its last region forever, every pending obligation accepts
the end) costs the time of its last position; a lasso costs the time of its repeating part's first position.
Search: A* by time plus an admissible, consistent lower bound: an ``F``/``U`` obligation anchored at the first
position (reached from the root through ``&``/``|`` only, never re-anchored) must be met at a later position,
no earlier than its window's lower end and than the WTS distance to a region where it can be met, and before the
run's cost (it cannot be pending in a repeating part: its age would grow around the cycle). A state whose bound is
infinite cannot lead to acceptance. A lasso's first repeating position has no such obligation pending, so its
bound is 0 and it is popped at its earliest time; whether it lies on an accepting cycle is decided on the full
product reachable from it (not cut by the bound). States whose time plus bound reaches the current best cost are
never expanded: they cannot lead to a cheaper run.
"""

from __future__ import annotations

import heapq
import math
from collections.abc import Iterator

import networkx as nx

from tubempc.errors import SearchLimitError
from tubempc.planning.automaton import AND, EV, OR, UNT, State, TimedAutomaton
from tubempc.planning.product import DWELL, MOVE, STAY, WAIT, Found, Product, Step, accepting_cycle, assemble

__all__ = ["EXACT_MODES", "exact_search", "root_anchored", "root_existential"]

EXACT_MODES = ("silent", "observed", "none")
_INF = math.inf


def root_existential(aut: TimedAutomaton) -> frozenset[int]:
    """``F``/``U`` nodes anchored only at the first position (``root_anchored``)."""
    return frozenset(i for i in root_anchored(aut) if aut.nodes[i].kind in (EV, UNT))


def root_anchored(aut: TimedAutomaton) -> frozenset[int]:
    """Temporal nodes anchored only at the first position: reached from the root through ``&``/``|`` nodes and no
    child of any temporal node (so a copy, once met or failed, never comes back, and its age only grows)."""
    nested: set[int] = set()
    temporal = {i for i, n in enumerate(aut.nodes) if n.kind >= EV}
    stack = [c for i in temporal for c in aut.nodes[i].children]
    while stack:
        c = stack.pop()
        if c in nested:
            continue
        nested.add(c)
        stack.extend(aut.nodes[c].children)
    top: set[int] = set()
    stack = [aut.root]
    while stack:
        c = stack.pop()
        if c in top:
            continue
        top.add(c)
        if aut.nodes[c].kind in (AND, OR):
            stack.extend(aut.nodes[c].children)
    return frozenset(i for i in top - nested if aut.nodes[i].kind >= EV)


def _distances(aut: TimedAutomaton, nodes: frozenset[int], cls: list[int],
               adj: list[list[tuple[int, int]]]) -> dict[int, list[float]]:
    """Per node: WTS travel time (ticks) from every region to the nearest region where the node can be met."""
    radj: list[list[tuple[int, int]]] = [[] for _ in cls]
    for a, row in enumerate(adj):
        for b, w in row:
            radj[b].append((a, w))
    out: dict[int, list[float]] = {}
    for nid in nodes:
        dist: list[float] = [_INF] * len(cls)
        heap: list[tuple[float, int]] = []
        for r, c in enumerate(cls):
            if aut.triggers(nid, c):
                dist[r] = 0
                heap.append((0, r))
        heapq.heapify(heap)
        while heap:
            d, r = heapq.heappop(heap)
            if d > dist[r]:
                continue
            for a, w in radj[r]:
                if d + w < dist[a]:
                    dist[a] = d + w
                    heapq.heappush(heap, (d + w, a))
        out[nid] = dist
    return out


class _Exact:
    """One exact search (real state: the explored product, the heap, the closure used to decide cycles)."""

    def __init__(self, aut: TimedAutomaton, cls: list[int], adj: list[list[tuple[int, int]]], mode: str,
                 max_states: int) -> None:
        if mode not in EXACT_MODES:
            raise ValueError(f"mode={mode!r} must be one of {EXACT_MODES}")
        self.aut = aut
        self.cls = cls
        self.adj = adj
        self.mode = mode
        self.max_states = max_states
        self.prod = Product()
        self.prod.classes = cls
        self.expanded_edges: list[bool] = []
        self.roots = root_existential(aut)
        self.once = root_anchored(aut)
        self.caps = [n.cap for n in aut.nodes]
        self.dist = _distances(aut, frozenset(i for i, n in enumerate(aut.nodes) if n.kind in (EV, UNT)), cls, adj)
        self.reach = [n.lo if n.lo_closed else n.lo + 1 for n in aut.nodes]
        self.component: dict[int, int] = {}  # state -> strongly connected component (states explored for cycles)
        self.component_ok: dict[int, bool] = {}  # component -> cyclic and meets every Büchi set
        self.expanded = 0

    def bound(self, region: int, obl: State) -> float:
        """Admissible, consistent lower bound (ticks) on the cost still to come (module docstring)."""
        h: float = 0
        for nid, age in obl:
            if nid in self.roots:
                h = max(h, self.reach[nid] - age, self.dist[nid][region])
            elif nid in self.dist and self.dist[nid][region] == _INF:
                return _INF  # a pending F/U copy that no reachable region can meet: a dead state
        return h

    def state(self, region: int, obl: State, pos: bool) -> int:
        sid, new = self.prod.get(region, obl, pos)
        if new:
            self.expanded_edges.append(False)
            if len(self.prod.region) > self.max_states:
                raise SearchLimitError(
                    f"the exact search reached its limit of {self.max_states} product states while searching for "
                    f"{self.aut.formula}, before it found a run or proved that none exists; raise the limit "
                    f"(tubempc plan --max-states N, or max_states=N in Python) or shorten the formula's windows",
                    limit=self.max_states)
        return sid

    def successors(self, sid: int) -> list[Step]:
        """Edges of ``sid`` (computed once): moves, one-tick delays, observed dwells."""
        prod = self.prod
        if self.expanded_edges[sid]:
            return prod.edges[sid]
        aut, mode = self.aut, self.mode
        r, obl, pos = prod.region[sid], prod.obl[sid], prod.pos[sid]
        out: list[Step] = []
        if pos or mode == "silent":
            for j, w in self.adj[r]:
                for o2 in aut.step(obl, w, self.cls[j]):
                    out.append((self.state(j, o2, True), w, MOVE, 0))
        if mode != "none":
            aged = aut.age(obl, 1)
            if aged != obl:
                out.append((self.state(r, aged, False), 1, WAIT, 0))
            if mode == "observed":
                for o2 in aut.step(obl, 1, self.cls[r]):
                    out.append((self.state(r, o2, True), 1, DWELL, 0))
        prod.edges[sid] = out
        self.expanded_edges[sid] = True
        return out

    def on_accepting_cycle(self, sid: int) -> bool:
        """Whether ``sid`` lies on a cycle (with at least one position) that meets every Büchi set: the strongly
        connected components of the product reachable from ``sid`` (iterative Tarjan; states already in a
        component are skipped: the explored part is closed under successors, so old components never change)."""
        caps = self.caps
        if any(nid in self.once and age < caps[nid] for nid, age in self.prod.obl[sid]):
            return False  # a copy anchored only at the first position, still ageing: the state cannot recur
        if sid not in self.component:
            self._tarjan(sid)
        return self.component_ok[self.component[sid]]

    def _tarjan(self, root: int) -> None:
        component = self.component
        index: dict[int, int] = {}
        low: dict[int, int] = {}
        stack: list[int] = []
        on_stack: set[int] = set()
        work: list[tuple[int, Iterator[int]]] = []

        def push(v: int) -> None:
            index[v] = low[v] = len(index)
            stack.append(v)
            on_stack.add(v)
            work.append((v, iter([e[0] for e in self.successors(v)])))

        push(root)
        nb = len(self.aut.buchi)
        while work:
            v, it = work[-1]
            descended = False
            for w in it:
                if w in component:
                    continue
                if w not in index:
                    push(w)
                    descended = True
                    break
                if w in on_stack:
                    low[v] = min(low[v], index[w])
            if descended:
                continue
            work.pop()
            if work:
                u = work[-1][0]
                low[u] = min(low[u], low[v])
            if low[v] == index[v]:
                comp: list[int] = []
                while True:
                    w = stack.pop()
                    on_stack.discard(w)
                    comp.append(w)
                    if w == v:
                        break
                k = len(self.component_ok)
                for w in comp:
                    component[w] = k
                cyclic = len(comp) > 1 or any(e[0] == v for e in self.successors(v))
                self.component_ok[k] = cyclic and all(
                    any(self.aut.accepting(self.prod.obl[w])[b] for w in comp) for b in range(nb))

    def cycle(self, sid: int) -> list[Step]:
        k = self.component[sid]
        comp = {s for s, c in self.component.items() if c == k}
        g = nx.DiGraph()
        g.add_nodes_from(comp)
        for s in comp:
            for v, d, kind, waited in self.successors(s):
                if v in comp and (not g.has_edge(s, v) or g.edges[s, v]["d"] > d):
                    g.add_edge(s, v, d=d, kind=kind, wait=waited)
        return accepting_cycle(g, sid, self.aut, self.prod, len(self.aut.buchi))


def exact_search(aut: TimedAutomaton, names: list[str], cls: list[int], adj: list[list[tuple[int, int]]], r0: int,
                 *, mode: str, bound: float = _INF, max_states: int) -> tuple[Found | None, int]:
    """A run cheaper than ``bound`` ticks (time-optimal among all runs on the tick grid), or None when there is
    none (module docstring), and the number of product states created. Raises ``SearchLimitError`` past
    ``max_states`` product states."""
    ex = _Exact(aut, cls, adj, mode, max_states)
    prod = ex.prod
    heap: list[tuple[float, int, int, int]] = []
    for obl in aut.initial(cls[r0]):
        sid = ex.state(r0, obl, True)
        prod.best[sid] = (0, 0)
        heapq.heappush(heap, (ex.bound(r0, obl), 0, 0, sid))
    best: tuple[int, list[Step] | None] | None = None  # (entry state, cycle; None: stay)
    while heap:
        f, t, travel, sid = heapq.heappop(heap)
        if f >= bound:
            break
        if prod.settled[sid] or prod.best[sid] != (t, travel):
            continue
        prod.settled[sid] = True
        ex.expanded += 1
        obl, pos = prod.obl[sid], prod.pos[sid]
        if pos and f == t:
            if mode == "silent" and aut.final(obl):
                best, bound = (sid, None), t
                continue
            if ex.on_accepting_cycle(sid):
                best, bound = (sid, ex.cycle(sid)), t
                continue
        for v, d, kind, waited in ex.successors(sid):
            cand = (t + d, travel + (d if kind == MOVE else 0))
            if prod.settled[v] or cand >= prod.best[v]:
                continue
            h = ex.bound(prod.region[v], prod.obl[v])
            if cand[0] + h >= bound:
                continue
            prod.best[v] = cand
            prod.parent[v] = (sid, d, kind, waited)
            heapq.heappush(heap, (cand[0] + h, cand[0], cand[1], v))
    if best is None:
        return None, len(prod.region)
    entry, cyc = best
    start, prefix = prod.prefix(entry)
    if cyc is not None and len(cyc) == 1 and cyc[0][2] == DWELL:
        # staying put with observed dwells: one long dwell period (ages saturate at the caps) if it closes the loop
        slow = max([n.cap for n in aut.nodes] + [1])
        if prod.obl[entry] in aut.step(prod.obl[entry], slow, cls[prod.region[entry]]):
            cyc = [(entry, slow, DWELL, 0)]
    if cyc is None:
        cyc = [(entry, 0, STAY, 0)]
    found = assemble(prod, names, aut.tick, start=start, prefix=prefix, cycle=cyc, expanded=ex.expanded)
    return found, len(prod.region)
