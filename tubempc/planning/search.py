"""Product search: WTS x formula automaton -> a time-optimal accepting lasso timed run (exact, in ticks).

input: a WTS (``tubempc.planning.wts``: nodes = safe regions with ``LABELS``, edges with exact ``WEIGHT``), a
``Formula``, whether the robot may wait in a region and what a wait is (``dwell``: ``silent`` — no position, the
next move arrives later; ``observed`` — a position of the run) -> output: a ``SearchResult`` with a ``LassoRun``
(prefix + repeating suffix, or a finite run that stays in its last region) and the explored product graph;
``NoAcceptingRunError`` naming the obligation that cannot be met when no run exists.

Times are scaled to integer ticks (the gcd of all weights and interval endpoints, halved when waiting is allowed
so that "strictly after a constant" is one tick after it); every clock value is then an integer and the product is
a finite graph. Cost of a run: the time of its last position (a finite run) or of its repeating part's first one.

With waiting, two stages:
1. a fast first attempt. Observed dwells: the zone search (``tubempc.planning.zones``: clocks as difference-bound
   matrices, a dwell of any length one symbolic step), and if it finds nothing the event-driven search; silent
   waits (or ``zones=False``): the event-driven search (this module's ``_search``): Dijkstra over
   ``(region, automaton state)`` by (time, travel)
   with *event-driven* waits only — a silent wait lands the next arrival, or the one after it, where a pending
   obligation changes status (``TimedAutomaton.silent_goals``); an observed dwell lasts until an obligation changes
   status (``event_delays`` / ``targeted_delays``) — and pruning by dominance. It may miss a run or find a late
   one, so its answer is re-checked by the reference semantics and only used as an upper bound;
2. the exact search (``tubempc.planning.exact``): waiting as one-tick delay transitions, A* below the first
   attempt's cost. It finds a cheaper run, or proves that none exists (then the first attempt's run is optimal),
   or — without a first run — proves that no run exists at all. "No accepting run" is never said by stage 1.
Without waiting the product is finite and stage 1 explores it completely (no pruning): it is exact on its own.
Past ``max_states`` product states a search raises ``SearchLimitError`` (undecided, not "no run").
"""

from __future__ import annotations

import heapq
import math
import time
from dataclasses import dataclass, field
from fractions import Fraction

import networkx as nx

from tubempc.errors import NoAcceptingRunError, SearchLimitError
from tubempc.mitl import And, Formula, Interval, subformulas
from tubempc.mitl.ast import Always, Eventually, Next, Until
from tubempc.planning.automaton import State, TimedAutomaton, compile_formula, tick_of
from tubempc.planning.exact import exact_search
from tubempc.planning.product import DWELL, MOVE, STAY, Found, Product, accepting_cycle, assemble
from tubempc.planning.reference_semantics import LassoRun, holds
from tubempc.planning.wts import wts_edges, wts_initial, wts_labels
from tubempc.planning.zones import DEFAULT_ZONE_STATES, zone_search

__all__ = ["DEFAULT_MAX_STATES", "DWELL_MODES", "OBSERVED", "SILENT", "SearchLimitError", "SearchResult", "export_dot",
           "find_run"]

DEFAULT_MAX_STATES = 500_000  # about 40 s and a few hundred MB of product; raise with --max-states
SILENT, OBSERVED = "silent", "observed"
DWELL_MODES = (SILENT, OBSERVED)
FAST = "first attempt, proved optimal by the exact search"
EXACT = "exact search"
ZONE = "zone search, proved optimal by the exact search"
_DIAGNOSIS_STATES = 100_000  # per conjunct set checked while naming the obligation (undecided: named nothing)
_DOMINANCE_WINDOW = 4  # how many earlier states of the same region and obligation skeleton are compared


