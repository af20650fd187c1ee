"""The MITL monitor: pointwise semantics against a brute-force oracle, finite-log rules, trajectory conservatism."""

from __future__ import annotations

from fractions import Fraction

import numpy as np
import pytest
from hypothesis import example, given
from hypothesis import strategies as st

from tubempc.mitl import (
    TRUE,
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
)
from tubempc.scenario import builtin_scenario
from verify import SpecError, check_timed_run
from verify.monitor.engine import range_reduce, sliding_reduce
from verify.semantics.trajectory import check_trajectory

LABELS = {"A": ["p"], "B": ["q"], "C": ["p", "r"], "D": []}
_ORD = {"F": 0, "U": 1, "T": 2}
_INV = {0: "F", 1: "U", 2: "T"}


def oracle(f: Formula, run: list[tuple[str, float]], i: int, end: Fraction) -> str:
    """Brute-force 3-valued pointwise semantics, written from the definitions (exact rational times)."""
    t = [Fraction(x) for _, x in run]
    n = len(run)
    if isinstance(f, Atom):
        return "T" if f.name in LABELS.get(run[i][0], ()) else "F"
    if isinstance(f, Const):
        return "T" if f.value else "F"
    if isinstance(f, Not):
        return _INV[2 - _ORD[oracle(f.arg, run, i, end)]]
    if isinstance(f, And):
        return _INV[min(_ORD[oracle(a, run, i, end)] for a in f.args)]
    if isinstance(f, Or):
        return _INV[max(_ORD[oracle(a, run, i, end)] for a in f.args)]
    if isinstance(f, Implies):
        return oracle(Or((Not(f.left), f.right)), run, i, end)
    iv = f.interval
    incomplete = iv.hi is not None and t[i] + iv.hi > end
    if isinstance(f, Next):
        if i + 1 < n:
            return oracle(f.arg, run, i + 1, end) if iv.contains(t[i + 1] - t[i]) else "F"
        return "U" if incomplete else "F"
    if isinstance(f, Eventually):
        return oracle(Until(iv, TRUE, f.arg), run, i, end)
    if isinstance(f, Always):
        return _INV[2 - _ORD[oracle(Until(iv, TRUE, Not(f.arg)), run, i, end)]]
    best, prefix = 0, 2
    for j in range(i, n):
        if iv.contains(t[j] - t[i]):
            best = max(best, min(_ORD[oracle(f.right, run, j, end)], prefix))
        prefix = min(prefix, _ORD[oracle(f.left, run, j, end)])
    if incomplete:  # positions after the end could still satisfy the right side
        best = max(best, min(prefix, 1))
    return _INV[best]


@st.composite
def intervals(draw: st.DrawFn) -> Interval:
    lo = Fraction(draw(st.integers(0, 3)))
    if draw(st.booleans()) and draw(st.booleans()):
        return Interval(lo, None, draw(st.booleans()), False)
    hi = lo + Fraction(draw(st.integers(0, 3)))
    if hi == lo:
        return Interval(lo, hi, True, True)
    return Interval(lo, hi, draw(st.booleans()), draw(st.booleans()))


def formulas(depth: int = 3) -> st.SearchStrategy[Formula]:
    atom = st.sampled_from([Atom("p"), Atom("q"), Atom("r")])
    return st.recursive(
        atom,
        lambda sub: st.one_of(
            sub.map(Not),
            st.tuples(sub, sub).map(And),
            st.tuples(sub, sub).map(Or),
            st.tuples(sub, sub).map(lambda ab: Implies(*ab)),
            st.tuples(intervals(), sub).map(lambda a: Eventually(*a)),
            st.tuples(intervals(), sub).map(lambda a: Always(*a)),
            st.tuples(intervals(), sub).map(lambda a: Next(*a)),
            st.tuples(intervals(), sub, sub).map(lambda a: Until(*a)),
        ),
        max_leaves=depth + 2,
    )


runs = st.lists(st.tuples(st.sampled_from("ABCD"), st.integers(0, 12)), min_size=1, max_size=7).map(
    lambda r: [(reg, float(t)) for reg, t in sorted(r, key=lambda e: e[1])])


@given(formulas(), runs, st.integers(0, 3))
@example(parse("F[30,50] p"), [("A", 0.0), ("B", 29.0)], 0)  # window past the end: undecided
@example(parse("p U[0,2] q"), [("A", 0.0), ("A", 0.0), ("B", 2.0)], 0)  # equal timestamps are distinct positions
@example(parse("X(0,1] p"), [("A", 0.0), ("A", 1.0)], 0)
def test_timed_run_matches_brute_force_oracle(f: Formula, run: list[tuple[str, float]], extra: int) -> None:
    end = run[-1][1] + extra
    expected = {"T": "pass", "F": "fail", "U": "inconclusive"}[oracle(f, run, 0, Fraction(end))]
    assert check_timed_run(str(f), run, LABELS, end=end).verdict == expected


