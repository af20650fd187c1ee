"""``verify.monitor.engine.explain`` walks from a false or undecided formula to the sub-formula and time that decide
it: an exact-zero value is undecided, never false; an undecided conjunction or disjunction names its undecided
argument; a false conjunction its earliest false conjunct (not an undecided one)."""

from __future__ import annotations

import numpy as np
import pytest

from tests.verify.positions import with_gaps as _with_gaps
from tubempc.mitl import parse
from verify.monitor import engine
from verify.monitor.engine import Positions, Truth, evaluate_at_points, explain

S = 1_000_000_000


def _pos(n: int) -> Positions:
    """``n`` sample points 1 s apart (no gaps)."""
    t = np.arange(n, dtype=np.int64) * S
    return Positions(t, t.copy(), np.ones(n, dtype=bool), int(t[-1]))


def _truth(lo: list[float], hi: list[float]) -> Truth:
    return Truth(np.array(lo, dtype=np.float64), np.array(hi, dtype=np.float64))


TRUE4 = _truth([1.0] * 4, [1.0] * 4)


def test_an_exact_zero_or_a_positive_upper_bound_is_undecided_not_false() -> None:
    pos = _pos(4)
    for hi in (0.0, 0.5):
        atoms = {"p": _truth([-1.0, -1.0, -1.0, -1.0], [hi, hi, hi, hi])}
        values = evaluate_at_points(parse("p"), pos, atoms)
        e = explain(parse("p"), 0, pos, values)
        assert e.reason.startswith("unknown here"), (hi, e)


def test_a_false_conjunction_names_its_earliest_false_conjunct_not_an_undecided_one() -> None:
    pos = _pos(4)
    f = parse("p & G[0,3] q")
    for hi in (0.0, 0.5):  # p undecided at 0 (its upper bound is not below zero); q false at 2 s
        atoms = {"p": _truth([-1.0] * 4, [hi] * 4), "q": _truth([1.0, 1.0, -1.0, 1.0], [1.0, 1.0, -1.0, 1.0])}
        values = evaluate_at_points(f, pos, atoms)
        e = explain(f, 0, pos, values)
        assert (e.subformula, e.time_ns) == ("q", 2 * S), (hi, e)


def test_an_undecided_disjunction_names_its_undecided_argument() -> None:
    pos = _pos(4)
    f = parse("p | q")
    atoms = {"p": _truth([0.0] * 4, [1.0] * 4), "q": _truth([-1.0] * 4, [-1.0] * 4)}  # p: lower bound exactly 0
    values = evaluate_at_points(f, pos, atoms)
    e = explain(f, 0, pos, values)
    assert e.subformula == "p" and e.reason.startswith("unknown here"), e


def test_an_undecided_conjunction_names_its_undecided_argument_not_a_true_one() -> None:
    pos = _pos(4)
    f = parse("p & q")
    atoms = {"p": _truth([0.5] * 4, [1.0] * 4), "q": _truth([-1.0] * 4, [1.0] * 4)}  # p true (0.5), q unknown
    values = evaluate_at_points(f, pos, atoms)
    e = explain(f, 0, pos, values)
    assert e.subformula == "q" and e.reason.startswith("unknown here"), e


def test_a_false_disjunction_is_named_itself_every_alternative_being_false() -> None:
    pos = _pos(4)
    f = parse("p | G[0,3] q")
    atoms = {"p": _truth([-1.0] * 4, [-1.0] * 4), "q": _truth([1.0, -1.0, 1.0, 1.0], [1.0, -1.0, 1.0, 1.0])}
    e = explain(f, 0, pos, evaluate_at_points(f, pos, atoms))
    assert (e.subformula, e.time_ns, e.reason, e.node, e.index) == ("p | G[0,3] q", 0, "every alternative is false",
                                                                    f, 0)


def test_a_false_conjunction_names_the_conjunct_violated_first_not_the_first_written() -> None:
    pos = _pos(4)
    f = parse("G[0,3] p & G[0,3] q")  # p false at 2 s, q false at 1 s
    atoms = {"p": _truth([1.0, 1.0, -1.0, 1.0], [1.0, 1.0, -1.0, 1.0]),
             "q": _truth([1.0, -1.0, 1.0, 1.0], [1.0, -1.0, 1.0, 1.0])}
    e = explain(f, 0, pos, evaluate_at_points(f, pos, atoms))
    assert (e.subformula, e.time_ns) == ("q", 1 * S), e