@dataclass(frozen=True, slots=True)
class SearchResult:
    """A lasso run in exact seconds; ``kinds[i]`` is ``start``, ``move`` or ``dwell``.

    ``waits_s[i]`` is the silent wait (seconds) in the previous region before the move that arrives at position
    ``i`` (0 for the start, dwells and moves without a wait); ``closing_wait_s`` that of the move from the last
    position back to ``loop_start`` (0 for a finite run). ``dwell`` is ``silent``, ``observed`` or ``none``.
    A finite run (``run.loop_start is None``) stays in its last region forever without a further position.

    ``method`` says how the run was established: by the exact search, or by the fast first attempt with the exact
    search proving that no cheaper run exists; ``exact_s`` is the time spent in the exact search (the cost of
    exactness), ``states`` the product states created by both."""

    run: LassoRun
    kinds: tuple[str, ...]
    tick_s: Fraction
    states: int
    expanded: int
    seconds: float
    waits_s: tuple[Fraction, ...]
    closing_wait_s: Fraction
    dwell: str
    method: str
    exact_s: float
    automaton: TimedAutomaton = field(compare=False, repr=False)
    product: Product = field(compare=False, repr=False)
    region_names: tuple[str, ...] = field(compare=False, repr=False, default=())

    def explored(self) -> nx.DiGraph:
        """The explored product: nodes with region, time, pending obligations; edges with kind and duration."""
        return _explored_graph(self.product, self.automaton, list(self.region_names), self.tick_s)


def _intervals(formula: Formula) -> list[Interval]:
    return [f.interval for f in subformulas(formula) if isinstance(f, Next | Eventually | Always | Until)]


def find_run(wts: nx.DiGraph, formula: Formula, *, wait: bool = True, initial: str | None = None,
             max_states: int = DEFAULT_MAX_STATES, diagnose: bool = True, dwell: str = SILENT,
             first_attempt: bool = True, optimal: bool = True, zones: bool = True) -> SearchResult:
    """Time-optimal accepting lasso run of ``wts`` for ``formula`` (see the module docstring).

    ``wait``: whether the robot may wait in a region; ``dwell`` (with ``wait``): ``silent`` (a wait adds no
    position: the move after it just arrives later) or ``observed`` (each dwell is a position of the run).
    ``first_attempt=False`` skips the fast first stage (the exact search alone decides; same answer, usually
    slower); ``zones=False`` makes the first stage of observed dwells the event-driven search instead of the zone
    search (``tubempc.planning.zones``; the explicit-state first attempt, kept as the baseline and the oracle);
    ``optimal=False`` accepts the first attempt's run without the exact search's proof that no cheaper run exists (a
    satisfiability check). When the exact search reaches ``max_states`` after the first attempt found a run, that
    run is returned with ``method`` saying that its optimality is not proved. Raises ``NoAcceptingRunError`` only
    when the exact search proves that no run exists, and ``SearchLimitError`` when a search reaches ``max_states``
    product states first."""
    if dwell not in DWELL_MODES:
        raise ValueError(f"dwell={dwell!r} must be one of {DWELL_MODES}")
    start = time.perf_counter()
    init = initial if initial is not None else wts_initial(wts)
    if init is None or init not in wts:
        raise ValueError(f"initial region {init!r} is not a state of the WTS (safe regions: {sorted(wts.nodes)})")
    weights = [w for _, _, w in wts_edges(wts)]
    for a, b, w in wts_edges(wts):
        if not isinstance(w, Fraction | int) or w <= 0:
            raise ValueError(f"WTS edge {a}->{b}: t_ij={w!r} must be a positive exact number (Fraction)")
    consts = [c for iv in _intervals(formula) for c in (iv.lo, iv.hi) if c is not None]
    tick = tick_of([Fraction(w) for w in weights] + consts, refine=2 if wait else 1)
    aut = compile_formula(formula, tick)
    silent = wait and dwell == SILENT
    names = sorted(wts.nodes)
    idx = {n: i for i, n in enumerate(names)}
    cls = [aut.label_class(wts_labels(wts, n)) for n in names]
    labels = {n: wts_labels(wts, n) for n in names}
    states = 0
    exact_s = 0.0
    if not wait:
        # without waiting the product is finite and explored completely: the event-driven search is exact
        result = _search(wts, aut, init, wait=False, silent=False, prune=False, max_states=max_states)
        method = EXACT
        if result is not None:
            states = len(result[4].region)
    else:
        # a fast first attempt (zones for observed dwells, else event-driven waits with pruning by dominance); it
        # may miss runs or find a late one, so the exact search (delay transitions) runs below its cost: it finds
        # a cheaper run or proves there is none
        fast: Found | None = None
        proved = FAST
        if first_attempt:
            fast, states, proved = _first_attempt(wts, aut, formula, init, labels, names=names, cls=cls, idx=idx,
                                                  silent=silent, zones=zones, max_states=max_states)
        bound = math.inf if fast is None else float(_cost(fast[0]) / tick)
        exact: Found | None = None
        if fast is None or optimal:
            adj = _adjacency(wts, names, idx, tick)
            exact_start = time.perf_counter()
            try:
                exact, exact_states = exact_search(aut, names, cls, adj, idx[init],
                                                   mode=SILENT if silent else OBSERVED, bound=bound,
                                                   max_states=max_states)
            except SearchLimitError:
                if fast is None:
                    raise  # undecided: neither a run nor a proof that none exists
                # a valid run is known, only its optimality is undecided: return it and say so
                method = f"first attempt; optimality not proved (the exact search reached {max_states} states)"
                exact_states = max_states
            else:
                method = proved if exact is None and fast is not None else EXACT
            states += exact_states
            exact_s = time.perf_counter() - exact_start
        else:
            method = "first attempt (optimality not checked)"
        result = exact if exact is not None else fast
    if result is None:
        if diagnose:
            raise _no_run_error(wts, formula, wait=wait, dwell=dwell, initial=init, max_states=max_states)
        raise NoAcceptingRunError(f"no timed run of the WTS satisfies {formula}", obligation=str(formula))
    run, kinds, waits, closing, prod, expanded = result
    return SearchResult(run=run, kinds=kinds, tick_s=tick, states=states, expanded=expanded,
                        seconds=time.perf_counter() - start, waits_s=tuple(w * tick for w in waits),
                        closing_wait_s=closing * tick, dwell=(dwell if wait else "none"), automaton=aut,
                        product=prod, region_names=tuple(names), method=method, exact_s=exact_s)


