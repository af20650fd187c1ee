"""Closed loop under the worst-case disturbance: tube, inputs, obstacles and arrival for every adjacent pair."""

from __future__ import annotations

import math

import numpy as np
import pytest

from tubempc.control import (
    InvalidArgumentError,
    Target,
    clearance_m,
    design_tube,
    hold_position,
    model_for,
    run_closed_loop,
)
from tubempc.scenario import builtin_scenario, scenario_from_dict

SCENARIO = builtin_scenario()
ADJACENT = [("R1", "R2"), ("R2", "R3"), ("R3", "R4"), ("R4", "R5"), ("R5", "R1")]
# The world model is integrated exactly (ZOH input and disturbance over each 10 ms sample), and the discrete tube
# recursion |q+| <= (1 - sigma dt)|q| + delta_bar dt has the same fixed point r_q: only float rounding remains.
ROUNDING_M = 1e-12


@pytest.mark.parametrize(("source", "target"), ADJACENT)
def test_worst_case_transition_keeps_every_guarantee(source: str, target: str) -> None:
    res = run_closed_loop(SCENARIO, [Target(target)], start_region=source, disturbance="worst", seed=7)
    assert res.ok, res.reason
    # the worst case drives |q| to the tube radius: the bound is tight and holds
    assert res.max_tube_error_m <= res.tube_radius_m + ROUNDING_M
    assert res.max_tube_error_m >= 0.99 * res.tube_radius_m
    # body-frame command inside the box at every sample (the planar disc makes it frame-independent)
    assert np.all(np.abs(res.u_body) <= np.asarray(SCENARIO.inputs.max_abs) + ROUNDING_M)
    # the robot disc never intersects a region other than source and target, nor leaves the workspace
    assert float(np.min(clearance_m(SCENARIO, source, target, res.x[:, :2]))) >= -ROUNDING_M
    # arrival: Algorithm 1 time at a multiple of h, robot disc fully inside the target at the end
    arrival = res.arrivals[0]
    assert arrival.t_ij_s is not None and arrival.inside_s is not None
    assert arrival.t_ij_s / SCENARIO.mpc.h == pytest.approx(round(arrival.t_ij_s / SCENARIO.mpc.h), abs=1e-6)
    region = SCENARIO.region(target)
    assert math.dist(res.x[-1, :2], region.center) + SCENARIO.robot.radius <= region.radius
    # every solve succeeded, none needed the backup, and the status is recorded
    assert all(r.success and not r.backup for r in res.solver)
    assert len(res.solver) == math.floor(res.t_s[-1] / SCENARIO.mpc.h + 1e-9) + 1


def test_algorithm1_time_is_first_entry_of_the_nominal_into_the_terminal_ball() -> None:
    res = run_closed_loop(SCENARIO, [Target("R3")], disturbance="random", seed=1)
    tube = design_tube(SCENARIO, model_for(SCENARIO))
    goal = np.array([*SCENARIO.region("R3").center, SCENARIO.initial_heading])
    per_step = round(SCENARIO.mpc.h * SCENARIO.mocap.rate_hz)
    dist = np.linalg.norm(res.x_hat[::per_step] - goal, axis=1)
    first = int(np.argmax(dist <= tube.terminal_radius_m))
    assert dist[first] <= tube.terminal_radius_m and np.all(dist[:first] > tube.terminal_radius_m)
    assert res.arrivals[0].t_ij_s == pytest.approx(first * SCENARIO.mpc.h)


def test_dwell_holds_position_until_departure_then_goes_on() -> None:
    res = run_closed_loop(SCENARIO, [hold_position("R3", 35.0), Target("R4")], disturbance="bias", seed=3)
    assert res.ok, res.reason
    first, second = res.arrivals
    assert first.departure_s is not None and first.departure_s >= 35.0 - 1e-9
    assert first.departure_s < 35.0 + SCENARIO.mpc.h + 1e-9
    r3 = SCENARIO.region("R3")
    held = (res.t_s >= first.inside_s) & (res.t_s <= first.departure_s)
    assert np.all(np.hypot(res.x[held, 0] - r3.center[0], res.x[held, 1] - r3.center[1]) + 0.27 <= r3.radius)
    assert second.departed_s == first.departure_s and second.t_ij_s is not None


def test_last_target_is_held_until_t_end() -> None:
    res = run_closed_loop(SCENARIO, [Target("R3")], disturbance="sine", seed=2, t_end_s=30.0)
    assert res.ok and res.t_s[-1] == pytest.approx(30.0)
    assert res.arrivals[0].departure_s is None


def test_unreached_target_is_reported_not_raised() -> None:
    res = run_closed_loop(SCENARIO, [Target("R4")], disturbance="none", t_end_s=5.0)
    assert not res.ok and res.reason is not None and "R4" in res.reason


def test_same_seed_same_run_and_disturbance_is_seeded() -> None:
    a = run_closed_loop(SCENARIO, [Target("R3")], disturbance="random", seed=11, t_end_s=3.0)
    b = run_closed_loop(SCENARIO, [Target("R3")], disturbance="random", seed=11, t_end_s=3.0)
    c = run_closed_loop(SCENARIO, [Target("R3")], disturbance="random", seed=12, t_end_s=3.0)
    assert np.array_equal(a.x, b.x)
    assert not np.array_equal(a.x, c.x)


def test_mocap_noise_enters_the_measurement_only() -> None:
    res = run_closed_loop(SCENARIO, [Target("R3")], disturbance="none", seed=4, t_end_s=2.0, mocap_noise_m=0.002)
    assert not np.array_equal(res.x_measured, res.x)
    assert np.allclose(res.x_measured[:, 2], res.x[:, 2])
    # 6 sigma of the noise bounds the gap (probability of a larger one ~1e-9 per sample)
    assert float(np.max(np.abs(res.x_measured - res.x))) <= 6 * 0.002


def test_body_model_worst_case_stays_in_tube() -> None:
    data = SCENARIO.to_dict()
    data["dynamics"] = {"model": "body", "theta_max": 1.0}
    sc = scenario_from_dict(data)
    res = run_closed_loop(sc, [Target("R3")], disturbance="worst", seed=5)
    assert res.ok, res.reason
    # RK4 with 4 substeps of 2.5 ms and a ZOH ancillary input: the continuous-time bound holds up to O(dt) terms,
    # far below 1 % of r_q here
    assert res.max_tube_error_m <= 1.01 * res.tube_radius_m
    assert np.all(np.abs(res.u_body) <= np.asarray(sc.inputs.max_abs) + 1e-9)
    assert float(np.max(np.abs(res.x[:, 2]))) < 1.0


@pytest.mark.parametrize(
    ("kwargs", "match"),
    [
        ({"disturbance": "storm"}, "disturbance='storm'"),
        ({"start_region": "R42"}, "R42"),
        ({"mocap_noise_m": -1.0}, "mocap_noise_m"),
        ({"t_end_s": 0.0}, "t_end_s"),
    ],
)
def test_invalid_arguments_name_the_argument(kwargs: dict[str, object], match: str) -> None:
    with pytest.raises(InvalidArgumentError, match=match):
        run_closed_loop(SCENARIO, [Target("R2")], **kwargs)  # type: ignore[arg-type]


@pytest.mark.slow
def test_full_tour_of_the_paper() -> None:
    res = run_closed_loop(SCENARIO, [Target(n) for n in ("R2", "R3", "R4", "R5", "R1")], disturbance="worst",
                          seed=0)
    assert res.ok, res.reason
    assert res.max_tube_error_m <= res.tube_radius_m + ROUNDING_M
    assert all(a.t_ij_s is not None for a in res.arrivals)
