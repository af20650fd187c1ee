"""Convex (SOCP) FHOCP for the linear world-frame model: a cross-check of the NLP solver, with cvxpy.

input: an ``FhocpProblem`` of the linear world model, the nominal state, the references, the obstacle slots and a
linearisation trajectory -> output: a frozen ``SocpSolution`` (inputs, states, cost, status).

The world model makes the dynamics linear and the input set (planar disc + box) second-order-cone representable;
only the obstacle constraints are non-convex. Each one, ``|p_k - c| >= r``, is replaced by the half-plane
``n_k . (p_k - c) >= r`` with ``n_k`` the unit direction from c to the linearisation point ``pbar_k``: a convex
restriction (its solutions are feasible for the original problem). Linearised at a KKT point of the NLP, the
restriction has the same KKT point, so both optimal costs agree: that is the cross-check.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

import cvxpy
import numpy as np

from tubempc.control.fhocp import CHECK_TOL, FhocpProblem
from tubempc.errors import SolverError

__all__ = ["SocpSolution", "solve_socp"]

cp: Any = cvxpy  # cvxpy's partial annotations do not cover its atoms; treat the module as untyped


@dataclass(frozen=True, slots=True)
class SocpSolution:
    inputs: np.ndarray  # N x 3
    states: np.ndarray  # N+1 x 3
    cost: float
    status: str


def solve_socp(problem: FhocpProblem, x_hat: np.ndarray, refs: np.ndarray, obstacles: np.ndarray,
               linearise_at: np.ndarray) -> SocpSolution:
    """Solve the convexified FHOCP (``linearise_at``: N+1 x 2 positions, e.g. the NLP's plan)."""
    if not problem.linear_world:
        raise SolverError("the SOCP cross-check needs the linear world-frame model (dynamics.model: world)")
    n, h, tube = problem.steps, problem.h_s, problem.tube
    Q, R, P = (np.asarray(w, dtype=float) for w in problem.weights)
    u = cp.Variable((n, 3))
    x = cp.Variable((n + 1, 3))
    tol = CHECK_TOL
    cons = [x[0] == x_hat, x[1:] == x[:-1] + h * u]
    box = np.asarray(tube.u_box) - tol
    cons += [cp.abs(u) <= np.tile(box, (n, 1))]
    if tube.planar_disc_mps is not None:
        cons += [cp.norm(u[:, :2], axis=1) <= tube.planar_disc_mps - tol]
    cons += [x[1:, 0] >= tube.workspace_x[0] + tol, x[1:, 0] <= tube.workspace_x[1] - tol,
             x[1:, 1] >= tube.workspace_y[0] + tol, x[1:, 1] <= tube.workspace_y[1] - tol]
    for cx, cy, rad in obstacles.T:
        if rad <= 0:
            continue
        c = np.array([cx, cy])
        d = linearise_at[1:, :2] - c
        normals = d / np.linalg.norm(d, axis=1, keepdims=True)
        cons += [cp.sum(cp.multiply(normals, x[1:, :2] - c), axis=1) >= rad + tol]
    e = x - refs
    cost = h * (cp.sum(cp.multiply(np.tile(Q, (n, 1)), cp.square(e[:-1])))
                + cp.sum(cp.multiply(np.tile(R, (n, 1)), cp.square(u)))) + cp.sum(cp.multiply(P, cp.square(e[-1])))
    prob = cp.Problem(cp.Minimize(cost), cons)
    try:
        prob.solve(solver=cp.CLARABEL, canon_backend=cp.SCIPY_CANON_BACKEND)
    except cp.error.SolverError as err:
        raise SolverError(f"SOCP cross-check: the convex solver failed ({err})") from err
    if u.value is None or x.value is None:
        raise SolverError(f"SOCP cross-check: no solution (status {prob.status})")
    return SocpSolution(inputs=np.asarray(u.value, dtype=float), states=np.asarray(x.value, dtype=float),
                        cost=float(prob.value), status=str(prob.status))
