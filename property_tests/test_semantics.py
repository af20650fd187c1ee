"""Semantics cross-checks: the certifier's monitor, a brute-force oracle, and the planner's automaton and search.

1. ``verify.check_timed_run`` agrees with ``oracle`` below, written straight from the certifier issue's pointwise
   semantics (finite logs: an unbounded interval ranges to the end of the log; a bounded window reaching past the
   end of observation that is not yet decided is inconclusive; Kleene's three-valued logic), on small random runs.
2. The planner's automaton acceptance (``find_run`` on a WTS that is one lasso: a chain of positions closing into
   a cycle, without waiting, so the lasso is its only run) agrees with the certifier's verdict on the unrolled run,
   for formulas whose intervals are all bounded (their truth at 0 is decided by a finite prefix).
3. Every plan ``plan_from_wts`` returns (re-timed) satisfies its formula per the certifier.
4. On tiny random WTSs, when brute force (every simple lasso up to a length) finds an accepting run, the planner
   finds one too, with and without waiting.
5. On chain-shaped WTSs (3-5 moves, late windows, response obligations: the waits that matter lie several moves
   before the goal), the planner (silent waits) against ``brute_force_silent`` (every run with every wait on the
   planner's tick grid): no missed run, no later-than-optimal run, no unsound run (reference semantics and certifier).
Times are exact (half seconds), so no tolerance is involved.
"""

from __future__ import annotations

import itertools
from collections.abc import Mapping, Sequence
from fractions import Fraction

import networkx as nx
from hypothesis import HealthCheck, assume, example, given, settings
from hypothesis import strategies as st

from tubempc import strategies
from tubempc.errors import NoAcceptingRunError
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
    parse,
    to_fraction,
)
from tubempc.planning import (
    LassoRun,
    SearchLimitError,
    find_run,
    holds,
    make_wts,
    plan_from_wts,
    wts_all_labels,
    wts_weight,
)
from tubempc.planning.automaton import tick_of
from tubempc.planning.reference_semantics import brute_force_silent
from tubempc.planning.search import OBSERVED, SILENT
from tubempc.strategies import TimedRun
from verify import check_timed_run

ATOMS = ("p", "q", "r")
T, U, F = 1.0, 0.5, 0.0  # Kleene truth values: and = min, or = max, not = 1 - x
VERDICT = {T: "pass", F: "fail", U: "inconclusive"}
# cheap tests get five times the profile's budget (200 under ci, 5000 under nightly)
CHEAP = 5 * settings().max_examples
MAX_STATES = 20_000  # product states before a search is abandoned (the case is then skipped, not failed)


# ---------------------------------------------------------------------------------------------------- the oracle
def oracle(f: Formula, times: Sequence[Fraction], labels_at: Sequence[frozenset[str]], end: Fraction) -> float:
    """Three-valued truth of ``f`` at position 0 of a finite observed run (brute force, from the definitions)."""
    n = len(times)
    memo: dict[tuple[Formula, int], float] = {}

    def incomplete(i: int, iv: Interval) -> bool:
        """Some instant of the window t_i + I lies after the end of observation (future positions may fall in)."""
        return iv.hi is not None and times[i] + iv.hi > end

    def until(a: Formula | None, b: Formula, iv: Interval, i: int) -> float:
        result = F
        prefix = T  # a holds at every position in [i, j)
        for j in range(i, n):
            if iv.contains(times[j] - times[i]):
                result = max(result, min(prefix, val(b, j)))
            prefix = min(prefix, T if a is None else val(a, j))
        if incomplete(i, iv):
            result = max(result, min(prefix, U))
        return result

    def val(g: Formula, i: int) -> float:
        key = (g, i)
        if key in memo:
            return memo[key]
        out: float
        if isinstance(g, Const):
            out = T if g.value else F
        elif isinstance(g, Atom):
            out = T if g.name in labels_at[i] else F
        elif isinstance(g, Not):
            out = 1.0 - val(g.arg, i)
        elif isinstance(g, And):
            out = min(val(a, i) for a in g.args)
        elif isinstance(g, Or):
            out = max(val(a, i) for a in g.args)
        elif isinstance(g, Implies):
            out = max(1.0 - val(g.left, i), val(g.right, i))
        elif isinstance(g, Next):
            if i + 1 < n:
                out = min(T if g.interval.contains(times[i + 1] - times[i]) else F, val(g.arg, i + 1))
            else:
                out = U if incomplete(i, g.interval) else F
        elif isinstance(g, Eventually):
            out = until(None, g.arg, g.interval, i)
        elif isinstance(g, Always):
            out = 1.0 - until(None, Not(g.arg), g.interval, i)
        elif isinstance(g, Until):
            out = until(g.left, g.right, g.interval, i)
        else:
            raise TypeError(f"formula={g!r} is not an MITL formula")
        memo[key] = out
        return out

    return val(f, 0)


