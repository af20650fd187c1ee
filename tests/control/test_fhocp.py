"""The FHOCP solver: success is recorded, an infeasible problem is never applied (explicit shifted backup)."""

from __future__ import annotations

import numpy as np
import pytest

from tubempc.control import design_tube, model_for
from tubempc.control.fhocp import CHECK_TOL, NominalMPC, build_fhocp
from tubempc.scenario import builtin_scenario

SCENARIO = builtin_scenario()


def _setup() -> tuple[NominalMPC, np.ndarray, np.ndarray, np.ndarray]:
    model = model_for(SCENARIO)
    tube = design_tube(SCENARIO, model)
    mpc = NominalMPC(build_fhocp(SCENARIO, model, tube, 4))
    x0 = np.array([-1.99, -1.78, 0.0])
    refs = np.tile(np.array([-1.99, -1.0, 0.0]), (SCENARIO.mpc.steps + 1, 1))
    free = np.tile(np.array([[x0[0] + 10.0], [x0[1]], [0.0]]), (1, 4))
    return mpc, x0, refs, free


def test_solve_records_status_and_respects_tightened_sets() -> None:
    mpc, x0, refs, free = _setup()
    out = mpc.solve(x0, refs, free)
    assert out.success and not out.backup and out.iterations >= 1 and out.solve_time_s > 0
    assert out.status == "Solve_Succeeded"
    # the tightened planar disc (0.18 m/s) is respected; the robot heads for the reference at that speed
    speeds = np.linalg.norm(out.inputs[:, :2], axis=1)
    assert np.all(speeds <= 0.18 - CHECK_TOL + 1e-9)
    assert speeds[0] > 0.17
    assert np.allclose(out.states[0], x0)


def test_infeasible_problem_applies_the_shifted_previous_plan() -> None:
    mpc, x0, refs, free = _setup()
    first = mpc.solve(x0, refs, free)
    x1 = first.states[1]
    # an obstacle slot centred on the nominal state makes every plan infeasible
    blocked = free.copy()
    blocked[:, 0] = [x1[0], x1[1], 0.5]
    out = mpc.solve(x1, refs, blocked)
    assert out.backup and not out.success
    assert "ipopt" in out.status
    assert np.array_equal(out.inputs[:-1], first.inputs[1:])
    assert np.array_equal(out.inputs[-1], np.zeros(3))
    assert np.allclose(out.states[0], x1)


@pytest.mark.parametrize("slots", [4, 6])
def test_problem_is_cached_per_slot_count(slots: int) -> None:
    model = model_for(SCENARIO)
    tube = design_tube(SCENARIO, model)
    assert build_fhocp(SCENARIO, model, tube, slots) is build_fhocp(SCENARIO, model, tube, slots)
