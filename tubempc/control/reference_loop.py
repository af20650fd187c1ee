"""The tube MPC's closed loop as it was before the controller protocol: the reference the one loop is tested
against (``tests/control/test_loop_equality.py``). Not used by the package otherwise.

It simulates a whole MPC step at once: the linear world model in closed form (``_world_block``: the per-sample
recursion summed in another order), any other model (and the world model under ``worst`` with MoCap noise) as one
CasADi function of the step's samples (``_casadi_block``). ``run_closed_loop`` (``tubempc.control.loop``) steps
``TubeMPC`` per sample instead; its nominal states, solves and arrivals are the same bits, its real states and
inputs the same up to the rounding of the summation order (1e-12).
"""

from __future__ import annotations

import math
from collections.abc import Sequence

import casadi as ca
import numpy as np

from tubempc.control.closed_loop import (
    LOOKAHEAD_M,
    MIN_OBSTACLE_SLOTS,
    Arrival,
    ClosedLoopResult,
    SolverRecord,
    Target,
    _block_function,
    _Leg,
    _slots,
    _start_leg,
    check_run_arguments,
    disturbance_of,
)
from tubempc.control.disturbance import DisturbanceLike
from tubempc.control.dynamics import STATE_DIM, DynamicsModel, model_for
from tubempc.control.fhocp import NominalMPC, build_fhocp
from tubempc.control.guide import references
from tubempc.control.tube import design_tube
from tubempc.errors import DesignError
from tubempc.scenario import Scenario

__all__ = ["run_closed_loop_reference"]


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


def _disc(scenario: Scenario, name: str) -> tuple[float, float, float]:
    region = scenario.region(name)
    return float(region.center[0]), float(region.center[1]), float(region.radius)


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


def run_closed_loop_reference(scenario: Scenario, targets: Sequence[Target], *, start_region: str | None = None,
                    disturbance: str | DisturbanceLike = "random", seed: int = 0, t_end_s: float | None = None,
                    mocap_noise_m: float = 0.0, model: DynamicsModel | None = None,
                    start_pose: Sequence[float] | None = None) -> ClosedLoopResult:
    """``run_closed_loop``'s run (same arguments, same checks), by the straight loop of this module: the reference
    the equality test holds the general loop to."""
    source = check_run_arguments(scenario, targets, start_region=start_region, mocap_noise_m=mocap_noise_m,
                                 t_end_s=t_end_s, start_pose=start_pose)
    model = model or model_for(scenario)
    tube = design_tube(scenario, model)
    rng = np.random.default_rng(seed)
    dist = disturbance_of(disturbance, scenario, rng)
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
