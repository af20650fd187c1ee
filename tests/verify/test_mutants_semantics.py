"""``verify.semantics`` on hand-made inputs, at the edges each rule draws (written against its surviving mutants).

The joint run of several robots (``joint``): the joint axis and span, where each joint instant and gap lies in a
robot's own samples, a robot's margin bounds and two robots' distance bounds on that axis. The timed run
(``timed_run``), the trajectory semantics (``trajectory``) and the reading of a judged formula (``analysis``)."""

from __future__ import annotations

import math
import re

import numpy as np
import pytest

from tubempc.mitl import parse
from tubempc.scenario import Scenario, builtin_scenario
from tubempc.scenario.model import Region, RobotSpec
from verify.monitor.engine import Positions, Truth, evaluate, evaluate_at_points
from verify.semantics import joint, trajectory
from verify.semantics.analysis import decided_times, margin_source
from verify.semantics.joint import RobotTrack, joint_axis, margin_bounds, pair_distance_bounds
from verify.semantics.timed_run import (
    UNKNOWN_ENTRY,
    TimedRunVerdict,
    check_timed_run,
    entry_exits,
    timed_run_of,
    timed_run_of_sets,
)
from verify.semantics.trajectory import (
    check_trajectory,
    interleave,
    reported_margin,
    trajectory_positions,
    trajectory_values,
)
from verify.signals import SignalBounds

INF = math.inf


def _track(name: str, t: list[int], xy: list[tuple[float, float]], step: list[float],
           radius_m: float = 0.5) -> RobotTrack:
    return RobotTrack(name, np.array(t, dtype=np.int64), np.array([p[0] for p in xy], dtype=np.float64),
                      np.array([p[1] for p in xy], dtype=np.float64), radius_m, np.array(step, dtype=np.float64))


def _eq(actual: np.ndarray, expected: list[float]) -> None:
    np.testing.assert_allclose(actual, np.array(expected, dtype=np.float64), rtol=1e-12, atol=0.0)


# --- joint: the axis ---------------------------------------------------------------------------------------------


def test_a_robot_track_spans_its_first_to_its_last_sample_and_an_empty_one_spans_nothing() -> None:
    assert _track("a", [3, 7, 12], [(0, 0)] * 3, [0, 0]).span_ns == (3, 12)
    assert _track("a", [], [], []).span_ns is None


def test_the_joint_axis_is_every_robots_samples_inside_the_span_all_robots_were_observed_in() -> None:
    a = _track("a", [0, 10, 20, 30], [(0, 0)] * 4, [0, 0, 0])
    b = _track("b", [5, 15, 25, 40], [(0, 0)] * 4, [0, 0, 0])
    axis, span = joint_axis([a, b])
    assert span == (5, 30)
    assert axis.dtype == np.int64
    assert axis.tolist() == [5, 10, 15, 20, 25, 30]
    # a shared sample appears once
    axis, span = joint_axis([a, _track("c", [10, 20], [(0, 0)] * 2, [0])])
    assert (axis.tolist(), span) == ([10, 20], (10, 20))


def test_spans_that_meet_at_one_instant_give_that_instant_and_disjoint_ones_give_nothing() -> None:
    a = _track("a", [0, 10], [(0, 0)] * 2, [0])
    axis, span = joint_axis([a, _track("b", [10, 20], [(0, 0)] * 2, [0])])
    assert (axis.tolist(), span) == ([10], (10, 10))
    for tracks in ([a, _track("b", [11, 20], [(0, 0)] * 2, [0])], [a, _track("b", [], [], [])], []):
        axis, span = joint_axis(tracks)
        assert (axis.tolist(), span) == ([], None)
        assert axis.dtype == np.int64


def test_each_joint_instant_and_gap_is_placed_at_the_robots_sample_or_in_its_gap() -> None:
    track_t = np.array([10, 20, 30], dtype=np.int64)
    joint_t = np.array([5, 10, 15, 20, 25, 30, 35], dtype=np.int64)
    sample, point_gap, gap = joint._where(track_t, joint_t)
    assert sample.tolist() == [-1, 0, -1, 1, -1, 2, -1]
    assert point_gap.tolist() == [-1, -1, 0, -1, 1, -1, -1]
    assert gap.tolist() == [-1, 0, 0, 1, 1, -1]  # the axis gap (30, 35) lies after the robot's last sample
    sample, point_gap, gap = joint._where(np.zeros(0, dtype=np.int64), joint_t[:3])
    assert (sample.tolist(), point_gap.tolist(), gap.tolist()) == ([-1] * 3, [-1] * 3, [-1] * 2)


# --- joint: one robot's margin -----------------------------------------------------------------------------------


def test_a_robots_margin_is_exact_at_its_samples_bounded_in_its_gaps_and_unknown_outside() -> None:
    # gap bounds: (1 + 2 -+ 1) / 2 = [1, 2] and (2 + 4 -+ 2) / 2 = [2, 4]
    track = _track("a", [10, 20, 30], [(0, 0)] * 3, [1.0, 2.0])
    b = margin_bounds(track, np.array([1.0, 2.0, 4.0]), np.array([5, 10, 15, 20, 25, 30, 35], dtype=np.int64))
    _eq(b.point_lo, [-INF, 1.0, 1.0, 2.0, 2.0, 4.0, -INF])
    _eq(b.point_hi, [INF, 1.0, 2.0, 2.0, 4.0, 4.0, INF])
    _eq(b.gap_lo, [-INF, 1.0, 1.0, 2.0, 2.0, -INF])
    _eq(b.gap_hi, [INF, 2.0, 2.0, 4.0, 4.0, INF])


def test_a_nan_sample_margin_is_unknown_at_the_sample_and_in_its_gaps() -> None:
    track = _track("a", [10, 20, 30], [(0, 0)] * 3, [1.0, 1.0])
    b = margin_bounds(track, np.array([1.0, np.nan, 3.0]), np.array([10, 15, 20, 30], dtype=np.int64))
    _eq(b.point_lo, [1.0, -INF, -INF, 3.0])
    _eq(b.point_hi, [1.0, INF, INF, 3.0])
    _eq(b.gap_lo, [-INF, -INF, -INF])
    _eq(b.gap_hi, [INF, INF, INF])


