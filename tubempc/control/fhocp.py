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
from collections.abc import Callable
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
    check: ca.Function  # (x0, U 3xN, obs 3xM) -> (X 3x(N+1) = roll(x0, U), largest violation of the true sets)
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

    def __post_init__(self) -> None:
        object.__setattr__(self, "u_box_arr", np.asarray(self.tube.u_box, dtype=float))
        object.__setattr__(self, "ws_lo", np.array([self.tube.workspace_x[0], self.tube.workspace_y[0]]))
        object.__setattr__(self, "ws_hi", np.array([self.tube.workspace_x[1], self.tube.workspace_y[1]]))

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
    check = _check_function(model, tube, F, n=n, h=h, obstacle_slots=obstacle_slots)
    # a chord between two nodes outside a disc of radius r cuts at most r - sqrt(r^2 - (v h / 2)^2) into it
    rho_max = max((r.radius for r in scenario.regions), default=0.0) + tube.clearance_m
    half_chord = tube.max_planar_speed_mps * h / 2
    chord = rho_max - math.sqrt(max(rho_max**2 - half_chord**2, 0.0))
    problem = FhocpProblem(
        steps=n, h_s=h, obstacle_slots=obstacle_slots,
        solver=ca.nlpsol("fhocp", "sqpmethod", nlp, _SQP_OPTIONS),
        fallback=ca.nlpsol("fhocp_ipopt", "ipopt", nlp, _IPOPT_OPTIONS),
        rollout=rollout, check=check, lbx=lbx, ubx=ubx, lbg=np.asarray(lbg), ubg=np.asarray(ubg), tube=tube,
        chord_margin_m=chord, weights=(tuple(Q), tuple(R), tuple(P)), linear_world=model.linear_world,
    )
    _CACHE[key] = problem
    return problem


def _check_function(model: DynamicsModel, tube: TubeDesign, F: ca.Function, *, n: int, h: float,
                    obstacle_slots: int) -> ca.Function:
    """``(x0, U, obs) -> (X, worst)``: ``FhocpProblem.roll`` and ``_violation`` (unclipped) in one CasADi call.

    The same floating-point operations as the numpy versions, so the results are bitwise equal: the linear
    rollout is ``x0 + h * cumsum(U)`` (running sum, then scaled, then shifted), the nonlinear one the
    ``rollout`` function's expression; the maxima are exact whatever the order, and sqrt and the subtraction of
    a bound are monotone, so ``sqrt(max) - b`` is the maximum of ``sqrt - b``.
    """
    x0 = ca.SX.sym("x0", STATE_DIM)
    u = ca.SX.sym("U", STATE_DIM, n)
    obs = ca.SX.sym("obs", 3, obstacle_slots)
    if model.linear_world:
        cols = [x0]
        run = u[:, 0]
        for k in range(n):
            if k > 0:
                run = run + u[:, k]
            cols.append(run * h + x0)
        states = ca.horzcat(*cols)
    else:
        states = ca.horzcat(x0, F.mapaccum(n)(x0, u))
    lo_x, hi_x = tube.workspace_x
    lo_y, hi_y = tube.workspace_y
    terms: list[ca.SX] = []
    for k in range(n):
        for i in range(STATE_DIM):
            terms.append(ca.fabs(u[i, k]) - tube.u_box[i])
        if tube.planar_disc_mps is not None:
            terms.append(ca.sqrt(u[0, k] * u[0, k] + u[1, k] * u[1, k]) - tube.planar_disc_mps)
    for k in range(1, n + 1):
        px, py = states[0, k], states[1, k]
        terms += [lo_x - px, lo_y - py, px - hi_x, py - hi_y]
        for m in range(obstacle_slots):
            dx, dy = px - obs[0, m], py - obs[1, m]
            terms.append(obs[2, m] - ca.sqrt(dx * dx + dy * dy))
        if tube.theta_bound_rad is not None:
            terms.append(ca.fabs(states[2, k]) - tube.theta_bound_rad)
    return ca.Function("plan_check", [x0, u, obs], [states, ca.mmax(ca.vertcat(*terms))])


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
    _bound: dict[int, _BoundSolver] = field(default_factory=dict, init=False, repr=False)

    def solve(self, x_hat: np.ndarray, refs: np.ndarray, obstacles: np.ndarray) -> SolveOutcome:
        """Solve from nominal state ``x_hat`` with references ``refs`` (N+1 x 3) and obstacle slots (3 x M)."""
        prob = self.problem
        n, nx = prob.steps, prob.n_x
        main = self._buffer(prob.solver)
        main.set_parameters(x_hat, refs, obstacles)
        self._warm_start(main)
        status, success, iters, elapsed, inputs, states = self._attempt(main)
        if not success:  # one SQP restart from the rolled-out iterate (cheap), then IPOPT
            w0 = main.w0.copy()
            main.w0[:nx] = states.ravel()
            main.w0[nx:] = inputs.ravel()
            s1, ok1, it1, t1, in1, st1 = self._attempt(main)
            status, success, iters, elapsed = f"{status}; restart: {s1}", ok1, iters + it1, elapsed + t1
            inputs, states = in1, st1
            if not success:
                fallback = self._buffer(prob.fallback)
                fallback.p[:] = main.p
                fallback.w0[:] = w0
                s2, ok2, it2, t2, in2, st2 = self._attempt(fallback)
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

    def _warm_start(self, bound: _BoundSolver) -> None:
        """The shifted previous plan (last input repeated; zeros without one) and its rollout, into ``bound.w0``."""
        nx = self.problem.n_x
        inputs = bound.w0[nx:].reshape(self.problem.steps, STATE_DIM)
        prev = self._prev_inputs
        if prev is None:
            inputs[:] = 0.0
        else:
            inputs[:-1] = prev[1:]
            inputs[-1] = prev[-1]
        bound.roll_warm_start()  # w0[:nx] = roll(x_hat, w0[nx:])

    def _buffer(self, solver: ca.Function) -> _BoundSolver:
        bound = self._bound.get(id(solver))
        if bound is None:
            bound = self._bound[id(solver)] = _BoundSolver(solver, self.problem)
        return bound

    def _attempt(self, bound: _BoundSolver) -> tuple[str, bool, int, float, np.ndarray, np.ndarray]:
        """One solve from ``bound.w0`` with ``bound.p``; the plan is checked against the true (tightened) sets."""
        prob = self.problem
        n, nx = prob.steps, prob.n_x
        start = time.perf_counter()
        try:
            bound.evaluate()  # solver(x0=w0, p=p, lbx=..., ubx=..., lbg=..., ubg=...) without DM conversions
        except RuntimeError as err:  # CasADi reports numerical breakdowns as RuntimeError
            elapsed = time.perf_counter() - start
            return f"exception: {err}".splitlines()[0][:200], False, 0, elapsed, np.zeros((n, 3)), np.zeros((n + 1, 3))
        elapsed = time.perf_counter() - start
        stats = bound.buffer.stats()
        status = str(stats.get("return_status", "unknown"))
        iters = int(stats.get("iter_count", 0))
        w = bound.w
        # the applied nominal is the rollout of the inputs from x_hat, never the solver's state iterate
        bound.check_plan()  # states = roll(x_hat, w[nx:]), worst = largest violation of the true sets
        inputs = w[nx:].reshape(n, STATE_DIM).copy()  # the bound arrays are overwritten by the next call
        states = bound.states.reshape(n + 1, STATE_DIM).copy()
        success = bool(stats.get("success", False)) and bool(np.isfinite(w).all())
        if success:
            worst = float(bound.worst[0])
            viol = worst if worst > 1e-12 else 0.0  # as _violation
            if viol > 0:
                status = f"{status} (rejected: constraint violated by {viol:.3g})"
                success = False
        return status, success, iters, elapsed, inputs, states


