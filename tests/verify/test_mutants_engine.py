"""The MITL engine's building blocks (``verify.monitor.engine``) and the formula's judgement per obligation
(``verify.judging.judge_formula`` and its sentences), stated exactly on small hand-made inputs: each test pins a rule
that a mutant of the code broke without any other test of the kill suite noticing (docs/property-testing.md,
"Mutation testing of the judging core")."""

from __future__ import annotations

import math
from fractions import Fraction
from pathlib import Path

import numpy as np
import pytest

from tests.verify.positions import with_gaps as _interleaved
from tubempc.mitl import Eventually, Interval, parse
from tubempc.scenario import Scenario, load_scenario
from verify.errors import SpecError
from verify.ingest.fields import SignalStream
from verify.judging import FormulaJudgement, Unknown, formula_of, judge_formula
from verify.monitor import engine
from verify.monitor.engine import Positions, Truth, evaluate, evaluate_at_points, range_reduce
from verify.semantics.timed_run import check_timed_run
from verify.signals import SignalBounds

S = 1_000_000_000
NS = Fraction(1, S)


def _truth(lo: list[float], hi: list[float] | None = None) -> Truth:
    return Truth(np.array(lo, dtype=np.float64), np.array(lo if hi is None else hi, dtype=np.float64))


def _points(n: int) -> Positions:
    """``n`` sample points 1 s apart (no gaps), observed to the last one."""
    t = np.arange(n, dtype=np.int64) * S
    return Positions(t, t.copy(), np.ones(n, dtype=bool), int(t[-1]) if n else 0)




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


# ---- judge_formula: what an undecided obligation says (verify.judging._unknown_*) ----------------------------------
ROOT = Path(__file__).resolve().parents[2]
T0 = 1_700_000_000 * S


@pytest.fixture(scope="module")
def room() -> Scenario:
    return load_scenario(ROOT / "docs" / "examples" / "diffdrive-room.yaml")