def _labels_at(run: Sequence[tuple[str, Fraction]], labels: Mapping[str, Sequence[str]]) -> list[frozenset[str]]:
    return [frozenset(labels.get(r, ())) for r, _ in run]


small_intervals = strategies.intervals(max_s=6)
bounded_intervals = strategies.intervals(max_s=4, allow_unbounded=False)
small_formulas = strategies.formulas(strategies.atom_names(ATOMS), max_depth=3, interval_strategy=small_intervals)
bounded_formulas = strategies.formulas(strategies.atom_names(ATOMS), max_depth=3,
                                       interval_strategy=bounded_intervals)


# ---------------------------------------------------------------------------------------------------- 1. monitor
@given(run=strategies.timed_runs(max_len=6, max_gap=4, strictly_increasing=False),
       f=small_formulas, extra=st.integers(0, 6))
@example(run=TimedRun(entries=(("R1", Fraction(0)),), labels={"R1": ()}), f=parse("X[0,1] p"), extra=2)
@example(run=TimedRun(entries=(("R1", Fraction(0)), ("R1", Fraction(0))), labels={"R1": ("p",)}),
         f=parse("!p U[0,0] p"), extra=0)
@settings(max_examples=CHEAP, suppress_health_check=[HealthCheck.too_slow])
def test_monitor_agrees_with_brute_force_oracle(run: TimedRun, f: Formula, extra: int) -> None:
    end = run.entries[-1][1] + Fraction(extra, 2)
    want = VERDICT[oracle(f, [t for _, t in run.entries], _labels_at(run.entries, run.labels), end)]
    got = check_timed_run(str(f), run.as_floats(), run.label_lists(), end=float(end))
    assert got.verdict == want, (str(f), run.entries, float(end), got)


# ---------------------------------------------------------------------------------------------------- 2. automaton
def horizon(f: Formula) -> Fraction:
    """Time after position 0 beyond which no position affects the truth of a bounded formula at 0."""
    if isinstance(f, Atom | Const):
        return Fraction(0)
    if isinstance(f, Not):
        return horizon(f.arg)
    if isinstance(f, And | Or):
        return max(horizon(a) for a in f.args)
    if isinstance(f, Implies):
        return max(horizon(f.left), horizon(f.right))
    hi = f.interval.hi
    if hi is None:
        raise ValueError(f"{f} has an unbounded interval")
    if isinstance(f, Until):
        return hi + max(horizon(f.left), horizon(f.right))
    return hi + horizon(f.arg)


def unroll(regions: Sequence[str], times: Sequence[Fraction], loop_start: int | None, period: Fraction | None,
           until_s: Fraction) -> list[tuple[str, Fraction]]:
    """The lasso's positions up to the first one after ``until_s`` (ours, not the planner's ``unrolled``)."""
    out = list(zip(regions, times, strict=True))
    if loop_start is None or period is None:
        return out
    copy = 1
    while out[-1][1] <= until_s:
        out.extend((regions[k], times[k] + copy * period) for k in range(loop_start, len(regions)))
        copy += 1
    return out


def certifier_on_lasso(f: Formula, run: LassoRun, labels: Mapping[str, Sequence[str]]) -> str:
    """Certifier's verdict on the lasso unrolled past the formula's horizon (plus one period of margin)."""
    span = horizon(f) + (run.period or Fraction(0)) + 1
    positions = unroll(run.regions, run.times, run.loop_start, run.period, span)
    floats = [(r, float(t)) for r, t in positions]
    return check_timed_run(str(f), floats, {k: list(v) for k, v in labels.items()}).verdict


