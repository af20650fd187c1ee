"""The non-temporal checks (``verify.checks``) on hand-made samples: the verdict, the worst margin, the first
violation and the details each check states, at the edges of each rule (a margin of exactly 0, NaN samples, a gap the
robot may have crossed, unmatched nominal samples, one NaN component beside a known violation)."""

from __future__ import annotations

import math

import numpy as np
import pytest

from tubempc.scenario import InputLimits, builtin_scenario
from verify.checks import INPUT_TOLERANCE, check_clearance, check_input_box, check_tube, check_workspace, margin_check


def _t(*s: float) -> np.ndarray:
    return (np.asarray(s, dtype=np.float64) * 1e9).astype(np.int64)


def test_no_samples_is_inconclusive() -> None:
    r = margin_check("w", _t(), np.zeros(0), np.zeros(0), {"margin_unit": "m"})
    assert (r.name, r.verdict, r.margin, r.first_violation_ns) == ("w", "inconclusive", None, None)
    assert r.details == {"margin_unit": "m", "reason": "no samples"}


def test_a_zero_margin_sample_is_not_a_violation_and_the_least_margin_is_reported_on_fail() -> None:
    r = margin_check("w", _t(0, 1, 2), np.array([0.5, 0.0, 0.3]), np.zeros(2), {})
    assert (r.verdict, r.margin) == ("pass", 0.0)
    r = margin_check("w", _t(0, 1, 2, 3), np.array([0.5, -0.1, -0.4, 0.2]), np.zeros(3), {})
    assert (r.verdict, r.margin, r.first_violation_ns) == ("fail", -0.4, 1_000_000_000)


def test_a_pass_states_the_guaranteed_margin_between_samples_and_the_least_sample_margin() -> None:
    # gaps: (1.0 + 0.8 - 0.4) / 2 = 0.7 and (0.8 + 0.6 - 1.0) / 2 = 0.2 < the least sample margin 0.6
    r = margin_check("w", _t(0, 1, 2), np.array([1.0, 0.8, 0.6]), np.array([0.4, 1.0]), {"margin_unit": "m"})
    assert (r.verdict, r.first_violation_ns) == ("pass", None)
    assert r.margin == pytest.approx(0.2)
    assert r.details == {"margin_unit": "m", "sample_margin_m": 0.6}
    # the least sample margin is the guarantee when every gap is wider
    r = margin_check("w", _t(0, 1), np.array([0.3, 0.5]), np.array([0.1]), {})
    assert r.margin == pytest.approx(0.3)


def test_a_gap_the_robot_may_have_crossed_is_inconclusive_and_says_where() -> None:
    # second gap: (0.2 + 0.1 - 0.5) / 2 = -0.1; a gap bound of exactly 0 would still pass
    r = margin_check("w", _t(0, 1, 2), np.array([0.3, 0.2, 0.1]), np.array([0.5, 0.5]), {"margin_unit": "m"})
    assert (r.verdict, r.margin, r.first_violation_ns) == ("inconclusive", 0.1, None)
    assert r.details == {"margin_unit": "m", "guaranteed_margin_m": None,
                         "reason": "the robot may have crossed the limit between samples at 1000000000 ns and "
                                   "2000000000 ns (bound -0.1000 m)"}
    r = margin_check("w", _t(0, 1), np.array([0.25, 0.25]), np.array([0.5]), {})
    assert (r.verdict, r.margin) == ("pass", 0.0)


def test_nan_samples_are_counted_and_never_pass() -> None:
    r = margin_check("w", _t(0, 1, 2, 3), np.array([0.5, np.nan, np.nan, 0.4]), np.zeros(3), {})
    assert (r.verdict, r.margin) == ("inconclusive", 0.4)
    assert r.details["reason"].startswith("2 NaN sample(s); the robot may have crossed the limit between samples at "
                                          "0 ns and 1000000000 ns")
    r = margin_check("w", _t(0, 1), np.array([np.nan, np.nan]), np.zeros(1), {})
    assert (r.verdict, r.margin) == ("inconclusive", None)
    # one NaN sample and no gap: the reason is the NaN alone
    r = margin_check("w", _t(0), np.array([np.nan]), np.zeros(0), {})
    assert r.details["reason"] == "1 NaN sample(s)"
    # a violation elsewhere wins over NaN samples; the fail's margin ignores them
    r = margin_check("w", _t(0, 1, 2), np.array([np.nan, -0.2, 0.1]), np.zeros(2), {})
    assert (r.verdict, r.margin, r.first_violation_ns) == ("fail", -0.2, 1_000_000_000)