def _first_attempt(wts: nx.DiGraph, aut: TimedAutomaton, formula: Formula, init: str,
                   labels: dict[str, tuple[str, ...]], *, names: list[str], cls: list[int], idx: dict[str, int],
                   silent: bool, zones: bool, max_states: int) -> tuple[Found | None, int, str]:
    """The first attempt's run (re-checked by the reference semantics; None if it fails or none was found), the
    states it created and how a run of it is called once the exact search proves it optimal. Observed dwells:
    the zone search (``zones.zone_search``), then the event-driven search if the zone search found nothing."""
    states = 0
    if zones and not silent:
        found, created = zone_search(aut, names, cls, _adjacency(wts, names, idx, aut.tick), idx[init],
                                     max_states=min(max_states, DEFAULT_ZONE_STATES))
        states += created
        if found is not None and holds(formula, found[0], labels):
            return found, states, ZONE
    try:
        fast = _search(wts, aut, init, wait=True, silent=silent, prune=True, max_states=max_states)
    except SearchLimitError:
        return None, states, FAST
    if fast is None:
        return None, states, FAST
    states += len(fast[4].region)
    if not holds(formula, fast[0], labels):
        return None, states, FAST  # never trust the first attempt's answer unchecked
    return fast, states, FAST


def _cost(run: LassoRun) -> Fraction:
    """The cost the search minimises: the first position of the repeating part, or the last of a finite run."""
    return run.times[run.loop_start if run.loop_start is not None else run.size - 1]


def _adjacency(wts: nx.DiGraph, names: list[str], idx: dict[str, int], tick: Fraction) -> list[list[tuple[int, int]]]:
    """Out-edges per region index as (target index, weight in ticks); the one place the WTS weights are read."""
    adj: list[list[tuple[int, int]]] = [[] for _ in names]
    for a, b, w in wts_edges(wts):
        if a != b:
            adj[idx[a]].append((idx[b], int(Fraction(w) / tick)))
    return adj


