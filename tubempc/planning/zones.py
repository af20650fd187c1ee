"""Zone search: the observed-dwell first attempt with clocks as difference-bound matrices (DBMs).

input: the formula's ``TimedAutomaton``, the WTS as region indices (label class, out-edges in ticks), the initial
region -> output: an accepting run (``Found``) that dwells in its last region forever, found by a search over
*symbolic* states, or ``None`` (nothing of that shape found within the budget; the caller falls back).

Why: with observed dwells a dwell position may come any number of ticks after the previous position, and the
explicit product keeps one state per tick and per copy of an obligation. Here a symbolic state is

* a region, a *skeleton* — the pending obligations grouped by the position that anchored them, oldest first (one
  clock per group: all obligations anchored at one position share their age) — and
* a canonical DBM over the clocks ``0`` (the reference), ``T`` (the global time, never reset) and the group
  clocks: the set of ages (and times) with which that skeleton is reachable.

A step (a move of weight ``w``: delay exactly ``w``; a dwell: delay of at least one tick, any length) lets time
pass (every clock grows by the delay), then *splits* the zone at every age where a pending obligation changes
status (the constants ``reach``, ``hi``, ``cap`` of ``Node``: before its window, inside, last tick of the window,
past it, at its cap), evaluates the automaton's progression once per piece at a representative age
(``TimedAutomaton.expand``: the progression depends on an age only through those comparisons), resets a clock for
the obligations anchored at the new position and drops the clocks whose obligations are all met. Subsumption of
in-window copies (the older ``F``/``U`` copy implies the younger, the younger ``G``/``R`` copy the older) is decided on
the skeleton: the age order of two groups is their anchoring order. Zones are then extrapolated with each clock's
largest constant (its obligations' caps: older ages behave alike) and kept canonical (Floyd-Warshall closure).

The search is by earliest time: the priority of a symbolic state is the least time in its zone, raised by the
exact search's admissible lower bound (``exact.root_existential`` windows, WTS distances). A symbolic state is not
explored when an explored one of the same region and skeleton contains it with time allowed to grow (``Z ⊆ Z'↑T``,
the passed list of timed-automaton model checkers: the same ages, reached no later). Each step also records its
constraints on the times of the positions (``lo <= t_k - t_p <= hi``); a path's earliest concrete times are the
least solution of that difference-constraint system (Bellman-Ford), so a symbolic run is turned into a timed run
exactly, on the tick grid. A candidate (no pending ``F``/``U`` obligation) is replayed with the explicit automaton at
those times and accepted when its state is accepting and recurs after a long dwell (the run stays in its last
region with dwell positions). Lassos of other shapes are left to the caller's other stages.

The result is an upper bound only: the caller re-checks it with the reference semantics and the exact search
(``exact.exact_search``) proves that no cheaper run exists or finds one.
"""

from __future__ import annotations

import heapq
import itertools
import operator
from dataclasses import dataclass
from fractions import Fraction

from tubempc.planning.automaton import EV, UNT, State, TimedAutomaton
from tubempc.planning.exact import _distances, root_existential
from tubempc.planning.product import DWELL, MOVE, Found, Product
from tubempc.planning.reference_semantics import LassoRun

__all__ = ["DEFAULT_ZONE_STATES", "Dbm", "ZoneSearch", "close", "zone_search"]

INF = 1 << 60
DEFAULT_ZONE_STATES = 50_000  # symbolic states before the zone search gives up (the caller falls back)
Dbm = list[list[int]]  # D[i][j]: upper bound of x_i - x_j (integers; INF: none); index 0 = 0, 1 = T, 2.. = clocks
_T = 1
Constraint = tuple[int, int, int, int]  # (position p, position k, lo, hi): lo <= t_k - t_p <= hi


def close(d: Dbm) -> bool:
    """Floyd-Warshall closure in place; False when the zone is empty."""
    n = len(d)
    for k in range(n):
        dk = d[k]
        for i in range(n):
            dik = d[i][k]
            if dik >= INF:
                continue
            di = d[i]
            for j in range(n):
                dkj = dk[j]
                if dkj < INF and dik + dkj < di[j]:
                    di[j] = dik + dkj
    return all(d[i][i] >= 0 for i in range(n))


