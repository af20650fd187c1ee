"""The NLP solver's plans are optimal: a convex SOCP (cvxpy + Clarabel) of the same FHOCP finds the same cost."""

from __future__ import annotations

import numpy as np
import pytest

from tubempc.control import Target, design_tube, model_for, run_closed_loop
from tubempc.control.fhocp import NominalMPC, SolveOutcome, build_fhocp
from tubempc.control.socp import solve_socp
from tubempc.scenario import builtin_scenario

SCENARIO = builtin_scenario()


def _instances() -> list[tuple[np.ndarray, np.ndarray, np.ndarray]]:
    recorded: list[tuple[np.ndarray, np.ndarray, np.ndarray]] = []
    original = NominalMPC.solve

    def recording(self: NominalMPC, x_hat: np.ndarray, refs: np.ndarray, obstacles: np.ndarray) -> SolveOutcome:
        recorded.append((x_hat.copy(), refs.copy(), obstacles.copy()))
        return original(self, x_hat, refs, obstacles)

    NominalMPC.solve = recording  # type: ignore[method-assign]
    try:
        run_closed_loop(SCENARIO, [Target("R5")], start_region="R4", disturbance="worst", seed=0)
    finally:
        NominalMPC.solve = original  # type: ignore[method-assign]
    return recorded


def test_nlp_and_socp_costs_agree_along_a_run_with_obstacles() -> None:
    model = model_for(SCENARIO)
    tube = design_tube(SCENARIO, model)
    instances = _instances()
    with_obstacle = [k for k, (_, _, obs) in enumerate(instances) if np.any(obs[2] > 0)]
    assert len(with_obstacle) > 20  # R4 -> R5 slides around R9: obstacle constraints are active
    picks = sorted({0, 5, 40, *with_obstacle[::max(1, len(with_obstacle) // 6)]})
    for k in picks:
        x_hat, refs, obs = instances[k]
        problem = build_fhocp(SCENARIO, model, tube, obs.shape[1])
        ours = NominalMPC(problem).solve(x_hat, refs, obs)  # cold start: optimality must not need a warm start
        assert ours.success
        socp = solve_socp(problem, x_hat, refs, obs, ours.states[:, :2])
        ours_cost = _cost(problem, x_hat, refs, ours.inputs)
        # both solvers stop at 1e-6..1e-8 tolerances; costs are O(0.1..1): agree to 1e-5 relative
        assert ours_cost == pytest.approx(socp.cost, rel=1e-5, abs=1e-7), k


def _cost(problem: object, x0: np.ndarray, refs: np.ndarray, inputs: np.ndarray) -> float:
    from tubempc.control.fhocp import FhocpProblem

    assert isinstance(problem, FhocpProblem)
    Q, R, P = (np.asarray(w) for w in problem.weights)
    states = problem.roll(x0, inputs)
    e = states - refs
    return float(problem.h_s * (np.sum(Q * e[:-1] ** 2) + np.sum(R * inputs**2)) + np.sum(P * e[-1] ** 2))