@st.composite
def lassos(draw: st.DrawFn) -> tuple[LassoRun, dict[str, tuple[str, ...]]]:
    """A lasso over fresh position names P0..Pn-1 (labels drawn per position), half-second times."""
    run = draw(strategies.timed_runs(draw(strategies.label_maps(max_regions=3, atoms=ATOMS)), max_len=5,
                                     max_gap=4))
    n = len(run.entries)
    names = tuple(f"P{i}" for i in range(n))
    labels = {names[i]: tuple(run.labels[r]) for i, (r, _) in enumerate(run.entries)}
    loop = draw(st.integers(0, n - 1))
    times = tuple(t for _, t in run.entries)
    period = times[-1] - times[loop] + Fraction(draw(st.integers(1, 6)), 2)
    if loop == n - 1:
        # a one-position cycle would need a self-loop edge, which a WTS does not have (the planner ignores
        # self-loops: staying is a dwell): unroll it once more, the same run as a two-position cycle
        names = (*names, f"P{n}")
        labels[names[-1]] = labels[names[loop]]
        times = (*times, times[-1] + period)
        period *= 2
    return LassoRun(regions=names, times=times, loop_start=loop, period=period), labels


def lasso_wts(run: LassoRun, labels: Mapping[str, Sequence[str]]) -> nx.DiGraph:
    """A WTS whose only infinite run (without waiting) is ``run``."""
    if run.loop_start is None or run.period is None:
        raise ValueError("a lasso is needed")
    n = run.size
    weights: dict[tuple[str, str], Fraction | int | str] = {
        (run.regions[i], run.regions[i + 1]): run.times[i + 1] - run.times[i] for i in range(n - 1)}
    back = run.times[run.loop_start] + run.period - run.times[-1]
    weights[(run.regions[-1], run.regions[run.loop_start])] = back
    return make_wts(dict(labels), weights, initial=run.regions[0], oracle_name="lasso")


def planner_accepts(wts: nx.DiGraph, f: Formula, *, wait: bool, dwell: str = SILENT) -> LassoRun | None:
    try:
        return find_run(wts, f, wait=wait, dwell=dwell, max_states=MAX_STATES, diagnose=False).run
    except NoAcceptingRunError:
        return None


def planner_accepts_lasso(run: LassoRun, labels: dict[str, tuple[str, ...]], f: Formula) -> bool:
    """Whether the planner accepts ``run`` (the only run of its WTS); examples past the search limit are skipped."""
    try:
        return planner_accepts(lasso_wts(run, labels), f, wait=False) is not None
    except SearchLimitError:
        assume(False)
        raise  # unreachable: assume(False) rejects the example


@given(lasso=lassos(), f=bounded_formulas)
@settings(max_examples=CHEAP, suppress_health_check=[HealthCheck.too_slow])
def test_automaton_acceptance_agrees_with_certifier(lasso: tuple[LassoRun, dict[str, tuple[str, ...]]],
                                                     f: Formula) -> None:
    run, labels = lasso
    accepted = planner_accepts_lasso(run, labels, f)
    verdict = certifier_on_lasso(f, run, labels)
    assert verdict != "inconclusive", (str(f), run)
    assert accepted == (verdict == "pass"), (str(f), run, labels, verdict)