def _search(wts: nx.DiGraph, aut: TimedAutomaton, init: str, *, wait: bool, silent: bool, prune: bool,
            max_states: int) -> Found | None:
    """The event-driven first attempt (module docstring, stage 1): Dijkstra by (time, travel) over the product
    states, with event-driven waits and, with ``prune``, pruning by dominance."""
    names = sorted(wts.nodes)
    idx = {n: i for i, n in enumerate(names)}
    cls = [aut.label_class(wts_labels(wts, n)) for n in names]
    adj = _adjacency(wts, names, idx, aut.tick)
    arrivals = [[(w, cls[j]) for j, w in row] for row in adj]
    prod = Product()
    prod.classes = cls
    heap: list[tuple[int, int, int]] = []
    r0 = idx[init]
    for obl in aut.initial(cls[r0]):
        sid, _ = prod.get(r0, obl)
        prod.best[sid] = (0, 0)
        heapq.heappush(heap, (0, 0, sid))
    buckets: dict[tuple[int, tuple[int, ...]], list[int]] = {}
    aimed: set[int] = set()  # observed dwell positions aimed at landing the next arrival on a window end
    stop_at: int | None = None
    expanded = 0
    while heap:
        t, travel, sid = heapq.heappop(heap)
        if prod.settled[sid] or prod.best[sid] != (t, travel):
            continue
        if stop_at is not None and t > stop_at:
            break
        prod.settled[sid] = True
        r, obl = prod.region[sid], prod.obl[sid]
        if prune and _dominated(aut, prod, buckets, sid=sid, t=t, cls=cls[r], silent=silent, aimed=sid in aimed):
            prod.pruned[sid] = True
            continue
        expanded += 1
        succs = _moves(aut, obl, adj, r, cls, silent=silent)
        targeted: set[int] = set()
        if silent:
            if aut.final(obl):
                # stay here forever without a further position: a finite run that ends in an accepting way
                succs.append((r, obl, _stay_ticks(aut), 0, STAY, 0))
                if stop_at is None:
                    stop_at = t
        elif wait:
            targeted = aut.targeted_delays(obl, arrivals[r])
            dwells, settles = _dwells(aut, obl, cls[r], r, targeted)
            succs.extend(dwells)
            if settles and stop_at is None:
                stop_at = t
        _relax(prod, heap, sid, (t, travel), succs, targeted=targeted, aimed=aimed)
        if len(prod.region) > max_states:
            raise SearchLimitError(f"the search reached its limit of {max_states} product states while searching "
                                   f"for {aut.formula}, before it found a run or proved that none exists; raise the "
                                   f"limit (tubempc plan --max-states N, or max_states=N in Python) or shorten the "
                                   f"formula's windows", limit=max_states)
    return _best_lasso(prod, aut, nb=len(aut.buchi), names=names, tick=aut.tick, expanded=expanded)


Succ = tuple[int, State, int, int, str, int]  # (region, state, delta, travel, kind, silent wait)


def _relax(prod: Product, heap: list[tuple[int, int, int]], sid: int, cost: tuple[int, int], succs: list[Succ], *,
           targeted: set[int], aimed: set[int]) -> None:
    """Record the edges from ``sid`` (reached at ``cost`` = (time, travel)) to its successors and push every
    successor whose (time, travel) improves; a dwell that lasts a targeted duration marks its target ``aimed``."""
    t, travel = cost
    for j, o2, d, moved, kind, waited in succs:
        v, _ = prod.get(j, o2)
        prod.edges[sid].append((v, d, kind, waited))
        if kind == DWELL and d in targeted:
            aimed.add(v)
        if kind == STAY:
            continue
        cand = (t + d, travel + moved)
        if cand < prod.best[v] and not prod.settled[v]:
            prod.best[v] = cand
            prod.parent[v] = (sid, d, kind, waited)
            heapq.heappush(heap, (cand[0], cand[1], v))


def _moves(aut: TimedAutomaton, obl: State, adj: list[list[tuple[int, int]]], r: int, cls: list[int], *,
           silent: bool) -> list[Succ]:
    """The moves out of region ``r``, and in silent mode the same moves after an event-driven wait: the arrival
    (or the one after it) lands on a goal of the state (``TimedAutomaton.silent_goals``)."""
    succs: list[Succ] = []
    far_goals: dict[int, tuple[int, ...]] = {}  # label class -> goals of an arrival two moves ahead
    for j, w in adj[r]:
        for o2 in aut.step(obl, w, cls[j]):
            succs.append((j, o2, w, w, MOVE, 0))
        if silent and obl:
            for d in _silent_waits(aut, obl, adj[j], w, cls=cls, far_goals=far_goals, into=cls[j]):
                for o2 in aut.step(obl, w + d, cls[j]):
                    succs.append((j, o2, w + d, w, MOVE, d))
    return succs


