"""The regular-grid fast path of the trajectory monitor gives the same values as the general interleaved engine."""

from __future__ import annotations

from fractions import Fraction

import numpy as np
import pytest
from hypothesis import example, given
from hypothesis import strategies as st

from tests.verify.positions import engine_on_grid
from tubempc.mitl import Always, And, Atom, Eventually, Formula, Implies, Interval, Next, Not, Or, Until, parse
from tubempc.scenario import builtin_scenario
from verify.geometry import label_margins, step_bound_m, step_bound_regular_m
from verify.monitor.grid import (
    Grid,
    UnsupportedFormulaError,
    evaluate_grid,
    evaluate_root,
    regular_grid,
    sliding_clipped,
)
from verify.semantics.trajectory import check_trajectory

NS = Fraction(1, 10**9)


@st.composite
def ns_intervals(draw: st.DrawFn) -> Interval:
    """Intervals of a few nanoseconds, so that windows on a grid of 2..6 ns cut through samples and gaps."""
    lo = draw(st.integers(0, 8)) * NS
    if draw(st.integers(0, 3)) == 0:
        return Interval(lo, None, draw(st.booleans()), False)
    hi = lo + draw(st.integers(0, 10)) * NS
    if hi == lo:
        return Interval(lo, hi, True, True)
    return Interval(lo, hi, draw(st.booleans()), draw(st.booleans()))


def grid_formulas(with_until: bool = False) -> st.SearchStrategy[Formula]:
    atom = st.sampled_from([Atom("p"), Atom("q"), Atom("none")])

    def extend(sub: st.SearchStrategy[Formula]) -> st.SearchStrategy[Formula]:
        options = [
            sub.map(Not),
            st.tuples(sub, sub).map(And),
            st.tuples(sub, sub).map(Or),
            st.tuples(sub, sub).map(lambda ab: Implies(*ab)),
            st.tuples(ns_intervals(), sub).map(lambda a: Eventually(*a)),
            st.tuples(ns_intervals(), sub).map(lambda a: Always(*a)),
            st.tuples(ns_intervals(), sub).map(lambda a: Next(*a)),
        ]
        if with_until:
            options.append(st.tuples(ns_intervals(), sub, sub).map(lambda a: Until(*a)))
        return st.one_of(options)

    return st.recursive(atom, extend, max_leaves=6)


@st.composite
def grids(draw: st.DrawFn) -> tuple[Grid, dict[str, np.ndarray], np.ndarray]:
    n = draw(st.integers(2, 14))
    grid = Grid(draw(st.integers(0, 5)), draw(st.integers(2, 6)), n)
    # few distinct values: ties and exact zeros are common
    vals = st.sampled_from([-1.0, -0.5, 0.0, 0.25, 0.5, 1.0])
    margins = {name: np.array(draw(st.lists(vals, min_size=n, max_size=n))) for name in ("p", "q")}
    margins["none"] = np.full(n, -np.inf)  # a label no region carries
    step = np.array(draw(st.lists(st.sampled_from([0.0, 0.25, 1.0, 3.0]), min_size=n - 1, max_size=n - 1)))
    return grid, margins, step




@given(grid_formulas(), grids())
@example(And((Eventually(Interval(0, 1 * NS, True, True), Atom("p")),
              Always(Interval(0, 2 * NS, True, True), Eventually(Interval(0, 1 * NS, True, True), Atom("p"))))),
         (Grid(0, 2, 4), {"p": np.array([1.0, 1.0, -1.0, 1.0]), "q": np.zeros(4), "none": np.full(4, -np.inf)},
          np.ones(3)))  # a sub-formula needed at the top and under G (the general engine once mixed the two)
@example(Eventually(Interval(NS, NS, True, True), Atom("p")),
         (Grid(0, 3, 3), {"p": np.array([-1.0, 1.0, -1.0]), "q": np.zeros(3), "none": np.full(3, -np.inf)},
          np.ones(2)))  # window inside one gap
