"""Closed-loop simulation of the tube MPC: nominal FHOCP every h, ancillary law at the MoCap rate.

input: a ``Scenario``, a sequence of ``Target`` (region, optional hold-until time), a disturbance model name and a
seed -> output: a frozen ``ClosedLoopResult`` with the real, measured and nominal states and the applied inputs
(world frame and the body-frame command as logged) at every MoCap sample, one ``SolverRecord`` per MPC step,
one ``Arrival`` per target, and ``ok``/``reason``.

Loop: at t_k = k h the FHOCP is solved from the nominal state x_hat(t_k) (the nominal evolves on its own, it
is never reset to the measurement, so q = x - x_hat stays in the tube); its first input u_hat is held over h.
At every MoCap sample ``u = u_hat - sigma (x_meas - x_hat)`` is held over 1/rate; the plant
``x' = f(x) + g(x) u + delta`` is integrated exactly for the linear world model and with RK4 (4 substeps per
sample) otherwise. A target is *arrived* when the nominal enters the terminal ball (Algorithm 1, checked at
multiples of h); the robot then holds position there until ``depart_after_s`` and goes on to the next target.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass, field
from typing import Any

import casadi as ca
import numpy as np

from tubempc.control.disturbance import DisturbanceLike, InvalidArgumentError, make_disturbance
from tubempc.control.dynamics import STATE_DIM, DynamicsModel, model_for
from tubempc.control.fhocp import FAR_AWAY_M, NominalMPC, build_fhocp
from tubempc.control.guide import GuidePath, guide_path, references
from tubempc.control.tube import TubeDesign, design_tube
from tubempc.errors import DesignError
from tubempc.scenario import Scenario

__all__ = ["Arrival", "ClosedLoopResult", "SolverRecord", "Target", "hold_position", "leg_obstacles",
           "run_closed_loop"]

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
    sub = 4
    dt = dt_s / sub

    def rk4(z: ca.SX, u: ca.SX, d: ca.SX) -> ca.SX:
        for _ in range(sub):
            k1 = model.f(z) + model.g(z) @ u + d
            k2 = model.f(z + dt / 2 * k1) + model.g(z + dt / 2 * k1) @ u + d
            k3 = model.f(z + dt / 2 * k2) + model.g(z + dt / 2 * k2) @ u + d
            k4 = model.f(z + dt * k3) + model.g(z + dt * k3) @ u + d
            z = z + dt / 6 * (k1 + 2 * k2 + 2 * k3 + k4)
        return z

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


def _casadi_block(i: int, m_blk: int, x: np.ndarray, x_hat: np.ndarray, u_hat: np.ndarray, *, xs: np.ndarray,
                  xms: np.ndarray, xhs: np.ndarray, uw: np.ndarray, t0_s: float, dist: DisturbanceLike,
                  rng: np.random.Generator, sigma: float, dt: float, noise_m: float,
                  fn: ca.Function, samples: int) -> tuple[np.ndarray, np.ndarray]:
    """``m_blk`` (<= samples) samples through ``_block_function``; the arrays get the sample-start values."""
    noise = np.zeros((samples, STATE_DIM))
    if noise_m > 0:
        noise[:, :2] = rng.normal(scale=noise_m, size=(samples, 2))
    worst = dist.worst_at(t0_s)
    deltas = np.zeros((samples, STATE_DIM)) if worst else dist.batch(t0_s + dt * np.arange(samples))
    states, nominal, inputs, x_end, xh_end = fn(x, x_hat, u_hat, noise.T, deltas.T, float(worst), dist.bound,
                                                dist.direction, sigma)
    states = np.asarray(states, dtype=float).T
    xs[i:i + m_blk] = states[:m_blk]
    xms[i:i + m_blk] = states[:m_blk] + noise[:m_blk]
    xhs[i:i + m_blk] = np.asarray(nominal, dtype=float).T[:m_blk]
    uw[i:i + m_blk] = np.asarray(inputs, dtype=float).T[:m_blk]
    return np.asarray(x_end, dtype=float).ravel(), np.asarray(xh_end, dtype=float).ravel()


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


def _disc(scenario: Scenario, name: str) -> tuple[float, float, float]:
    region = scenario.region(name)
    return float(region.center[0]), float(region.center[1]), float(region.radius)


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


def _world_block(i: int, m_blk: int, x: np.ndarray, x_hat: np.ndarray, u_hat: np.ndarray, *, xs: np.ndarray,
                 xms: np.ndarray, xhs: np.ndarray, uw: np.ndarray, t_arr: np.ndarray, dist: DisturbanceLike,
                 rng: np.random.Generator, sigma: float, dt: float, noise_m: float, powers: np.ndarray,
                 lower: np.ndarray, k_dt: np.ndarray | None = None,
                 drift: np.ndarray | None = None) -> tuple[np.ndarray, np.ndarray]:
    """``m_blk`` samples of the linear world model in closed form (exactly the per-sample recursion).

    q_k = x_k - x_hat_k obeys ``q+ = a q + dt (delta - sigma n)`` with a = 1 - sigma dt. Under the outward push (no
    noise) q keeps its direction e and ``|q|+ = a |q| + dt delta_bar``. ``k_dt`` ((m+1) x 1, k dt) and ``drift``
    (m+1, the delta_bar part of |q|_k) are per-run constants for ``m_blk <= m`` (computed here when omitted).
    """
    if k_dt is None:
        k_dt = (np.arange(m_blk + 1) * dt)[:, None]
    nominal = x_hat + k_dt[: m_blk + 1] * u_hat  # m+1 x 3
    q0 = x - x_hat
    noise = None
    if noise_m > 0:
        noise = np.zeros((m_blk, 3))
        noise[:, :2] = rng.normal(scale=noise_m, size=(m_blk, 2))
    if dist.worst_at(float(t_arr[i])):
        r0 = math.sqrt(float(q0.dot(q0)))  # np.linalg.norm's own formula
        e = q0 / r0 if r0 > 1e-15 else dist.direction
        if drift is None:
            drift = dt * dist.bound * (1.0 - powers) / (sigma * dt)
        radius = r0 * powers[: m_blk + 1] + drift[: m_blk + 1]
        q = radius[:, None] * e
    else:
        w = dt * dist.batch(t_arr[i:i + m_blk]) if noise is None else dt * (dist.batch(t_arr[i:i + m_blk])
                                                                            - sigma * noise)
        q = powers[: m_blk + 1, None] * q0 + lower[: m_blk + 1, :m_blk] @ w
    states = nominal + q
    xs[i:i + m_blk] = states[:m_blk]
    xhs[i:i + m_blk] = nominal[:m_blk]
    if noise is None:
        xms[i:i + m_blk] = states[:m_blk]
        uw[i:i + m_blk] = u_hat - sigma * q[:m_blk]
    else:
        xms[i:i + m_blk] = states[:m_blk] + noise
        uw[i:i + m_blk] = u_hat - sigma * (q[:m_blk] + noise)
    return states[m_blk], nominal[m_blk]


def run_closed_loop(scenario: Scenario, targets: Sequence[Target], *, start_region: str | None = None,
                    disturbance: str | DisturbanceLike = "random", seed: int = 0, t_end_s: float | None = None,
                    mocap_noise_m: float = 0.0, model: DynamicsModel | None = None,
                    start_pose: Sequence[float] | None = None) -> ClosedLoopResult:
    """Simulate the tube MPC through ``targets`` from the centre of ``start_region`` (see module docstring).

    ``disturbance``: a model name (``DISTURBANCE_MODELS``, drawn from ``seed``) or a ``DisturbanceLike`` signal.
    ``start_pose``: (x, y, theta) where the robot and the nominal start (default: the start region's centre with
    the scenario's initial heading). ``seed`` also draws the MoCap noise.
    """
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
    model = model or model_for(scenario)
    tube = design_tube(scenario, model)
    rng = np.random.default_rng(seed)
    if isinstance(disturbance, str):
        dist: DisturbanceLike = make_disturbance(disturbance, scenario.disturbance.bound, rng)
    else:
        dist = disturbance
        if not (math.isfinite(dist.bound) and dist.bound >= 0):
            raise InvalidArgumentError(f"disturbance bound={dist.bound!r} must be a finite non-negative number")
    h = scenario.mpc.h
    dt = 1.0 / scenario.mocap.rate_hz
    per_step = round(h / dt)
    if per_step < 1 or abs(per_step * dt - h) > 1e-9:
        raise DesignError(f"mpc.h={h!r} s is not a whole number of MoCap samples (mocap.rate_hz="
                          f"{scenario.mocap.rate_hz!r})")
    n_stages = scenario.mpc.steps
    speed = tube.max_planar_speed_mps
    reach = n_stages * h * speed + 0.2
    problem = build_fhocp(scenario, model, tube, MIN_OBSTACLE_SLOTS)
    chord = problem.chord_margin_m
    mpc_by_slots: dict[int, NominalMPC] = {}
    fast = model.linear_world and not (dist.may_be_worst and mocap_noise_m > 0)
    block_fn = None if fast else _block_function(model, dt, per_step)

    start = scenario.region(source)
    x = np.array([start.center[0], start.center[1], scenario.initial_heading] if start_pose is None
                 else [float(v) for v in start_pose], dtype=float)
    x_hat = x.copy()
    if t_end_s is None:
        budget = 0.0
        prev = start.center
        for tg in targets:
            c = scenario.region(tg.region).center
            budget += 3.0 * math.dist(prev, c) / speed + 30.0
            prev = c
        t_max = max(budget, max((tg.depart_after_s or 0.0) for tg in targets) + 30.0)
    else:
        t_max = t_end_s
    n_max = math.floor(t_max / dt + 1e-9) + 1
    t_arr = np.round(np.arange(n_max) * dt, 9)  # sample times without accumulated float noise
    xs = np.zeros((n_max, 3))
    xms = np.zeros((n_max, 3))
    xhs = np.zeros((n_max, 3))
    uw = np.zeros((n_max, 3))
    ub = np.zeros((n_max, 3))
    records: list[SolverRecord] = []
    legs: list[_Leg] = [_start_leg(scenario, tube, index=0, target=targets[0], source=source, x_hat=x_hat, t_s=0.0,
                                   chord_m=chord)]
    u_hat = np.zeros(3)
    terminal = tube.terminal_radius_m
    eta = scenario.robot.radius
    done_at: int | None = None
    sigma = tube.sigma
    cx, cy, rho = _disc(scenario, targets[0].region)
    a_step = 1.0 - sigma * dt  # q+ = a q + dt (delta - sigma noise) for the linear world model
    powers = a_step ** np.arange(per_step + 1)  # a^k, k = 0..m
    lower = np.array([[a_step ** (k - 1 - j) if j < k else 0.0 for j in range(per_step)]
                      for k in range(per_step + 1)])  # (m+1) x m: q_k = a^k q_0 + sum_j a^(k-1-j) w_j
    k_dt = (np.arange(per_step + 1) * dt)[:, None]  # k dt, k = 0..m
    drift = dt * dist.bound * (1.0 - powers) / (sigma * dt)  # |q|_k - a^k |q|_0 under the worst case
    step_m = speed * h
    i = 0
    while i < n_max:
        t = float(t_arr[i])
        leg = legs[-1]
        if i % per_step == 0:
            to_goal = x_hat - leg.goal
            if leg.entered_s is None and math.sqrt(float(to_goal.dot(to_goal))) <= terminal:  # np.linalg.norm
                leg.entered_s = t
            if leg.entered_s is not None and leg.inside_s is not None:
                ready = leg.target.depart_after_s is None or t >= leg.target.depart_after_s - 1e-9
                if ready and leg.index + 1 < len(targets):
                    leg.departure_s = t
                    leg = _start_leg(scenario, tube, index=leg.index + 1, target=targets[leg.index + 1],
                                     source=leg.target.region, x_hat=x_hat, t_s=t, chord_m=chord)
                    legs.append(leg)
                    cx, cy, rho = _disc(scenario, leg.target.region)
                elif ready and t_end_s is None:
                    done_at = i
            leg.s_m = leg.path.project(x_hat[:2], leg.s_m, 1.0)
            refs = np.empty((n_stages + 1, 3))
            references(leg.path, leg.s_m, lookahead_m=LOOKAHEAD_M, step_m=step_m, stages=n_stages + 1, out=refs)
            refs[:, 2] = leg.goal[2]
            slots = _slots(leg, x_hat[:2], reach)
            m = slots.shape[1]
            if m not in mpc_by_slots:
                mpc_by_slots[m] = NominalMPC(build_fhocp(scenario, model, tube, m) if m != MIN_OBSTACLE_SLOTS
                                             else problem)
            out = mpc_by_slots[m].solve(x_hat, refs, slots)
            for other, ctrl in mpc_by_slots.items():  # keep every warm start current
                if other != m:
                    ctrl.adopt(out)
            records.append(SolverRecord(t_s=t, status=out.status, success=out.success, iterations=out.iterations,
                                        solve_time_s=out.solve_time_s, backup=out.backup, target=leg.target.region))
            u_hat = out.inputs[0].copy()
        m_blk = 1 if done_at is not None else min(per_step, n_max - i)
        if block_fn is None:
            x_next, xh_next = _world_block(i, m_blk, x, x_hat, u_hat, xs=xs, xms=xms, xhs=xhs, uw=uw, t_arr=t_arr,
                                           dist=dist, rng=rng, sigma=sigma, dt=dt, noise_m=mocap_noise_m,
                                           powers=powers, lower=lower, k_dt=k_dt, drift=drift)
        else:
            x_next, xh_next = _casadi_block(i, m_blk, x, x_hat, u_hat, xs=xs, xms=xms, xhs=xhs, uw=uw, t0_s=t,
                                            dist=dist, rng=rng, sigma=sigma, dt=dt, noise_m=mocap_noise_m,
                                            fn=block_fn, samples=per_step)
        if leg.inside_s is None:
            inside = np.hypot(xs[i:i + m_blk, 0] - cx, xs[i:i + m_blk, 1] - cy) + eta <= rho
            if inside.any():
                leg.inside_s = float(t_arr[i + int(np.argmax(inside))])
        i += m_blk
        if done_at is not None:
            break
        x, x_hat = x_next, xh_next
    n = (done_at + 1) if done_at is not None else n_max
    # uw holds the applied input u; as a world-frame velocity (g(x) u) and as the body-frame command (cmd_vel)
    applied = uw[:n].copy()
    if model.input_frame == "world":
        cos, sin = np.cos(xs[:n, 2]), np.sin(xs[:n, 2])
        ub[:n, 0] = cos * applied[:, 0] + sin * applied[:, 1]
        ub[:n, 1] = -sin * applied[:, 0] + cos * applied[:, 1]
        ub[:n, 2] = applied[:, 2]
    else:
        ub[:n] = applied
    if not model.linear_world and n:
        g_all = np.asarray(model.g.map(n)(xs[:n].T), dtype=float).reshape(STATE_DIM, n, STATE_DIM)
        uw[:n] = np.einsum("ikj,kj->ki", g_all, applied)
    arrivals = tuple(Arrival(region=lg.target.region, departed_s=lg.departed_s,
                             t_ij_s=None if lg.entered_s is None else round(lg.entered_s - lg.departed_s, 9),
                             entered_terminal_s=lg.entered_s, inside_s=lg.inside_s, departure_s=lg.departure_s)
                     for lg in legs)
    ok, reason = True, None
    for k, tg in enumerate(targets):
        if k >= len(legs) or legs[k].entered_s is None or legs[k].inside_s is None:
            ok = False
            reason = f"target {tg.region} (#{k + 1}) not reached by t={t_arr[n - 1]:.2f} s"
            break
    return ClosedLoopResult(t_s=t_arr[:n].copy(), x=xs[:n].copy(), x_measured=xms[:n].copy(), x_hat=xhs[:n].copy(),
                            u_world=uw[:n].copy(), u_body=ub[:n].copy(), solver=tuple(records), arrivals=arrivals,
                            targets=tuple(targets), start_region=source, tube_radius_m=tube.radius_m,
                            sigma=tube.sigma, seed=seed, disturbance=dist.kind, disturbance_params=dist.params,
                            mocap_noise_m=mocap_noise_m, ok=ok, reason=reason)