def _silent_waits(aut: TimedAutomaton, obl: State, onward: list[tuple[int, int]], w: int, *, cls: list[int],
                  far_goals: dict[int, tuple[int, ...]], into: int) -> list[int]:
    """Silent waits before a move of weight ``w`` into label class ``into`` (whose region's moves are ``onward``)
    after which the arrival, or the next one, lands on a goal of the state."""
    delays = {g - w for g in aut.silent_goals(obl, into) if g > w}
    for k, w2 in onward:
        ck = cls[k]
        goals = far_goals.get(ck)
        if goals is None:
            goals = far_goals[ck] = aut.silent_goals(obl, ck, direct=False)
        far = w + w2
        delays.update(g - far for g in goals if g > far)
    return sorted(delays)


def _dwells(aut: TimedAutomaton, obl: State, cls: int, r: int, targeted: set[int]) -> tuple[list[Succ], bool]:
    """Observed dwell positions after the event-driven and targeted durations, and whether the state is accepting
    and a dwell keeps it (the search may then stop after this time)."""
    out: list[Succ] = []
    settles = False
    for d in sorted(aut.event_delays(obl, cls) | targeted):
        for o2 in aut.step(obl, d, cls):
            out.append((r, o2, d, 0, DWELL, 0))
            if o2 == obl and all(aut.accepting(obl)):
                settles = True
    return out, settles


def _stay_ticks(aut: TimedAutomaton) -> int:
    """Nominal length of a 'stay forever' self-loop (only its presence matters)."""
    return max([n.cap for n in aut.nodes] + [1])


def _dominated(aut: TimedAutomaton, prod: Product, buckets: dict[tuple[int, tuple[int, ...]], list[int]], *,
               sid: int, t: int, cls: int, silent: bool, aimed: bool = False) -> bool:
    """Whether state ``sid`` (popped at ``t``) is dominated by an earlier state of its region that can wait until
    ``t`` and be no harder. An ``aimed`` dwell position (``targeted_delays``: it lands the next arrival on a window
    end) is not pruned by its own origin: the origin's dwell to ``t`` *is* this state, and pruning it would lose the
    aimed arrival (``G(m1 -> F[10,20] m2) & F[50,60] m1`` on the built-in scenario: the dwell in R3 that makes R1
    arrive at 50 s)."""
    r, obl = prod.region[sid], prod.obl[sid]
    key = (r, tuple(sorted({nid for nid, _ in obl})))
    bucket = buckets.setdefault(key, [])
    for other in bucket[-_DOMINANCE_WINDOW:]:
        t_other = prod.best[other][0]
        if t_other == t:
            if aut.weaker(prod.obl[other], obl):
                return True
        elif t_other < t:
            # the earlier state waits until t (silently, or with one dwell position) and is then no harder
            later = (aut.age(prod.obl[other], t - t_other),) if silent else aut.step(prod.obl[other], t - t_other,
                                                                                     cls)
            if any(aut.weaker(o, obl) for o in later if not (aimed and o == obl)):
                return True
    bucket.append(sid)
    return False


def _best_lasso(prod: Product, aut: TimedAutomaton, *, nb: int, names: list[str], tick: Fraction,
                expanded: int) -> Found | None:
    g = nx.DiGraph()
    live = [s for s in range(len(prod.region)) if prod.settled[s] and not prod.pruned[s]]
    alive = set(live)
    for s in live:
        g.add_node(s)
        for v, d, kind, waited in prod.edges[s]:
            if v in alive and (not g.has_edge(s, v) or g.edges[s, v]["d"] > d):
                g.add_edge(s, v, d=d, kind=kind, wait=waited)
    best: tuple[tuple[int, int], int, set[int]] | None = None
    for comp in nx.strongly_connected_components(g):
        if len(comp) == 1:
            (only,) = comp
            if not g.has_edge(only, only):
                continue
        covered = [any(aut.accepting(prod.obl[s])[b] for s in comp) for b in range(nb)]
        if not all(covered):
            continue
        entry = min(comp, key=lambda s: prod.best[s])
        if best is None or prod.best[entry] < best[0]:
            best = (prod.best[entry], entry, comp)
    if best is None:
        return None
    _, entry, comp = best
    sub = g.subgraph(comp)
    cycle = accepting_cycle(sub, entry, aut, prod, nb)
    if len(cycle) == 1 and cycle[0][2] == DWELL:
        # staying put: prefer one long dwell period (ages saturate at the caps) over a one-tick repetition
        slow = _stay_ticks(aut)
        obl = prod.obl[entry]
        cls = prod.classes[prod.region[entry]]
        if obl in aut.step(obl, slow, cls):
            cycle = [(entry, slow, DWELL, 0)]
    start, prefix = prod.prefix(entry)
    return assemble(prod, names, tick, start=start, prefix=prefix, cycle=cycle, expanded=expanded)


