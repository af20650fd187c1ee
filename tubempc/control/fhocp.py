"""The nominal FHOCP (CasADi ``nlpsol``) and the warm-started MPC that solves it every h.

input: a ``Scenario``, its ``DynamicsModel`` and ``TubeDesign`` -> output: ``FhocpProblem`` (a ready solver
with its bounds; cached per scenario, model and number of obstacle slots) and ``NominalMPC`` (the warm start, the
only mutable state), whose ``solve`` returns a frozen ``SolveOutcome`` with status, iterations and time.

Formulation (multiple shooting, N = horizon / h stages, ZOH input): minimise
``h sum_k (|x_k - r_k|_Q^2 + |u_k|_R^2) + |x_N - r_N|_P^2`` subject to the nominal dynamics (exact for the linear
world model, RK4 otherwise), the tightened input set, the workspace shrunk by eta + r_q and, for every active
obstacle slot m, ``|p_k - c_m| >= rho_m + eta + r_q + chord margin`` at k = 1..N. The references r_k are
intermediate targets on a free-space guide path (``guide.references``), so that the problem is feasible far
from the target; Algorithm 1 still measures the entry into the terminal ball.

Solver: ``sqpmethod`` with the DAQP active-set QP solver and a regularised (convexified) exact Hessian, warm
started from the shifted previous solution. The NLP's sets are shrunk by ``CHECK_TOL`` so that a
solution within the solver's tolerance still lies in the true sets; an unsuccessful solve, or a returned plan
that violates one of the true (tightened) sets, is restarted once from its own iterate and then retried once
with IPOPT; if that fails too the shifted previous plan is applied and the outcome is marked ``backup=True``.
A failed iterate is never applied.
"""

from __future__ import annotations

import math
import time
from dataclasses import dataclass, field
from typing import Any

import casadi as ca
import numpy as np

from tubempc.control.dynamics import STATE_DIM, DynamicsModel
from tubempc.control.tube import TubeDesign
from tubempc.scenario import Scenario

__all__ = ["CHECK_TOL", "FAR_AWAY_M", "FhocpProblem", "NominalMPC", "SolveOutcome", "build_fhocp", "discrete_step"]

CHECK_TOL = 1e-5  # m, m/s, rad: the NLP uses sets shrunk by this; a plan violating the unshrunk sets is rejected
FAR_AWAY_M = 10.0  # offset from the robot of an unused obstacle slot (kept small: constraint scaling)
_SQP_OPTIONS: dict[str, Any] = {
    "qpsol": "daqp",
    "qpsol_options": {"error_on_fail": False},
    "convexify_strategy": "regularize",
    "convexify_margin": 1e-4,
    "max_iter": 30,
    "max_iter_ls": 0,
    "tol_pr": 1e-6,
    "tol_du": 1e-6,
    "print_time": False,
    "print_header": False,
    "print_iteration": False,
    "print_status": False,
    "error_on_fail": False,
}
_IPOPT_OPTIONS: dict[str, Any] = {"print_time": False, "ipopt.print_level": 0, "ipopt.sb": "yes",
                                  "ipopt.max_iter": 500, "error_on_fail": False}


def discrete_step(model: DynamicsModel, dt_s: float, substeps: int = 1) -> ca.Function:
    """``x+ = F(x, u)`` over ``dt_s`` with u held: exact for the linear world model, RK4 otherwise."""
    x = ca.SX.sym("x", STATE_DIM)
    u = ca.SX.sym("u", STATE_DIM)
    if model.linear_world:
        return ca.Function("F", [x, u], [x + dt_s * u])
    dt = dt_s / substeps
    xk = x
    for _ in range(substeps):
        k1 = model.f(xk) + model.g(xk) @ u
        k2 = model.f(xk + dt / 2 * k1) + model.g(xk + dt / 2 * k1) @ u
        k3 = model.f(xk + dt / 2 * k2) + model.g(xk + dt / 2 * k2) @ u
        k4 = model.f(xk + dt * k3) + model.g(xk + dt * k3) @ u
        xk = xk + dt / 6 * (k1 + 2 * k2 + 2 * k3 + k4)
    return ca.Function("F", [x, u], [xk])


