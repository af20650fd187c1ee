"""Closed-loop simulation of the tube MPC: nominal FHOCP every h, ancillary law at the MoCap rate.

input: a ``Scenario``, a sequence of ``Target`` (region, optional hold-until time), a disturbance model name and a
seed -> output: a frozen ``ClosedLoopResult`` with the real, measured and nominal states and the applied inputs
(world frame and the body-frame command as logged) at every MoCap sample, one ``SolverRecord`` per MPC step,
one ``Arrival`` per target, and ``ok``/``reason``.

Loop: ``run_closed_loop`` runs ``TubeMPC`` (``tubempc.control.tube_controller``, an implementation of the
controller protocol) in the one closed loop (``tubempc.control.loop``). At t_k = k h the FHOCP is solved from the
nominal state x_hat(t_k) (the nominal evolves on its own, it is never reset to the measurement, so q = x - x_hat
stays in the tube); its first input u_hat is held over h. At every MoCap sample ``u = u_hat - sigma (x_meas -
x_hat)`` is held over 1/rate; the plant ``x' = f(x) + g(x) u + delta`` is integrated exactly for the linear world
model and with RK4 (4 substeps per sample) otherwise. A target is *arrived* when the nominal enters the terminal
ball (Algorithm 1, checked at multiples of h) and the robot disc has been inside the region; the robot then holds
position there until ``depart_after_s`` and goes on to the next target.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass, field, replace
from typing import Any

import casadi as ca
import numpy as np

from tubempc.control.disturbance import DisturbanceLike, InvalidArgumentError, make_disturbance
from tubempc.control.dynamics import STATE_DIM, DynamicsModel, model_for
from tubempc.control.fhocp import FAR_AWAY_M
from tubempc.control.guide import GuidePath, guide_path
from tubempc.control.tube import TubeDesign, design_tube
from tubempc.errors import DesignError
from tubempc.scenario import Scenario

__all__ = ["Arrival", "ClosedLoopResult", "SolverRecord", "Target", "check_run_arguments", "disturbance_of",
           "hold_position", "leg_obstacles", "rk4_symbolic", "run_closed_loop"]

LOOKAHEAD_M = 0.5  # guide-path look-ahead of the first reference: far enough to saturate the speed
GUIDE_MARGIN_M = 0.05  # extra clearance of the guide path around the constraint discs
MIN_OBSTACLE_SLOTS = 4


@dataclass(frozen=True)
class Target:
    """Steer to ``region``; once arrived, hold there until ``depart_after_s`` (None: leave at once)."""

    region: str
    depart_after_s: float | None = None


def hold_position(region: str, until_s: float) -> Target:
    """A dwell: go to (or stay in) ``region`` and hold position there until time ``until_s``."""
    return Target(region=region, depart_after_s=until_s)


@dataclass(frozen=True, slots=True)
class SolverRecord:
    t_s: float
    status: str
    success: bool
    iterations: int
    solve_time_s: float
    backup: bool
    target: str


@dataclass(frozen=True, slots=True)
class Arrival:
    """One target: leg start ``departed_s`` (absolute), Algorithm-1 duration ``t_ij_s`` and absolute times."""

    region: str
    departed_s: float
    t_ij_s: float | None  # entered_terminal_s - departed_s
    entered_terminal_s: float | None  # nominal entered the terminal ball (a multiple of h)
    inside_s: float | None  # first sample with the robot disc fully inside the region
    departure_s: float | None  # when it left for the next target (None: held to the end)


@dataclass(frozen=True)
class ClosedLoopResult:
    t_s: np.ndarray  # n, MoCap sample times from 0
    x: np.ndarray  # n x 3 real state
    x_measured: np.ndarray  # n x 3 as the MoCap reports it (x plus noise)
    x_hat: np.ndarray  # n x 3 nominal state
    u_world: np.ndarray  # n x 3 applied input as a world-frame velocity (without drift f)
    u_body: np.ndarray  # n x 3 body-frame command (cmd_vel)
    solver: tuple[SolverRecord, ...]
    arrivals: tuple[Arrival, ...]
    targets: tuple[Target, ...]
    start_region: str
    tube_radius_m: float
    sigma: float
    seed: int
    disturbance: str
    disturbance_params: dict[str, Any]
    mocap_noise_m: float
    ok: bool
    reason: str | None

    @property
    def max_tube_error_m(self) -> float:
        """max over samples of |x - x_hat| (real state, all three components)."""
        return float(np.max(np.linalg.norm(self.x - self.x_hat, axis=1))) if len(self.t_s) else 0.0


def leg_obstacles(scenario: Scenario, source: str, target: str) -> list[tuple[float, float, float]]:
    """Regions other than ``source`` and ``target`` as (cx, cy, rho) discs."""
    return [(r.center[0], r.center[1], r.radius) for r in scenario.regions if r.name not in (source, target)]


_BLOCK_CACHE: dict[tuple[str, float, int], ca.Function] = {}


def rk4_symbolic(model: DynamicsModel, z: ca.SX, u: ca.SX, d: ca.SX, dt_s: float, *, sub: int = 4) -> ca.SX:
    """One sample of ``x' = f(x) + g(x) u + d`` with ``sub`` RK4 substeps (u, d held), as a casadi expression."""
    dt = dt_s / sub
    for _ in range(sub):
        k1 = model.f(z) + model.g(z) @ u + d
        k2 = model.f(z + dt / 2 * k1) + model.g(z + dt / 2 * k1) @ u + d
        k3 = model.f(z + dt / 2 * k2) + model.g(z + dt / 2 * k2) @ u + d
        k4 = model.f(z + dt * k3) + model.g(z + dt * k3) @ u + d
        z = z + dt / 6 * (k1 + 2 * k2 + 2 * k3 + k4)
    return z