def constrain(d: Dbm, i: int, j: int, c: int) -> bool:
    """``x_i - x_j <= c`` on a canonical DBM, kept canonical (O(n^2)); False when the zone becomes empty."""
    if c >= d[i][j]:
        return True
    if d[j][i] < INF and d[j][i] + c < 0:
        return False
    d[i][j] = c
    n = len(d)
    for a in range(n):
        dai = d[a][i]
        if dai >= INF:
            continue
        da = d[a]
        for b in range(n):
            djb = d[j][b]
            if djb >= INF:
                continue
            v = dai + c + djb
            da[b] = min(da[b], v)
    return True


def delay(d: Dbm, lo: int, hi: int) -> Dbm:
    """Every clock (``T`` too) grows by a delay in ``[lo, hi]`` (``hi`` may be INF); exact and canonical."""
    out = [row[:] for row in d]
    n = len(d)
    for i in range(1, n):
        out[i][0] = INF if out[i][0] >= INF or hi >= INF else out[i][0] + hi
        out[0][i] = out[0][i] - lo
    return out


def up_t(d: Dbm) -> Dbm:
    """The zone with the global time allowed to grow (same ages, any later time): drops the bounds ``T - x <= c``."""
    out = [row[:] for row in d]
    out[_T] = [INF] * len(d)
    out[_T][_T] = 0
    return out


def included(small: Dbm, big: Dbm) -> bool:
    return all(a <= b for ra, rb in zip(small, big, strict=True) for a, b in zip(ra, rb, strict=True))


def extrapolate(d: Dbm, m: list[int]) -> None:
    """Extra_M in place (``m[i]``: ages above ``m[i]`` behave alike; INF for ``T``, 0 for the reference), then close."""
    n = len(d)
    for i in range(n):
        for j in range(n):
            if i == j:
                continue
            v = d[i][j]
            if v >= INF:
                continue
            if i != 0 and v > m[i]:
                d[i][j] = INF
            elif j != 0 and m[j] < INF and v < -m[j]:
                d[i][j] = -(m[j] + 1)
    close(d)


@dataclass(slots=True)
class _Sym:
    region: int
    groups: tuple[tuple[int, ...], ...]  # node ids per clock, oldest clock first
    born: tuple[int, ...]  # position index that anchored each clock
    dbm: Dbm
    depth: int  # position index of this state
    parent: int  # -1: the first position
    kind: str
    dwells: int  # consecutive dwell positions ending here
    constraints: tuple[Constraint, ...]  # this step's constraints on the position times


