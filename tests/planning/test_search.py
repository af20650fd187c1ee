"""Product search on hand-made WTSs: each operator, open/closed endpoints, nesting, waiting, lasso, no run."""

from __future__ import annotations

from fractions import Fraction

import pytest

from tubempc.errors import NoAcceptingRunError
from tubempc.mitl import parse
from tubempc.planning import export_dot, find_run, holds, make_wts

LABELS = {"A": ("p",), "B": ("q",), "C": ("r",)}
# A <-> B 2 s, B <-> C 3 s, A <-> C 4 s
WEIGHTS = {("A", "B"): 2, ("B", "A"): 2, ("B", "C"): 3, ("C", "B"): 3, ("A", "C"): 4, ("C", "A"): 4}
WTS = make_wts(LABELS, WEIGHTS, initial="A")


def plan(text: str, *, wait: bool = True, dwell: str = "silent"):  # type: ignore[no-untyped-def]
    f = parse(text)
    found = find_run(WTS, f, wait=wait, dwell=dwell)
    assert holds(f, found.run, LABELS), found.run  # the independent reference semantics agrees
    return found


def first_time(found, region: str) -> Fraction:  # type: ignore[no-untyped-def]
    return next(t for r, t in zip(found.run.regions, found.run.times, strict=True) if r == region)


def test_eventually_is_time_optimal() -> None:
    found = plan("F[0,10] r")
    assert first_time(found, "C") == 4  # direct A->C (4 s) beats A->B->C (5 s)


def test_eventually_lower_bound_uses_a_silent_wait_before_the_first_departure() -> None:
    found = plan("F[7,8] r")
    # wait 3 s in A (no position), then A->C (4 s) arrives at 7; the run ends there (stay in C)
    assert found.run.regions == ("A", "C") and found.run.times == (0, 7) and found.run.loop_start is None
    assert found.kinds == ("start", "move") and found.waits_s == (0, 3)


def test_eventually_lower_bound_uses_an_observed_dwell() -> None:
    found = plan("F[7,8] r", dwell="observed")
    assert any(k == "dwell" for k in found.kinds)
    times = [t for r, t in zip(found.run.regions, found.run.times, strict=True) if r == "C" and 7 <= t <= 8]
    assert times


def test_eventually_lower_bound_without_wait_needs_a_detour() -> None:
    found = plan("F[7,8] r", wait=False)
    assert "dwell" not in found.kinds
    assert any(r == "C" and 7 <= t <= 8 for r, t in zip(found.run.regions, found.run.times, strict=True))


@pytest.mark.parametrize(("text", "ok"), [("F[0,4] r", True), ("F[0,4) r", False), ("F(4,5] r", True),
                                          ("F[0,3] r", False)])
def test_closed_and_open_endpoints_without_wait(text: str, ok: bool) -> None:
    f = parse(text)
    if ok:
        found = find_run(WTS, f, wait=False)
        assert holds(f, found.run, LABELS)
    else:
        with pytest.raises(NoAcceptingRunError):
            find_run(WTS, f, wait=False)


def test_open_lower_endpoint_with_wait_lands_strictly_inside() -> None:
    found = plan("F(4,5) r", dwell="observed")
    t = next(t for r, t in zip(found.run.regions, found.run.times, strict=True) if r == "C" and 4 < t < 5)
    assert 4 < t < 5
    found = plan("F(4,5) r")  # silent: the arrival itself lands one tick past 4
    assert found.run.regions[-1] == "C" and found.run.times[-1] == Fraction(9, 2)


def test_silent_wait_lands_past_the_end_of_an_always_window() -> None:
    found = plan("G[0,6] !q & F[0,10] q")
    # B is entered only after 6: a silent wait of 4.5 s in A, then A->B (2 s) lands at 6.5 (one tick past 6)
    assert found.run.regions == ("A", "B") and found.run.times == (0, Fraction(13, 2))
    assert found.kinds == ("start", "move")


def test_always_forbids_a_region_inside_its_window() -> None:
    found = plan("G[0,6] !q & F[0,10] r")
    for r, t in zip(found.run.regions, found.run.times, strict=True):
        assert not (r == "B" and t <= 6)


def test_until() -> None:
    found = plan("p U[3,6] r")
    # p holds only in A: wait in A until the move to C arrives in [3,6]
    c = first_time(found, "C")
    assert 3 <= c <= 6
    assert all(r == "A" for r, t in zip(found.run.regions, found.run.times, strict=True) if t < c)


def test_next() -> None:
    found = plan("X[2,2] q")
    assert found.run.regions[1] == "B" and found.run.times[1] == 2
    with pytest.raises(NoAcceptingRunError):
        find_run(WTS, parse("X[0,1] q"), wait=True)
    found = plan("X[0,1] p", dwell="observed")  # only a dwell in A can be the next position within 1 s
    assert found.kinds[1] == "dwell"
    with pytest.raises(NoAcceptingRunError):  # a silent wait is no position: no move reaches p within 1 s
        find_run(WTS, parse("X[0,1] p"), dwell="silent")
    found = plan("X[6,7] r")  # silent: the next position is the arrival in C after a 2 s wait in A
    assert found.run.regions[1] == "C" and found.run.times[1] == 6