def _block_function(model: DynamicsModel, dt_s: float, samples: int) -> ca.Function:
    """One MPC step of the sampled loop as a CasADi function (any model, any disturbance, with noise).

    inputs: x0, x_hat0, u_hat (3), noise (3 x m), delta (3 x m), worst (1: delta = bound q/|q|), bound, direction
    (3, used while q = 0), sigma; outputs: X, X_hat, U (3 x m: states at the sample starts and the applied u),
    x_end, x_hat_end. RK4 with 4 substeps per sample for the plant and the nominal.
    """
    key = (model.cache_key, dt_s, samples)
    cached = _BLOCK_CACHE.get(key)
    if cached is not None:
        return cached
    x0, xh0, uh = (ca.SX.sym(n, STATE_DIM) for n in ("x0", "xh0", "uh"))
    noise, delta = ca.SX.sym("noise", STATE_DIM, samples), ca.SX.sym("delta", STATE_DIM, samples)
    worst, bound, sigma = ca.SX.sym("worst"), ca.SX.sym("bound"), ca.SX.sym("sigma")
    direction = ca.SX.sym("direction", STATE_DIM)

    def rk4(z: ca.SX, u: ca.SX, d: ca.SX) -> ca.SX:
        return rk4_symbolic(model, z, u, d, dt_s)

    x, xh = x0, xh0
    xs, xhs, us = [], [], []
    zero = ca.SX.zeros(STATE_DIM)
    for k in range(samples):
        q = x - xh
        u = uh - sigma * (q + noise[:, k])
        norm = ca.norm_2(q)
        d_worst = bound * ca.if_else(norm > 1e-15, q / ca.fmax(norm, 1e-300), direction)
        d = ca.if_else(worst > 0.5, d_worst, delta[:, k])
        xs.append(x)
        xhs.append(xh)
        us.append(u)
        x = rk4(x, u, d)
        xh = rk4(xh, uh, zero)
    fn = ca.Function("sample_block", [x0, xh0, uh, noise, delta, worst, bound, direction, sigma],
                     [ca.horzcat(*xs), ca.horzcat(*xhs), ca.horzcat(*us), x, xh])
    _BLOCK_CACHE[key] = fn
    return fn


@dataclass
class _Leg:
    index: int
    target: Target
    goal: np.ndarray
    path: GuidePath
    obstacles: np.ndarray  # K x 3: cx, cy, required distance of the nominal
    departed_s: float
    obstacle_cols: tuple[np.ndarray, np.ndarray, np.ndarray] = field(init=False, repr=False)  # contiguous columns
    s_m: float = 0.0
    entered_s: float | None = None
    inside_s: float | None = None
    departure_s: float | None = None

    def __post_init__(self) -> None:
        obs = self.obstacles
        self.obstacle_cols = (np.ascontiguousarray(obs[:, 0]), np.ascontiguousarray(obs[:, 1]),
                              np.ascontiguousarray(obs[:, 2]))


def _start_leg(scenario: Scenario, tube: TubeDesign, *, index: int, target: Target, source: str, x_hat: np.ndarray,
               t_s: float, chord_m: float) -> _Leg:
    region = scenario.region(target.region)
    if region.unsafe:
        raise DesignError(f"target {target.region} is an unsafe region")
    discs = leg_obstacles(scenario, source, target.region)
    grown = [(cx, cy, rho + tube.clearance_m) for cx, cy, rho in discs]
    path = guide_path(tuple(float(v) for v in x_hat[:2]), region.center, grown, box_x=tube.workspace_x,
                      box_y=tube.workspace_y, margin_m=GUIDE_MARGIN_M)
    obstacles = np.array([(cx, cy, r + chord_m) for cx, cy, r in grown], dtype=float).reshape(-1, 3)
    goal = np.array([region.center[0], region.center[1], scenario.initial_heading])
    return _Leg(index=index, target=target, goal=goal, path=path, obstacles=obstacles, departed_s=t_s)