def lasso_oracle(f: Formula, run: LassoRun, labels: Mapping[str, Sequence[str]]) -> bool:
    """Infinite-run (pointwise) truth of ``f`` at position 0 of a lasso, brute force from the definitions.

    Values are computed per canonical position, children first; position ``k`` of the unrolled run has the future
    of canonical position ``canon(k)``. An until scan stops at a witness, at a position where the left side fails,
    past a bounded window, or, for an unbounded window, after one full repetition of the loop inside the window
    (from then on the scanned values repeat).
    """
    if run.loop_start is None or run.period is None:
        raise ValueError("a lasso is needed")
    n, loop, period = run.size, run.loop_start, run.period
    length = n - loop

    def canon(k: int) -> int:
        return k if k < n else loop + (k - loop) % length

    def time(k: int) -> Fraction:
        if k < n:
            return run.times[k]
        copies, rem = divmod(k - loop, length)
        return run.times[loop + rem] + copies * period

    vals: dict[Formula, list[bool]] = {}

    def until(left: list[bool] | None, right: list[bool], iv: Interval, i: int) -> bool:
        k, inside_seen = i, 0
        while True:
            d = time(k) - time(i)
            if iv.hi is not None and d > iv.hi:
                return False
            if iv.contains(d) and right[canon(k)]:
                return True
            if left is not None and not left[canon(k)]:
                return False
            if iv.hi is None and d >= iv.lo and k >= loop:
                inside_seen += 1
                if inside_seen > length:
                    return False
            k += 1

    def value(g: Formula) -> list[bool]:
        if g in vals:
            return vals[g]
        out: list[bool]
        if isinstance(g, Const):
            out = [g.value] * n
        elif isinstance(g, Atom):
            out = [g.name in labels.get(run.regions[i], ()) for i in range(n)]
        elif isinstance(g, Not):
            out = [not v for v in value(g.arg)]
        elif isinstance(g, And):
            parts = [value(a) for a in g.args]
            out = [all(p[i] for p in parts) for i in range(n)]
        elif isinstance(g, Or):
            parts = [value(a) for a in g.args]
            out = [any(p[i] for p in parts) for i in range(n)]
        elif isinstance(g, Implies):
            a, b = value(g.left), value(g.right)
            out = [(not a[i]) or b[i] for i in range(n)]
        elif isinstance(g, Next):
            a = value(g.arg)
            out = [g.interval.contains(time(i + 1) - time(i)) and a[canon(i + 1)] for i in range(n)]
        elif isinstance(g, Eventually):
            a = value(g.arg)
            out = [until(None, a, g.interval, i) for i in range(n)]
        elif isinstance(g, Always):
            na = [not v for v in value(g.arg)]
            out = [not until(None, na, g.interval, i) for i in range(n)]
        elif isinstance(g, Until):
            a, b = value(g.left), value(g.right)
            out = [until(a, b, g.interval, i) for i in range(n)]
        else:
            raise TypeError(f"formula={g!r} is not an MITL formula")
        vals[g] = out
        return out

    return value(f)[0]


@given(lasso=lassos(), f=small_formulas)
@settings(max_examples=CHEAP, suppress_health_check=[HealthCheck.too_slow])
def test_automaton_acceptance_agrees_with_lasso_oracle(lasso: tuple[LassoRun, dict[str, tuple[str, ...]]],
                                                      f: Formula) -> None:
    """Unbounded operators included (Büchi acceptance): the planner accepts the lasso iff the oracle says so."""
    run, labels = lasso
    accepted = planner_accepts_lasso(run, labels, f)
    assert accepted == lasso_oracle(f, run, labels), (str(f), run, labels)


# ---------------------------------------------------------------------------------------------------- 3 and 4. plans
@st.composite
def tiny_wts(draw: st.DrawFn) -> nx.DiGraph:
    """2-3 regions, random labels, a cycle through all regions plus random extra edges, weights of 1..8 half
    seconds (every region lies on a cycle, so runs never dead-end)."""
    labels = draw(strategies.label_maps(min_regions=2, max_regions=3, atoms=ATOMS))
    names = sorted(labels)
    ring = list(itertools.pairwise([*names, names[0]]))
    pairs = [(a, b) for a in names for b in names if a != b and (a, b) not in ring]
    extra = draw(st.lists(st.sampled_from(pairs), unique=True, max_size=len(pairs))) if pairs else []
    chosen = ring + extra
    weights: dict[tuple[str, str], Fraction | int | str] = {
        e: Fraction(draw(st.integers(1, 8)), 2) for e in chosen}
    return make_wts(dict(labels), weights, initial=names[0])


MODES = st.sampled_from([(False, SILENT), (True, SILENT), (True, OBSERVED)])  # (wait, dwell mode)