def test_grid_values_equal_general_engine(f: Formula, case: tuple[Grid, dict[str, np.ndarray], np.ndarray]) -> None:
    grid, margins, step = case
    want, point_at, _ = engine_on_grid(f, grid, margins, step)
    res = evaluate_grid(f, grid, margins, step)
    # bit-identical: min/max are exact and the gap bounds are computed by the same operations
    np.testing.assert_array_equal(res.root.p_lo, want[f].lo[point_at])
    np.testing.assert_array_equal(res.root.p_hi, want[f].hi[point_at])
    got = res.values()
    gap_at = point_at[:-1] + 1
    for g, v in got.items():
        np.testing.assert_array_equal(v.p_lo, want[g].lo[point_at], err_msg=str(g))
        np.testing.assert_array_equal(v.p_hi, want[g].hi[point_at], err_msg=str(g))
        if v.g_lo is not None and v.g_hi is not None and not np.isnan(want[g].lo[gap_at]).any():
            np.testing.assert_array_equal(v.g_lo, want[g].lo[gap_at], err_msg=str(g))
            np.testing.assert_array_equal(v.g_hi, want[g].hi[gap_at], err_msg=str(g))


@given(grid_formulas(), grids())
@example(Not(Eventually(Interval(0, 4 * NS, True, True), Atom("p"))),
         (Grid(0, 2, 5), {"p": np.array([1.0, -1.0, 0.5, 1.0, -0.5]), "q": np.zeros(5), "none": np.full(5, -np.inf)},
          np.ones(4)))  # the root's lower bound is the negated upper bound of F (computed at every sample)
def test_root_bounds_equal_grid_values(f: Formula, case: tuple[Grid, dict[str, np.ndarray], np.ndarray]) -> None:
    """``evaluate_root``: the root's lower bound at every sample and upper bound at the first, as the general
    engine gives them (bit-identical: the same operations, only fewer of them)."""
    grid, margins, step = case
    want, point_at, _ = engine_on_grid(f, grid, margins, step)
    got = evaluate_root(f, grid, margins, step)
    np.testing.assert_array_equal(got.lo, want[f].lo[point_at])
    assert got.hi_first == want[f].hi[0]
    np.testing.assert_array_equal(got.lo, evaluate_grid(f, grid, margins, step).root.p_lo)


def test_until_is_left_to_the_general_engine() -> None:
    grid = Grid(0, 2, 3)
    margins = {"p": np.ones(3), "q": np.ones(3)}
    try:
        evaluate_grid(parse("p U[0,1] q"), grid, margins, np.ones(2))
    except UnsupportedFormulaError:
        pass
    else:
        raise AssertionError("until must be refused")
    try:
        evaluate_root(parse("F[0,1] (p U[0,1] q)"), grid, margins, np.ones(2))
    except UnsupportedFormulaError:
        return
    raise AssertionError("until must be refused")


def test_regular_grid_detection() -> None:
    assert regular_grid(np.array([0, 10, 20, 30], dtype=np.int64)) == Grid(0, 10, 4)
    assert regular_grid(np.array([0, 10, 21, 30], dtype=np.int64)) is None  # jitter: general engine
    assert regular_grid(np.array([0, 1, 2], dtype=np.int64)) is None  # no instant between samples
    assert regular_grid(np.array([5], dtype=np.int64)) is None


def test_sliding_clipped_matches_naive() -> None:
    rng = np.random.default_rng(3)
    x = rng.normal(size=301)
    for w in (1, 2, 7, 64, 300, 400):
        want = np.array([x[k : k + w].max() for k in range(x.size)])
        np.testing.assert_array_equal(sliding_clipped(x, w, np.maximum, -np.inf), want)