def test_nested_response_with_lasso() -> None:
    found = plan("G(p -> F[0,5] r) & G(r -> F[0,5] p)", wait=False)
    assert found.run.loop_start is not None and found.run.period is not None
    cycle = set(found.run.regions[found.run.loop_start:])
    assert {"A", "C"} <= cycle


def test_infinitely_often_needs_a_cycle_through_both() -> None:
    found = plan("G F p & G F r")
    loop = found.run.loop_start
    assert loop is not None
    cycle = set(found.run.regions[loop:])
    assert {"A", "C"} <= cycle


def test_young_obligations_do_not_block_acceptance() -> None:
    # every p spawns F[2,inf) q; a run alternating A and B keeps young copies pending forever
    found = plan("G(p -> F[2,inf) q) & G F p", wait=False)
    assert found.run.loop_start is not None


def test_unsatisfiable_names_the_obligation() -> None:
    with pytest.raises(NoAcceptingRunError) as info:
        find_run(WTS, parse("G !r & F[0,10] q & F[0,20] r"), wait=True)
    assert info.value.obligation == "F[0,20] r"
    with pytest.raises(NoAcceptingRunError) as info:
        find_run(WTS, parse("F[0,3] r & F[0,1] q"), wait=True)
    assert info.value.obligation == "F[0,3] r"


def test_wait_and_no_wait_differ() -> None:
    f = parse("F[5,6] p")
    # without waiting A is re-entered at 4, 8, 9, ... (A->B->A, twice that, A->B->C->A): never in [5,6]
    with pytest.raises(NoAcceptingRunError):
        find_run(WTS, f, wait=False)
    found = plan("F[5,6] p", dwell="observed")
    assert any(r == "A" and 5 <= t <= 6 for r, t in zip(found.run.regions, found.run.times, strict=True))
    # silent: A is only observed again by re-entering it (A->B->A with a 1 s wait)
    found = plan("F[5,6] p")
    assert found.run.regions == ("A", "B", "A") and found.run.times[-1] == 5
    assert sum(found.waits_s) == 1


def test_silent_stay_needs_only_universal_obligations() -> None:
    found = plan("G !q")
    assert found.run.regions == ("A",) and found.run.loop_start is None  # stay in A forever
    found = plan("G F p & G F r")  # infinitely many arrivals: a lasso of moves
    assert found.run.loop_start is not None and set(found.kinds) <= {"start", "move"}


def test_export_dot() -> None:
    found = plan("F[0,10] r")
    text = export_dot(found.explored())
    assert text.startswith("digraph product {") and "->" in text


# ---- exactness: waits taken several moves before the goal, proofs of "no run", the state limit ----------------
CHAIN_LABELS = {"A": (), "B": ("q",), "C": (), "D": ("p",)}
CHAIN = make_wts(CHAIN_LABELS, {("A", "B"): 1, ("B", "C"): 1, ("C", "D"): 1}, initial="A")
RESPONSE = "F[4,5] p & G(q -> F[0,2] p)"


def test_wait_three_moves_before_the_goal_is_found() -> None:
    # the wait must be taken in A: waiting in B or C breaks F[0,2] p after q; the event-driven first attempt
    # misses it (it aims a wait at the next two arrivals only), the exact search finds it
    f = parse(RESPONSE)
    found = find_run(CHAIN, f, initial="A")
    assert found.run.regions == ("A", "B", "C", "D") and found.run.times == (0, 2, 3, 4)
    assert found.waits_s == (0, 1, 0, 0) and found.run.loop_start is None
    assert found.method == "exact search"
    assert holds(f, found.run, CHAIN_LABELS)
    from verify.semantics.timed_run import check_timed_run

    verdict = check_timed_run(RESPONSE, [(r, float(t)) for r, t in zip(found.run.regions, found.run.times,
                                                                         strict=True)],
                              {k: list(v) for k, v in CHAIN_LABELS.items()}, end=10.0)
    assert verdict.verdict == "pass"


def test_issue_example_through_plan_from_wts_keeps_the_optimum() -> None:
    from tubempc.planning import plan_from_wts

    plan_ = plan_from_wts(CHAIN, parse(RESPONSE), initial="A")
    assert [r for r, _ in plan_.run] == ["A", "B", "C", "D"]
    assert plan_.run[-1][1] == 4.0  # the optimum: the LP re-timing does not make it later by default
    assert plan_.targets[0].region == "A" and plan_.targets[0].depart_after_s == 1.0


def test_first_attempt_alone_would_have_said_no_run() -> None:
    # the fast stage on its own finds nothing here; the answer comes from the exact search
    from tubempc.planning.automaton import compile_formula, tick_of
    from tubempc.planning.search import _search

    f = parse(RESPONSE)
    aut = compile_formula(f, tick_of([Fraction(1), Fraction(4), Fraction(5), Fraction(2)], refine=2))
    assert _search(CHAIN, aut, "A", wait=True, silent=True, prune=True, max_states=10_000) is None