def test_an_overflowed_margin_fails_with_minus_inf() -> None:
    r = margin_check("w", _t(0, 1), np.array([-np.inf, 0.1]), np.zeros(1), {})
    assert (r.verdict, r.margin, r.first_violation_ns) == ("fail", -math.inf, 0)


def _nominal(*xy: tuple[float, float, float]) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    t = [p[0] for p in xy]
    return _t(*t), np.array([p[1] for p in xy], dtype=np.float64), np.array([p[2] for p in xy], dtype=np.float64)


def test_tube_without_a_nominal_state_is_inconclusive() -> None:
    for nominal in (None, _nominal()):
        r = check_tube(_t(0, 1), np.zeros(2), np.zeros(2), nominal, radius_m=0.1, tolerance_m=0.01, match_ns=10)
        assert (r.name, r.verdict, r.margin, r.first_violation_ns) == ("tube", "inconclusive", None, None)
        assert r.details["reason"] == "no nominal state logged: tube containment cannot be checked"
        assert r.details["checked_at"] == "logged samples (pose matched to the nearest nominal sample)"
        assert (r.details["radius_m"], r.details["noise_tolerance_m"], r.details["margin_unit"]) == (0.1, 0.01, "m")


def test_tube_matches_each_pose_to_the_nearest_nominal_sample() -> None:
    # poses at 0, 1, 2 s; nominal at 0.1 s (x=0), 0.8 s (x=5: nearest to 1 s), 2.6 s (x=0.05, nearest to 2 s)
    nominal = _nominal((0.1, 0.0, 0.0), (0.8, 5.0, 0.0), (2.6, 0.05, 0.0))
    x = np.array([0.0, 5.0, 0.0])
    r = check_tube(_t(0, 1, 2), x, np.zeros(3), nominal, radius_m=0.1, tolerance_m=0.0, match_ns=700_000_000)
    assert (r.name, r.verdict) == ("tube", "pass")
    assert r.margin == pytest.approx(0.05)
    assert r.details["max_deviation_m"] == pytest.approx(0.05)
    assert (r.details["matched_samples"], r.details["unmatched_samples"]) == (3, 0)
    # a tie between two nominal samples takes the earlier one
    nominal = _nominal((0.5, 0.0, 0.0), (1.5, 1.0, 0.0))
    r = check_tube(_t(1), np.array([0.0]), np.zeros(1), nominal, radius_m=0.1, tolerance_m=0.0, match_ns=10**9)
    assert (r.verdict, r.margin) == ("pass", 0.1)
    # a pose before the first nominal sample matches it
    nominal = _nominal((2.0, 0.0, 0.0), (3.0, 1.0, 0.0))
    r = check_tube(_t(0), np.array([0.0]), np.zeros(1), nominal, radius_m=0.1, tolerance_m=0.0, match_ns=2 * 10**9)
    assert (r.verdict, r.margin) == ("pass", 0.1)
    # one nominal sample serves every pose
    nominal = _nominal((0.0, 0.0, 0.0))
    r = check_tube(_t(0, 1), np.array([0.0, 0.05]), np.zeros(2), nominal, radius_m=0.1, tolerance_m=0.0,
                   match_ns=10**9)
    assert r.verdict == "pass"
    assert r.margin == pytest.approx(0.05)


def test_tube_fails_beyond_radius_plus_tolerance_and_not_at_it() -> None:
    nominal = _nominal((0.0, 0.0, 0.0), (1.0, 0.0, 0.0), (2.0, 0.0, 0.0))
    y = np.array([0.0, 0.25, 0.5])
    r = check_tube(_t(0, 1, 2), np.zeros(3), y, nominal, radius_m=0.2, tolerance_m=0.05, match_ns=1)
    assert (r.name, r.verdict, r.first_violation_ns) == ("tube", "fail", 2_000_000_000)
    assert r.margin == pytest.approx(-0.25)
    assert r.details["max_deviation_m"] == pytest.approx(0.5)
    r = check_tube(_t(0, 1), np.zeros(2), y[:2], nominal, radius_m=0.2, tolerance_m=0.05, match_ns=1)
    assert (r.verdict, r.margin) == ("pass", 0.0)
    # the deviation is the distance to the nominal position, in y as in x
    nominal = _nominal((0.0, 0.0, 1.0))
    r = check_tube(_t(0), np.zeros(1), np.array([1.05]), nominal, radius_m=0.1, tolerance_m=0.0, match_ns=1)
    assert r.verdict == "pass"
    assert r.margin == pytest.approx(0.05)


