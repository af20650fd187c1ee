"""The explored product of a WTS and a formula automaton, shared by the event-driven and the exact search.

input: product states ``(region index, automaton state, position flag)`` added by a search, with their earliest
times, parents and edges -> output: the accepting cycle through a state and the timed run (``LassoRun`` with the
kind of each position and the silent wait before each move) assembled from a path and a cycle.

Edge kinds: ``move`` (a WTS transition, a new position), ``dwell`` (an observed dwell: a new position in the same
region), ``wait`` (one tick without a position: the exact search's delay transition) and ``stay`` (the run ends
here, the robot stays in its last region forever without a further position).
"""

from __future__ import annotations

import itertools
from fractions import Fraction

import networkx as nx

from tubempc.planning.automaton import State, TimedAutomaton
from tubempc.planning.reference_semantics import LassoRun

__all__ = ["DWELL", "MOVE", "STAY", "WAIT", "Found", "Product", "Step", "accepting_cycle", "assemble", "path_steps"]

MOVE, DWELL, STAY, WAIT = "move", "dwell", "stay", "wait"
Step = tuple[int, int, str, int]  # (state reached, ticks, kind, silent wait included in the ticks)
_FAR = 1 << 62


class Product:
    """Explored part of the product (real state of one search)."""

    def __init__(self) -> None:
        self.index: dict[tuple[int, State, bool], int] = {}
        self.region: list[int] = []
        self.obl: list[State] = []
        self.pos: list[bool] = []  # False: reached by a delay (no position at this time)
        self.best: list[tuple[int, int]] = []
        self.parent: list[Step | None] = []  # (previous state, ticks, kind, silent wait)
        self.settled: list[bool] = []
        self.pruned: list[bool] = []
        self.edges: list[list[Step]] = []  # (state, ticks, kind, silent wait)
        self.classes: list[int] = []  # label class of each region index

    def get(self, region: int, obl: State, pos: bool = True) -> tuple[int, bool]:
        key = (region, obl, pos)
        sid = self.index.get(key)
        if sid is not None:
            return sid, False
        sid = len(self.region)
        self.index[key] = sid
        self.region.append(region)
        self.obl.append(obl)
        self.pos.append(pos)
        self.best.append((_FAR, _FAR))
        self.parent.append(None)
        self.settled.append(False)
        self.pruned.append(False)
        self.edges.append([])
        return sid, True

    def prefix(self, sid: int) -> tuple[int, list[Step]]:
        """The initial state and the steps of the earliest path to ``sid``."""
        steps: list[Step] = []
        cur = sid
        while (p := self.parent[cur]) is not None:
            steps.append((cur, p[1], p[2], p[3]))
            cur = p[0]
        steps.reverse()
        return cur, steps


# (run, kind of each position, silent wait before each position, closing wait, product, expanded states)
Found = tuple[LassoRun, tuple[str, ...], tuple[int, ...], int, Product, int]


def path_steps(sub: nx.DiGraph, path: list[int]) -> list[Step]:
    return [(b, sub.edges[a, b]["d"], sub.edges[a, b]["kind"], sub.edges[a, b]["wait"])
            for a, b in itertools.pairwise(path)]


def accepting_cycle(sub: nx.DiGraph, entry: int, aut: TimedAutomaton, prod: Product, nb: int) -> list[Step]:
    """A cycle from ``entry`` back to it through one accepting state per Büchi set, inside the strongly connected
    ``sub`` (edges with ``d``, ``kind``, ``wait``). A silent stay (a ``stay`` self-loop) is preferred."""
    if sub.has_edge(entry, entry) and sub.edges[entry, entry]["kind"] == STAY:
        return [(entry, sub.edges[entry, entry]["d"], STAY, 0)]
    steps: list[Step] = []
    cur = entry
    for b in range(nb):
        if aut.accepting(prod.obl[cur])[b] or any(aut.accepting(prod.obl[s])[b] for s, _, _, _ in steps):
            continue
        dist, paths = nx.single_source_dijkstra(sub, cur, weight="d")
        target = min((s for s in sub if aut.accepting(prod.obl[s])[b]), key=lambda s: (dist.get(s, _FAR), s))
        steps.extend(path_steps(sub, paths[target]))
        cur = target
    if cur != entry or not steps:
        if not steps:
            best: tuple[int, list[int]] | None = None
            for v in sub.successors(entry):
                if v == entry:
                    cand = (sub.edges[entry, entry]["d"], [entry, entry])
                else:
                    d, back = nx.single_source_dijkstra(sub, v, entry, weight="d")
                    cand = (sub.edges[entry, v]["d"] + d, [entry, *back])
                if best is None or cand[0] < best[0]:
                    best = cand
            if best is None:
                raise RuntimeError("an accepting component without a cycle")  # excluded by the callers
            steps.extend(path_steps(sub, best[1]))
        else:
            steps.extend(path_steps(sub, nx.dijkstra_path(sub, cur, entry, weight="d")))
    return steps


def assemble(prod: Product, names: list[str], tick: Fraction, *, start: int, prefix: list[Step],
             cycle: list[Step] | None, expanded: int) -> Found:
    """The timed run of ``prefix`` (from ``start``) followed by ``cycle`` (None or a ``stay``: a finite run).

    ``wait`` steps become the silent wait of the next move (or lengthen the next observed dwell)."""
    regions = [names[prod.region[start]]]
    times = [Fraction(0)]
    kinds = ["start"]
    waits = [0]
    t = 0
    acc = 0

    def add(s: int, kind: str, waited: int) -> None:
        regions.append(names[prod.region[s]])
        times.append(t * tick)
        kinds.append(kind)
        waits.append(waited)

    for s, d, kind, waited in prefix:
        t += d
        if kind == WAIT:
            acc += d
            continue
        add(s, kind, acc + waited if kind == MOVE else 0)
        acc = 0
    if cycle is None or (len(cycle) == 1 and cycle[0][2] == STAY):
        return LassoRun(tuple(regions), tuple(times)), tuple(kinds), tuple(waits), 0, prod, expanded
    loop_start = len(regions) - 1
    period = 0
    closing = 0
    for k, (s, d, kind, waited) in enumerate(cycle):
        period += d
        if kind == WAIT:
            acc += d
            t += d
            continue
        if k == len(cycle) - 1:
            closing = acc + waited if kind == MOVE else 0
            break  # the last step returns to the loop's first position
        t += d
        add(s, kind, acc + waited if kind == MOVE else 0)
        acc = 0
    run = LassoRun(tuple(regions), tuple(times), loop_start=loop_start, period=period * tick)
    return run, tuple(kinds), tuple(waits), closing, prod, expanded
