"""The judging core's small rules (``verify.judging``), each pinned: the overall verdict's order (fail, stream
problems, undecided checks, partial log, pass), the margin as the certificate states it, the tube tolerance, the
one-sentence explanation of a check."""

from __future__ import annotations

import math

import pytest

from tubempc.scenario import builtin_scenario
from verify.judging import (
    POSITION_ROUNDING_M,
    check_explanation,
    margin_entry,
    overall_verdict,
    timed_run_explanation,
    tube_tolerance_m,
)
from verify.semantics.timed_run import TimedRunVerdict


def test_no_check_is_never_a_pass() -> None:
    assert overall_verdict([], partial=False) == ("inconclusive", "no check was run: nothing is certified")


def test_a_fail_wins_over_everything() -> None:
    checks = [("a", "pass"), ("b", "inconclusive"), ("c", "fail")]
    assert overall_verdict(checks, partial=True, problems={"pose": "x"}) == ("fail", None)


def test_stream_problems_come_before_undecided_checks_and_are_sorted() -> None:
    got = overall_verdict([("a", "pass"), ("b", "inconclusive")], partial=True, problems={"z": "late", "pose": "bad"})
    assert got == ("inconclusive", "pose: bad; z: late")


def test_undecided_checks_are_named_in_order() -> None:
    got = overall_verdict([("a", "inconclusive"), ("b", "pass"), ("c", "inconclusive")], partial=True)
    assert got == ("inconclusive", "check(s) not decided: a, c")


def test_a_partial_log_is_never_a_pass() -> None:
    assert overall_verdict([("a", "pass")], partial=True, problems={}) == (
        "inconclusive", "the log is partial (salvaged): a partial log is never certified as pass")


def test_every_check_passing_on_a_whole_log_is_a_pass() -> None:
    assert overall_verdict([("a", "pass"), ("b", "pass")], partial=False) == ("pass", None)


@pytest.mark.parametrize(("verdict", "margin", "reason", "want"), [
    ("pass", 0.25, None, (0.25, None)),
    ("fail", -0.0, "ignored", (0.0, None)),  # a finite margin is stated, whatever the reason
    ("fail", None, "own reason", (None, "own reason")),
    ("fail", math.inf, "own reason", (None, "own reason")),
    ("inconclusive", None, None, (None, None)),
    ("pass", None, None, (None, None)),
    ("fail", math.nan, None, (None, "the margin is not a number (NaN data)")),
    ("fail", None, None, (None, "the check computed no margin")),
])
def test_margin_entry(verdict: str, margin: float | None, reason: str | None,
                      want: tuple[float | None, str | None]) -> None:
    assert margin_entry(verdict, margin, reason=reason) == want


@pytest.mark.parametrize(("margin", "sign"), [(math.inf, "+inf"), (-math.inf, "-inf")])
@pytest.mark.parametrize("verdict", ["pass", "fail", "inconclusive"])
def test_an_infinite_margin_is_always_said(margin: float, sign: str, verdict: str) -> None:
    assert margin_entry(verdict, margin) == (None, f"the margin is {sign}: a value at or beyond float64's range (a "
                                                   "position, field value or region size that overflowed)")


def test_margin_entry_returns_a_python_float() -> None:
    import numpy as np

    value, _ = margin_entry("pass", np.float64(0.5))
    assert type(value) is float


def test_tube_tolerance_is_three_sigma_plus_rounding() -> None:
    sc = builtin_scenario()
    sc = sc.model_copy(update={"mocap": sc.mocap.model_copy(update={"noise_std": 0.002})})
    assert tube_tolerance_m(sc) == pytest.approx(0.006 + POSITION_ROUNDING_M, abs=0, rel=1e-15)
    assert POSITION_ROUNDING_M == 1e-9


def test_check_explanation() -> None:
    assert check_explanation({"verdict": "pass"}) is None
    got = check_explanation({"verdict": "fail", "first_violation_time": 1.234, "region": "R6", "margin": -0.05,
                             "margin_unit": "m"})
    assert got == "violated at 1.23 s (region R6); margin -0.05 m"
    got = check_explanation({"verdict": "fail", "margin": None, "margin_reason": "why"})
    assert got == "violated; no finite margin (why)"
    got = check_explanation({"verdict": "inconclusive", "reason": "no nominal state logged: tube"})
    assert got == "no nominal state logged: tube; log the MPC's nominal state on topics.nominal"
    got = check_explanation({"verdict": "inconclusive"})
    assert got == "not decided; more or better data would decide it"


def test_check_explanation_names_what_was_violated_and_states_a_margin_without_a_unit_as_is() -> None:
    got = check_explanation({"verdict": "fail", "first_violation_time": 2, "component": "angular.z", "margin": -0.5})
    assert got == "violated at 2.00 s (component angular.z); margin -0.5"
    got = check_explanation({"verdict": "fail", "region": "R1", "pair": "a-b", "component": None, "margin": -1.0,
                             "margin_unit": None})
    assert got == "violated (region R1, pair a-b); margin -1"


@pytest.mark.parametrize(("reason", "decide"), [
    ("no nominal state logged: tube containment cannot be checked", "log the MPC's nominal state on topics.nominal"),
    ("no cmd_vel logged: the input box cannot be checked", "log the applied commands on topics.cmd_vel"),
    ("no samples", "a log with pose samples"),
    ("the robot may have crossed the limit between samples",
     "samples closer together there (or a lower speed bound) would decide it"),
    ("a NaN position", "usable values there would decide it"),
    ("3 pose sample(s) without a usable nominal", "a nominal sample within half a MoCap period of each pose sample"),
])
def test_an_undecided_check_says_what_would_decide_it(reason: str, decide: str) -> None:
    assert check_explanation({"verdict": "inconclusive", "reason": reason}) == f"{reason}; {decide}"


def test_timed_run_explanation_says_each_verdict_in_one_sentence() -> None:
    assert timed_run_explanation(TimedRunVerdict("pass", "F[0,5] a"), 9.0) is None
    fail = TimedRunVerdict("fail", "F[0,5] a", "F[0,5] a", 5.0, "never satisfied within its window", -1.25)
    assert timed_run_explanation(fail, 9.0) == ("violated at 5.00 s: F[0,5] a (never satisfied within its window); "
                                                "margin -1.25 s")
    fail = TimedRunVerdict("fail", "G !b", "b", None, "false here", None)
    assert timed_run_explanation(fail, 9.0) == "violated: b (false here); no finite margin"
    empty = TimedRunVerdict("inconclusive", "F a", "F a", None, "the timed run is empty")
    assert timed_run_explanation(empty, 9.0) == (
        "the timed run is empty: the robot disc was never fully inside a region; a run that enters a region would "
        "decide it")
    window = TimedRunVerdict("inconclusive", "F[0,20] a", "F[0,20] a", 0.0,
                             "the window reaches past the end of the log")
    assert timed_run_explanation(window, 9.0) == (
        "F[0,20] a: its window reaches past the end of the log at 9.00 s; a longer log would decide it")
    unknown = TimedRunVerdict("inconclusive", "G a", "a", 3.5, "unknown here (missing or ambiguous data)")
    assert timed_run_explanation(unknown, 9.0) == (
        "a unknown at 3.50 s: unknown here (missing or ambiguous data); data that decides its atoms there would decide "
        "it")
    unknown = TimedRunVerdict("inconclusive", "G a", "a", None, None)
    assert timed_run_explanation(unknown, 9.0) == "a unknown: None; data that decides its atoms there would decide it"