def test_a_robot_with_one_sample_is_known_only_at_it() -> None:
    track = _track("a", [10], [(0, 0)], [])
    b = margin_bounds(track, np.array([0.5]), np.array([5, 10, 15], dtype=np.int64))
    _eq(b.point_lo, [-INF, 0.5, -INF])
    _eq(b.point_hi, [INF, 0.5, INF])
    _eq(b.gap_lo, [-INF, -INF])
    _eq(b.gap_hi, [INF, INF])
    b = margin_bounds(track, np.array([0.5]), np.array([10], dtype=np.int64))
    assert (b.gap_lo.shape, b.gap_hi.shape) == ((0,), (0,))



def test_a_robot_with_two_samples_is_bounded_in_its_one_gap() -> None:
    track = _track("a", [10, 20], [(0, 0)] * 2, [1.0])
    b = margin_bounds(track, np.array([1.0, 2.0]), np.array([10, 15, 20], dtype=np.int64))
    _eq(b.point_lo, [1.0, 1.0, 2.0])
    _eq(b.point_hi, [1.0, 2.0, 2.0])
    _eq(b.gap_lo, [1.0, 1.0])
    _eq(b.gap_hi, [2.0, 2.0])

# --- joint: two robots' distance ---------------------------------------------------------------------------------


def _mean_distance(a_ends: tuple[tuple[float, float], tuple[float, float]],
                   b_ends: tuple[tuple[float, float], tuple[float, float]]) -> float:
    return sum(math.dist(p, q) for p in a_ends for q in b_ends) / 4


def test_two_robots_distance_is_exact_at_shared_samples_and_bounded_by_both_paths_elsewhere() -> None:
    # a: (1, 1) at 0, (7, 2) at 10, path length <= 8; b: (2, 5) at 0, (8, 9) at 5, (4, 3) at 10, paths <= 9 and 7
    a = _track("a", [0, 10], [(1.0, 1.0), (7.0, 2.0)], [8.0], radius_m=0.5)
    b = _track("b", [0, 5, 10], [(2.0, 5.0), (8.0, 9.0), (4.0, 3.0)], [9.0, 7.0], radius_m=0.25)
    axis = np.array([0, 5, 10], dtype=np.int64)
    d = pair_distance_bounds(a, b, axis)
    radii = 0.75
    a0, a1 = (1.0, 1.0), (7.0, 2.0)
    b0, b1, b2 = (2.0, 5.0), (8.0, 9.0), (4.0, 3.0)
    at0 = math.dist(a0, b0) - radii
    at5 = _mean_distance((a0, a1), (b1, b1)) - radii  # a in its gap (length 8), b at its sample
    at10 = math.dist(a1, b2) - radii
    _eq(d.point_lo, [at0, at5 - 4.0, at10])
    _eq(d.point_hi, [at0, at5 + 4.0, at10])
    g0 = _mean_distance((a0, a1), (b0, b1)) - radii  # half of 8 + 9
    g1 = _mean_distance((a0, a1), (b1, b2)) - radii  # half of 8 + 7
    _eq(d.gap_lo, [g0 - 8.5, g1 - 7.5])
    _eq(d.gap_hi, [g0 + 8.5, g1 + 7.5])


def test_two_robots_distance_is_unknown_where_either_is_not_observed() -> None:
    a = _track("a", [0, 10], [(1.0, 1.0), (7.0, 2.0)], [8.0])
    b = _track("b", [5, 10], [(2.0, 5.0), (4.0, 3.0)], [3.0])
    d = pair_distance_bounds(a, b, np.array([0, 5, 10, 15], dtype=np.int64))
    _eq(d.point_lo, [-INF, _mean_distance(((1.0, 1.0), (7.0, 2.0)), ((2.0, 5.0), (2.0, 5.0))) - 1.0 - 4.0,
                     math.dist((7.0, 2.0), (4.0, 3.0)) - 1.0, -INF])
    _eq(d.point_hi[[0, 3]], [INF, INF])
    _eq(d.gap_lo[[0, 2]], [-INF, -INF])
    _eq(d.gap_hi[[0, 2]], [INF, INF])
    g1 = _mean_distance(((1.0, 1.0), (7.0, 2.0)), ((2.0, 5.0), (4.0, 3.0))) - 1.0
    _eq(d.gap_lo[[1]], [g1 - 5.5])
    _eq(d.gap_hi[[1]], [g1 + 5.5])


def test_path_ends_of_a_robot_at_its_samples_and_in_its_gaps() -> None:
    track = _track("a", [0, 10, 20], [(1.0, 2.0), (3.0, 4.0), (5.0, 6.0)], [3.0, 4.0])
    x0, y0, x1, y1, d = joint._segments(track, np.array([0, -1, 2, -1]), np.array([-1, 1, -1, -1]))
    _eq(x0, [1.0, 3.0, 5.0, np.nan])
    _eq(y0, [2.0, 4.0, 6.0, np.nan])
    _eq(x1, [1.0, 5.0, 5.0, np.nan])
    _eq(y1, [2.0, 6.0, 6.0, np.nan])
    _eq(d, [0.0, 4.0, 0.0, np.nan])


# --- timed_run: the run of region sets -------------------------------------------------------------------------