def test_finite_log_rules() -> None:
    run = [("A", 0.0), ("B", 10.0)]
    # unbounded: ranges to the end of the log, so an unmet F fails and G holds "throughout the log"
    assert check_timed_run("F[0,inf) r", run, LABELS).verdict == "fail"
    assert check_timed_run("G[0,inf) (p | q)", run, LABELS).verdict == "pass"
    # bounded window reaching past the end, undecided -> inconclusive; decided -> decided
    assert check_timed_run("F[5,20] r", run, LABELS).verdict == "inconclusive"
    assert check_timed_run("F[5,20] q", run, LABELS).verdict == "pass"
    assert check_timed_run("G[0,20] p", run, LABELS).verdict == "fail"
    # the window [10, 10] ends exactly at the end of observation: complete
    assert check_timed_run("F[10,10] r", run, LABELS).verdict == "fail"
    # observation continued to t=30 without a new position: the window is complete
    assert check_timed_run("F[15,20] r", run, LABELS, end=30.0).verdict == "fail"


def test_witness_names_subformula_and_time() -> None:
    res = check_timed_run("G[0,inf) !q & F[0,inf) p", [("A", 0.0), ("B", 4.5)], LABELS)
    assert res.verdict == "fail"
    assert res.subformula == "!q"
    assert res.time_s == pytest.approx(4.5)


def test_bad_formula_is_unusable_input() -> None:
    with pytest.raises(SpecError, match="column"):
        check_timed_run("F[0,1] (", [("A", 0.0)], LABELS)


def test_range_reduce_matches_naive() -> None:
    rng = np.random.default_rng(7)
    x = rng.normal(size=500)
    j0 = np.sort(rng.integers(0, 500, size=400))
    j1 = np.minimum(j0 + rng.integers(0, 60, size=400), 500)
    got = range_reduce(x, j0, j1, np.maximum, -np.inf)
    want = np.array([x[a:b].max() if b > a else -np.inf for a, b in zip(j0, j1, strict=True)])
    assert np.array_equal(got, want)
    assert np.array_equal(sliding_reduce(x, 7, np.minimum, np.inf),
                          np.array([x[i : i + 7].min() for i in range(494)]))


def _straight(x0: float, x1: float, y: float, dt_s: float, v: float) -> tuple[np.ndarray, ...]:
    n = round(abs(x1 - x0) / (v * dt_s)) + 1
    t_ns = (np.arange(n) * dt_s * 1e9).round().astype(np.int64)
    return t_ns, np.linspace(x0, x1, n), np.full(n, y)


def test_obstacle_crossed_between_samples_is_never_pass() -> None:
    """Two samples on either side of an obstacle, too far apart to exclude contact: not pass (peers say pass)."""
    sc = builtin_scenario()
    r8 = sc.region("R8")  # obs_3 at (0.16, -1.41), radius 0.45
    eta = sc.robot.radius
    clear = r8.radius + eta + 0.05
    t_ns = np.array([0, 10 * 10**9], dtype=np.int64)
    x = np.array([r8.center[0] - clear, r8.center[0] + clear])
    y = np.full(2, r8.center[1])
    res = check_trajectory(parse("G[0,inf) !obs_3"), t_ns, x, y, sc, max_speed_mps=sc.max_speed_mps)
    assert res.verdict == "inconclusive"
    # dense samples of the same crossing: a sample lies inside the obstacle -> fail, with its time as evidence
    t2, x2, y2 = _straight(x[0], x[1], r8.center[1], 0.01, 0.2)
    res2 = check_trajectory(parse("G[0,inf) !obs_3"), t2, x2, y2, sc, max_speed_mps=sc.max_speed_mps)
    assert res2.verdict == "fail"
    assert res2.subformula == "!obs_3"
    first_inside = int(np.argmax(np.hypot(x2 - r8.center[0], y2 - r8.center[1]) < r8.radius + eta))
    assert res2.time_ns == t2[first_inside]


def test_dense_safe_trajectory_passes_with_metric_margin() -> None:
    sc = builtin_scenario()
    r1 = sc.region("R1")
    t_ns, x, y = _straight(r1.center[0] - 0.05, r1.center[0] + 0.05, r1.center[1], 0.01, 0.1)
    res = check_trajectory(parse("G[0,inf) mission_1"), t_ns, x, y, sc, max_speed_mps=sc.max_speed_mps)
    assert res.verdict == "pass"
    # margin: r - eta - max offset (0.05), minus half the speed-bound path per 10 ms gap (<= 0.0015 m)
    assert 0.45 - 0.27 - 0.05 - 0.0015 <= res.margin_m <= 0.45 - 0.27 - 0.05 + 1e-12