def test_tube_poses_without_a_nominal_sample_within_match_are_inconclusive() -> None:
    nominal = _nominal((0.0, 0.0, 0.0), (1.0, 0.0, 0.0))
    t = np.array([0, 1_000_000_000, 1_500_000_000], dtype=np.int64)
    r = check_tube(t, np.zeros(3), np.array([0.01, 0.02, 0.0]), nominal, radius_m=0.1, tolerance_m=0.0,
                   match_ns=500_000_000)
    assert r.verdict == "pass"  # 0.5 s from the nearest nominal sample: matched (at most match_ns)
    r = check_tube(t, np.zeros(3), np.array([0.01, 0.02, 0.0]), nominal, radius_m=0.1, tolerance_m=0.0,
                   match_ns=499_999_999)
    assert (r.name, r.verdict, r.first_violation_ns) == ("tube", "inconclusive", None)
    assert r.margin == pytest.approx(0.08)
    assert (r.details["matched_samples"], r.details["unmatched_samples"]) == (2, 1)
    assert r.details["reason"] == "1 pose sample(s) without a usable nominal sample or with NaN positions"
    # a violation is still a fail beside unmatched poses
    r = check_tube(t, np.zeros(3), np.array([0.5, 0.0, 0.0]), nominal, radius_m=0.1, tolerance_m=0.0,
                   match_ns=499_999_999)
    assert (r.verdict, r.first_violation_ns) == ("fail", 0)
    assert r.margin == pytest.approx(-0.4)


def _box(model: str = "holonomic") -> InputLimits:
    if model == "holonomic":
        return InputLimits(model="holonomic", max_abs=(0.2, 0.3, 0.4))
    return InputLimits(model="unicycle", max_abs=(0.5, 1.0), lateral_tolerance=0.01)


def test_input_box_without_commands_is_inconclusive() -> None:
    for t, u in ((None, None), (_t(), np.zeros((0, 3))), (_t(0), None)):
        r = check_input_box(t, u, _box())
        assert (r.name, r.verdict, r.margin, r.first_violation_ns) == ("input_box", "inconclusive", None, None)
        assert r.details["reason"] == "no cmd_vel logged"
        assert r.details["bounds"] == {"linear.x": 0.2, "linear.y": 0.3, "angular.z": 0.4}
        assert (r.details["tolerance"], r.details["margin_unit"]) == (INPUT_TOLERANCE, "m/s or rad/s")
        assert r.details["frame"] == "body (as logged)"


def test_input_box_names_the_tightest_component_and_its_unit() -> None:
    u = np.array([[0.1, -0.22, 0.0], [-0.18, 0.0, 0.36]])
    r = check_input_box(_t(0, 1), u, _box())
    assert (r.name, r.verdict) == ("input_box", "pass")
    assert r.margin == pytest.approx(0.02 + INPUT_TOLERANCE)
    assert (r.details["margin_component"], r.details["margin_unit"]) == ("linear.x", "m/s")
    assert r.details["component_margins"] == pytest.approx(
        {"linear.x": 0.02 + INPUT_TOLERANCE, "linear.y": 0.08 + INPUT_TOLERANCE, "angular.z": 0.04 + INPUT_TOLERANCE})
    r = check_input_box(_t(0), np.array([[0.0, 0.0, 0.39]]), _box())
    assert (r.details["margin_component"], r.details["margin_unit"]) == ("angular.z", "rad/s")
    assert r.margin == pytest.approx(0.01 + INPUT_TOLERANCE)
    r = check_input_box(_t(0), np.array([[0.0, 0.29, 0.0]]), _box())
    assert (r.details["margin_component"], r.details["margin_unit"]) == ("linear.y", "m/s")


def test_input_box_fails_at_the_first_command_over_its_bound_and_names_the_component() -> None:
    u = np.array([[0.1, 0.0, 0.0], [0.0, 0.0, -0.5], [0.0, 0.9, 0.0]])
    r = check_input_box(_t(0, 1, 2), u, _box())
    assert (r.verdict, r.first_violation_ns) == ("fail", 1_000_000_000)
    assert r.margin == pytest.approx(-0.6 + INPUT_TOLERANCE)
    assert (r.details["component"], r.details["value"]) == ("angular.z", -0.5)
    # exactly at the bound is not a violation (and the rounding tolerance is added)
    r = check_input_box(_t(0), np.array([[0.2 + INPUT_TOLERANCE, -0.3, 0.4]]), _box())
    assert r.verdict == "pass"