@dataclass(frozen=True)
class FhocpProblem:
    """A ready FHOCP solver: decision vector ``[vec(X) (3 x N+1), vec(U) (3 x N)]`` (column-major)."""

    steps: int
    h_s: float
    obstacle_slots: int
    solver: ca.Function
    fallback: ca.Function
    rollout: ca.Function  # (x0, U 3xN) -> X 3x(N+1)
    lbx: np.ndarray
    ubx: np.ndarray
    lbg: np.ndarray
    ubg: np.ndarray
    tube: TubeDesign
    chord_margin_m: float
    weights: tuple[tuple[float, ...], tuple[float, ...], tuple[float, ...]]  # Q, R, P diagonals
    linear_world: bool  # x+ = x + h u: rollouts in numpy
    u_box_arr: np.ndarray = field(init=False)
    ws_lo: np.ndarray = field(init=False)
    ws_hi: np.ndarray = field(init=False)
    bounds_dm: tuple[ca.DM, ca.DM, ca.DM, ca.DM] = field(init=False)  # lbx, ubx, lbg, ubg converted once

    def __post_init__(self) -> None:
        object.__setattr__(self, "u_box_arr", np.asarray(self.tube.u_box, dtype=float))
        object.__setattr__(self, "ws_lo", np.array([self.tube.workspace_x[0], self.tube.workspace_y[0]]))
        object.__setattr__(self, "ws_hi", np.array([self.tube.workspace_x[1], self.tube.workspace_y[1]]))
        object.__setattr__(self, "bounds_dm", tuple(ca.DM(v) for v in (self.lbx, self.ubx, self.lbg, self.ubg)))

    def roll(self, x0: np.ndarray, inputs: np.ndarray) -> np.ndarray:
        """Nominal states (N+1 x 3) of a plan (N x 3) from ``x0``, with the FHOCP's own discretisation."""
        if self.linear_world:
            out = np.empty((len(inputs) + 1, STATE_DIM))
            out[0] = x0
            np.cumsum(inputs, axis=0, out=out[1:])
            out[1:] *= self.h_s
            out[1:] += x0
            return out
        return np.asarray(self.rollout(x0, inputs.T), dtype=float).T

    @property
    def n_x(self) -> int:
        return STATE_DIM * (self.steps + 1)


_CACHE: dict[tuple[str, str, TubeDesign, int], FhocpProblem] = {}