class _BoundSolver:
    """An nlpsol and the plan check bound to arrays owned here (CasADi ``FunctionBuffer``): no DM conversions.

    The solver reads x0 = ``w0``, ``p`` and the problem's bounds (lam_x0, lam_g0 unbound: zero, as in a keyword
    call without them) and writes only x into ``w``. ``check_plan`` evaluates ``FhocpProblem.check`` on
    (x_hat = p[:3], the inputs in ``w``, the obstacle slots in ``p``) into ``states`` and ``worst``;
    ``roll_warm_start`` rolls the inputs in ``w0`` out into the states part of ``w0``. One per ``NominalMPC`` and
    solver, so that the CasADi memory is never shared between runs or threads.
    """

    __slots__ = ("_keep", "buffer", "check_plan", "evaluate", "p", "roll_warm_start", "states", "w", "w0", "worst")

    def __init__(self, solver: ca.Function, problem: FhocpProblem) -> None:
        nx = problem.n_x
        self.w0 = np.zeros(solver.nnz_in(0))
        self.p = np.zeros(solver.nnz_in(1))
        self.w = np.zeros(solver.nnz_out(0))
        self.states = np.zeros(nx)
        self.worst = np.zeros(1)
        scratch = np.zeros(1)
        self.buffer, self.evaluate = solver.buffer()
        for i, arr in enumerate((self.w0, self.p, problem.lbx, problem.ubx, problem.lbg, problem.ubg)):
            _bind(self.buffer.set_arg, i, arr)
        _bind(self.buffer.set_res, 0, self.w)
        x_hat, obstacles = self.p[:STATE_DIM], self.p[STATE_DIM * (problem.steps + 2):]
        check, self.check_plan = problem.check.buffer()
        warm, self.roll_warm_start = problem.check.buffer()
        for buf, inputs, states, worst in ((check, self.w[nx:], self.states, self.worst),
                                          (warm, self.w0[nx:], self.w0[:nx], scratch)):
            for i, arr in enumerate((x_hat, inputs, obstacles)):
                _bind(buf.set_arg, i, arr)
            _bind(buf.set_res, 0, states)
            _bind(buf.set_res, 1, worst)
        self._keep = (check, warm, scratch)  # the evaluators need their FunctionBuffer objects alive

    def set_parameters(self, x_hat: np.ndarray, refs: np.ndarray, obstacles: np.ndarray) -> None:
        """p = [x_hat, vec(refs^T), vec(obstacles)] (column-major, as the NLP's parameter)."""
        k = STATE_DIM * (len(refs) + 1)
        p = self.p
        p[:STATE_DIM] = x_hat
        p[STATE_DIM:k] = refs.ravel()
        p[k:] = obstacles.T.ravel()


def _bind(setter: Callable[..., None], i: int, arr: np.ndarray) -> None:
    """``FunctionBuffer.set_arg``/``set_res`` on a contiguous float64 array (or a contiguous slice of one)."""
    if arr.dtype != np.float64 or not arr.flags.c_contiguous:
        raise ValueError(f"argument {i}: a CasADi buffer needs contiguous float64 data, not {arr.dtype} {arr.strides}")
    setter(i, arr.data)  # the memoryview carries the size (the stubs' third argument is not in the Python API)