def test_named_conjuncts_are_themselves_unsatisfiable() -> None:
    # F[0,2] p cannot be met from A (D is 3 s away): named alone, and the message names nothing false
    with pytest.raises(NoAcceptingRunError) as info:
        find_run(CHAIN, parse("G(q -> F[0,2] p) & F[0,2] p"), initial="A")
    assert info.value.obligation == "F[0,2] p"
    with pytest.raises(NoAcceptingRunError):
        find_run(CHAIN, parse("F[0,2] p"), initial="A", diagnose=False)
    # each conjunct alone is satisfiable, the pair is not: named together
    with pytest.raises(NoAcceptingRunError) as info:
        find_run(CHAIN, parse("F[3,3] p & G(q -> F[0,1] p)"), initial="A")
    assert "cannot be met together with" in str(info.value)
    find_run(CHAIN, parse("F[3,3] p"), initial="A")
    find_run(CHAIN, parse("G(q -> F[0,1] p)"), initial="A")


def test_state_limit_is_not_no_run() -> None:
    from tubempc.planning import SearchLimitError

    with pytest.raises(SearchLimitError) as info:
        find_run(CHAIN, parse(RESPONSE), initial="A", max_states=3)
    assert info.value.limit == 3
    assert not isinstance(info.value, NoAcceptingRunError)
    assert "--max-states" in str(info.value) and "3" in str(info.value)


def test_exact_search_is_optimal_where_the_first_attempt_is_late() -> None:
    # the same formula with first_attempt=False (exact search alone) gives the same cost as the default
    f = parse(RESPONSE)
    alone = find_run(CHAIN, f, initial="A", first_attempt=False)
    assert alone.run.times[-1] == 4 and alone.method == "exact search"


@pytest.mark.parametrize(("text", "first_attempt_cost", "cost"), [
    ("G[2,2] p", Fraction(5, 2), Fraction(2)),  # the first attempt's lasso enters its repeating part late
    ("G(2,inf) p", None, Fraction(5, 2)),  # the first attempt (with its pruning) finds nothing
])
def test_observed_exact_search_beats_the_first_attempt(text: str, first_attempt_cost: Fraction | None,
                                                       cost: Fraction) -> None:
    from tubempc.planning.automaton import compile_formula
    from tubempc.planning.search import _cost, _search

    found = plan(text, dwell="observed")
    assert _cost(found.run) == cost
    old = find_run(WTS, parse(text), dwell="observed", zones=False)  # the event-driven first attempt
    assert old.method == "exact search" and _cost(old.run) == cost
    fast = _search(WTS, compile_formula(parse(text), found.tick_s), "A", wait=True, silent=False, prune=True,
                   max_states=10_000)
    assert (None if fast is None else _cost(fast[0])) == first_attempt_cost


# the built-in scenario's safe regions and Algorithm 1 transition times (seconds), mission_1 in R1, mission_2 in R3
NEXUS_LABELS = {"R1": ("mission_1",), "R2": (), "R3": ("mission_2",), "R4": (), "R5": ()}
NEXUS_WEIGHTS = {
    ("R1", "R2"): "19.9", ("R1", "R3"): "16.7", ("R1", "R4"): "30.7", ("R1", "R5"): "22.5",
    ("R2", "R3"): "13", ("R2", "R4"): "37.2", ("R2", "R5"): "32.5", ("R3", "R4"): "13.4",
    ("R3", "R5"): "14.9", ("R4", "R5"): "21.1"}
NEXUS = make_wts(NEXUS_LABELS, {**{k: Fraction(v) for k, v in NEXUS_WEIGHTS.items()},
                                **{(b, a): Fraction(v) for (a, b), v in NEXUS_WEIGHTS.items()}}, initial="R1")


def test_aimed_observed_dwell_is_not_pruned_by_its_own_origin() -> None:
    # R1 at 0 asks for mission_2 in [10, 20] (R3 at 16.7); F[50,60] mission_1 needs a dwell position in R3 at 33.3
    # that makes R1 arrive at exactly 50. The first attempt used to prune that dwell as "dominated" by its own
    # origin (the origin dwelling until 33.3 is that very state) and found a lasso entering at 54.1; the exact
    # search then had to explore every observed dwell pattern below 54.1 s (tick 0.05 s) and ran out of states.
    # Found, the run meets the lower bound (the F window's lower end) and is proved optimal at once.
    f = parse("G(mission_1 -> F[10,20] mission_2) & F[50,60] mission_1")
    found = find_run(NEXUS, f, dwell="observed", max_states=20_000)
    assert holds(f, found.run, NEXUS_LABELS), found.run
    assert found.run.loop_start is not None and found.run.times[found.run.loop_start] == 50
    assert found.method == "zone search, proved optimal by the exact search"
    assert ("R3", Fraction(333, 10)) in set(zip(found.run.regions, found.run.times, strict=True))
    old = find_run(NEXUS, f, dwell="observed", max_states=20_000, zones=False)
    assert old.method == "first attempt, proved optimal by the exact search" and old.run == found.run
