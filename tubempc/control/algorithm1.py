"""Algorithm 1: the transition time t_ij between two regions, by closed-loop simulation of the tube MPC.

input: a ``Scenario`` and an ordered pair of region names -> output: a frozen, picklable ``TransitionResult``
(``ok``, why not, t_ij = first multiple of h at which ``|x_hat - x_j| <= eps / sqrt(lambda_min(P))``, the time
the robot disc is inside R_j, the largest tube error and the smallest clearance to the paper's X). A module-level
function, so that the planner can run it for every ordered pair in worker processes.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from tubempc.control.closed_loop import ClosedLoopResult, Target, leg_obstacles, run_closed_loop
from tubempc.errors import DesignError
from tubempc.scenario import Scenario

__all__ = ["TransitionResult", "clearance_m", "transition_time"]


@dataclass(frozen=True, slots=True)
class TransitionResult:
    source: str
    target: str
    ok: bool
    reason: str | None
    t_ij_s: float | None
    arrival_s: float | None
    max_tube_error_m: float | None
    min_clearance_m: float | None


def clearance_m(scenario: Scenario, source: str, target: str, positions: np.ndarray) -> np.ndarray:
    """Per sample: the smallest gap between the robot disc and the regions other than source and target, and
    the workspace boundary (negative: the paper's X is violated)."""
    eta = scenario.robot.radius
    ws = scenario.workspace
    gaps = [positions[:, 0] - ws.x[0] - eta, ws.x[1] - positions[:, 0] - eta,
            positions[:, 1] - ws.y[0] - eta, ws.y[1] - positions[:, 1] - eta]
    for cx, cy, rho in leg_obstacles(scenario, source, target):
        gaps.append(np.hypot(positions[:, 0] - cx, positions[:, 1] - cy) - rho - eta)
    return np.asarray(np.min(np.vstack(gaps), axis=0), dtype=float)


def _fail(source: str, target: str, reason: str, result: ClosedLoopResult | None = None,
          clearance: float | None = None) -> TransitionResult:
    return TransitionResult(source=source, target=target, ok=False, reason=reason, t_ij_s=None,
                            arrival_s=None if result is None else result.arrivals[0].inside_s,
                            max_tube_error_m=None if result is None else result.max_tube_error_m,
                            min_clearance_m=clearance)


def transition_time(scenario: Scenario, source: str, target: str, *, disturbance: str = "none",
                    seed: int = 0) -> TransitionResult:
    """Run the tube MPC from the centre of ``source`` to ``target`` and measure t_ij (Algorithm 1)."""
    if source == target:
        return _fail(source, target, f"source and target are the same region {source}")
    try:
        src, dst = scenario.region(source), scenario.region(target)
    except KeyError as err:
        return _fail(source, target, f"unknown region: {err.args[0]}")
    if src.unsafe or dst.unsafe:
        return _fail(source, target, f"design check: {src.name if src.unsafe else dst.name} is an unsafe region")
    try:
        result = run_closed_loop(scenario, [Target(target)], start_region=source, disturbance=disturbance,
                                 seed=seed)
    except DesignError as err:
        return _fail(source, target, f"design check: {err}")
    gap = float(np.min(clearance_m(scenario, source, target, result.x[:, :2])))
    if gap < 0:
        return _fail(source, target, f"constraint violated: the robot disc enters X's complement by {-gap:.3g} m",
                     result, gap)
    backups = sum(r.backup for r in result.solver)
    if not result.ok:
        why = "infeasible" if backups else "timeout"
        return _fail(source, target, f"{why}: {result.reason} ({backups} backup step(s))", result, gap)
    arrival = result.arrivals[0]
    t_ij = arrival.t_ij_s
    if t_ij is None or not math.isfinite(t_ij):
        return _fail(source, target, "timeout: the nominal never entered the terminal set", result, gap)
    return TransitionResult(source=source, target=target, ok=True, reason=None, t_ij_s=t_ij,
                            arrival_s=arrival.inside_s, max_tube_error_m=result.max_tube_error_m, min_clearance_m=gap)