@given(wts=tiny_wts(), f=bounded_formulas, mode=MODES)
@settings(max_examples=CHEAP, suppress_health_check=[HealthCheck.too_slow])
def test_every_plan_satisfies_its_formula_per_the_certifier(wts: nx.DiGraph, f: Formula,
                                                            mode: tuple[bool, str]) -> None:
    """A lasso plan is unrolled past the formula's horizon; a finite plan (the robot stays in its last region
    without new positions: a silent wait adds none, Definition 3) is observed until after the horizon."""
    wait, dwell = mode
    try:
        plan = plan_from_wts(wts, f, wait=wait, dwell=dwell, max_states=MAX_STATES)
    except (NoAcceptingRunError, SearchLimitError):
        assume(False)
        return
    labels = wts_all_labels(wts)
    regions = tuple(r for r, _ in plan.run)
    times = plan.exact_times
    period = to_fraction(plan.period_s) if plan.period_s > 0 else None
    span = horizon(f) + (period or Fraction(0)) + 1
    positions = unroll(regions, times, plan.loop_start if period is not None else None, period, span)
    end = max(positions[-1][1], span)
    verdict = check_timed_run(str(f), [(r, float(t)) for r, t in positions], {k: list(v) for k, v in labels.items()},
                              end=float(end))
    assert verdict.verdict == "pass", (str(f), plan.run, plan.loop_start, plan.period_s, dwell, verdict)


def simple_lassos(wts: nx.DiGraph, init: str, max_len: int) -> list[LassoRun]:
    """Every lasso ``init -> ... -> v_k -> v_l`` (a walk of at most ``max_len`` positions closed by an edge)."""
    out: list[LassoRun] = []
    stack: list[tuple[tuple[str, ...], tuple[Fraction, ...]]] = [((init,), (Fraction(0),))]
    while stack:
        path, times = stack.pop()
        last = path[-1]
        for nxt in wts.successors(last):
            w = wts_weight(wts, last, nxt)
            for loop in range(len(path)):
                if path[loop] == nxt:
                    period = times[-1] + w - times[loop]
                    out.append(LassoRun(regions=path, times=times, loop_start=loop, period=period))
            if len(path) < max_len:
                stack.append(((*path, nxt), (*times, times[-1] + w)))
    return out


@given(wts=tiny_wts(), f=bounded_formulas)
@settings(max_examples=CHEAP, suppress_health_check=[HealthCheck.too_slow])
def test_planner_finds_a_run_when_brute_force_does(wts: nx.DiGraph, f: Formula) -> None:
    labels = wts_all_labels(wts)
    init = next(iter(sorted(wts.nodes)))
    witness = next((run for run in simple_lassos(wts, init, 4) if certifier_on_lasso(f, run, labels) == "pass"),
                   None)
    assume(witness is not None)
    decided = 0
    for wait, dwell in ((False, SILENT), (True, SILENT), (True, OBSERVED)):
        try:
            found = planner_accepts(wts, f, wait=wait, dwell=dwell)
        except SearchLimitError:
            continue
        decided += 1
        assert found is not None, (str(f), witness, labels, wait, dwell)
    # a search that hits its limit in every configuration would assert nothing: at least one must decide
    assert decided >= 1, (str(f), witness, "the planner hit its search limit in every configuration")


def test_oracle_examples() -> None:
    """The oracle itself on hand-checked cases (it must be able to say each of the three verdicts)."""
    z, one, two = Fraction(0), Fraction(1), Fraction(2)
    p: frozenset[str] = frozenset({"p"})
    none: frozenset[str] = frozenset()
    assert oracle(parse("F[0,1] p"), [z, one], [none, p], one) == T
    assert oracle(parse("F[0,1] p"), [z, two], [none, p], two) == F
    assert oracle(parse("F[0,3] p"), [z, one], [none, none], one) == U
    assert oracle(parse("F[0,inf) p"), [z, one], [none, none], one) == F
    assert oracle(parse("G[0,inf) !p"), [z, one], [none, none], one) == T
    assert oracle(parse("X[0,1] p"), [z], [none], z) == U
    assert oracle(parse("X[0,inf) p"), [z], [none], z) == F


# ---------------------------------------------------------------------------------------------------- 5. chains
HALF = Fraction(1, 2)