def build_fhocp(scenario: Scenario, model: DynamicsModel, tube: TubeDesign, obstacle_slots: int) -> FhocpProblem:
    """Build (or fetch from the in-process cache) the FHOCP for a scenario, model and obstacle slot count."""
    key = (scenario.sha256(), model.cache_key, tube, obstacle_slots)
    cached = _CACHE.get(key)
    if cached is not None:
        return cached
    n, h = scenario.mpc.steps, scenario.mpc.h
    Q, R, P = (np.asarray(v, dtype=float) for v in (scenario.mpc.Q, scenario.mpc.R, scenario.mpc.P))
    F = discrete_step(model, h, substeps=2)
    X = ca.SX.sym("X", STATE_DIM, n + 1)
    U = ca.SX.sym("U", STATE_DIM, n)
    x0 = ca.SX.sym("x0", STATE_DIM)
    ref = ca.SX.sym("ref", STATE_DIM, n + 1)
    obs = ca.SX.sym("obs", 3, obstacle_slots)  # rows: cx, cy, required distance
    cost = ca.SX(0)
    g: list[ca.SX] = [X[:, 0] - x0]
    lbg: list[float] = [0.0] * STATE_DIM
    ubg: list[float] = [0.0] * STATE_DIM
    for k in range(n):
        e = X[:, k] - ref[:, k]
        cost += h * (ca.dot(Q * e, e) + ca.dot(R * U[:, k], U[:, k]))
        g.append(X[:, k + 1] - F(X[:, k], U[:, k]))
        lbg += [0.0] * STATE_DIM
        ubg += [0.0] * STATE_DIM
        if tube.planar_disc_mps is not None:
            g.append(ca.sumsqr(U[:2, k]))
            lbg.append(-math.inf)
            ubg.append((tube.planar_disc_mps - CHECK_TOL) ** 2)
    e_n = X[:, n] - ref[:, n]
    cost += ca.dot(P * e_n, e_n)
    for k in range(1, n + 1):
        for m in range(obstacle_slots):
            g.append(ca.sumsqr(X[:2, k] - obs[:2, m]) - (obs[2, m] + CHECK_TOL) ** 2)
            lbg.append(0.0)
            ubg.append(math.inf)
    w = ca.veccat(X, U)
    p = ca.veccat(x0, ref, obs)
    nlp = {"x": w, "p": p, "f": cost, "g": ca.vertcat(*g)}
    nx = STATE_DIM * (n + 1)
    lbx = np.full(w.shape[0], -math.inf)
    ubx = np.full(w.shape[0], math.inf)
    tol = CHECK_TOL
    lbx[STATE_DIM:nx:STATE_DIM] = tube.workspace_x[0] + tol
    ubx[STATE_DIM:nx:STATE_DIM] = tube.workspace_x[1] - tol
    lbx[STATE_DIM + 1:nx:STATE_DIM] = tube.workspace_y[0] + tol
    ubx[STATE_DIM + 1:nx:STATE_DIM] = tube.workspace_y[1] - tol
    if tube.theta_bound_rad is not None:
        lbx[STATE_DIM + 2:nx:STATE_DIM] = -tube.theta_bound_rad + tol
        ubx[STATE_DIM + 2:nx:STATE_DIM] = tube.theta_bound_rad - tol
    for i in range(STATE_DIM):
        lbx[nx + i::STATE_DIM] = -tube.u_box[i] + tol
        ubx[nx + i::STATE_DIM] = tube.u_box[i] - tol
    u_sym = ca.SX.sym("u", STATE_DIM, n)
    rollout = ca.Function("rollout", [x0, u_sym], [ca.horzcat(x0, F.mapaccum(n)(x0, u_sym))])
    # a chord between two nodes outside a disc of radius r cuts at most r - sqrt(r^2 - (v h / 2)^2) into it
    rho_max = max((r.radius for r in scenario.regions), default=0.0) + tube.clearance_m
    half_chord = tube.max_planar_speed_mps * h / 2
    chord = rho_max - math.sqrt(max(rho_max**2 - half_chord**2, 0.0))
    problem = FhocpProblem(
        steps=n, h_s=h, obstacle_slots=obstacle_slots,
        solver=ca.nlpsol("fhocp", "sqpmethod", nlp, _SQP_OPTIONS),
        fallback=ca.nlpsol("fhocp_ipopt", "ipopt", nlp, _IPOPT_OPTIONS),
        rollout=rollout, lbx=lbx, ubx=ubx, lbg=np.asarray(lbg), ubg=np.asarray(ubg), tube=tube,
        chord_margin_m=chord, weights=(tuple(Q), tuple(R), tuple(P)), linear_world=model.linear_world,
    )
    _CACHE[key] = problem
    return problem


@dataclass(frozen=True, slots=True)
class SolveOutcome:
    """One MPC step: the applied plan (N x 3 inputs, N+1 x 3 nominal states) and the solver's record."""

    inputs: np.ndarray
    states: np.ndarray
    status: str
    success: bool
    iterations: int
    solve_time_s: float
    backup: bool


def _violation(problem: FhocpProblem, states: np.ndarray, inputs: np.ndarray, obstacles: np.ndarray) -> float:
    """Largest constraint violation of a plan (m, m/s or rad); 0 when the plan is in the tightened sets."""
    tube = problem.tube
    pos = states[1:, :2]
    parts = [
        np.abs(inputs) - problem.u_box_arr,
        problem.ws_lo - pos,
        pos - problem.ws_hi,
        # obstacles: required distance minus the distance, per node and slot
        obstacles[2][None, :] - np.sqrt((pos[:, :1] - obstacles[0][None, :]) ** 2
                                        + (pos[:, 1:2] - obstacles[1][None, :]) ** 2),
    ]
    worst = max(float(part.max()) for part in parts)
    if tube.planar_disc_mps is not None:
        worst = max(worst, math.sqrt(float(np.max(np.einsum("ij,ij->i", inputs[:, :2], inputs[:, :2]))))
                    - tube.planar_disc_mps)
    if tube.theta_bound_rad is not None:
        worst = max(worst, float(np.max(np.abs(states[1:, 2]))) - tube.theta_bound_rad)
    return worst if worst > 1e-12 else 0.0


