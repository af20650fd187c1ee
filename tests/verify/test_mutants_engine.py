"""The MITL engine's building blocks (``verify.monitor.engine``) and the formula's judgement per obligation
(``verify.judging.judge_formula`` and its sentences), stated exactly on small hand-made inputs: each test pins a rule
that a mutant of the code broke without any other test of the kill suite noticing (docs/property-testing.md,
"Mutation testing of the judging core")."""

from __future__ import annotations

import math
from fractions import Fraction

import numpy as np
import pytest

from tubempc.mitl import Eventually, Interval, parse
from verify.monitor import engine
from verify.monitor.engine import Positions, Truth, evaluate, evaluate_at_points, range_reduce
from verify.semantics.timed_run import check_timed_run

S = 1_000_000_000
NS = Fraction(1, S)


def _truth(lo: list[float], hi: list[float] | None = None) -> Truth:
    return Truth(np.array(lo, dtype=np.float64), np.array(lo if hi is None else hi, dtype=np.float64))


def _points(n: int) -> Positions:
    """``n`` sample points 1 s apart (no gaps), observed to the last one."""
    t = np.arange(n, dtype=np.int64) * S
    return Positions(t, t.copy(), np.ones(n, dtype=bool), int(t[-1]) if n else 0)


def _interleaved(t_ns: list[int]) -> Positions:
    """Sample points at ``t_ns`` with the open gap between each two as a position of its own."""
    start, stop, point = [], [], []
    for k, t in enumerate(t_ns):
        if k:
            start.append(t_ns[k - 1] + 1)
            stop.append(t - 1)
            point.append(False)
        start.append(t)
        stop.append(t)
        point.append(True)
    return Positions(np.array(start, dtype=np.int64), np.array(stop, dtype=np.int64), np.array(point), t_ns[-1])


def _verdicts(t: Truth) -> list[str]:
    return [engine.verdict_of(float(a), float(b)) for a, b in zip(t.lo, t.hi, strict=True)]


# ---- Positions.points ----------------------------------------------------------------------------------------------
def test_points_are_whole_nanoseconds_observed_to_the_last_one_by_default() -> None:
    pos = Positions.points(np.array([0.0, 2.0 * S, 5.0 * S]))  # float input: stored as int64 nanoseconds
    assert pos.start_ns.dtype == np.int64 and pos.stop_ns.dtype == np.int64
    assert pos.end_ns == 5 * S  # the last point, not the first, second or the one before last
    assert Positions.points(np.array([0, 1, 7], dtype=np.int64), 9).end_ns == 9
    empty = Positions.points(np.zeros(0, dtype=np.int64))
    assert empty.size == 0 and empty.end_ns == 0 and isinstance(empty.end_ns, int)


# ---- range_reduce ---------------------------------------------------------------------------------------------------
def test_range_reduce_over_a_single_value() -> None:
    x = np.array([2.5])
    got = range_reduce(x, np.array([0, 0, 1]), np.array([1, 0, 1]), np.maximum, -math.inf)
    assert got.tolist() == [2.5, -math.inf, -math.inf]
    # the same rule through the monitor: a one-entry run decides F and G from its only entry
    assert check_timed_run("F[0,1] p", [("A", 0.0)], {"A": ["p"]}, end=1.0).verdict == "pass"
    assert check_timed_run("G[0,1] p", [("A", 0.0)], {"A": []}, end=1.0).verdict == "fail"


# ---- _first_at_or_after (Until's "a holds up to" and "a fails first at") -----------------------------------------
def test_first_at_or_after_looks_forward_from_each_position() -> None:
    cond = np.array([False, False, True, False, True, False])
    assert engine._first_at_or_after(cond).tolist() == [2, 2, 2, 4, 4, 6]
    assert engine._first_at_or_after(np.zeros(0, dtype=bool)).tolist() == []


def test_until_needs_its_left_side_up_to_the_witness_at_every_position() -> None:
    pos = _points(4)
    # p at 0 s and 1 s, q at 2 s and 3 s, p false at 2 s and 3 s
    atoms = {"p": _truth([1.0, 1.0, -1.0, -1.0]), "q": _truth([-1.0, -1.0, 1.0, 1.0])}
    assert _verdicts(evaluate(parse("p U[0,2] q"), pos, atoms)[parse("p U[0,2] q")]) == ["pass"] * 4
    # p at 0 s only: from 0 s, q at 2 s comes after p fails at 1 s
    atoms = {"p": _truth([1.0, -1.0, -1.0, -1.0]), "q": _truth([-1.0, -1.0, 1.0, -1.0])}
    assert _verdicts(evaluate(parse("p U[0,2] q"), pos, atoms)[parse("p U[0,2] q")]) == [
        "fail", "fail", "pass", "fail"]
    # q at 0 s, p false there and at 2 s: from 1 s, p holds at 1 s and q comes at 2 s
    atoms = {"p": _truth([-1.0, 1.0, -1.0, -1.0]), "q": _truth([1.0, -1.0, 1.0, -1.0])}
    assert _verdicts(evaluate(parse("p U[0,1] q"), pos, atoms)[parse("p U[0,1] q")]) == [
        "pass", "pass", "pass", "fail"]