def _slots(leg: _Leg, pos: np.ndarray, reach_m: float) -> np.ndarray:
    """3 x M obstacle slots: the leg's discs within ``reach_m`` of ``pos``, then unused ones (far, zero radius)."""
    ox, oy, orad = leg.obstacle_cols
    active = leg.obstacles[np.hypot(ox - pos[0], oy - pos[1]) - orad <= reach_m] if len(ox) else leg.obstacles
    k = len(active)
    slots = np.empty((3, max(MIN_OBSTACLE_SLOTS, k)))
    slots[:, :k] = active.T
    slots[0, k:] = pos[0] + FAR_AWAY_M
    slots[1, k:] = pos[1]
    slots[2, k:] = 0.0
    return slots


def check_run_arguments(scenario: Scenario, targets: Sequence[Target], *, start_region: str | None,
                        mocap_noise_m: float, t_end_s: float | None, start_pose: Sequence[float] | None) -> str:
    """The start region of a tube-MPC run, after checking its arguments (``InvalidArgumentError`` naming the bad
    one; ``DesignError`` for an unsafe start region)."""
    if not targets:
        raise InvalidArgumentError("targets: at least one target is required")
    if not (math.isfinite(mocap_noise_m) and mocap_noise_m >= 0):
        raise InvalidArgumentError(f"mocap_noise_m={mocap_noise_m!r} must be a finite non-negative number")
    if t_end_s is not None and not (math.isfinite(t_end_s) and t_end_s > 0):
        raise InvalidArgumentError(f"t_end_s={t_end_s!r} must be a positive number")
    source = start_region or scenario.initial_region
    for name in [source, *(t.region for t in targets)]:
        if name not in {r.name for r in scenario.regions}:
            raise InvalidArgumentError(f"region={name!r} is not in scenario {scenario.name!r}")
    if scenario.region(source).unsafe:
        raise DesignError(f"start region {source} is an unsafe region")
    if start_pose is not None and not (len(start_pose) == STATE_DIM and all(math.isfinite(v) for v in start_pose)):
        raise InvalidArgumentError(f"start_pose={start_pose!r} must be {STATE_DIM} finite numbers (x, y, theta)")
    return source


def disturbance_of(disturbance: str | DisturbanceLike, scenario: Scenario, rng: np.random.Generator
                   ) -> DisturbanceLike:
    """A model name drawn from ``rng`` with the scenario's bound, or a given signal (its bound checked)."""
    if isinstance(disturbance, str):
        return make_disturbance(disturbance, scenario.disturbance.bound, rng)
    if not (math.isfinite(disturbance.bound) and disturbance.bound >= 0):
        raise InvalidArgumentError(f"disturbance bound={disturbance.bound!r} must be a finite non-negative number")
    return disturbance


def run_closed_loop(scenario: Scenario, targets: Sequence[Target], *, start_region: str | None = None,
                    disturbance: str | DisturbanceLike = "random", seed: int = 0, t_end_s: float | None = None,
                    mocap_noise_m: float = 0.0, model: DynamicsModel | None = None,
                    start_pose: Sequence[float] | None = None) -> ClosedLoopResult:
    """Simulate the tube MPC through ``targets`` from the centre of ``start_region`` (see module docstring).

    ``disturbance``: a model name (``DISTURBANCE_MODELS``, drawn from ``seed``) or a ``DisturbanceLike`` signal.
    ``start_pose``: (x, y, theta) where the robot and the nominal start (default: the start region's centre with
    the scenario's initial heading). ``seed`` also draws the MoCap noise.
    """
    from tubempc.control.loop import Plant, drive
    from tubempc.control.tube_controller import TubeMPC

    source = check_run_arguments(scenario, targets, start_region=start_region, mocap_noise_m=mocap_noise_m,
                                 t_end_s=t_end_s, start_pose=start_pose)
    model = model or model_for(scenario)
    tube = design_tube(scenario, model)
    rng = np.random.default_rng(seed)
    dist = disturbance_of(disturbance, scenario, rng)
    # the linear world model's nominal in closed form, except under the outward push with noise (RK4 blocks)
    closed_form = model.linear_world and not (dist.may_be_worst and mocap_noise_m > 0)
    controller = TubeMPC(model, tube=tube, closed_form_nominal=closed_form)
    start = scenario.region(source)
    pose = (start.center[0], start.center[1], scenario.initial_heading) if start_pose is None else tuple(start_pose)
    result = drive(scenario, controller, targets, source=source, start=pose, dist=dist, rng=rng, seed=seed,
                   t_end_s=t_end_s, mocap_noise_m=mocap_noise_m, plant=Plant(model, full_blocks=not closed_form),
                   budget_speed_mps=tube.max_planar_speed_mps)
    return replace(result, solver=tuple(controller.records), tube_radius_m=tube.radius_m, sigma=tube.sigma)