def test_sliding_wide_windows_van_herk_matches_doubling() -> None:
    """Widths above the doubling limit use van Herk/Gil-Werman: the same values as the doubling and a naive scan."""
    x = np.random.default_rng(5).normal(size=20_000)
    for w in (9000, 19_999, 25_000):
        got = sliding_clipped(x, w, np.minimum, np.inf)
        np.testing.assert_array_equal(got, sliding_clipped(x, w, np.minimum, np.inf, block=4096))
        for k in (0, 1, 10_000, 10_999, 11_001, 19_999):
            assert got[k] == x[k : k + w].min()


@given(st.integers(1, 80), st.integers(1, 90), st.integers(1, 40), st.booleans(), st.integers(0, 10**6))
def test_sliding_doubling_blocks_match_naive(n: int, width: int, block: int, use_min: bool, seed: int) -> None:
    """The blocked doubling with tiny blocks (block edges, overlaps past the end, width > n) and ties, -inf."""
    x = np.random.default_rng(seed).choice(np.array([-np.inf, -1.0, 0.0, 0.5, 2.0]), size=n)
    red, op, ident = (np.min, np.minimum, np.inf) if use_min else (np.max, np.maximum, -np.inf)
    want = np.array([red(x[k : k + width]) for k in range(n)])
    np.testing.assert_array_equal(sliding_clipped(x, width, op, ident, block=block), want)
    np.testing.assert_array_equal(sliding_clipped(x, width, op, ident), want)


def _paper_like(n: int, dt_ns: int) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    sc = builtin_scenario()
    t_ns = np.arange(n, dtype=np.int64) * dt_ns
    r1, r3 = sc.region("R1").center, sc.region("R3").center
    s = np.linspace(0.0, 1.0, n)
    x = r1[0] + (r3[0] - r1[0]) * np.sin(np.pi * s) ** 2
    y = r1[1] + (r3[1] - r1[1]) * np.sin(np.pi * s) ** 2
    return t_ns, x, y


@given(st.sampled_from(["G[0,inf) !(obs_1 | obs_2 | obs_3 | obs_4) & F[1,3] mission_2 & F[4,6] mission_1",
                        "F[0,2] G[0,0.5] mission_1", "G[0,inf) (mission_1 -> F[0,1.5] mission_2)",
                        "mission_1 U[0,5] mission_2", "X[0,1] mission_1", "F[0,10] obs_3"]),
       st.integers(0, 10**6))
def test_check_trajectory_fast_path_matches_jittered_general_path(text: str, seed: int) -> None:
    """Same verdict and margins (to rounding: sqrt vs hypot distances) on a regular grid (fast path) as on the
    same trajectory with one stamp nudged by 1 ns (general engine); every sample stays where it is."""
    sc = builtin_scenario()
    f = parse(text)
    # 37 ms period: no window bound (multiples of 0.5 s) ever lands within 1 ms of a sample time, so nudging one
    # sample by 1 ns changes no window's membership
    t_ns, x, y = _paper_like(300, 37_000_000)
    rng = np.random.default_rng(seed)
    x = x + rng.normal(scale=0.02, size=x.size)
    fast = check_trajectory(f, t_ns, x, y, sc, max_speed_mps=sc.max_speed_mps)
    t_j = t_ns.copy()
    t_j[160] += 1  # irregular: the general engine; two gaps change by 1 ns (bounds move by ~1e-10 m)
    slow = check_trajectory(f, t_j, x, y, sc, max_speed_mps=sc.max_speed_mps)
    if abs(slow.margin_m) > 1e-6 and abs(slow.margin_hi_m) > 1e-6:
        assert fast.verdict == slow.verdict
        assert fast.subformula == slow.subformula
        # a witness at the nudged sample (or a window end computed from it) moves by that 1 ns
        assert (fast.time_ns is None) == (slow.time_ns is None)
        assert fast.time_ns is None or slow.time_ns is None or abs(fast.time_ns - slow.time_ns) <= 1
    # tolerance: distances differ by ulps, a 1 ns longer gap moves its bound by v_max * 1e-9 / 2
    np.testing.assert_allclose(fast.signal_rho_m, slow.signal_rho_m, rtol=0, atol=1e-9)