@dataclass
class NominalMPC:
    """The warm-started MPC: the previous plan is its only state."""

    problem: FhocpProblem
    _prev_inputs: np.ndarray | None = field(default=None, init=False)

    def solve(self, x_hat: np.ndarray, refs: np.ndarray, obstacles: np.ndarray) -> SolveOutcome:
        """Solve from nominal state ``x_hat`` with references ``refs`` (N+1 x 3) and obstacle slots (3 x M)."""
        prob = self.problem
        n = prob.steps
        p = np.concatenate([x_hat, refs.ravel(), obstacles.T.ravel()])
        w0 = self._warm_start(x_hat)
        status, success, iters, elapsed, inputs, states = self._attempt(prob.solver, w0, p, obstacles, x_hat)
        if not success:  # one SQP restart from the rolled-out iterate (cheap), then IPOPT
            w1 = np.concatenate([states.ravel(), inputs.ravel()])
            s1, ok1, it1, t1, in1, st1 = self._attempt(prob.solver, w1, p, obstacles, x_hat)
            status, success, iters, elapsed = f"{status}; restart: {s1}", ok1, iters + it1, elapsed + t1
            inputs, states = in1, st1
        if not success:
            s2, ok2, it2, t2, in2, st2 = self._attempt(prob.fallback, w0, p, obstacles, x_hat)
            status, success, iters, elapsed = f"{status}; ipopt: {s2}", ok2, iters + it2, elapsed + t2
            inputs, states = in2, st2
        if success:
            self._prev_inputs = inputs
            return SolveOutcome(inputs=inputs, states=states, status=status, success=True, iterations=iters,
                                solve_time_s=elapsed, backup=False)
        # explicit backup: the shifted previous plan, padded with a stop (or a stop when there is no plan yet)
        if self._prev_inputs is None:
            backup = np.zeros((n, STATE_DIM))
        else:
            backup = np.vstack([self._prev_inputs[1:], np.zeros((1, STATE_DIM))])
        states = prob.roll(x_hat, backup)
        self._prev_inputs = backup
        return SolveOutcome(inputs=backup, states=states, status=status, success=False, iterations=iters,
                            solve_time_s=elapsed, backup=True)

    def adopt(self, outcome: SolveOutcome) -> None:
        """Take the plan applied by another solver instance as this one's warm start."""
        self._prev_inputs = outcome.inputs

    def _warm_start(self, x_hat: np.ndarray) -> np.ndarray:
        prob = self.problem
        n = prob.steps
        if self._prev_inputs is None:
            inputs = np.zeros((n, STATE_DIM))
        else:
            inputs = np.vstack([self._prev_inputs[1:], self._prev_inputs[-1:]])
        states = prob.roll(x_hat, inputs)
        return np.concatenate([states.ravel(), inputs.ravel()])

    def _attempt(self, solver: ca.Function, w0: np.ndarray, p: np.ndarray, obstacles: np.ndarray,
                 x_hat: np.ndarray) -> tuple[str, bool, int, float, np.ndarray, np.ndarray]:
        prob = self.problem
        n = prob.steps
        start = time.perf_counter()
        try:
            lbx, ubx, lbg, ubg = prob.bounds_dm
            out = solver(x0=w0, p=p, lbx=lbx, ubx=ubx, lbg=lbg, ubg=ubg)
        except RuntimeError as err:  # CasADi reports numerical breakdowns as RuntimeError
            elapsed = time.perf_counter() - start
            return f"exception: {err}".splitlines()[0][:200], False, 0, elapsed, np.zeros((n, 3)), np.zeros((n + 1, 3))
        elapsed = time.perf_counter() - start
        stats = solver.stats()
        status = str(stats.get("return_status", "unknown"))
        iters = int(stats.get("iter_count", 0))
        w = np.asarray(out["x"], dtype=float).ravel()
        inputs = w[prob.n_x:].reshape(n, STATE_DIM)
        # the applied nominal is the rollout of the inputs from x_hat, never the solver's state iterate
        states = prob.roll(x_hat, inputs)
        success = bool(stats.get("success", False)) and np.all(np.isfinite(w))
        if success:
            viol = _violation(prob, states, inputs, obstacles)
            if viol > 0:
                status = f"{status} (rejected: constraint violated by {viol:.3g})"
                success = False
        return status, bool(success), iters, elapsed, inputs, states