# ---- _eval ----------------------------------------------------------------------------------------------------------
def test_constants_are_infinitely_true_or_false() -> None:
    pos = _points(2)
    values = evaluate(parse("true & !false"), pos, {})
    assert values[parse("true")].lo.tolist() == values[parse("true")].hi.tolist() == [math.inf, math.inf]
    assert values[parse("false")].lo.tolist() == values[parse("false")].hi.tolist() == [-math.inf, -math.inf]
    run = [("A", 0.0), ("A", 1.0)]
    assert check_timed_run("true", run, {}).verdict == "pass"
    assert check_timed_run("false", run, {}).verdict == "fail"
    assert check_timed_run("F[0,1] false", run, {}).verdict == "fail"


def test_an_atom_without_a_valuation_is_named() -> None:
    with pytest.raises(KeyError, match="atom='z' has no valuation"):
        evaluate(parse("p & z"), _points(1), {"p": _truth([1.0])})


def test_evaluate_at_points_leaves_the_nodes_above_a_temporal_operator_undefined_at_gaps() -> None:
    """The formula's temporal operators at the top level are needed at the samples only, and so are the connectives
    above them: not computed (NaN) at the gaps, equal to ``evaluate`` at the samples; what sits below a temporal
    operator is computed everywhere."""
    pos = _interleaved([0, 2 * S, 4 * S])
    t = [1.0, 0.5, -1.0, 0.5, 1.0]
    atoms = {"p": _truth(t), "q": _truth([-x for x in t]), "r": _truth([0.5] * 5, [2.0] * 5)}
    f = parse("!((F[0,1] p | q) & ((G[0,1] q & r) -> (q | F[0,1] (r & p))))")
    part = evaluate_at_points(f, pos, atoms)
    full = evaluate(f, pos, atoms)
    gaps = ~pos.is_point
    above = [f, *map(parse, ("(F[0,1] p | q) & ((G[0,1] q & r) -> (q | F[0,1] (r & p)))", "F[0,1] p | q", "F[0,1] p",
                             "(G[0,1] q & r) -> (q | F[0,1] (r & p))", "G[0,1] q & r", "G[0,1] q",
                             "q | F[0,1] (r & p)", "F[0,1] (r & p)"))]
    for g in above:
        assert np.isnan(part[g].lo[gaps]).all() and np.isnan(part[g].hi[gaps]).all(), g
        assert part[g].lo[pos.is_point].tolist() == full[g].lo[pos.is_point].tolist(), g
        assert part[g].hi[pos.is_point].tolist() == full[g].hi[pos.is_point].tolist(), g
    below = parse("r & p")
    assert part[below].lo.tolist() == full[below].lo.tolist() and not np.isnan(part[below].lo).any()


# ---- _next ----------------------------------------------------------------------------------------------------------
def test_every_operator_on_no_positions_gives_empty_values() -> None:
    pos = Positions(np.zeros(0, dtype=np.int64), np.zeros(0, dtype=np.int64), np.zeros(0, dtype=bool), 0)
    f = parse("X[0,1] p & X p & F[0,1] p & G p & (p U[0,1] p) & !p & (p -> p) & true")
    values = evaluate(f, pos, {"p": _truth([])})
    for g, v in values.items():
        assert v.lo.shape == v.hi.shape == (0,), g


def test_next_at_a_gap_is_unknown_even_without_any_sample() -> None:
    """A position that is a gap has no "next sample" of its own: X is unknown there, whether samples follow or
    not (the positions of one open gap alone)."""
    gap = Positions(np.array([1], dtype=np.int64), np.array([5], dtype=np.int64), np.array([False]), 6)
    v = evaluate(parse("X[0,1] p"), gap, {"p": _truth([1.0])})[parse("X[0,1] p")]
    assert (v.lo.tolist(), v.hi.tolist()) == ([-math.inf], [math.inf])
    pos = _interleaved([0, 2 * S])
    v = evaluate(parse("X p"), pos, {"p": _truth([1.0, 1.0, 1.0])})[parse("X p")]
    assert _verdicts(v) == ["pass", "inconclusive", "fail"]


# ---- _windows -------------------------------------------------------------------------------------------------------
def test_an_unbounded_window_at_a_gap_counts_as_certain_only_what_every_instant_reaches() -> None:
    """Samples at 0, 10 and 20 s; p holds at the sample at 10 s only (false at the others and in the gaps). From an
    instant t of the gap (0, 10) s, F[5,inf) p looks at [t + 5, inf): it holds for t <= 5 s and not after, so at the
    gap it is undecided, and G[0,9] F[5,inf) p (whose window covers the whole gap) is not a pass."""
    pos = _interleaved([0, 10 * S, 20 * S])
    atoms = {"p": _truth([-1.0, -1.0, 1.0, -1.0, -1.0])}
    ev = parse("F[5,inf) p")
    values = evaluate(parse("G[0,9] F[5,inf) p"), pos, atoms)
    assert _verdicts(values[ev]) == ["pass", "inconclusive", "fail", "fail", "fail"]
    assert _verdicts(values[parse("G[0,9] F[5,inf) p")])[0] == "inconclusive"


def test_a_gap_exactly_as_long_as_the_window_has_one_instant_every_window_holds() -> None:
    """Samples at 0 and 4 ns, the gap [1, 3] ns between them, F[0,2ns] p: from every instant t of the gap the
    window [t, t + 2] ns contains 3 ns (the gap's own last instant), where p holds."""
    pos = _interleaved([0, 4])
    f = Eventually(Interval(Fraction(0), 2 * NS, True, True), parse("p"))
    v = evaluate(f, pos, {"p": _truth([-1.0, 1.0, -1.0])})[f]
    assert _verdicts(v) == ["pass", "pass", "inconclusive"]  # 4 ns: its window runs past the end
    assert v.lo[1] == 1.0