def test_nan_sample_makes_safety_inconclusive_not_pass() -> None:
    sc = builtin_scenario()
    r1 = sc.region("R1")
    t_ns, x, y = _straight(r1.center[0] - 0.05, r1.center[0] + 0.05, r1.center[1], 0.01, 0.1)
    x = x.copy()
    x[5] = np.nan
    res = check_trajectory(parse("G[0,inf) mission_1"), t_ns, x, y, sc, max_speed_mps=sc.max_speed_mps)
    assert res.verdict == "inconclusive"


# ---- the engine's small rules, stated exactly (mutants of each survived the suite: docs/property-testing.md) -------
def test_a_margin_of_exactly_zero_is_undecided() -> None:
    from verify.monitor.engine import verdict_of

    assert verdict_of(0.0, 1.0) == "inconclusive" and verdict_of(-1.0, 0.0) == "inconclusive"
    assert verdict_of(1e-300, 1.0) == "pass" and verdict_of(-1.0, -1e-300) == "fail"
    assert verdict_of(0.0, 0.0) == "inconclusive"


def test_boolean_atoms_are_plus_or_minus_one_and_unknown_is_both() -> None:
    from verify.monitor.engine import truth_from_bool

    t = truth_from_bool(np.array([True, False, True]), known=np.array([True, True, False]))
    assert t.lo.tolist() == [1.0, -1.0, -1.0] and t.hi.tolist() == [1.0, -1.0, 1.0]
    plain = truth_from_bool(np.array([True, False]))
    assert plain.lo.tolist() == plain.hi.tolist() == [1.0, -1.0]


def test_interval_bounds_round_inwards_to_whole_nanoseconds() -> None:
    from tubempc.mitl import Interval
    from verify.monitor.engine import bounds_ns

    assert bounds_ns(Interval(1, 2, True, True)) == (1_000_000_000, 2_000_000_000)
    assert bounds_ns(Interval(1, 2, False, False)) == (1_000_000_001, 1_999_999_999)
    ns = Fraction(1, 10**9)
    assert bounds_ns(Interval(ns, 3 * ns, True, True)) == (1, 3)  # whole nanoseconds: as written
    assert bounds_ns(Interval(ns, 3 * ns, False, False)) == (2, 2)  # open ends: one nanosecond inside
    assert bounds_ns(Interval(Fraction(3, 2) * ns, Fraction(5, 2) * ns, True, True)) == (2, 2)  # rounded inwards
    assert bounds_ns(Interval(Fraction(3, 2) * ns, Fraction(5, 2) * ns, False, False)) == (2, 2)
    assert bounds_ns(Interval(Fraction(3, 2) * ns, None, False, False)) == (2, None)


def test_an_incomplete_inner_window_is_unknown_not_nan() -> None:
    """``G F``: an inner ``F`` that already failed decides the ``G``, whatever the inner windows still open at the
    end (their upper bound is +inf, which ``min`` skips; a NaN there would hide the failure)."""
    run = [("A", 0.0), ("B", 5.0)]
    labels: dict[str, list[str]] = {"A": [], "B": []}
    assert check_timed_run("G[0,inf) F[0,2] p", run, labels, end=6.0).verdict == "fail"
    assert check_timed_run("G[0,inf) F[0,2] p", [("A", 0.0), ("B", 1.0)], {"A": [], "B": ["p"]},
                           end=1.5).verdict == "pass"


def test_next_includes_its_closed_lower_bound() -> None:
    assert check_timed_run("X[1,2] p", [("A", 0.0), ("B", 1.0)], {"A": [], "B": ["p"]}, end=2.0).verdict == "pass"
    assert check_timed_run("X[0,1] p", [("A", 0.0), ("B", 0.0)], {"A": [], "B": ["p"]}, end=1.0).verdict == "pass"
    assert check_timed_run("X(1,2] p", [("A", 0.0), ("B", 1.0)], {"A": [], "B": ["p"]}, end=2.0).verdict == "fail"


def test_next_unbounded_and_known_false_and_pending() -> None:
    labels: dict[str, list[str]] = {"A": [], "B": ["p"], "C": []}
    assert check_timed_run("X p", [("A", 0.0), ("B", 1.0)], labels).verdict == "pass"  # X = X[0,inf)
    assert check_timed_run("X[0,2] p", [("A", 0.0), ("C", 1.0)], labels, end=2.0).verdict == "fail"
    # a pending X at the last entry is unknown (upper bound +inf): the violation at the first entry still shows
    assert check_timed_run("G[0,inf) X[0,5] p", [("A", 0.0), ("C", 0.5)], labels, end=1.0).verdict == "fail"
