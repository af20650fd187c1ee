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


@pytest.mark.parametrize("model_name", ["world", "body"])
def test_plan_check_is_bitwise_the_numpy_rollout_and_violation(model_name: str) -> None:
    from tubempc.control.dynamics import body_model, world_model
    from tubempc.control.fhocp import _violation

    model = world_model() if model_name == "world" else body_model(0.5)
    tube = design_tube(SCENARIO, model)
    prob = build_fhocp(SCENARIO, model, tube, 4)
    n = prob.steps
    rng = np.random.default_rng(3)
    violated = 0
    for k in range(300):
        # odd k: inputs beyond the box and the disc, states near and outside the workspace and the discs;
        # even k: slow plans from the centre with the discs far away (inside every set)
        wide = k % 2
        inputs = rng.uniform(-0.3, 0.3, (n, 3)) if wide else rng.uniform(-0.05, 0.05, (n, 3))
        x0 = np.array([rng.uniform(-2.6, 2.6), rng.uniform(-2.6, 2.6), rng.uniform(-0.6, 0.6)]) * (wide or 0.1)
        obstacles = np.vstack([rng.uniform(-2.0, 2.0, (2, 4)) + 8.0 * (1 - wide), rng.uniform(0.0, 1.2, (1, 4))])
        states, worst = prob.check(x0, inputs.T, obstacles)
        states = np.asarray(states, dtype=float).T
        worst = float(worst)
        # exact equality: the CasADi check performs the same floating-point operations (see _check_function)
        assert np.array_equal(states, prob.roll(x0, inputs))
        expected = _violation(prob, states, inputs, obstacles)
        assert (worst if worst > 1e-12 else 0.0) == expected
        violated += expected > 0
    assert 0 < violated < 300  # both outcomes were exercised


def test_buffered_solve_is_the_keyword_call() -> None:
    mpc, x0, refs, free = _setup()
    prob = mpc.problem
    n = prob.steps
    first = mpc.solve(x0, refs, free)
    x1 = first.states[1]
    out = mpc.solve(x1, refs, free)
    # the same solve through CasADi's keyword call, from the same shifted warm start
    warm = np.vstack([first.inputs[1:], first.inputs[-1:]])
    w0 = np.concatenate([prob.roll(x1, warm).ravel(), warm.ravel()])
    p = np.concatenate([x1, refs.ravel(), free.T.ravel()])
    ref = prob.solver(x0=w0, p=p, lbx=prob.lbx, ubx=prob.ubx, lbg=prob.lbg, ubg=prob.ubg)
    w = np.asarray(ref["x"], dtype=float).ravel()
    assert out.success
    assert np.array_equal(out.inputs, w[prob.n_x:].reshape(n, 3))
    assert np.array_equal(out.states, prob.roll(x1, out.inputs))
    assert out.iterations == int(prob.solver.stats()["iter_count"])