@st.composite
def chain_cases(draw: st.DrawFn) -> tuple[dict[str, tuple[str, ...]], dict[tuple[str, str], Fraction], Formula]:
    """A chain ``C0 -> C1 -> ... -> Cn`` (n = 3..5 moves of 1 or 2 s; the last region labelled ``p``, the others
    random over ``p``, ``q``) and a late window on ``p`` with one or two response obligations (``G(q -> F[..] p)``,
    ``G(q -> F[..] r)``, a ``G`` window on ``!q``): meeting them needs waits taken moves before the goal."""
    n = draw(st.integers(3, 5))
    names = [f"C{k}" for k in range(n + 1)]
    labels = {c: tuple(sorted(draw(st.sets(st.sampled_from(("p", "q", "r")), max_size=2)))) for c in names[:-1]}
    labels[names[-1]] = ("p",)
    weights = {(a, b): Fraction(draw(st.integers(1, 2))) for a, b in itertools.pairwise(names)}
    lo = draw(st.integers(n, 2 * n + 3))
    width = draw(st.integers(0, 2))
    window = Interval(Fraction(lo), Fraction(lo + width), True, True) if width == 0 else Interval(
        Fraction(lo), Fraction(lo + width), draw(st.booleans()), draw(st.booleans()))
    parts: list[Formula] = [Eventually(window, Atom("p"))]
    for _ in range(draw(st.integers(1, 2))):
        kind = draw(st.integers(0, 3))
        c = Fraction(draw(st.integers(1, 4)))
        if kind == 0:
            parts.append(Always(Interval(Fraction(0), None), Implies(Atom("q"), Eventually(
                Interval(Fraction(0), c), Atom("p")))))
        elif kind == 1:
            parts.append(Always(Interval(Fraction(0), None), Implies(Atom("q"), Eventually(
                Interval(Fraction(0), c, True, draw(st.booleans())), Atom("r")))))
        elif kind == 2:
            parts.append(Always(Interval(Fraction(0), None), Implies(Atom("r"), Eventually(
                Interval(HALF, c), Atom("p")))))
        else:
            parts.append(Always(Interval(Fraction(0), c), Not(Atom("q"))))
    return labels, weights, And(tuple(parts))


@given(case=chain_cases())
@example(case=({"A": (), "B": ("q",), "C": (), "D": ("p",)},
               {("A", "B"): Fraction(1), ("B", "C"): Fraction(1), ("C", "D"): Fraction(1)},
               parse("F[4,5] p & G(q -> F[0,2] p)")))
@settings(max_examples=max(10, settings().max_examples // 2), deadline=None,
          suppress_health_check=[HealthCheck.too_slow])
def test_chain_planner_matches_brute_force(
        case: tuple[dict[str, tuple[str, ...]], dict[tuple[str, str], Fraction], Formula]) -> None:
    labels, weights, f = case
    names = sorted(labels)
    wts = make_wts(labels, weights, initial=names[0])
    moves = len(names) - 1
    until = sum(max((c for c in (iv.lo, iv.hi) if c is not None), default=Fraction(0)) for iv in _intervals_of(f)) + 1

    def dead(run: LassoRun) -> bool:
        # every interval here is bounded but the outer G[0,inf): a verdict F of the three-valued oracle at the run's
        # last position is final (later positions fall outside every decided window)
        return oracle(f, run.times, _labels_at(list(zip(run.regions, run.times, strict=True)), labels),
                      run.times[-1]) == F

    # the planner's tick grid: half the gcd of every weight and constant ("strictly after c" is one tick after c)
    grid = tick_of([*weights.values(), *(c for iv in _intervals_of(f) for c in (iv.lo, iv.hi) if c is not None)],
                   refine=2)
    best = brute_force_silent(labels, weights, f, initial=names[0], grid_s=grid, max_moves=moves, until_s=until,
                              dead=dead)
    try:
        found = find_run(wts, f, dwell=SILENT, diagnose=False).run
    except NoAcceptingRunError:
        found = None
    assert (found is None) == (best is None), (str(f), labels, weights, found, best)  # no missed run
    if found is None or best is None:
        return
    assert holds(f, found, labels), (str(f), found)  # sound under the reference semantics
    verdict = check_timed_run(str(f), [(r, float(t)) for r, t in zip(found.regions, found.times, strict=True)],
                              {k: list(v) for k, v in labels.items()}, end=float(until + 10))
    assert verdict.verdict == "pass", (str(f), found, verdict)  # and per the certifier
    assert found.loop_start is None  # a chain has no cycle: the run ends and the robot stays
    assert found.times[-1] == best.times[-1], (str(f), labels, weights, found, best)  # time-optimal


def _intervals_of(f: Formula) -> list[Interval]:
    from tubempc.mitl import subformulas

    return [g.interval for g in subformulas(f) if isinstance(g, Next | Eventually | Always | Until)]