def test_fast_path_keeps_between_sample_conservatism() -> None:
    """Regularly sampled crossing of an obstacle between samples: inconclusive (fast path), never pass."""
    sc = builtin_scenario()
    r8 = sc.region("R8")
    clear = r8.radius + sc.robot.radius + 0.05
    t_ns = np.array([0, 10 * 10**9, 20 * 10**9], dtype=np.int64)
    x = np.array([r8.center[0] - clear, r8.center[0] + clear, r8.center[0] + 2 * clear])
    y = np.full(3, r8.center[1])
    res = check_trajectory(parse("G[0,inf) !obs_3"), t_ns, x, y, sc, max_speed_mps=sc.max_speed_mps)
    assert res.verdict == "inconclusive"
    assert res.subformula == "!obs_3"


def test_exact_margins_agree_with_fast_margins_to_rounding() -> None:
    sc = builtin_scenario()
    rng = np.random.default_rng(11)
    x = rng.uniform(-2.5, 2.5, 1000)
    y = rng.uniform(-2.5, 2.5, 1000)
    names = frozenset({"obs_1", "obs_2", "obs_3", "obs_4", "mission_1", "mission_2", "nowhere"})
    exact = label_margins(x, y, sc, names)
    fast = label_margins(x, y, sc, names, exact=False)
    for name in names:
        # sqrt(dx*dx + dy*dy) vs hypot: a few ulps of distances below 10 m
        np.testing.assert_allclose(fast[name], exact[name], rtol=0, atol=1e-14)
    t_ns = np.arange(1000, dtype=np.int64) * 10_000_000
    step = step_bound_m(t_ns, x, y, 0.3)
    want = np.fmax(0.3 * np.diff(t_ns) * 1e-9, np.hypot(np.diff(x), np.diff(y)))
    np.testing.assert_array_equal(step, want)  # the hypot-free shortcut is exact
    np.testing.assert_array_equal(step_bound_regular_m(10_000_000, x, y, 0.3), want)
    slow = np.linspace(0.0, 0.01, 1000)  # below the speed bound everywhere except where it jumps
    slow[500] += 1.0
    np.testing.assert_array_equal(step_bound_regular_m(10_000_000, slow, slow, 0.3),
                                  step_bound_m(t_ns, slow, slow, 0.3))


def test_step_bound_regular_blocks_equal_hypot_everywhere() -> None:
    """Several cache blocks: slow motion with jumps at block edges and inside blocks, one NaN position (its block
    takes the hypot path): the same values as ``max(v dt, hypot)`` with NaN ignored by ``fmax``."""
    n = 3 * (1 << 15) + 17
    x = np.linspace(0.0, 1.0, n)
    y = np.linspace(0.0, -0.5, n)
    for k in (1 << 15, (1 << 15) - 1, 2 * (1 << 15) + 3, n - 2):
        x[k] += 0.5
    y[40_000] = np.nan
    want = np.fmax(0.3 * 0.01, np.hypot(np.diff(x), np.diff(y)))
    got = step_bound_regular_m(10_000_000, x, y, 0.3)
    np.testing.assert_array_equal(got, want)
    assert got[(1 << 15) - 2] > 0.4 and got[39_999] == 0.3 * 0.01  # a jump; the NaN step keeps v dt
    assert step_bound_regular_m(10_000_000, x[:1], y[:1], 0.3).shape == (0,)


def test_root_bounds_refuse_a_step_array_of_the_wrong_length() -> None:
    grid = Grid(0, 10, 3)
    with pytest.raises(ValueError, match=r"^step_m has shape \(3,\), expected \(2,\)$"):
        evaluate_root(parse("p"), grid, {"p": np.ones(3)}, np.ones(3))