def _regions_ab() -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Regions A and B over six samples 1 s apart: A, A+B, unknown, unknown, none, B."""
    contains = np.array([[True, True, False, False, False, False],
                         [False, True, False, False, False, True]])
    known = np.array([True, True, False, False, True, True])
    return contains, np.arange(6, dtype=np.float64), known


def test_the_run_of_region_sets_names_each_stretch_and_one_entry_per_unknown_stretch() -> None:
    contains, times, known = _regions_ab()
    run, labels = timed_run_of_sets(contains, times, ["A", "B"], {"A": ["a"], "B": ["c", "b"]}, known)
    assert run == [("A", 0.0), ("A+B", 1.0), (UNKNOWN_ENTRY, 2.0), ("B", 5.0)]
    assert labels == {"A": ["a"], "A+B": ["a", "b", "c"], UNKNOWN_ENTRY: [], "B": ["b", "c"]}
    # each entry is left where the set of regions, or whether it is known, changes; the last at the last sample
    assert entry_exits(contains, times, known) == [1.0, 2.0, 4.0, 5.0]
    # without ``known`` every sample is known: the unknown samples are outside both regions
    assert timed_run_of_sets(contains, times, ["A", "B"], {}, None)[0] == [("A", 0.0), ("A+B", 1.0), ("B", 5.0)]
    assert entry_exits(contains, times) == [1.0, 2.0, 5.0]


def test_a_run_of_one_sample_has_its_entry_and_no_samples_have_none() -> None:
    one = np.array([[False], [True]])
    assert timed_run_of_sets(one, np.array([3.0]), ["A", "B"], {"B": ["b"]}) == ([("B", 3.0)], {"B": ["b"]})
    assert entry_exits(one, np.array([3.0])) == [3.0]
    for contains in (np.zeros((2, 0), dtype=bool), np.zeros(0, dtype=bool)):
        assert timed_run_of_sets(contains, np.zeros(0), ["A", "B"], {}) == ([], {})
        assert entry_exits(contains, np.zeros(0)) == []


def test_the_run_of_single_regions_starts_an_entry_at_each_stretch_and_skips_samples_outside_every_region() -> None:
    idx = np.array([-1, 0, 0, -1, 1, 1, 0], dtype=np.int64)
    assert timed_run_of(idx, np.arange(7, dtype=np.float64), ["A", "B"]) == [("A", 1.0), ("B", 4.0), ("A", 6.0)]
    assert timed_run_of(np.array([0], dtype=np.int64), np.array([2.5]), ["A"]) == [("A", 2.5)]
    assert timed_run_of(np.zeros(0, dtype=np.int64), np.zeros(0), ["A"]) == []


# --- timed_run: the margin of a fail in seconds ------------------------------------------------------------------

B = {"B": ["b"]}


@pytest.mark.parametrize(("spec", "run", "end", "margin_s"), [
    ("F[0,2] b", [("A", 0.0), ("B", 5.0)], 6.0, -3.0),  # b holds 3 s after the window closes
    ("F[3,4] b", [("A", 0.0), ("B", 1.0), ("A", 2.0)], 10.0, -2.0),  # b held 2 s before the window opened
    ("F[3,4] b", [("A", 0.0), ("B", 1.0), ("A", 2.0), ("B", 9.0)], 10.0, -2.0),  # the nearer of before (2 s), after
    ("F[3,4] b", [("A", 0.0), ("B", 0.5), ("A", 2.0), ("B", 5.0)], 10.0, -1.0),  # (2.5 s, 1 s)
    ("F[0,2] b", [("A", 0.0)], 10.0, -8.0),  # never: at least until the log's end
])
def test_a_missed_eventually_is_off_by_the_time_from_its_window_to_the_nearest_entry_where_it_held(
        spec: str, run: list[tuple[str, float]], end: float, margin_s: float) -> None:
    r = check_timed_run(spec, run, B, end=end)
    assert (r.verdict, r.subformula, r.margin_s, r.margin_reason) == ("fail", spec, margin_s, None)


def test_a_missed_eventually_whose_window_closes_at_the_logs_end_has_no_margin_and_says_why() -> None:
    r = check_timed_run("F[0,2] b", [("A", 0.0)], B, end=2.0)
    assert (r.verdict, r.margin_s) == ("fail", None)
    assert r.margin_reason is not None and r.margin_reason.startswith("no time stretch to measure")


def test_an_undecided_signal_at_an_entry_is_not_where_a_missed_eventually_held() -> None:
    # s is exactly 0 (undecided) at 2 s, outside the window [3, 4]; it holds at 6 s: 2 s after the window
    values = {"s": (np.array([-1.0, 0.0, 1.0]), np.array([-1.0, 0.0, 1.0]))}
    r = check_timed_run("F[3,4] s", [("A", 0.0), ("A", 2.0), ("A", 6.0)], {}, end=10.0, atom_values=values)
    assert (r.verdict, r.margin_s) == ("fail", -2.0)


def test_an_eventually_missed_only_at_its_open_window_end_has_no_negative_margin() -> None:
    # b holds at 3 s, exactly where the window (3, 4] is open: the distance to the window is 0, not a margin < 0
    r = check_timed_run("F(3,4] b", [("A", 0.0), ("B", 3.0), ("A", 3.5)], B, end=10.0)
    assert (r.verdict, r.margin_s) == ("fail", None)


def test_a_false_atom_stays_false_until_the_first_entry_where_it_is_not_false() -> None:
    # s false at 0 s, exactly 0 (undecided, not false) at 2 s: false for 2 s
    values = {"s": (np.array([-1.0, 0.0, 0.5, 1.0]), np.array([-1.0, 0.0, 0.5, 1.0]))}
    r = check_timed_run("G[0,10] s", [("A", 0.0), ("A", 2.0), ("A", 3.0), ("A", 5.0)], {}, end=10.0,
                        atom_values=values)
    assert (r.verdict, r.subformula, r.time_s, r.margin_s) == ("fail", "s", 0.0, -2.0)


@pytest.mark.parametrize(("run", "exits", "margin_s"), [
    ([("A", 0.0), ("C", 1.0)], [1.0, 4.0], -4.0),  # A left at 1 s into C, C (the last entry) left at 4 s
    ([("A", 0.0), ("C", 1.0), ("P", 3.0)], [1.0, 3.0, 5.0], -3.0),  # ... until P, where p holds, at 3 s
    ([("A", 0.0), ("C", 2.0), ("P", 3.0)], [1.0, 3.0, 5.0], -1.0),  # A left at 1 s: C starts a new stretch
])
def test_a_false_atom_stays_false_across_the_entries_it_is_false_in_while_each_starts_where_the_last_was_left(
        run: list[tuple[str, float]], exits: list[float], margin_s: float) -> None:
    r = check_timed_run("G[0,10] p", run, {"P": ["p"]}, end=5.0, exits=exits)
    assert (r.verdict, r.subformula, r.margin_s) == ("fail", "p", margin_s)


def test_a_false_atom_seen_only_at_the_logs_last_instant_has_no_negative_margin() -> None:
    for exits in (None, [5.0, 5.0]):
        r = check_timed_run("G[0,10] p", [("P", 0.0), ("C", 5.0)], {"P": ["p"]}, end=5.0, exits=exits)
        assert (r.verdict, r.subformula, r.time_s, r.margin_s) == ("fail", "p", 5.0, None), exits


def test_without_exits_a_false_atom_stays_false_until_the_next_entry_where_it_holds() -> None:
    run = [("P", 0.0), ("A", 1.0), ("A", 2.0), ("P", 4.0), ("P", 6.0)]
    r = check_timed_run("G[0,10] p", run, {"P": ["p"]}, end=7.0)
    assert (r.verdict, r.subformula, r.time_s, r.margin_s) == ("fail", "p", 1.0, -3.0)


def test_an_empty_run_is_inconclusive_and_says_so() -> None:
    r = check_timed_run("F[0,1]  p", [], {})
    assert r == TimedRunVerdict("inconclusive", "F[0,1] p", "F[0,1] p", None, "the timed run is empty")


def test_a_run_with_decreasing_times_an_end_before_its_last_entry_or_a_time_not_finite_is_refused() -> None:
    with pytest.raises(ValueError, match=re.escape("run times must be non-decreasing, got [1.0, 0.5]")):
        check_timed_run("p", [("A", 1.0), ("A", 0.5)], {})
    with pytest.raises(ValueError, match=re.escape("end=0.5 is before the last run time 1.0")):
        check_timed_run("p", [("A", 1.0)], {}, end=0.5)
    with pytest.raises(ValueError, match=re.escape("time=nan is not finite")):
        check_timed_run("p", [("A", math.nan)], {})
    # equal times are two entries at one instant; the end defaults to the last entry
    assert check_timed_run("p", [("A", 1.0), ("B", 1.0)], {"A": ["p"]}).verdict == "pass"
    assert check_timed_run("F[0,1] p", [("A", 0.0)], {"A": ["q"]}, end=0.5).verdict == "inconclusive"


# --- trajectory --------------------------------------------------------------------------------------------------


@pytest.mark.parametrize(("verdict", "lo_m", "hi_m", "margin"), [
    ("pass", 0.5, 2.0, 0.5),  # the guaranteed margin
    ("fail", -3.0, -1.0, -1.0),  # violated by at least the optimistic margin
    ("fail", -2.0, math.nan, -2.0),  # ... or by the guaranteed one when the optimistic one is not finite
    ("fail", -INF, -INF, None),  # failing on constants: no finite margin
    ("inconclusive", -1.0, 1.0, None),
])
def test_the_reported_margin_of_each_verdict(verdict: str, lo_m: float, hi_m: float, margin: float | None) -> None:
    assert reported_margin(verdict, lo_m, hi_m) == margin


def test_trajectory_positions_are_the_samples_and_the_open_gaps_between_samples_more_than_1_ns_apart() -> None:
    pos, point_at, gap_at = trajectory_positions(np.array([0, 1, 5, 6, 10], dtype=np.int64))
    assert pos.start_ns.tolist() == [0, 1, 2, 5, 6, 7, 10]
    assert pos.stop_ns.tolist() == [0, 1, 4, 5, 6, 9, 10]
    assert pos.is_point.tolist() == [True, True, False, True, True, False, True]
    assert pos.end_ns == 10
    assert (point_at.tolist(), gap_at.tolist()) == ([0, 1, 3, 4, 6], [-1, 2, -1, 5])
    pos, point_at, gap_at = trajectory_positions(np.zeros(0, dtype=np.int64))
    assert (pos.size, pos.end_ns, point_at.tolist(), gap_at.tolist()) == (0, 0, [], [])
    # absolute stamps (ns since the epoch) stay exact integers
    t0 = 1_700_000_000_000_000_001
    pos, _, _ = trajectory_positions(np.array([t0, t0 + 1, t0 + 5], dtype=np.int64))
    assert pos.start_ns.tolist() == [t0, t0 + 1, t0 + 2, t0 + 5]
    assert pos.stop_ns.tolist() == [t0, t0 + 1, t0 + 4, t0 + 5]


def test_interleave_puts_sample_values_at_the_samples_and_gap_values_at_the_gaps() -> None:
    _, point_at, gap_at = trajectory_positions(np.array([0, 1, 5, 6, 10], dtype=np.int64))
    v = interleave(np.array([1.0, 2.0, 3.0, 4.0, 5.0]), np.array([11.0, 12.0, 13.0, 14.0, 15.0]),
                   np.array([-1.0, -2.0, -3.0, -4.0]), np.array([-11.0, -12.0, -13.0, -14.0]),
                   point_at=point_at, gap_at=gap_at, size=7)
    assert v.lo.tolist() == [1.0, 2.0, -2.0, 3.0, 4.0, -4.0, 5.0]
    assert v.hi.tolist() == [11.0, 12.0, -12.0, 13.0, 14.0, -14.0, 15.0]
    # every pair of samples leaves a gap
    pos, point_at, gap_at = trajectory_positions(np.array([0, 5, 10], dtype=np.int64))
    v = interleave(np.array([1.0, 2.0, 3.0]), np.array([11.0, 12.0, 13.0]), np.array([-1.0, -2.0]),
                   np.array([-11.0, -12.0]), point_at=point_at, gap_at=gap_at, size=pos.size)
    assert v.lo.tolist() == [1.0, -1.0, 2.0, -2.0, 3.0]
    assert v.hi.tolist() == [11.0, -11.0, 12.0, -12.0, 13.0]
    # one pair 1 ns apart: 3 samples, 1 gap
    pos, point_at, gap_at = trajectory_positions(np.array([0, 1, 5], dtype=np.int64))
    v = interleave(np.array([1.0, 2.0, 3.0]), np.array([11.0, 12.0, 13.0]), np.array([-1.0, -2.0]),
                   np.array([-11.0, -12.0]), point_at=point_at, gap_at=gap_at, size=pos.size)
    assert (v.lo.tolist(), v.hi.tolist()) == ([1.0, 2.0, -2.0, 3.0], [11.0, 12.0, -12.0, 13.0])
    pos, point_at, gap_at = trajectory_positions(np.array([7], dtype=np.int64))
    v = interleave(np.array([1.0]), np.array([2.0]), np.zeros(0), np.zeros(0), point_at=point_at, gap_at=gap_at,
                   size=pos.size)
    assert (v.lo.tolist(), v.hi.tolist()) == ([1.0], [2.0])


def test_a_nan_sample_margin_is_unknown_and_a_known_one_is_exact() -> None:
    lo, hi = trajectory._sample_truth(np.array([0.5, np.nan, -0.25]))
    assert (lo.tolist(), hi.tolist()) == ([0.5, -INF, -0.25], [0.5, INF, -0.25])
    margin = np.array([0.5, -0.25])
    lo, hi = trajectory._sample_truth(margin)
    assert (lo.tolist(), hi.tolist()) == ([0.5, -0.25], [0.5, -0.25])


def test_a_trajectory_without_samples_is_inconclusive_and_says_so() -> None:
    empty = np.zeros(0)
    r = check_trajectory(parse("G !obs"), np.zeros(0, dtype=np.int64), empty, empty, builtin_scenario(),
                         max_speed_mps=1.0)
    assert (r.verdict, r.margin_m, r.margin_hi_m, r.subformula, r.time_ns, r.reason) == (
        "inconclusive", -INF, INF, "G[0,inf) !obs", None, "no pose samples")
    assert (r.signal_t_ns.dtype, r.signal_t_ns.size, r.signal_rho_m.size) == (np.dtype(np.int64), 0, 0)


# --- analysis: when each verdict was decided, which atom a margin is ---------------------------------------------

S = 1_000_000_000
FIVE = Positions.points(np.arange(5, dtype=np.int64) * S, 4 * S)  # samples at 0..4 s, observed until 4 s


def _bits(*bits: int | None) -> Truth:
    """1 true, 0 false, None unknown."""
    lo = [-INF if b is None else (1.0 if b else -1.0) for b in bits]
    hi = [INF if b is None else (1.0 if b else -1.0) for b in bits]
    return Truth(np.array(lo), np.array(hi))


def _values(*margins: float) -> Truth:
    return Truth(np.array(margins, dtype=np.float64), np.array(margins, dtype=np.float64))


BITS = {"p": _bits(0, 0, 1, 0, 0), "q": _bits(1, 1, 0, 1, 1), "r": _bits(1, 0, 0, 0, None)}


@pytest.mark.parametrize(("spec", "decided_s"), [
    ("p", [0, 1, 2, 3, 4]),  # an atom at its sample
    ("true", [0, 1, 2, 3, 4]),
    ("!p", [0, 1, 2, 3, 4]),
    ("F[0,2] p", [2, 2, 2, None, None]),  # at its witness; undecided while the window is open at the log's end
    ("G[0,1] q", [1, 2, 2, 4, None]),  # true: when the window closes; false: at the first false sample
    ("F[0,2] p | r", [0, 2, 2, None, None]),  # true: the first true argument (r at 0 s, not F at 2 s)
    ("F[0,2] p & r", [2, 1, 2, 3, None]),  # true: the last argument decided (F at 2 s); false: the first false one
    ("r -> F[0,2] p", [2, 1, 2, 3, None]),  # true: a false premise (r) or a true conclusion (F), whichever first
    ("X p", [1, 2, 3, 4, 4]),  # the next sample; none: the end of the log
    ("X[0,0.5] p", [1, 2, 3, 4, None]),  # the next sample shows it outside the window
    ("q U[0,3] p", [2, 2, 2, None, None]),  # true: the witness p at 2 s, q held before it
    ("q U[1,3] p", [2, 2, 2, None, None]),  # false at 2 s: q fails at 2 s before p holds in [3, 5]
    ("!q U p", [0, 1, 2, 3, 4]),  # false where !q fails at once, true where p holds at once
])
def test_each_verdict_is_decided_when_the_data_seen_settles_it(spec: str, decided_s: list[int | None]) -> None:
    f = parse(spec)
    d = decided_times(f, FIVE, evaluate_at_points(f, FIVE, BITS))[f]
    assert [None if math.isinf(x) else x / S for x in d] == decided_s



LATER = {"p": _bits(0, 0, 0, 1, 0), "q": _bits(1, 1, 0, 1, 1), "e": _bits(0, 0, 0, 0, 1), "l": _bits(0, 0, 0, 1, 1),
         "n": _bits(0, 0, 0, 0, 0), "t": _bits(1, 1, 1, 1, 1)}


@pytest.mark.parametrize(("spec", "decided_s"), [
    # F[0,1] p is decided at 2 s (false at 1 s: its window closes) and at 3 s (true at 1 s and 2 s: p at 3 s)
    ("X (F[0,1] p)", [2, 3, 3, None, 4]),  # the next sample is in the window: when its argument is decided there
    ("X[0,1] (F[0,1] p)", [2, 3, 3, None, None]),  # ... a window closed at 1 s includes the sample 1 s later
    ("X[1,2] (F[0,1] p)", [2, 3, 3, None, None]),  # ... and one that opens at 1 s
    ("X[0,0.5] (F[0,1] p)", [1, 2, 3, 4, None]),  # outside the window: false when the next sample shows it
    ("q U[0,3] n", [2, 2, 2, None, None]),  # false when q fails (at 2 s), n never holding
    ("t U[0,1] n", [1, 2, 3, 4, None]),  # false when the window closes without n
    ("t U[0,3] l", [3, 3, 3, 3, 4]),  # the witness at the last sample is that sample
    ("t U[0,4] e", [4, 4, 4, 4, 4]),  # the only witness is the last sample
])
def test_next_and_until_are_decided_when_their_witness_or_window_end_is_seen(
        spec: str, decided_s: list[int | None]) -> None:
    f = parse(spec)
    d = decided_times(f, FIVE, evaluate_at_points(f, FIVE, LATER))[f]
    assert [None if math.isinf(x) else x / S for x in d] == decided_s


def test_a_next_without_a_next_sample_is_decided_at_the_end_of_observation() -> None:
    f = parse("X p")
    for times, end_ns, decided in (([0, 1, 2, 3, 4], 6 * S, [1, 2, 3, 4, 6]), ([0], 0, [0]), ([0], 2 * S, [2])):
        pos = Positions.points(np.array(times, dtype=np.int64) * S, end_ns)
        atoms = {"p": _bits(*([1] * len(times)))}
        d = decided_times(f, pos, evaluate_at_points(f, pos, atoms))[f]
        assert (d / S).tolist() == decided

def test_an_atom_over_a_gap_is_decided_at_the_next_sample() -> None:
    pos, _, _ = trajectory_positions(np.array([0, S, 2 * S], dtype=np.int64))
    f = parse("p & F[0,1] p")
    values = evaluate_at_points(f, pos, {"p": Truth(np.array([1.0, 0.5, 2.0, 0.5, 3.0]), np.full(5, 4.0))})
    d = decided_times(f, pos, values)
    assert (d[parse("p")] / S).tolist() == [0.0, 1.0, 1.0, 2.0, 2.0]
    assert (d[f][pos.is_point] / S).tolist() == [0.0, 1.0, 2.0]  # temporal sub-formulas: at the samples only


MARGINS = {"p": _values(-0.5, 0.3, 0.7, -0.2, 0.1), "q": _values(0.4, 0.2, 0.9, -0.6, 0.8),
           "r": _values(1.0, -INF, 1.0, 1.0, 1.0)}


@pytest.mark.parametrize(("spec", "i", "bound", "source"), [
    ("p & q", 1, "lo", ("q", 1)), ("p & q", 3, "hi", ("q", 3)), ("p | q", 3, "lo", ("p", 3)),
    ("!p", 2, "lo", ("p", 2)), ("!(p & q)", 1, "hi", ("q", 1)),
    ("p -> q", 0, "lo", ("p", 0)), ("p -> q", 1, "lo", ("q", 1)), ("p -> q", 3, "hi", ("p", 3)),
    ("F[0,2] p", 0, "lo", ("p", 2)), ("F[0,2] p", 3, "lo", ("p", 4)), ("F[0,2] p", 3, "hi", None),
    ("G[0,2] q", 0, "lo", ("q", 1)), ("G[0,2] q", 1, "hi", ("q", 3)), ("G[0,2] p", 3, "lo", None),
    ("X p", 2, "lo", ("p", 3)), ("X p", 4, "lo", None), ("X[0,0.5] p", 0, "lo", None),
    ("q U[0,3] p", 0, "lo", ("p", 1)), ("q U[0,3] p", 3, "lo", ("p", 3)),
    ("true", 0, "lo", None), ("false | p", 1, "hi", ("p", 1)), ("F[0,2] (p & q)", 1, "lo", ("p", 2)),
    ("G[0,2] r", 0, "lo", None),
])
def test_a_margin_is_traced_to_the_atom_and_sample_whose_value_it_is(
        spec: str, i: int, bound: str, source: tuple[str, int] | None) -> None:
    f = parse(spec)
    assert margin_source(f, i, bound, FIVE, evaluate_at_points(f, FIVE, MARGINS)) == source


def test_an_infinite_margin_is_traced_only_when_asked() -> None:
    f = parse("G[0,2] r")
    values = evaluate_at_points(f, FIVE, MARGINS)
    assert margin_source(f, 0, "lo", FIVE, values, infinite=True) == ("r", 1)
    assert margin_source(parse("true"), 0, "lo", FIVE, evaluate_at_points(parse("true"), FIVE, {}),
                         infinite=True) is None


NO_STRETCH = ("no time stretch to measure: the violation is decided by constants or at the end of the log (e.g. a "
              "window that opens after the log ends)")


def test_the_timed_runs_verdicts_state_the_canonical_formula_the_witness_and_its_reason() -> None:
    assert check_timed_run("F[0,2]  p", [("P", 0.0)], {"P": ["p"]}) == TimedRunVerdict("pass", "F[0,2] p")
    r = check_timed_run("G[0,10]  p", [("P", 0.0), ("C", 5.0)], {"P": ["p"]}, end=5.0)
    assert r == TimedRunVerdict("fail", "G[0,10] p", "p", 5.0, "false here", None, NO_STRETCH)
    r = check_timed_run("G[0,10] p", [("P", 0.0), ("C", 2.0), ("P", 3.0)], {"P": ["p"]}, end=5.0)
    assert r == TimedRunVerdict("fail", "G[0,10] p", "p", 2.0, "false here", -1.0, None)
    # the end defaults to the last entry's time
    assert check_timed_run("p", [("A", 0.0), ("A", 1.0), ("A", 2.0)], {"A": ["p"]}).verdict == "pass"
    assert check_timed_run("F[0,1.5] b", [("A", 0.0), ("A", 1.0), ("B", 2.0)], B).verdict == "fail"


def test_an_inconclusive_timed_run_states_no_margin() -> None:
    r = check_timed_run("F[0,5] b", [("A", 0.0)], B, end=2.0)
    assert (r.verdict, r.margin_s, r.margin_reason) == ("inconclusive", None, None)


@pytest.mark.parametrize("labels", [{}, {UNKNOWN_ENTRY: ["p"]}])
def test_every_atom_is_unknown_at_an_unknown_entry_whatever_its_labels(labels: dict[str, list[str]]) -> None:
    assert check_timed_run("p", [(UNKNOWN_ENTRY, 0.0)], labels).verdict == "inconclusive"
    assert check_timed_run("!p", [(UNKNOWN_ENTRY, 0.0)], labels).verdict == "inconclusive"
    r = check_timed_run("G[0,2] !p", [("A", 0.0), (UNKNOWN_ENTRY, 1.0), ("A", 2.0)], labels, end=3.0)
    assert (r.verdict, r.subformula, r.time_s) == ("inconclusive", "!p", 1.0)



def test_two_robots_distance_is_unknown_where_its_bound_is_undefined() -> None:
    # an infinite coordinate with an unbounded path: the lower bound is inf - inf; the distance is unknown, not NaN
    a = _track("a", [0, 10], [(0.0, 0.0), (INF, 0.0)], [INF])
    b = _track("b", [0, 10], [(1.0, 0.0), (1.0, 0.0)], [0.0])
    with np.errstate(invalid="ignore"):
        d = pair_distance_bounds(a, b, np.array([0, 5, 10], dtype=np.int64))
    assert (d.point_lo[1], d.point_hi[1], d.gap_lo.tolist(), d.gap_hi.tolist()) == (-INF, INF, [-INF, -INF],
                                                                                      [INF, INF])


def _home(radius_m: float) -> Scenario:
    """One disc region ``home`` centred at the origin; robot radius 0.25 m."""
    return builtin_scenario().model_copy(update={
        "regions": (Region.model_validate({"name": "H", "center": (0.0, 0.0), "radius": radius_m,
                                           "labels": ("home",)}),),
        "robot": RobotSpec(radius=0.25)})


# parked at (0.252, 0.336): sqrt(dx*dx + dy*dy) = 0.42 and hypot = 0.42000000000000004 (one ulp apart)
T3 = np.arange(3, dtype=np.int64) * 100_000_000
X3, Y3 = np.full(3, 0.252), np.full(3, 0.336)
FAST_D, EXACT_D = float(np.sqrt(0.252 * 0.252 + 0.336 * 0.336)), float(np.hypot(0.252, 0.336))


def test_a_comfortable_pass_on_a_regular_grid_keeps_the_fast_distances() -> None:
    assert 1.0 - FAST_D != 1.0 - EXACT_D  # the two distances give two margins here
    r = check_trajectory(parse("home"), T3, X3, Y3, _home(1.25), max_speed_mps=1.0)
    assert (r.verdict, r.margin_m, r.margin_hi_m, r.subformula, r.time_ns, r.reason) == (
        "pass", 1.0 - FAST_D, 1.0 - FAST_D, None, None, None)
    assert r.signal_t_ns is T3
    assert r.signal_rho_m.tolist() == [1.0 - FAST_D] * 3


def test_a_margin_within_rounding_of_zero_is_judged_on_exact_distances() -> None:
    assert 0.67 - 0.25 == EXACT_D > FAST_D  # the fast margin is positive, the exact one exactly 0 (undecided)
    r = check_trajectory(parse("home"), T3, X3, Y3, _home(0.67), max_speed_mps=1.0)
    assert (r.verdict, r.margin_m, r.margin_hi_m, r.subformula, r.time_ns) == ("inconclusive", 0.0, 0.0, "home", 0)


def test_a_pass_near_a_zero_margin_states_the_exact_margin_and_no_witness() -> None:
    exact = (0.67 + 5e-7 - 0.25) - EXACT_D
    r = check_trajectory(parse("home"), T3, X3, Y3, _home(0.67 + 5e-7), max_speed_mps=1.0)
    assert (r.verdict, r.margin_m, r.margin_hi_m, r.subformula, r.time_ns, r.reason) == (
        "pass", exact, exact, None, None, None)
    assert r.signal_t_ns is T3
    assert r.signal_rho_m.tolist() == [exact] * 3


@pytest.mark.parametrize("t_ns", [T3, np.array([0, 100_000_000, 300_000_000], dtype=np.int64)])
def test_a_fail_states_the_formulas_bounds_at_the_first_sample(t_ns: np.ndarray) -> None:
    # regular (grid path) and irregular (general engine) sampling; the robot leaves home 1 m, 0.5 m, 0 m outside
    r = check_trajectory(parse("home"), t_ns, np.array([2.0, 1.5, 1.0]), np.zeros(3), _home(1.25), max_speed_mps=10.0)
    assert (r.verdict, r.margin_m, r.margin_hi_m, r.subformula, r.time_ns, r.reason) == (
        "fail", -1.0, -1.0, "home", 0, "false here")
    assert (r.signal_t_ns.tolist(), r.signal_rho_m.tolist()) == (t_ns.tolist(), [-1.0, -0.5, 0.0])


def test_samples_1_ns_apart_leave_no_gap_between_them() -> None:
    t_ns = np.array([0, 1, 100_000_001], dtype=np.int64)
    r = check_trajectory(parse("G[0,0.1] home"), t_ns, X3, Y3, _home(1.25), max_speed_mps=1.0)
    assert (r.verdict, r.signal_t_ns.tolist()) == ("pass", [0, 1, 100_000_001])


def test_signal_atoms_of_the_formula_are_judged_from_their_bounds_on_a_regular_grid_too() -> None:
    slow = SignalBounds(np.full(3, 0.3), np.full(3, 0.4), np.full(2, 0.2), np.full(2, 0.5))
    unused = SignalBounds(np.zeros(0), np.zeros(0), np.zeros(0), np.zeros(0))  # not in the formula: never read
    r = check_trajectory(parse("G[0,0.2] (home & slow)"), T3, X3, Y3, _home(1.25), max_speed_mps=1.0,
                         signals={"slow": slow, "fast": unused})
    assert (r.verdict, r.margin_m, r.margin_hi_m) == ("pass", 0.2, 0.4)


@pytest.mark.parametrize("t_ns", [T3, np.array([0, 100_000_000, 300_000_000], dtype=np.int64)])
def test_the_values_obligations_are_read_from_use_exact_distances_on_interleaved_positions(t_ns: np.ndarray) -> None:
    tv = trajectory_values(parse("F[0,0.1] home"), t_ns, X3, Y3, _home(0.67), max_speed_mps=1.0)
    assert (tv.point_at.tolist(), tv.gap_at.tolist(), tv.pos.size) == ([0, 2, 4], [1, 3], 5)
    home = tv.values[parse("home")]
    assert home.lo[tv.point_at].tolist() == [0.0, 0.0, 0.0]  # 0.67 - 0.25 - hypot: exactly 0


@pytest.mark.parametrize(("spec", "end_s", "decided_s"), [
    ("G[0,1.5] q", 4, [2, 2, 2, None, None]),  # true when the first sample after the window (2 s) is seen
    ("G[0,0.5] q", 4, [1, 2, 2, 4, None]),  # ... the window closing between two samples
    ("G[0,1] q", 6, [1, 2, 2, 4, 6]),  # no sample after the window: when observation ends
])
def test_an_always_is_decided_true_when_its_window_has_been_observed_to_its_end(
        spec: str, end_s: int, decided_s: list[int | None]) -> None:
    pos = Positions.points(np.arange(5, dtype=np.int64) * S, end_s * S)
    f = parse(spec)
    d = decided_times(f, pos, evaluate_at_points(f, pos, BITS))[f]
    assert [None if math.isinf(x) else x / S for x in d] == decided_s


def test_a_point_window_on_one_sample_closes_at_that_sample() -> None:
    pos = Positions.points(np.array([0], dtype=np.int64), 2 * S)
    f = parse("G[0,0] p")
    assert decided_times(f, pos, evaluate_at_points(f, pos, {"p": _bits(1)}))[f].tolist() == [0.0]


def test_an_exact_zero_or_a_straddling_value_is_undecided_and_has_no_decision_time() -> None:
    z = Truth(np.array([0.0, -1.0, -1.0, 1.0, 0.5]), np.array([0.0, 0.5, 0.0, 1.0, 0.5]))
    d = decided_times(parse("z"), FIVE, {parse("z"): z})[parse("z")]
    assert [None if math.isinf(x) else x / S for x in d] == [None, None, None, 3, 4]


def test_an_always_is_decided_false_at_its_first_false_sample_not_at_a_true_one() -> None:
    f = parse("G[0,2] w")  # w: 0.5 (true), -1 (false), then true
    d = decided_times(f, FIVE, evaluate_at_points(f, FIVE, {"w": _values(0.5, -1.0, 1.0, 1.0, 1.0)}))[f]
    assert [None if math.isinf(x) else x / S for x in d] == [1, 1, 4, None, None]


P_BOUNDS = Truth(np.array([-0.5, 0.3, 0.7, -0.2, 0.1]), np.array([0.5, 1.3, 1.7, 0.8, 1.1]))
Q_BOUNDS = Truth(np.array([0.4, 0.2, 0.9, -0.6, 0.8]), np.array([1.4, 1.2, 1.9, 0.4, 1.8]))


@pytest.mark.parametrize(("spec", "i", "bound", "source"), [
    ("!p", 1, "lo", ("p", 1)),  # -1.3: p's upper bound
    ("!p", 1, "hi", ("p", 1)),  # -0.3: p's lower bound
    ("!(p & q)", 1, "lo", ("q", 1)),  # -min(1.3, 1.2) of the upper bounds: q's
    ("!(p & s)", 1, "lo", ("s", 1)),  # -min(1.3, 1.25) of the upper bounds: s's (p has the lesser lower bound)
    ("!(p & s)", 1, "hi", ("p", 1)),  # -min(0.3, 0.35) of the lower bounds: p's
    ("p -> q", 0, "hi", ("q", 0)),  # max(-(-0.5), 1.4): q's upper bound
    ("X p", 3, "lo", ("p", 4)),  # the one later sample
    ("q U[0,1] p", 3, "lo", ("p", 3)),  # the window of its own position, not of the first
])
def test_a_bound_is_traced_through_negations_to_the_atoms_other_bound(
        spec: str, i: int, bound: str, source: tuple[str, int]) -> None:
    f = parse(spec)
    s_bounds = Truth(np.full(5, 0.35), np.full(5, 1.25))
    values = evaluate_at_points(f, FIVE, {"p": P_BOUNDS, "q": Q_BOUNDS, "s": s_bounds})
    assert margin_source(f, i, bound, FIVE, values) == source


def test_on_samples_and_gaps_a_margin_is_traced_inside_the_window_its_bound_reads() -> None:
    pos, _, _ = trajectory_positions(np.array([0, 1, 2, 3], dtype=np.int64) * S)  # 7 positions, gaps at 1, 3, 5
    p = Truth(np.array([-0.5, 0.2, 0.3, 0.2, 0.7, 0.6, -0.2]), np.array([0.5, 1.1, 1.3, 1.2, 1.7, 1.6, 0.8]))
    f = parse("X p")
    values = evaluate_at_points(f, pos, {"p": p})
    assert margin_source(f, 0, "lo", pos, values) == ("p", 2)  # the next sample, not the gap before it
    assert margin_source(f, 2, "lo", pos, values) == ("p", 4)
    # at the gap (0 s, 1 s): G's lower bound reads every position overlapping [0.5 s, 2.5 s) (the gap itself first),
    # F's lower bound only those certainly in it (the gap (1 s, 2 s)), though the gap (0 s, 1 s) has the same value
    for spec, source in (("G[0.5,1.5] p", ("p", 1)), ("F[0.5,1.5] p", ("p", 3))):
        f = parse(spec)
        assert margin_source(f, 1, "lo", pos, evaluate(f, pos, {"p": p})) == source, spec


UNTIL = {"t": _values(1, 1, 1, 1, 1), "n": _values(-1, -1, -1, -1, -1), "z": _values(0, 1, 1, 1, 1),
         "y": _values(1, 1, -1, 1, 1), "y0": _values(1, 0, -1, 1, 1), "y5": _values(1, 0.5, -1, 1, 1),
         "r": _values(1, 1, 1, -1, 1), "p": _values(1, 1, 1, 1, 1)}


@pytest.mark.parametrize(("spec", "end_s", "i", "decided_s"), [
    ("t U[0,3] z", 4, 0, 1),  # z exactly 0 at 0 s is no witness: the witness is z at 1 s
    ("y0 U[0,3] n", 4, 0, 2),  # y0 exactly 0 at 1 s does not fail it: y0 fails at 2 s
    ("y5 U[0,3] n", 4, 0, 2),  # y5 is 0.5 (true) at 1 s and fails at 2 s
    ("(X r) U[0,1] n", 4, 0, 1),  # X r fails at 2 s, just after the window [0, 1]: false when the window closes
    ("y U[0,3] (X n)", 4, 0, 3),  # y fails at 2 s; X n there is known only at 3 s
    ("(X p) U[0,10] n", 6, 3, 6),  # X p fails at the last sample, known at the end of observation (6 s)
])
def test_a_false_until_is_decided_when_its_left_side_fails_or_its_window_closes_and_the_right_side_is_known(
        spec: str, end_s: int, i: int, decided_s: int) -> None:
    pos = Positions.points(np.arange(5, dtype=np.int64) * S, end_s * S)
    f = parse(spec)
    assert decided_times(f, pos, evaluate_at_points(f, pos, UNTIL))[f][i] == decided_s * S


def test_an_until_margin_is_traced_inside_its_window_even_when_the_right_side_has_that_value_later() -> None:
    # q U[0,1] p at 0 s: max(p(0), min(p(1), q(0))) = min(0.9, 0.4): q's 0.4 at 0 s, though p is 0.4 at 3 s
    f = parse("q U[0,1] p")
    values = evaluate_at_points(f, FIVE, {"q": _values(0.4, 1, 1, 1, 1), "p": _values(-1, 0.9, 0.5, 0.4, 0.2)})
    assert margin_source(f, 0, "lo", FIVE, values) == ("q", 0)