def _judge_slow(room: Scenario, spec: str, msg_s: list[float], values: list[float], *, rate_hz: float | None = None,
                pose_s: tuple[float, ...] = (0.0, 1.0, 2.0, 3.0)) -> FormulaJudgement:
    """``spec`` over the room's signal ``slow`` (/odom twist.twist.linear.x <= 0.5 m/s, messages every 0.1 s by their
    median spacing unless ``rate_hz``), the robot parked in the dock at the pose samples ``pose_s``."""
    sp = room.signals["slow"] if rate_hz is None else room.signals["slow"].model_copy(update={"rate_hz": rate_hz})
    msg_ns = T0 + np.round(np.array(msg_s, dtype=np.float64) * S).astype(np.int64)
    stream = SignalStream("slow", sp, msg_ns, np.array(values, dtype=np.float64), S // 10, "header")
    t = np.round(np.array(pose_s) * S).astype(np.int64)
    cx, cy = room.region("dock").center
    return judge_formula(parse(spec), t, np.full(t.size, cx), np.full(t.size, cy), room, time0_ns=T0,
                         max_speed_mps=0.5, streams={"slow": stream})


MEDIAN = "hold 0.15 s = 1.5 periods of 0.1 s from the median spacing of its messages"


@pytest.mark.parametrize(("spec", "msg_s", "values", "rate_hz", "pose_s", "want"), [
    # no message before the sample: the first one comes later
    ("slow", [0.5], [0.2], None, (0.0, 1.0, 2.0, 3.0),
     Unknown("slow", "slow", 0.0, 3.0, "no message of /odom before 0.00 s (its first at 0.50 s)",
             "a message of /odom by 0.00 s would decide it")),
    # the message held at the sample has no usable value
    ("slow", [0.0], [math.nan], None, (0.0, 1.0, 2.0, 3.0),
     Unknown("slow", "slow", 0.0, 3.0, "the message of /odom at 0.00 s has no usable twist.twist.linear.x (NaN, or "
             "messages at one time that disagree)", "a usable twist.twist.linear.x there would decide it")),
    ("slow", [0.5], [math.nan], None, (0.5, 1.0, 2.0, 3.0),
     Unknown("slow", "slow", 0.5, 3.0, "the message of /odom at 0.50 s has no usable twist.twist.linear.x (NaN, or "
             "messages at one time that disagree)", "a usable twist.twist.linear.x there would decide it")),
    # silent at a gap: the first silence longer than the hold in it (after the message at 1 s held at its start,
    # not after the last one at 1.5 s), unknown from when its hold ran out; the period from the messages' spacing
    ("G[0,inf) slow", [k / 10 for k in range(11)] + [1.5], [0.2] * 12, None, (0.0, 1.0, 2.0, 3.0),
     Unknown("slow", "slow", 1.15, 3.0, f"/odom silent 0.50 s after its message at 1.00 s > {MEDIAN}",
             "give signals.slow.rate_hz if /odom publishes less often")),
    # silent at a sample (F[2,2]: the sample at 2 s), the period from rate_hz
    ("F[2,2] slow", [0.0, 1.0], [0.2, 0.2], 10.0, (0.0, 1.0, 2.0, 3.0),
     Unknown("slow", "slow", 1.15, 3.0, "/odom silent 1.00 s after its message at 1.00 s > hold 0.15 s = 1.5 periods "
             "of 0.1 s from rate_hz", "messages of /odom at least every 0.15 s would decide it")),
    # every message in time, on both sides of the threshold between two samples
    ("G[0,inf) slow", [k / 10 for k in range(11)], [0.2, 0.8] * 5 + [0.2], None, (0.0, 1.0),
     Unknown("slow", "slow", 1e-9, 1.0, "twist.twist.linear.x is on both sides of <= 0.5 between the pose samples "
             f"around 0.00 s (or a message in between is missing: {MEDIAN})",
             "pose samples closer together there would decide it")),
    # exactly on the threshold everywhere (a zero margin is undecided): the whole log, whichever position the window
    # of the formula starts at
    *[(spec, [k / 10 for k in range(21)], [0.5] * 21, None, (0.0, 1.0, 2.0),
       Unknown("slow", "slow", 0.0, 2.0, "twist.twist.linear.x is on both sides of <= 0.5 between the pose samples "
               f"around 0.00 s (or a message in between is missing: {MEDIAN})",
               "pose samples closer together there would decide it"))
      for spec in ("G[0,inf) slow", "G[0.5,inf) slow", "G[1,inf) slow")],
    # ... to the last sample, 1 ns after the one before it (no gap between them)
    ("G[0,inf) slow", [k / 10 for k in range(21)], [0.5] * 21, None, (0.0, 1.0, 2.0, 2.000000001),
     Unknown("slow", "slow", 0.0, 2.000000001, "twist.twist.linear.x is on both sides of <= 0.5 between the pose "
             f"samples around 0.00 s (or a message in between is missing: {MEDIAN})",
             "pose samples closer together there would decide it")),
])
def test_an_undecided_signal_atom_says_why_and_what_would_decide_it(
        room: Scenario, *, spec: str, msg_s: list[float], values: list[float], rate_hz: float | None,
        pose_s: tuple[float, ...], want: Unknown) -> None:
    res = _judge_slow(room, spec, msg_s, values, rate_hz=rate_hz, pose_s=pose_s).whole
    assert res.verdict == "inconclusive"
    assert res.unknown == want
    assert res.explanation == want.sentence()
    assert res.to_json()["unknown"] == want.to_json()


def _judge_pose(room: Scenario, spec: str, t_s: list[float], x_m: list[float], y_m: list[float], *,
                joint: dict[str, tuple[SignalBounds, str]] | None = None) -> FormulaJudgement:
    t = np.round(np.array(t_s) * S).astype(np.int64)
    return judge_formula(parse(spec), t, np.array(x_m), np.array(y_m), room, time0_ns=T0, max_speed_mps=0.5,
                         joint_atoms=joint)


_CROSSED = ("the samples at {t0} s and {t1} s are {m0} m and -0.2 m from table's boundary, and the robot may move "
            "0.5 m between them (speed bound 0.5 m/s): it may have crossed")


@pytest.mark.parametrize(("spec", "t_s", "x_m", "y_m", "want"), [
    # an unknown pose sample (the first): the sample and the gap after it
    ("G[0,inf) !table", [0.0, 1.0, 3.0], [0.75] * 3, [math.nan, 1.4, 1.4],
     Unknown("!table", "table", 0.0, 1.0, "the pose at 0.00 s is unknown (NaN, or samples at one time that disagree)",
             "a usable pose sample there would decide it")),
    ("G[0,inf) !table", [0.5, 1.0, 3.0], [0.75] * 3, [math.nan, 1.4, 1.4],
     Unknown("!table", "table", 0.5, 1.0, "the pose at 0.50 s is unknown (NaN, or samples at one time that disagree)",
             "a usable pose sample there would decide it")),
    # an unknown pose next to the first gap
    ("G[0,inf) !table", [0.0, 1.0, 3.0], [0.75] * 3, [1.4, math.nan, 1.4],
     Unknown("!table", "table", 1e-9, 3.0, "a pose next to the gap 0.00-1.00 s is unknown (NaN or conflicting samples)",
             "usable pose samples there would decide it")),
    # 0.20 m and 0.25 m clear of the table (the disc's edge), a second apart at 0.5 m/s: the second gap
    ("G[0,inf) !table", [0.0, 0.1, 1.1], [0.75, 0.70, 0.75], [1.4] * 3,
     Unknown("!table", "table", 0.100000001, 1.1, _CROSSED.format(t0="0.10", t1="1.10", m0="-0.25"),
             "samples at most 0.9 s apart there (or a lower speed bound) would decide it")),
    # the window opens in the second gap: only that gap, not the one before it
    ("G[1.5,inf) !table", [0.0, 1.0, 2.0], [0.75] * 3, [1.4] * 3,
     Unknown("!table", "table", 1.000000001, 2.0, _CROSSED.format(t0="1.00", t1="2.00", m0="-0.2"),
             "samples at most 0.8 s apart there (or a lower speed bound) would decide it")),
])
def test_an_undecided_region_atom_says_which_samples_leave_it_open(
        room: Scenario, *, spec: str, t_s: list[float], x_m: list[float], y_m: list[float], want: Unknown) -> None:
    res = _judge_pose(room, spec, t_s, x_m, y_m).whole
    assert res.verdict == "inconclusive"
    assert res.unknown == want
    assert res.explanation == want.sentence()


def test_an_undecided_atom_of_a_joint_run_says_whose_samples_would_decide_it(room: Scenario) -> None:
    # known at the samples and over the first gap, unknown over the second
    bounds = SignalBounds(np.ones(3), np.ones(3), np.array([1.0, -math.inf]), np.array([1.0, math.inf]))
    two_docks = room.model_copy(update={"regions": [*room.regions, room.region("dock").model_copy(
        update={"name": "dock2"})]})
    cases = [
        (room, "b.dock", "robot b may have crossed the boundary of dock between its own samples (or was not observed "
         "there)", "samples of b closer together there (or a lower speed bound) would decide it"),
        (two_docks, "b.dock", "robot b may have crossed the boundary of dock or dock2 between its own samples (or was "
         "not observed there)", "samples of b closer together there (or a lower speed bound) would decide it"),
        (room, "b.slow", "b's signal slow is on both sides of its threshold or not known there",
         "samples of b closer together there (or a lower speed bound) would decide it"),
        (room, "near", "the robots may have crossed the proximity distance between their samples (or were not "
         "observed)", "samples of both robots closer together there would decide it"),
    ]
    for scenario, atom, cause, decide in cases:
        res = _judge_pose(scenario, f"G[0,inf) {atom}", [0.0, 1.0, 3.0], [0.75] * 3, [1.4] * 3,
                          joint={atom: (bounds, "m")}).whole
        assert res.verdict == "inconclusive"
        assert res.unknown == Unknown(atom, atom, 1.000000001, 3.0, cause, decide), atom


def test_a_log_without_pose_samples_decides_nothing_and_says_so(room: Scenario) -> None:
    f = parse("G[0,inf) !table & F[15,25] dock & slow")
    none = np.zeros(0)
    res = judge_formula(f, np.zeros(0, dtype=np.int64), none, none, room, time0_ns=T0, max_speed_mps=0.5)
    why = Unknown(str(f), None, None, None, "the log has no pose samples", "a log with pose samples")
    assert [(r.formula, r.role, r.window_s, r.body) for r in res.entries] == [
        (str(f), "formula", None, str(f)), ("G[0,inf) !table", "conjunct", (0.0, None), "!table"),
        ("F[15,25] dock", "conjunct", (15.0, 25.0), "dock"), ("slow", "conjunct", None, "slow")]
    for r in res.entries:
        assert (r.verdict, r.lo, r.hi, r.margin, r.margin_unit, r.margin_atom, r.margin_time_ns, r.margin_reason,
                r.first_violation_ns, r.decided_ns, r.subformula, r.reason, r.unknown, r.body_unit) == (
            "inconclusive", -math.inf, math.inf, None, None, None, None, None, None, None, r.formula,
            "no pose samples", why, None)
        assert r.curve_t_ns.shape == r.curve.shape == (0,) and r.curve_t_ns.dtype == np.int64
        assert r.curve.dtype == np.float64
        assert r.explanation == f"{f} unknown: the log has no pose samples; a log with pose samples"
    assert res.signal_t_ns.shape == res.signal.shape == (0,) and res.signal_t_ns.dtype == np.int64
    assert res.panels == res.conjuncts
    single = judge_formula(parse("dock"), np.zeros(0, dtype=np.int64), none, none, room, time0_ns=T0,
                           max_speed_mps=0.5)
    assert single.conjuncts == () and single.panels == (single.whole,)
    two = judge_formula(parse("dock & slow"), np.zeros(0, dtype=np.int64), none, none, room, time0_ns=T0,
                        max_speed_mps=0.5)
    assert [c.formula for c in two.conjuncts] == ["dock", "slow"]


def test_a_log_of_one_pose_sample_is_judged_at_it(room: Scenario) -> None:
    cx, cy = room.region("dock").center
    one = np.zeros(1, dtype=np.int64)
    res = judge_formula(parse("dock"), one, np.array([cx]), np.array([cy]), room, time0_ns=T0, max_speed_mps=0.5)
    assert res.whole.verdict == "pass" and res.whole.decided_ns == 0 and res.whole.margin_atom == "dock"


_X, _Y = 0.75, 1.4  # in the room, 0.2 m clear of the table's disc edge, far from the dock


@pytest.mark.parametrize(("spec", "t_s", "y_m", "want"), [
    # a window past the end of the log: an Eventually could still hold before the end if its window opens before it
    ("F[2,5] dock", [0.0, 1.0, 3.0], [_Y] * 3,
     Unknown("F[2,5] dock", None, 2.0, 5.0, "its window 2.00-5.00 s reaches past the end of the log at 3.00 s",
             "a log that runs to 5.00 s would decide it (or dock holding before 3.00 s)")),
    ("F[2,5] dock", [0.5, 1.0, 3.0], [_Y] * 3,  # the first sample at 0.5 s: the window from there
     Unknown("F[2,5] dock", None, 2.5, 5.5, "its window 2.50-5.50 s reaches past the end of the log at 3.00 s",
             "a log that runs to 5.50 s would decide it (or dock holding before 3.00 s)")),
    ("F[4,5] dock", [0.0, 1.0, 3.0], [_Y] * 3,
     Unknown("F[4,5] dock", None, 4.0, 5.0, "its window 4.00-5.00 s reaches past the end of the log at 3.00 s",
             "a log that runs to 5.00 s would decide it")),
    ("F[3,5] dock", [0.0, 1.0, 3.0], [_Y] * 3,  # opens as the log ends: nothing before the end could decide it
     Unknown("F[3,5] dock", None, 3.0, 5.0, "its window 3.00-5.00 s reaches past the end of the log at 3.00 s",
             "a log that runs to 5.00 s would decide it")),
    # times said to the nanosecond, whatever the bounds' digits beyond it
    ("F[2.0000000004,5.0000000004] dock", [0.0, 1.0, 3.0], [_Y] * 3,
     Unknown("F[2.0000000004,5.0000000004] dock", None, 2.0, 5.0, "its window 2.00-5.00 s reaches past the end of "
             "the log at 3.00 s", "a log that runs to 5.00 s would decide it (or dock holding before 3.00 s)")),
    ("in_room U[0.0000000004,5.0000000004] dock", [0.5, 1.0, 3.0], [_Y] * 3,
     Unknown("in_room U[0.0000000004,5.0000000004] dock", None, 0.5, 5.5, "undecided at the end of the log (3.00 s)",
             "a longer log would decide it")),
    ("G[1,5] !dock", [0.0, 1.0, 3.0], [_Y] * 3,
     Unknown("G[1,5] !dock", None, 1.0, 5.0, "its window 1.00-5.00 s reaches past the end of the log at 3.00 s",
             "a log that runs to 5.00 s would decide it")),
    # an Until left open, bounded and unbounded
    ("in_room U[0,5] dock", [0.0, 1.0, 3.0], [_Y] * 3,
     Unknown("in_room U[0,5] dock", None, 0.0, 5.0, "undecided at the end of the log (3.00 s)",
             "a longer log would decide it")),
    ("in_room U[0,inf) dock", [0.5, 1.0, 3.0], [_Y, math.nan, _Y],
     Unknown("in_room U[0,inf) dock", None, 0.5, None, "undecided at the end of the log (3.00 s)",
             "a longer log would decide it")),
    # a Next without its next sample
    ("X[0,5] !dock", [0.5], [_Y],
     Unknown("X[0,5] !dock", None, 0.5, 0.5, "no sample after 0.50 s within its window before the log ends at 0.50 s",
             "a later sample would decide it")),
    ("G[0,inf) X[0,5] !dock", [0.5, 1.0, 3.0], [_Y] * 3,
     Unknown("X[0,5] !dock", None, 0.500000001, 3.0,
             "no sample after 0.50 s within its window before the log ends at 3.00 s",
             "a later sample would decide it")),
])
def test_an_undecided_temporal_operator_says_what_log_would_decide_it(
        room: Scenario, spec: str, t_s: list[float], y_m: list[float], want: Unknown) -> None:
    res = _judge_pose(room, spec, t_s, [_X] * len(t_s), y_m).whole
    assert res.verdict == "inconclusive"
    assert res.unknown == want
    assert res.explanation == want.sentence()
    assert res.to_json()["unknown"] == want.to_json()


def _entry_json(room: Scenario, spec: str, x_m: list[float]) -> list[dict[str, object]]:
    t = np.round(np.array([0.0, 0.1, 0.25, 0.3]) * S).astype(np.int64)
    res = judge_formula(parse(spec), t, np.array(x_m), np.full(4, _Y), room, time0_ns=T0, max_speed_mps=0.5)
    return [r.to_json() for r in res.entries]


_TIMING = "-inf: decided by constants or timing (a window or next sample), not by an atom's value"


def test_each_obligation_states_its_times_in_seconds_and_its_window(room: Scenario) -> None:
    """Samples at 0, 0.1, 0.25 and 0.3 s (irregular: the general engine), 0.5 m/s."""
    # 0.23 m and 0.20 m clear of the table at 0.1 s and 0.25 s, 0.15 s apart: at least (0.23 + 0.20) / 2 - 0.5 *
    # 0.15 / 2 = 0.1775 m clear in between (the margin of the gap after the sample at 0.1 s)
    safe, = _entry_json(room, "G[0,inf) !table", [0.70, 0.72, 0.75, 0.74])
    assert safe == {"formula": "G[0,inf) !table", "role": "formula", "verdict": "pass",
                    "margin": pytest.approx(0.1775, abs=1e-12), "margin_unit": "m", "margin_atom": "table",
                    "margin_time": 0.1, "margin_reason": None, "first_violation_time": None, "decided_at": 0.3,
                    "subformula": None, "reason": None, "unknown": None, "window": [0.0, None], "explanation": None}
    # into the table: 0.05 m in at 0.1 s (the first violation), 0.15 m at 0.3 s (the margin)
    hit, = _entry_json(room, "G[0,inf) !table", [0.9, 1.0, 1.05, 1.1])
    assert hit == {"formula": "G[0,inf) !table", "role": "formula", "verdict": "fail",
                   "margin": pytest.approx(-0.15, abs=1e-12), "margin_unit": "m", "margin_atom": "table",
                   "margin_time": 0.3, "margin_reason": None, "first_violation_time": 0.1, "decided_at": 0.1,
                   "subformula": "!table", "reason": "its negation holds", "unknown": None, "window": [0.0, None],
                   "explanation": "violated at 0.10 s: !table (its negation holds); margin -0.15 m (table at 0.30 s)"}
    whole, _, bounded, unbounded = _entry_json(
        room, "G[0,inf) !table & in_room U[0,5] dock & in_room U[1,inf) dock", [0.70, 0.72, 0.75, 0.74])
    assert (whole["window"], bounded["window"], unbounded["window"]) == (None, [0.0, 5.0], [1.0, None])
    assert (bounded["verdict"], bounded["margin_time"], bounded["margin_reason"], bounded["first_violation_time"],
            bounded["decided_at"]) == ("inconclusive", None, None, None, None)
    assert unbounded == {"formula": "in_room U[1,inf) dock", "role": "conjunct", "verdict": "fail", "margin": None,
                         "margin_unit": None, "margin_atom": None, "margin_time": None, "margin_reason": _TIMING,
                         "first_violation_time": 0.0, "decided_at": 0.3, "subformula": "in_room U[1,inf) dock",
                         "reason": "violated", "unknown": None, "window": [1.0, None],
                         "explanation": f"violated at 0.00 s: in_room U[1,inf) dock (violated); no finite margin "
                                        f"({_TIMING})"}


def test_a_signal_without_a_unit_has_its_margin_in_the_field_unit(room: Scenario) -> None:
    room_no_unit = room.model_copy(update={"signals": {
        "slow": room.signals["slow"].model_copy(update={"unit": None})}})
    res = _judge_slow(room_no_unit, "G[0,inf) slow", [k / 10 for k in range(11)], [0.2] * 11, pose_s=(0.0, 1.0))
    assert (res.whole.verdict, res.whole.margin_atom, res.whole.margin_unit, res.whole.body_unit) == (
        "pass", "slow", "field unit", "field unit")
    assert res.whole.margin == pytest.approx(0.3)


@pytest.mark.parametrize(("unknown", "sentence"), [
    (Unknown("!table", "table", 1e-9, 3.0, "c", "d"), "table unknown 0.00-3.00 s: c; d"),
    (Unknown("X p", None, 0.5, 0.5, "c", "d"), "X p unknown at 0.50 s: c; d"),
    (Unknown("p", "p", 1.0, 1.004, "c", "d"), "p unknown at 1.00 s: c; d"),  # within 5 ms: one time
    (Unknown("p", "p", 1.0, 1.006, "c", "d"), "p unknown 1.00-1.01 s: c; d"),
    (Unknown("p", "p", 0.0, 0.005, "c", "d"), "p unknown 0.00-0.01 s: c; d"),  # 5 ms: two times
    (Unknown("p U q", None, 0.5, None, "c", "d"), "p U q unknown: c; d"),
    (Unknown("F p", None, None, None, "c", "d"), "F p unknown: c; d"),
])
def test_an_unknown_is_said_in_one_sentence_naming_its_atom_and_when(unknown: Unknown, sentence: str) -> None:
    assert unknown.sentence() == sentence


def test_the_formula_judged_names_atoms_that_mean_nothing_in_the_scenario(room: Scenario) -> None:
    with pytest.raises(SpecError) as err:
        formula_of(room, "G b.dock")
    assert str(err.value) == ("formula G[0,inf) b.dock: qualified atom(s) b.dock need a robots: block (this scenario "
                              "has one robot: write the atom without the robot's name)")
    with pytest.raises(SpecError) as err:
        formula_of(room, "F nowhere & G (zz | dock)")
    assert str(err.value) == ("formula F[0,inf) nowhere & G[0,inf) (zz | dock): proposition(s) nowhere, zz label no "
                              "region and name no signal of scenario 'diffdrive-room'")
    assert formula_of(room, "dock & slow") == parse("dock & slow")
    assert formula_of(room, None) == parse(room.spec)


def _positions(start: list[int], stop: list[int], point: list[bool], end: int) -> Positions:
    return Positions(np.array(start, dtype=np.int64), np.array(stop, dtype=np.int64), np.array(point), end)


@pytest.mark.parametrize(("start", "stop", "point", "end", "message"), [
    ([0, 5], [0, 5], [True, True, True], 5, "start_ns, stop_ns and is_point must have the same length"),
    ([0, 5], [1, 4], [False, False], 5, "position spans must be non-empty and sorted"),  # 5 > 4: empty span
    ([0, 1], [2, 3], [False, False], 3, "position spans must be non-empty and sorted"),  # overlapping spans
    ([0, 2, 3], [1, 4, 5], [False, False, False], 5, "position spans must be non-empty and sorted"),
    ([0, 0], [0, 5], [True, False], 5, "a gap span must not touch its neighbours"),
    ([0, 1, 5], [0, 5, 5], [True, False, True], 5, "a gap span must not touch its neighbours"),
    ([0, 5, 7], [0, 5, 7], [True, True, True], 6, "end_ns=6 is before the last position (7)"),
])
def test_positions_refuse_spans_out_of_order_and_say_why(start: list[int], stop: list[int], point: list[bool],
                                                         end: int, message: str) -> None:
    with pytest.raises(ValueError, match=r"^" + message.replace("(", r"\(").replace(")", r"\)") + "$"):
        _positions(start, stop, point, end)


def test_positions_allow_points_at_one_instant_and_a_gap_between_samples() -> None:
    assert _positions([0, 0, 1, 5], [0, 0, 4, 5], [True, True, False, True], 5).size == 4


def test_each_obligation_carries_its_bounds_its_bodys_curve_and_unit(room: Scenario) -> None:
    """slow's margin falls from 0.3 m/s at 0 s to 0.1 m/s at 1 s (messages every 0.1 s); the robot in the dock."""
    values = [0.2 + 0.02 * k for k in range(11)]
    res = _judge_slow(room, "G[0,inf) slow & F[0,1] (dock | slow) & true", [k / 10 for k in range(11)], values,
                      pose_s=(0.0, 1.0))
    whole, g, _, true = res.entries
    assert [(r.body, r.body_unit) for r in res.entries] == [
        (str(whole.formula), "mixed: dock m, slow m/s"), ("slow", "m/s"), ("dock | slow", "mixed: dock m, slow m/s"),
        ("true", None)]
    for r in res.entries:
        assert r.curve_t_ns.tolist() == [0, S] and r.curve.dtype == np.float64
    assert g.curve.tolist() == pytest.approx([0.3, 0.1])  # the body's guaranteed margin at each sample, not the G's
    assert [g.lo, g.hi] == pytest.approx([0.1, 0.1])
    assert (true.lo, true.hi, true.margin, true.margin_reason) == (math.inf, math.inf, None, "+inf: decided by "
                                                                   "constants or timing (a window or next sample), "
                                                                   "not by an atom's value")
    assert res.signal.tolist() == whole.curve.tolist() == pytest.approx([0.1, 0.1])
    assert res.signal_t_ns.tolist() == [0, S] and res.signal.dtype == np.float64
    # a field value beyond float64's range at 1 s: no finite margin, and where it comes from
    inf = _judge_slow(room, "G[0,inf) slow", [k / 10 for k in range(11)], [0.2] * 10 + [math.inf],
                      pose_s=(0.0, 1.0)).whole
    assert (inf.verdict, inf.margin, inf.margin_unit, inf.margin_atom, inf.margin_reason) == (
        "fail", None, None, "slow",
        "-inf: the margin of slow at 1.00 s is -inf (a position, field value or region size at or beyond float64's "
        "range)")


def test_an_until_over_more_positions_than_its_robustness_limit_says_why_it_has_no_margin(room: Scenario) -> None:
    n = engine.UNTIL_ROBUSTNESS_LIMIT // 2 + 1  # 10,001 samples, 10,000 gaps: one position over the limit
    t = np.arange(n, dtype=np.int64) * (S // 10) + np.arange(n, dtype=np.int64) % 2  # irregular: the general engine
    x, y = np.full(n, _X), np.full(n, _Y)
    big = judge_formula(parse("in_room U[0,0.01] dock"), t, x, y, room, time0_ns=T0, max_speed_mps=0.5).whole
    assert (big.verdict, big.margin, big.margin_reason) == (
        "fail", None, "Until over more than 20000 positions: only its verdict is computed, not its robustness")
    t[-1] = t[-2] + 1  # the last two samples 1 ns apart: no gap between them, 20,000 positions, at the limit
    at_limit = judge_formula(parse("false & in_room U[0,0.01] dock"), t, x, y, room, time0_ns=T0,
                             max_speed_mps=0.5).whole
    assert (at_limit.verdict, at_limit.margin_reason) == ("fail", _TIMING)


def test_a_crossing_under_a_zero_speed_bound_asks_for_no_closer_samples() -> None:
    """A robot that left the room between two samples, judged with a speed bound of 0 (the bound is the displacement
    alone): the window inside the gap is undecided, and what would decide it is said without dividing by the bound."""
    room = load_scenario(Path(__file__).resolve().parents[2] / "docs" / "examples" / "diffdrive-room.yaml")
    judged = judge_formula(parse("F[0.4,0.6] in_room"), np.array([0, 10**9], dtype=np.int64), np.array([1.0, 4.0]),
                           np.array([1.0, 1.0]), room, time0_ns=0, max_speed_mps=0.0)
    unknown = judged.whole.unknown
    assert judged.whole.verdict == "inconclusive" and unknown is not None
    assert unknown.cause == ("the samples at 0.00 s and 1.00 s are +0.75 m and -1.05 m from room's boundary, and the "
                             "robot may move 3 m between them (speed bound 0 m/s): it may have crossed")
    assert unknown.decide == "samples at most 0 s apart there (or a lower speed bound) would decide it"


def test_a_signal_silent_inside_a_gap_is_told_silent_even_if_a_message_ends_the_gap(room: Scenario) -> None:
    """Messages every 0.1 s to 1 s, none until one at the gap's last instant (2 s - 1 ns): the stretch is unknown
    because the signal fell silent after 1 s (it was told "on both sides of the threshold", from the last message)."""
    msgs = [k / 10 for k in range(11)] + [2.0 - 1e-9]
    res = _judge_slow(room, "G[0,inf) slow", msgs, [0.2] * 12, rate_hz=None, pose_s=(0.0, 1.0, 2.0, 3.0)).whole
    assert res.unknown is not None
    assert res.unknown.cause == f"/odom silent 1.00 s after its message at 1.00 s > {MEDIAN}"
    assert res.unknown.from_s == 1.15


_BASE = [k / 10 for k in range(11)]  # a message every 0.1 s to 1 s: every position before the gap 1-2 s known
RATE = "hold 0.15 s = 1.5 periods of 0.1 s from rate_hz"


@pytest.mark.parametrize(("spec", "msg_s", "values", "pose_s", "cause", "from_s"), [
    # the message held at the gap's start is the first silent one, not one before it
    ("F[1.2,1.3] slow", [0.0, 0.1, 0.2, 0.3, 0.4, 1.0, 1.5], [0.2] * 7, (0.0, 1.0, 2.0, 3.0),
     f"/odom silent 0.50 s after its message at 1.00 s > {RATE}", 1.15),
    # ... also when it is the stream's first message
    ("F[0.7,0.8] slow", [0.0, 0.5], [0.2, 0.2], (0.0, 1.0, 2.0), f"/odom silent 0.50 s after its message at 0.00 s > "
     f"{RATE}", 0.15),
    # ... and when it came 1 ns into the gap
    ("F[1.2,1.3] slow", [k / 10 for k in range(9)] + [1.000000001, 1.5], [0.2] * 11, (0.0, 1.0, 2.0, 3.0),
     f"/odom silent 0.50 s after its message at 1.00 s > {RATE}", 1.150000001),
    # the first silence longer than the hold, after shorter ones (one of exactly the hold: not longer)
    ("G[0,inf) slow", [*_BASE, 1.1, 1.2, 1.999999999], [0.2] * 14, (0.0, 1.0, 2.0, 3.0),
     f"/odom silent 0.80 s after its message at 1.20 s > {RATE}", 1.35),
    ("G[0,inf) slow", [*_BASE, 1.15, 1.2, 1.999999999], [0.2] * 14, (0.0, 1.0, 2.0, 3.0),
     f"/odom silent 0.80 s after its message at 1.20 s > {RATE}", 1.35),
    # every message in time within the gap (the one after it, at 2.5 s, does not count; nor does a last one held
    # exactly to the gap's end): on both sides of the threshold
    ("G[1.2,1.3] slow", _BASE + [1.1 + k / 10 for k in range(9)] + [2.5], [0.2] * 11 + [0.8, 0.2] * 4 + [0.8, 0.2],
     (0.0, 1.0, 2.0, 3.0), "twist.twist.linear.x is on both sides of <= 0.5 between the pose samples around 1.00 s "
     f"(or a message in between is missing: {RATE})", 1.000000001),
    ("G[1.2,1.3] slow", _BASE + [1.1 + k / 10 for k in range(7)] + [1.849999999], [0.2] * 11 + [0.8, 0.2] * 4,
     (0.0, 1.0, 2.0, 3.0), "twist.twist.linear.x is on both sides of <= 0.5 between the pose samples around 1.00 s "
     f"(or a message in between is missing: {RATE})", 1.000000001),
    # a message without a usable value at the gap's last instant
    ("G[0,inf) slow", _BASE + [1.1 + k / 10 for k in range(9)] + [1.999999999], [0.2] * 20 + [math.nan],
     (0.0, 1.0, 2.0, 3.0), "the message of /odom at 2.00 s has no usable twist.twist.linear.x (NaN, or messages at "
     "one time that disagree)", 1.000000001),
])
def test_an_undecided_signal_over_a_gap_is_told_by_its_first_silence_in_the_gap(
        room: Scenario, *, spec: str, msg_s: list[float], values: list[float], pose_s: tuple[float, ...], cause: str,
        from_s: float) -> None:
    res = _judge_slow(room, spec, msg_s, values, rate_hz=10.0, pose_s=pose_s).whole
    assert res.verdict == "inconclusive" and res.unknown is not None
    assert (res.unknown.cause, res.unknown.from_s) == (cause, from_s)