def test_an_undecided_implication_names_its_undecided_premise() -> None:
    pos = _pos(4)
    atoms = {"p": _truth([-1.0] * 4, [1.0] * 4), "q": _truth([-1.0] * 4, [-1.0] * 4)}  # p unknown, q false
    for text in ("p -> q", "(p -> q) & G[0,3] !p"):  # whether or not !p is a sub-formula elsewhere
        f = parse(text)
        e = explain(f, 0, pos, evaluate_at_points(f, pos, atoms))
        assert (e.subformula, e.time_ns, e.index) == ("p", 0, 0), (text, e)
        assert e.reason.startswith("unknown here"), (text, e)
    f = parse("p -> q")  # p true, q unknown: the conclusion is named
    atoms = {"p": _truth([1.0] * 4, [1.0] * 4), "q": _truth([-1.0] * 4, [1.0] * 4)}
    e = explain(f, 0, pos, evaluate_at_points(f, pos, atoms))
    assert (e.subformula, e.reason) == ("q", "unknown here (missing or ambiguous data)"), e


def test_a_negation_says_whether_its_argument_holds_or_is_undecided() -> None:
    pos = _pos(4)
    f = parse("!p")
    e = explain(f, 0, pos, evaluate_at_points(f, pos, {"p": TRUE4}))
    assert (e.subformula, e.time_ns, e.reason, e.node, e.index) == ("!p", 0, "its negation holds", f, 0)
    e = explain(f, 0, pos, evaluate_at_points(f, pos, {"p": _truth([-1.0] * 4, [1.0] * 4)}))
    assert (e.subformula, e.reason) == ("!p", "its argument is undecided")
    # an undecided negation of a temporal formula is explained by its argument's undecided instant
    f = parse("!G[0,3] p")
    e = explain(f, 0, pos, evaluate_at_points(f, pos, {"p": _truth([1.0, 1.0, -1.0, 1.0], [1.0, 1.0, 1.0, 1.0])}))
    assert (e.subformula, e.time_ns) == ("p", 2 * S), e
    # a false negation of a temporal formula is not descended into
    e = explain(f, 0, pos, evaluate_at_points(f, pos, {"p": TRUE4}))
    assert (e.subformula, e.reason) == ("!G[0,3] p", "its negation holds")


def test_a_nested_window_is_searched_from_the_position_it_is_explained_at() -> None:
    pos = _pos(4)
    f = parse("G[0,3] F[0,1] p")  # F[0,1] p: true at 0, undecided at 1 (p false at 1, undecided at 2)
    p = _truth([1.0, -1.0, -1.0, -1.0], [1.0, -1.0, 1.0, -1.0])
    e = explain(f, 0, pos, evaluate_at_points(f, pos, {"p": p}))
    assert (e.subformula, e.time_ns) == ("p", 2 * S), e


def test_an_undecided_always_names_its_first_instant_that_is_not_true() -> None:
    pos = _pos(4)
    f = parse("G[0,3] p")  # 0.5 is true; a lower bound of exactly 0 is not
    e = explain(f, 0, pos, evaluate_at_points(f, pos, {"p": _truth([0.5, 0.5, 0.0, 1.0], [1.0] * 4)}))
    assert (e.subformula, e.time_ns) == ("p", 2 * S), e