class ZoneSearch:
    """One zone search (real state: the symbolic states, the passed list, the heap)."""

    def __init__(self, aut: TimedAutomaton, cls: list[int], adj: list[list[tuple[int, int]]],
                 max_states: int = DEFAULT_ZONE_STATES, max_dwells: int = 1) -> None:
        self.aut = aut
        self.max_dwells = max_dwells
        self.cls = cls
        self.adj = adj
        self.max_states = max_states
        nodes = aut.nodes
        self.reach = [n.lo if n.lo_closed else n.lo + 1 for n in nodes]
        self.caps = [n.cap for n in nodes]
        self.hi_in = [INF if n.hi is None else (n.hi if n.hi_closed else n.hi - 1) for n in nodes]
        self.existential = [n.kind in (EV, UNT) for n in nodes]
        self.roots = root_existential(aut)
        self.dist = _distances(aut, frozenset(i for i, n in enumerate(nodes) if n.kind in (EV, UNT)), cls, adj)
        self.cuts = [sorted({c for c in (self.reach[i], self.hi_in[i], self.hi_in[i] + 1, self.caps[i])
                             if 1 <= c < INF}) for i in range(len(nodes))]
        self.below = [self._descendants(i) for i in range(len(nodes))]  # nodes a copy of node i can anchor
        self._class_memo: dict[tuple[tuple[tuple[int, ...], ...], int, int], list[tuple[int, int]]] = {}
        self.states: list[_Sym] = []
        # per region and skeleton: the zones explored (flattened) and the same with time allowed to grow
        self.passed: dict[tuple[int, tuple[tuple[int, ...], ...]], list[tuple[tuple[int, ...], tuple[int, ...]]]] = {}
        self._progress_memo: dict[tuple[tuple[tuple[int, ...], ...], tuple[int, ...], int],
                                  list[tuple[tuple[frozenset[int], ...], frozenset[int]]]] = {}
        # (priority, root windows pending, -least time, order, state)
        self.heap: list[tuple[int, int, int, int, int]] = []
        self.slow = max([n.cap for n in nodes] + [1])
        self.horizon = 2 * max([w for row in adj for _, w in row] + [1])

    def _descendants(self, nid: int) -> frozenset[int]:
        out: set[int] = set()
        stack = list(self.aut.nodes[nid].children)
        while stack:
            c = stack.pop()
            if c not in out:
                out.add(c)
                stack.extend(self.aut.nodes[c].children)
        return frozenset(out)

    # ---- symbolic steps -------------------------------------------------------------------------------------
    def _classes(self, groups: tuple[tuple[int, ...], ...], g: int, cls: int) -> list[tuple[int, int]]:
        """Age intervals of clock ``g`` on which every obligation of its group behaves alike at a position of
        ``cls``: the cuts of its nodes' constants, with neighbouring intervals merged where the progression is the
        same and no other copy of a node could be subsumed by it (whether a copy is in its window matters only
        then). Memoised per skeleton, clock and label class."""
        key = (groups, g, cls)
        hit = self._class_memo.get(key)
        if hit is not None:
            return hit
        group = groups[g]
        cuts = sorted({c for nid in group for c in self.cuts[nid]} | {1})
        raw = [(a, (cuts[k + 1] - 1) if k + 1 < len(cuts) else INF) for k, a in enumerate(cuts)]
        others = {nid for h, grp in enumerate(groups) if h != g for nid in grp}
        spawn = set().union(*(self.below[nid] for grp in groups for nid in grp))
        modes = self.aut.subsumption_modes
        relevant = [nid for nid in group if modes[nid] and (nid in others or nid in spawn)]
        out: list[tuple[int, int]] = []
        last: object = None
        for a, b in raw:
            sig = (self._behaviour(group, a, cls), tuple(a >= self.reach[nid] for nid in relevant))
            if out and sig == last:
                out[-1] = (out[-1][0], b)
            else:
                out.append((a, b))
                last = sig
        self._class_memo[key] = out
        return out

    def _behaviour(self, group: tuple[int, ...], age: int, cls: int) -> tuple[object, ...]:
        """What processing the group at ``age`` does: per node, per disjunct, whether its copy stays and what it
        anchors (or None when it fails)."""
        out: list[object] = []
        for nid in group:
            a = min(age, self.caps[nid])
            part = self.aut.expand(nid, a, cls)
            out.append(tuple(sorted((any(n == nid and x == a for n, x in disj),
                                     tuple(sorted(n for n, x in disj if not (n == nid and x == a))))
                                    for disj in part)))
        return tuple(out)

    def _pieces(self, d: Dbm, groups: tuple[tuple[int, ...], ...], cls: int
                ) -> list[tuple[Dbm, tuple[tuple[int, int], ...]]]:
        """The zone split by the age classes of every clock: (piece, class of each clock)."""
        out: list[tuple[Dbm, tuple[tuple[int, int], ...]]] = [(d, ())]
        for g in range(len(groups)):
            x = 2 + g
            nxt: list[tuple[Dbm, tuple[tuple[int, int], ...]]] = []
            for piece, chosen in out:
                lo_z, hi_z = -piece[0][x], piece[x][0]
                for a, b in self._classes(groups, g, cls):
                    if b < lo_z or a > hi_z:
                        continue
                    p = [row[:] for row in piece]
                    if not (constrain(p, x, 0, b) if b < INF else True) or not constrain(p, 0, x, -a):
                        continue
                    nxt.append((p, (*chosen, (a, b))))
            out = nxt
        return out

    def _progress(self, groups: tuple[tuple[int, ...], ...], ages: list[int], cls: int
                  ) -> list[tuple[tuple[frozenset[int], ...], frozenset[int]]]:
        """Disjuncts after processing every obligation at representative ages (one per age class, so the result
        is memoised per skeleton, classes and label class): nodes kept per clock, new nodes."""
        key = (groups, tuple(ages), cls)
        hit = self._progress_memo.get(key)
        if hit is None:
            hit = self._progress_memo[key] = self._progress_uncached(groups, ages, cls)
        return hit

    def _progress_uncached(self, groups: tuple[tuple[int, ...], ...], ages: list[int], cls: int
                           ) -> list[tuple[tuple[frozenset[int], ...], frozenset[int]]]:
        aut = self.aut
        acc: list[tuple[tuple[frozenset[int], ...], frozenset[int]]] = [
            (tuple(frozenset() for _ in groups), frozenset())]
        for g, group in enumerate(groups):
            for nid in group:
                age = min(ages[g], self.caps[nid])
                part = aut.expand(nid, age, cls)
                if not part:
                    return []
                options: list[tuple[frozenset[int], frozenset[int]]] = []
                for disj in part:
                    keep = frozenset(n for n, a in disj if a == age and n == nid)
                    new = frozenset(n for n, a in disj if not (a == age and n == nid))
                    options.append((keep, new))
                if len(options) == 1 and not options[0][0] and not options[0][1]:
                    continue  # met: nothing left of this obligation
                nxt = []
                for kept, new in acc:
                    for keep, more in options:
                        nxt.append((tuple(k | keep if i == g else k for i, k in enumerate(kept)), new | more))
                acc = nxt
        return acc

    def successors(self, sid: int) -> list[int]:
        s = self.states[sid]
        steps: list[tuple[int, int, int, str]] = [(j, w, w, MOVE) for j, w in self.adj[s.region]]
        if s.dwells < self.max_dwells:
            steps.append((s.region, 1, INF, DWELL))
        out: list[int] = []
        for j, lo, hi, kind in steps:
            out.extend(self._step(sid, s, j=j, lo=lo, hi=hi, kind=kind))
        return out

    def _step(self, sid: int, s: _Sym, *, j: int, lo: int, hi: int, kind: str) -> list[int]:
        cj = self.cls[j]
        k = s.depth + 1
        for g, nodes in enumerate(s.groups):
            # a pending F/U copy that cannot be met in j and whose window closes before any later region where
            # it can be met is reached: the step leads nowhere (checked before any zone is split)
            youngest = -s.dbm[0][2 + g] + lo
            for nid in nodes:
                dist = self.dist.get(nid)
                if dist is not None and dist[j] > 0 and youngest + dist[j] > self.hi_in[nid]:
                    return []
        base: tuple[Constraint, ...] = ((s.depth, k, lo, hi),)
        made: list[int] = []
        for piece, chosen in self._pieces(delay(s.dbm, lo, hi), s.groups, cj):
            ages = [a for a, _ in chosen]
            cons = base + tuple((s.born[g], k, a, b) for g, (a, b) in enumerate(chosen))
            for kept, new in self._progress(s.groups, ages, cj):
                sub = self._subsume(kept, new, ages)
                if sub is None:
                    continue
                kept2, new2 = sub
                made_id = self._make(sid, s, j=j, kind=kind, piece=piece, kept=kept2, new=new2, cons=cons)
                if made_id is not None:
                    made.append(made_id)
        return made

    def _subsume(self, kept: tuple[frozenset[int], ...], new: frozenset[int], ages: list[int]
                 ) -> tuple[tuple[frozenset[int], ...], frozenset[int]] | None:
        """Keep one in-window copy per subsumable node: the oldest F/U copy, the youngest G/R copy."""
        mode = self.aut.subsumption_modes
        reach = self.reach
        clocks = [*kept, new]
        ages_all = [*ages, 0]
        holders: dict[int, list[int]] = {}
        for c, nodes in enumerate(clocks):
            for nid in nodes:
                if mode[nid] and ages_all[c] >= reach[nid] and (c < len(kept) or reach[nid] <= 0):
                    holders.setdefault(nid, []).append(c)
        if not any(len(h) > 1 for h in holders.values()):
            return kept, new
        drop: dict[int, set[int]] = {}
        for nid, h in holders.items():
            if len(h) < 2:
                continue
            keep = min(h) if mode[nid] == 1 else max(h)
            for c in h:
                if c != keep:
                    drop.setdefault(c, set()).add(nid)
        out = [frozenset(n for n in nodes if n not in drop.get(c, ())) for c, nodes in enumerate(clocks)]
        return tuple(out[:-1]), out[-1]

    def _make(self, parent: int, s: _Sym, *, j: int, kind: str, piece: Dbm, kept: tuple[frozenset[int], ...],
              new: frozenset[int], cons: tuple[Constraint, ...]) -> int | None:
        k = s.depth + 1
        keep_idx = [g for g, nodes in enumerate(kept) if nodes]
        idx = [0, _T, *(2 + g for g in keep_idx)]
        d = [[piece[a][b] for b in idx] for a in idx]
        groups = [tuple(sorted(kept[g])) for g in keep_idx]
        born = [s.born[g] for g in keep_idx]
        if new:
            # a clock reset at this position: x_new = 0, so its bounds are those of the reference clock
            n = len(d)
            for row in d:
                row.append(row[0])
            d.append([*d[0][:n], 0])
            groups.append(tuple(sorted(new)))
            born.append(k)
        # deadline: a pending F/U copy must still be able to reach a region where it can be met in its window
        extra: list[Constraint] = []
        for g, nodes in enumerate(groups):
            x = 2 + g
            for nid in nodes:
                if not self.existential[nid]:
                    continue
                dist = self.dist[nid][j]
                if dist >= INF:
                    return None
                if self.hi_in[nid] < INF:
                    bound = self.hi_in[nid] - max(int(dist), 1)
                    if not constrain(d, x, 0, bound):
                        return None
                    extra.append((born[g], k, 0, bound))
        key = (j, tuple(groups))
        olds = self.passed.setdefault(key, [])
        flat = tuple(itertools.chain.from_iterable(d))
        if any(all(map(operator.le, flat, o_up)) for _, o_up in olds):
            return None  # covered before extrapolation (which only adds equivalent ages): no need to extrapolate
        m = [0, INF, *(max(self.caps[n] for n in grp) - 1 for grp in groups)]
        extrapolate(d, m)
        flat = tuple(itertools.chain.from_iterable(d))
        if any(all(map(operator.le, flat, o_up)) for _, o_up in olds):
            return None
        flat_up = tuple(itertools.chain.from_iterable(up_t(d)))
        olds[:] = [o for o in olds if not all(map(operator.le, o[0], flat_up))]  # now dominated by the new zone
        olds.append((flat, flat_up))
        sid = len(self.states)
        dwells = s.dwells + 1 if kind == DWELL else 0
        self.states.append(_Sym(j, tuple(groups), tuple(born), d, k, parent, kind, dwells, cons + tuple(extra)))
        return sid

    # ---- priority, candidates, concretisation --------------------------------------------------------------
    def pending_roots(self, s: _Sym) -> int:
        """Root windows still pending (ties of the priority go to the state that met more of them)."""
        return sum(1 for grp in s.groups for nid in grp if nid in self.roots)

    def priority(self, s: _Sym) -> int:
        """Least time in the zone raised by the exact search's lower bound (root windows, WTS distances)."""
        d = s.dbm
        f = -d[0][_T]
        for g, nodes in enumerate(s.groups):
            x = 2 + g
            for nid in nodes:
                if nid in self.roots:
                    if self.dist[nid][s.region] >= INF:
                        return INF
                    # the copy is met at an age >= reach, at a time >= now + distance
                    f = max(f, self.reach[nid] - d[x][_T], -d[0][_T] + int(self.dist[nid][s.region]))
        return f

    def times(self, sid: int) -> list[int] | None:
        """Earliest position times of the path to ``sid``: least solution of its difference constraints."""
        path = self.path(sid)
        n = len(path)
        edges: list[tuple[int, int, int]] = []  # (u, v, w): t_v - t_u <= w, searched from position 0 backwards
        for st in path:
            for p, k, lo, hi in st.constraints:
                if hi < INF:
                    edges.append((p, k, hi))
                edges.append((k, p, -lo))
        rho = [INF] * n  # rho[u]: shortest distance from u to position 0 (t_u >= -rho[u])
        rho[0] = 0
        for _ in range(n + 1):
            changed = False
            for u, v, w in edges:
                # t_v - t_u <= w: a path u -> 0 through v gives t_0 - t_u <= w + (t_0 - t_v) bound
                if rho[v] < INF and w + rho[v] < rho[u]:
                    rho[u] = w + rho[v]
                    changed = True
            if not changed:
                break
        else:
            return None  # a negative cycle: the path is not realisable
        if any(r >= INF for r in rho):
            return None
        return [-r for r in rho]

    def path(self, sid: int) -> list[_Sym]:
        out: list[_Sym] = []
        cur = sid
        while cur >= 0:
            out.append(self.states[cur])
            cur = self.states[cur].parent
        out.reverse()
        return out

    def replay(self, path: list[_Sym], times: list[int]) -> list[dict[State, State | None]]:
        """The explicit automaton along the path at the given times: per position, each state reached and the
        state it came from at the previous position (every disjunct followed)."""
        aut, cls = self.aut, self.cls
        layers: list[dict[State, State | None]] = [dict.fromkeys(aut.initial(cls[path[0].region]))]
        for k in range(1, len(path)):
            dt = times[k] - times[k - 1]
            layer: dict[State, State | None] = {}
            for obl in layers[-1]:
                for o2 in aut.step(obl, dt, cls[path[k].region]):
                    layer.setdefault(o2, obl)
            if not layer:
                break
            layers.append(layer)
        return layers

    def candidate(self, sid: int) -> tuple[int, list[_Sym], list[int], list[State], int | None] | None:
        """The path to ``sid`` at its earliest times, when the explicit automaton accepts it: its last position
        recurs on the path with every Büchi set met in between (a lasso entering at that earlier position), or its
        last state is accepting and recurs after a long dwell (the run dwells in its last region forever).
        Returns (cost in ticks, path, times, explicit states, loop entry index or None for the dwell loop)."""
        s = self.states[sid]
        dwell_ok = not any(self.existential[nid] for grp in s.groups for nid in grp)
        if not dwell_ok:
            cur = s.parent
            while cur >= 0:
                a = self.states[cur]
                if a.region == s.region and a.groups == s.groups:
                    break
                cur = a.parent
            else:
                return None  # no earlier position with this region and skeleton: no lasso closes here
        path = self.path(sid)
        same = [k for k in range(len(path) - 1) if path[k].region == s.region and path[k].groups == s.groups]
        times = self.times(sid)
        if times is None:
            return None
        layers = self.replay(path, times)
        if len(layers) < len(path):
            return None
        aut, nb = self.aut, len(self.aut.buchi)
        best: tuple[int, list[_Sym], list[int], list[State], int | None] | None = None
        for obl in layers[-1]:
            chain = [obl]
            for k in range(len(path) - 1, 0, -1):
                prev = layers[k][chain[-1]]
                assert prev is not None
                chain.append(prev)
            chain.reverse()
            for k in same:
                if chain[k] == obl and (best is None or times[k] < best[0]):
                    covered = all(any(aut.accepting(o)[b] for o in chain[k + 1:]) for b in range(nb))
                    if covered:
                        best = (times[k], path, times, chain, k)
            if (dwell_ok and (best is None or times[-1] < best[0]) and all(aut.accepting(obl))
                    and obl in aut.step(obl, self.slow, self.cls[s.region])):
                best = (times[-1], path, times, chain, None)
        return best

    def found(self, cand: tuple[int, list[_Sym], list[int], list[State], int | None], names: list[str]) -> Found:
        """The candidate as a timed run (positions, kinds, the explicit product of its path for inspection)."""
        _, path, times, chain, entry = cand
        tick = self.aut.tick
        prod = Product()
        prod.classes = self.cls
        prev: int | None = None
        last = len(path) if entry is None else len(path) - 1
        for k in range(len(path)):
            v, new = prod.get(path[k].region, chain[k])
            if new:
                prod.best[v] = (times[k], 0)
                prod.settled[v] = True
                if prev is not None:
                    prod.parent[v] = (prev, times[k] - times[k - 1], path[k].kind, 0)
            if prev is not None:
                prod.edges[prev].append((v, times[k] - times[k - 1], path[k].kind, 0))
            prev = v
        regions = tuple(names[st.region] for st in path[:last])
        stamps = tuple(Fraction(t) * tick for t in times[:last])
        kinds = tuple(st.kind for st in path[:last])
        if entry is None:
            period = Fraction(self.slow) * tick
            run = LassoRun(regions, stamps, loop_start=last - 1, period=period)
        else:
            run = LassoRun(regions, stamps, loop_start=entry, period=Fraction(times[-1] - times[entry]) * tick)
        return run, kinds, (0,) * len(regions), 0, prod, len(self.states)

    # ---- search ---------------------------------------------------------------------------------------------
    def run(self, r0: int, names: list[str]) -> Found | None:
        """Best-first by (priority, latest least time); every popped and every created state is checked as a
        candidate; the search ends when no state left is below the cheapest candidate's cost plus ``horizon``
        (two of the longest moves: a lasso closes after its entry, so a cheaper entry can be found a little
        later)."""
        aut = self.aut
        counter = itertools.count()
        for obl in aut.initial(self.cls[r0]):
            groups = (tuple(sorted({nid for nid, _ in obl})),) if obl else ()
            d: Dbm = [[0] * (2 + len(groups)) for _ in range(2 + len(groups))]
            s = _Sym(r0, groups, (0,) * len(groups), d, 0, -1, "start", 0, ())
            self.states.append(s)
            heapq.heappush(self.heap, (self.priority(s), 0, 0, next(counter), len(self.states) - 1))
        best: tuple[int, list[_Sym], list[int], list[State], int | None] | None = None
        if not self.heap:
            return None  # the first position already violates the formula
        floor = min(entry[0] for entry in self.heap)  # no run costs less (the exact search's lower bound)
        while self.heap:
            f, _, _, _, sid = heapq.heappop(self.heap)
            if best is not None and (f >= best[0] + self.horizon or best[0] <= floor):
                break
            cand = self.candidate(sid)
            if cand is not None and (best is None or cand[0] < best[0]):
                best = cand
            for v in self.successors(sid):
                sv = self.states[v]
                cand = self.candidate(v)
                if cand is not None and (best is None or cand[0] < best[0]):
                    best = cand
                heapq.heappush(self.heap, (self.priority(sv), self.pending_roots(sv), -sv.dbm[0][_T], next(counter), v))
            if len(self.states) > self.max_states:
                break
        return None if best is None else self.found(best, names)


def zone_search(aut: TimedAutomaton, names: list[str], cls: list[int], adj: list[list[tuple[int, int]]], r0: int,
                *, max_states: int = DEFAULT_ZONE_STATES) -> tuple[Found | None, int]:
    """An observed-dwell run that ends by dwelling in its last region (module docstring), and the number of
    symbolic states created; ``None`` when none was found within ``max_states`` symbolic states."""
    zs = ZoneSearch(aut, cls, adj, max_states)
    found = zs.run(r0, names)
    return found, len(zs.states)