def _explored_graph(prod: Product, aut: TimedAutomaton, names: list[str], tick: Fraction) -> nx.DiGraph:
    g = nx.DiGraph()
    for s in range(len(prod.region)):
        if not prod.settled[s]:
            continue
        t = prod.best[s][0]
        g.add_node(s, region=names[prod.region[s]], time_s=t * tick, obligations=aut.describe(prod.obl[s]),
                   pruned=prod.pruned[s], accepting=all(aut.accepting(prod.obl[s])))
    for s in list(g.nodes):
        for v, d, kind, waited in prod.edges[s]:
            if v in g:
                g.add_edge(s, v, delta_s=d * tick, kind=kind, wait_s=waited * tick)
    return g


def export_dot(explored: nx.DiGraph) -> str:
    """The explored product as Graphviz DOT text (node: region, time, pending obligations)."""
    lines = ["digraph product {", "  rankdir=LR;", "  node [shape=box, fontsize=10];"]
    for s, d in explored.nodes(data=True):
        label = f"{d['region']} t={float(d['time_s']):g}s\\n{d['obligations']}".replace('"', "'")
        style = ", style=dashed" if d["pruned"] else (", peripheries=2" if d["accepting"] else "")
        lines.append(f'  s{s} [label="{label}"{style}];')
    for a, b, d in explored.edges(data=True):
        lines.append(f'  s{a} -> s{b} [label="{d["kind"]} {float(d["delta_s"]):g}s"];')
    lines.append("}")
    return "\n".join(lines) + "\n"


def _no_run_error(wts: nx.DiGraph, formula: Formula, *, wait: bool, dwell: str, initial: str,
                  max_states: int) -> NoAcceptingRunError:
    """The proved 'no run' error; it names a conjunct (alone, or together with the ones before it) only when the
    exact search proves that conjunct set unsatisfiable on its own."""
    conjuncts = list(formula.args) if isinstance(formula, And) else [formula]
    mode = f"with {dwell} waiting" if wait else "without waiting (--no-wait)"

    budget = min(max_states, _DIAGNOSIS_STATES)

    def unsatisfiable(f: Formula) -> bool:
        try:
            find_run(wts, f, wait=wait, dwell=dwell, initial=initial, max_states=budget, diagnose=False,
                     optimal=False)
        except NoAcceptingRunError:
            return True
        except SearchLimitError:
            return False  # undecided: name nothing
        return False

    if len(conjuncts) > 1:
        for c in conjuncts:
            if unsatisfiable(c):
                return NoAcceptingRunError(f"no timed run of the WTS {mode} satisfies {formula}: the obligation "
                                           f"{c} cannot be met from {initial}", obligation=str(c))
        for k in range(2, len(conjuncts) + 1):
            # the whole conjunction is already proved unsatisfiable by the caller's exact search
            if k == len(conjuncts) or unsatisfiable(And(tuple(conjuncts[:k]))):
                others = " & ".join(str(c) for c in conjuncts[: k - 1])
                return NoAcceptingRunError(f"no timed run of the WTS {mode} satisfies {formula}: the obligation "
                                           f"{conjuncts[k - 1]} cannot be met together with {others}",
                                           obligation=str(conjuncts[k - 1]))
    return NoAcceptingRunError(f"no timed run of the WTS {mode} satisfies {formula} from {initial}",
                               obligation=str(formula))