def test_a_false_always_at_a_gap_names_a_violation_within_its_window_for_every_instant_of_the_gap() -> None:
    # samples 0, 1, 2, 4, 5.5 s; p false everywhere but undecided at the sample at 2 s. The inner G is explained at
    # the gap (1, 2) s: only positions inside [t + 1.5, t + 3.25] for every instant t of that gap count
    pos = _with_gaps([0, S, 2 * S, 4 * S, 11 * S // 2])
    f = parse("G[0.5,5] G[1.5,3.25] p")
    hi = [-1.0] * 9
    hi[4] = 1.0
    e = explain(f, 0, pos, evaluate_at_points(f, pos, {"p": _truth([-1.0] * 9, hi)}))
    assert (e.subformula, e.time_ns, e.index) == ("p", 2 * S + 1, 5), e


def test_an_undecided_always_at_a_gap_searches_every_position_its_window_can_reach() -> None:
    # samples 0, 1, 4, 5 s; p false over the gap (1, 4) s, which the window of the gap (0, 1) s partly covers
    pos = _with_gaps([0, S, 4 * S, 5 * S])
    f = parse("F[0,5] G[1,2] p")
    p = _truth([-1.0] * 6 + [1.0], [-1.0, 1.0, 1.0, -1.0, 1.0, 1.0, 1.0])
    e = explain(f, 0, pos, evaluate_at_points(f, pos, {"p": p}))
    assert (e.subformula, e.time_ns, e.reason) == ("p", S + 1, "false here"), e


@pytest.mark.parametrize(("text", "p", "q", "want"), [
    ("F[0,2] p", [-1.0] * 4, [-1.0] * 4, ("F[0,2] p", 2 * S, "never satisfied within its window")),
    ("F[0,10] p", [-1.0] * 4, [-1.0] * 4, ("F[0,10] p", 3 * S, "the window reaches past the end of the log")),
    ("G[0,10] p", [1.0] * 4, [-1.0] * 4, ("G[0,10] p", 3 * S, "the window reaches past the end of the log")),
    ("p U[0,2] q", [1.0] * 4, [-1.0] * 4, ("p U[0,2] q", 0, "violated")),
    ("p U[0,10] q", [1.0] * 4, [-1.0] * 4, ("p U[0,10] q", 3 * S, "undecided at the end of the log")),
    ("q", [1.0] * 4, [-1.0] * 4, ("q", 0, "false here")),
])
def test_each_leaf_of_the_walk_names_itself_its_time_and_its_reason(text: str, p: list[float], q: list[float],
                                                                     want: tuple[str, int, str]) -> None:
    pos = _pos(4)
    f = parse(text)
    e = explain(f, 0, pos, evaluate_at_points(f, pos, {"p": _truth(p, p), "q": _truth(q, q)}))
    assert (e.subformula, e.time_ns, e.reason, e.node, e.index) == (*want, f, 0), e


def test_an_undecided_eventually_names_its_first_instant_that_is_not_false() -> None:
    pos = _pos(4)
    f = parse("F[0,10] p")  # p false, but its upper bound is exactly 0 (undecided) at 1 s and 0.5 at 2 s
    e = explain(f, 0, pos, evaluate_at_points(f, pos, {"p": _truth([-1.0] * 4, [-1.0, 0.0, 0.5, -1.0])}))
    assert (e.subformula, e.time_ns, e.node, e.index) == ("p", 1 * S, parse("p"), 1), e


# ---- U: exact-zero values are undecided (``_until``'s counting rule) -------------------------------------------------
def _until_at_0(p: Truth, q: Truth, text: str = "p U[0,3] q") -> Truth:
    f = parse(text)
    return evaluate_at_points(f, _pos(4), {"p": p, "q": q})[f]


def test_until_is_not_true_on_a_witness_whose_value_is_exactly_zero() -> None:
    v = _until_at_0(TRUE4, _truth([0.0] * 4, [1.0] * 4))  # q undecided (lower bound exactly 0) everywhere
    assert v.lo[0] <= 0 < v.hi[0], (v.lo[0], v.hi[0])


def test_until_is_not_true_when_its_left_side_is_exactly_zero_before_the_witness() -> None:
    v = _until_at_0(_truth([0.0] * 4, [1.0] * 4), _truth([-1.0, -1.0, 1.0, 1.0], [-1.0, -1.0, 1.0, 1.0]))
    assert v.lo[0] <= 0, v.lo[0]


def test_until_is_not_false_when_its_left_side_is_only_undecided_and_the_window_runs_past_the_end() -> None:
    for hi in (0.0, 0.5):  # p undecided at 1 s (not false); q false everywhere; the window ends after the log
        v = _until_at_0(_truth([1.0, -1.0, 1.0, 1.0], [1.0, hi, 1.0, 1.0]), _truth([-1.0] * 4, [-1.0] * 4),
                        "p U[0,10] q")
        assert v.hi[0] >= 0, (hi, v.hi[0])


def test_until_is_not_false_when_a_witness_is_only_undecided() -> None:
    for hi in (0.0, 0.5):  # p true throughout; q false except at 1 s, where its upper bound is hi (undecided)
        v = _until_at_0(TRUE4, _truth([-1.0] * 4, [-1.0, hi, -1.0, -1.0]))
        assert (v.lo[0], v.hi[0]) == (-1.0, hi)


def test_until_counts_an_undecided_witness_at_the_position_where_its_left_side_first_fails() -> None:
    # p false at 1 s (it blocks every later witness); q undecided exactly there: p U q is undecided, not false
    v = _until_at_0(_truth([1.0, -1.0, 1.0, 1.0], [1.0, -1.0, 1.0, 1.0]), _truth([-1.0] * 4, [-1.0, 0.5, -1.0, -1.0]))
    assert v.lo[0] < 0 <= v.hi[0], (v.lo[0], v.hi[0])


def test_until_robustness_is_computed_up_to_the_limit_inclusive(monkeypatch: pytest.MonkeyPatch) -> None:
    p, q = TRUE4, _truth([-1.0, -1.0, 0.5, -1.0], [-1.0, -1.0, 0.5, -1.0])
    monkeypatch.setattr(engine, "UNTIL_ROBUSTNESS_LIMIT", 4)  # exactly the number of positions
    v = _until_at_0(p, q)
    assert (v.lo[0], v.hi[0]) == (0.5, 0.5)
    monkeypatch.setattr(engine, "UNTIL_ROBUSTNESS_LIMIT", 3)  # above it only the verdict: +-inf
    v = _until_at_0(p, q)
    assert (v.lo[0], v.hi[0]) == (np.inf, np.inf)
    v = _until_at_0(p, _truth([-1.0] * 4, [-1.0] * 4))  # false
    assert (v.lo[0], v.hi[0]) == (-np.inf, -np.inf)
    v = _until_at_0(p, _truth([-1.0] * 4, [-1.0, 0.5, -1.0, -1.0]))  # undecided
    assert (v.lo[0], v.hi[0]) == (-np.inf, np.inf)


def test_until_states_the_loops_robustness_when_true_or_false() -> None:
    # true: the witness's 0.5 (not raised to any floor); false: q's -0.5 (not lowered to any ceiling)
    v = _until_at_0(TRUE4, _truth([-1.0, -1.0, 0.5, -1.0], [-1.0, -1.0, 0.5, -1.0]))
    assert (v.lo[0], v.hi[0]) == (0.5, 0.5)
    v = _until_at_0(TRUE4, _truth([-1.0, -0.5, -1.0, -1.0], [-0.7, -0.5, -0.6, -0.8]))
    assert (v.lo[0], v.hi[0]) == (-0.5, -0.5)


def test_until_robustness_over_windows_outside_the_samples_and_past_the_end() -> None:
    p, q = TRUE4, _truth([-1.0] * 4, [-1.0] * 4)
    # the window lies after the last sample but before the end of observation (10 s): nothing can satisfy it
    f = parse("p U[5,6] q")
    t = np.arange(4, dtype=np.int64) * S
    v = evaluate_at_points(f, Positions(t, t.copy(), np.ones(4, dtype=bool), 10 * S), {"p": p, "q": q})[f]
    assert (v.lo[0], v.hi[0]) == (-np.inf, -np.inf)
    assert v.lo.dtype == v.hi.dtype == np.float64
    # the window reaches past the end: no witness yet (-inf), and at best p's least value so far (1.0)
    v = _until_at_0(p, q, "p U[10,20] q")
    assert (v.lo[0], v.hi[0]) == (-np.inf, 1.0)
    v = _until_at_0(_truth([1.0, 0.5, 0.7, 1.0], [1.0, 0.5, 0.7, 1.0]), q, "p U[0,10] q")
    assert (v.lo[0], v.hi[0]) == (-1.0, 0.5)


def test_until_is_only_proved_by_witnesses_at_samples_but_a_gap_can_keep_it_open() -> None:
    # sample 0 s, gap (0, 1) s, sample 1 s: q's bound is 0.5 only over the gap (its value at some instant there)
    start = np.array([0, 1, S], dtype=np.int64)
    stop = np.array([0, S - 1, S], dtype=np.int64)
    pos = Positions(start, stop, np.array([True, False, True]), S)
    f = parse("p U[0,1] q")
    q = _truth([-1.0, 0.5, -1.0], [-1.0, 0.5, -1.0])
    v = evaluate_at_points(f, pos, {"p": _truth([1.0] * 3, [1.0] * 3), "q": q})
    assert (v[f].lo[0], v[f].hi[0]) == (-1.0, 0.5)