def test_unicycle_box_bounds_sideways_speed_by_the_lateral_tolerance() -> None:
    r = check_input_box(_t(0), np.array([[0.5, 0.0, -1.0]]), _box("unicycle"))
    assert r.verdict == "pass"
    assert r.details["bounds"] == {"linear.x": 0.5, "angular.z": 1.0, "linear.y": 0.01}
    r = check_input_box(_t(0, 1), np.array([[0.0, 0.0, 0.0], [0.1, 0.02, 0.2]]), _box("unicycle"))
    assert (r.verdict, r.first_violation_ns) == ("fail", 1_000_000_000)
    assert (r.details["component"], r.details["value"]) == ("linear.y", 0.02)
    assert r.margin == pytest.approx(-0.01 + INPUT_TOLERANCE)
    assert r.details["model"] == "unicycle"
    r = check_input_box(_t(0), np.array([[0.6, 0.0, 0.0]]), _box("unicycle"))
    assert (r.verdict, r.details["component"]) == ("fail", "linear.x")
    assert r.details["max_abs"] == [0.5, 1.0]


def test_a_nan_component_never_hides_a_known_violation_and_alone_is_inconclusive() -> None:
    u = np.array([[np.nan, 0.0, 0.0], [np.nan, 0.0, 0.9], [0.0, 0.0, 0.0]])
    r = check_input_box(_t(0, 1, 2), u, _box())
    assert (r.verdict, r.first_violation_ns) == ("fail", 1_000_000_000)
    assert (r.details["component"], r.details["value"]) == ("angular.z", 0.9)
    u = np.array([[np.nan, 0.0, 0.0], [np.nan, np.nan, np.nan], [0.0, 0.1, 0.0]])
    r = check_input_box(_t(0, 1, 2), u, _box())
    assert (r.name, r.verdict, r.first_violation_ns) == ("input_box", "inconclusive", None)
    assert r.details["reason"] == "2 command(s) with a NaN component"
    assert r.margin == pytest.approx(0.2 + INPUT_TOLERANCE)
    assert r.details["component_margins"]["linear.x"] == pytest.approx(0.2 + INPUT_TOLERANCE)
    # every command unknown: no margin, no component named
    r = check_input_box(_t(0), np.array([[np.nan, np.nan, np.nan]]), _box())
    assert (r.verdict, r.margin) == ("inconclusive", None)
    assert r.details["component_margins"] == {"linear.x": None, "linear.y": None, "angular.z": None}
    assert "margin_component" not in r.details
    assert r.details["margin_unit"] == "m/s or rad/s"


def test_clearance_names_the_obstacle_hit_first() -> None:
    sc = builtin_scenario("nexus-sml")  # R6: disc at (-1.11, 0.54), radius 0.45; R7: (0.79, 1.49); robot radius 0.27
    x, y = np.array([2.0, 0.79, -1.11]), np.array([-2.0, 1.49, 0.54])
    r = check_clearance(_t(0, 1, 2), x, y, sc)
    assert (r.name, r.verdict, r.first_violation_ns) == ("obstacle_clearance", "fail", 1_000_000_000)
    assert r.details == {"margin_unit": "m", "region": "R7"}
    assert r.margin == pytest.approx(-0.72)
    r = check_clearance(_t(0, 0.1), np.array([-1.11 + 0.72 + 0.1, -1.11 + 0.72 + 0.1]), np.array([0.54, 0.54]), sc)
    assert r.verdict == "pass"
    assert r.margin == pytest.approx(0.1 - 0.05 * sc.max_speed_mps)
    free = sc.model_copy(update={"regions": [g for g in sc.regions if not g.unsafe]})
    r = check_clearance(_t(0), x[1:2], y[1:2], free)
    assert (r.name, r.verdict, r.margin, r.details) == ("obstacle_clearance", "pass", None,
                                                        {"reason": "no unsafe regions"})


def test_workspace_is_judged_with_the_scenarios_speed_bound_between_samples() -> None:
    sc = builtin_scenario("nexus-sml")  # box [-2.5, 2.5]^2, robot radius 0.27, speed bound ~0.283 m/s
    r = check_workspace(_t(0, 1), np.array([0.0, 0.0]), np.array([0.0, 0.0]), sc)
    assert (r.name, r.verdict) == ("workspace", "pass")
    assert r.margin == pytest.approx(2.5 - 0.27 - 0.5 * sc.max_speed_mps)
    assert r.details == {"margin_unit": "m", "between_samples": "bounded by max(v_max * dt, step)",
                         "sample_margin_m": pytest.approx(2.5 - 0.27)}
    r = check_workspace(_t(0, 1), np.array([2.3, 0.0]), np.array([0.0, 0.0]), sc)
    assert (r.verdict, r.first_violation_ns) == ("fail", 0)
    assert r.margin == pytest.approx(2.5 - 2.3 - 0.27)
