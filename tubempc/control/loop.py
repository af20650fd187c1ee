"""The one closed loop: any controller of the protocol (``tubempc.control.user.Controller``) on a plant, with the
scenario's disturbance and MoCap noise -> a ``ClosedLoopResult``.

The tube MPC (``tubempc.control.tube_controller.TubeMPC``, through ``run_closed_loop``) and a user's controller
(``run_controller``) both run here. The loop goes in blocks of the controller's decision period (``period_s``,
optional: one MoCap sample by default; the tube MPC's is ``mpc.h``). At a block start: the disturbance's
``worst_at`` is decided, the block's MoCap noise and disturbance samples are drawn (noise first), and the reference
moves on when the current target is reached (the robot disc was inside the region and, if the controller has
``arrived(t_s, reference)``, that says so too) and its hold time has passed. With a one-sample period the robot's
position at the block start counts; with a longer one, the samples before it. Then at every sample:
``step(t_s, measured, reference)`` -> body-frame command, held over the sample on the plant.

Plants: the kinematic holonomic/unicycle plant of ``tubempc.control.user`` (``worst`` pushes towards the nearest
unsafe region), or a ``DynamicsModel`` ``x' = f(x) + g(x) u + delta`` (``worst`` pushes along the tube error
``x - nominal()``), integrated exactly for the linear world model and with 4 RK4 substeps per sample otherwise.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass
from typing import Any

import casadi as ca
import numpy as np

from tubempc.control.closed_loop import Arrival, ClosedLoopResult, Target, rk4_symbolic
from tubempc.control.disturbance import DisturbanceLike
from tubempc.control.dynamics import STATE_DIM, DynamicsModel
from tubempc.control.user import (
    Controller,
    ControllerPlan,
    _command,
    _reference,
    _rk4,
    _towards_nearest_obstacle,
    _velocity,
)
from tubempc.errors import ControllerError
from tubempc.scenario import Scenario

__all__ = ["Plant", "drive"]


@dataclass(frozen=True)
class Plant:
    """``model`` None: the kinematic plant of the controller's input model. ``full_blocks``: draw the noise and the
    disturbance for a whole period even when the run ends within it, at times ``t0 + k dt`` (the RK4 sample
    block of the tube MPC's loop did so)."""

    model: DynamicsModel | None = None
    full_blocks: bool = False


_STEP_CACHE: dict[tuple[str, float], ca.Function] = {}


def _model_step(model: DynamicsModel, dt_s: float) -> ca.Function:
    """One sample of ``x' = f(x) + g(x) u + d`` with 4 RK4 substeps (u, d held)."""
    key = (model.cache_key, dt_s)
    fn = _STEP_CACHE.get(key)
    if fn is None:
        z0, u, d = (ca.SX.sym(n, STATE_DIM) for n in ("x", "u", "d"))
        fn = _STEP_CACHE[key] = ca.Function("plant_step", [z0, u, d], [rk4_symbolic(model, z0, u, d, dt_s)])
    return fn


def _period_samples(controller: Controller, dt: float) -> int:
    period_s = getattr(controller, "period_s", None)
    if period_s is None:
        return 1
    samples = round(float(period_s) / dt)
    if samples < 1 or abs(samples * dt - float(period_s)) > 1e-9:
        raise ControllerError(f"period_s={period_s!r} is not a whole number of MoCap samples ({dt!r} s)")
    return samples


def _time_budget_s(scenario: Scenario, targets: Sequence[Target], start_xy: Sequence[float], speed: float) -> float:
    budget, prev = 0.0, start_xy
    for tg in targets:
        c = scenario.region(tg.region).center
        budget += 3.0 * math.dist(prev, c) / speed + 30.0
        prev = c
    return max(budget, max((tg.depart_after_s or 0.0) for tg in targets) + 30.0)


@dataclass
class _Leg:
    index: int
    departed_s: float
    entered_s: float | None = None
    inside_s: float | None = None
    departure_s: float | None = None


@dataclass(frozen=True)
class _Loop:
    """What stays fixed during one run: the scenario, the controller and its hooks, the plant and its step."""

    scenario: Scenario
    controller: Controller
    plant: Plant
    dist: DisturbanceLike
    dt: float
    period: int  # samples per decision period
    eta: float  # robot radius
    model_step: ca.Function | None
    nominal: Any  # the controller's nominal() hook, or None
    arrived: Any  # the controller's arrived(t_s, reference) hook, or None


@dataclass(frozen=True)
class _Trace:
    """The run's samples, one row per sample: true, measured and nominal state, body and world input."""

    xs: np.ndarray
    xms: np.ndarray
    xhs: np.ndarray
    ub: np.ndarray
    uw: np.ndarray

    @classmethod
    def empty(cls, n: int) -> _Trace:
        return cls(np.zeros((n, 3)), np.zeros((n, 3)), np.full((n, 3), np.nan), np.zeros((n, 3)), np.zeros((n, 3)))


def _inside(x: np.ndarray, ref: Any, eta: float) -> bool:
    """The robot's disc lies inside the reference's region."""
    return bool(math.hypot(x[0] - ref.center_xy[0], x[1] - ref.center_xy[1]) + eta <= ref.radius_m)


def _update_legs(loop: _Loop, legs: list[_Leg], refs: Sequence[Any], x: np.ndarray, t0: float, *,
                 done: bool) -> bool:
    """At a block start: note the current target's entry, and move to the next target once the current one is
    reached and held (a new leg). True when the last target is reached and held now."""
    leg = legs[-1]
    ref = refs[leg.index]
    if loop.period == 1 and leg.inside_s is None and _inside(x, ref, loop.eta):
        leg.inside_s = t0
    if callable(loop.arrived) and loop.arrived(t0, ref) and leg.entered_s is None:
        leg.entered_s = t0
    if not callable(loop.arrived) and leg.entered_s is None:
        leg.entered_s = leg.inside_s
    if done or leg.entered_s is None or leg.inside_s is None or (
            ref.depart_after_s is not None and t0 < ref.depart_after_s - 1e-9):
        return False
    if leg.index + 1 < len(refs):
        leg.departure_s = t0
        legs.append(_Leg(leg.index + 1, t0))
        return False
    return True


def _run_block(loop: _Loop, trace: _Trace, x: np.ndarray, *, i: int, m_blk: int, t_arr: np.ndarray, leg: _Leg,
               ref: Any, rng: np.random.Generator, mocap_noise_m: float) -> np.ndarray:
    """One decision period from sample ``i`` (``m_blk`` samples): draw the block's noise and disturbance, then at
    every sample measure, ask the controller, record and advance the plant. Returns the state after the block."""
    dt, dist, plant = loop.dt, loop.dist, loop.plant
    t0 = float(t_arr[i])
    m_draw = loop.period if plant.full_blocks else m_blk
    noise = np.zeros((m_draw, 2))
    if mocap_noise_m > 0:
        noise = rng.normal(scale=mocap_noise_m, size=(m_draw, 2))
    worst = dist.worst_at(t0) if dist.may_be_worst else False
    deltas = None if worst else np.asarray(
        dist.batch(t0 + dt * np.arange(m_draw) if plant.full_blocks else t_arr[i:i + m_blk]), dtype=float)
    for j in range(m_blk):
        k = i + j
        t = float(t_arr[k])
        measured = x.copy()
        measured[:2] += noise[j]
        u = _command(loop.controller.step(t, measured.copy(), ref), loop.controller.input_model, t)
        trace.xs[k], trace.xms[k], trace.ub[k] = x, measured, u
        if callable(loop.nominal):
            trace.xhs[k] = np.asarray(loop.nominal(), dtype=float).ravel()[:3]
        if loop.period > 1 and leg.inside_s is None and _inside(x, ref, loop.eta):
            leg.inside_s = t
        x, trace.uw[k] = _advance(x, u, scenario=loop.scenario, plant=plant, model_step=loop.model_step,
                                  x_hat=trace.xhs[k], worst=worst, deltas=deltas, j=j, dist=dist, dt=dt)
    return x


def drive(scenario: Scenario, controller: Controller, targets: Sequence[Target], *, source: str,
          start: Sequence[float], dist: DisturbanceLike, rng: np.random.Generator, seed: int, t_end_s: float | None,
          mocap_noise_m: float, plant: Plant, budget_speed_mps: float) -> ClosedLoopResult:
    """Run ``controller`` from pose ``start`` through ``targets`` (already validated; see the module docstring).
    Without ``t_end_s`` the run ends when the last target is reached and held, or after a budget of 3x the
    straight-line time at ``budget_speed_mps`` + 30 s per target."""
    dt = 1.0 / scenario.mocap.rate_hz
    x = np.array([float(v) for v in start], dtype=float)
    refs = tuple(_reference(scenario, k, t) for k, t in enumerate(targets))
    controller.reset(scenario, ControllerPlan(source, (float(x[0]), float(x[1]), float(x[2])), refs))
    model = plant.model
    loop = _Loop(scenario, controller, plant, dist, dt, _period_samples(controller, dt), scenario.robot.radius,
                 None if model is None or model.linear_world else _model_step(model, dt),
                 getattr(controller, "nominal", None), getattr(controller, "arrived", None))
    t_max = t_end_s if t_end_s is not None else _time_budget_s(scenario, targets, scenario.region(source).center,
                                                               budget_speed_mps)
    n_max = math.floor(t_max / dt + 1e-9) + 1
    t_arr = np.round(np.arange(n_max) * dt, 9)  # sample times without accumulated float noise
    trace = _Trace.empty(n_max)
    legs = [_Leg(0, 0.0)]
    done = False
    n = n_max
    i = 0
    while i < n:
        if _update_legs(loop, legs, refs, x, float(t_arr[i]), done=done):
            done = True
            if t_end_s is None:
                n = i + 1
        m_blk = min(loop.period, n - i)
        x = _run_block(loop, trace, x, i=i, m_blk=m_blk, t_arr=t_arr, leg=legs[-1], ref=refs[legs[-1].index],
                       rng=rng, mocap_noise_m=mocap_noise_m)
        i += m_blk
    if model is not None and not model.linear_world and n:
        g_all = np.asarray(model.g.map(n)(trace.xs[:n].T), dtype=float).reshape(STATE_DIM, n, STATE_DIM)
        trace.uw[:n] = np.einsum("ikj,kj->ki", g_all, trace.ub[:n])
    return _result(trace, legs, targets, t_arr[:n], controller=controller, source=source, seed=seed, dist=dist,
                   mocap_noise_m=mocap_noise_m)


def _result(trace: _Trace, legs: list[_Leg], targets: Sequence[Target], t_s: np.ndarray, *, controller: Controller,
            source: str, seed: int, dist: DisturbanceLike, mocap_noise_m: float) -> ClosedLoopResult:
    """The run's samples (the first ``len(t_s)``), its arrivals and whether every target was reached."""
    n = len(t_s)
    arrivals = tuple(Arrival(targets[lg.index].region, lg.departed_s,
                             None if lg.entered_s is None else round(lg.entered_s - lg.departed_s, 9), lg.entered_s,
                             lg.inside_s, lg.departure_s) for lg in legs)
    ok, reason = True, None
    for k, tg in enumerate(targets):
        if k >= len(legs) or legs[k].entered_s is None or legs[k].inside_s is None:
            ok, reason = False, f"target {tg.region} (#{k + 1}) not reached by t={t_s[n - 1]:.2f} s"
            break
    claimed = getattr(controller, "tube_radius_m", None)
    return ClosedLoopResult(
        t_s=t_s.copy(), x=trace.xs[:n].copy(), x_measured=trace.xms[:n].copy(), x_hat=trace.xhs[:n].copy(),
        u_world=trace.uw[:n].copy(), u_body=trace.ub[:n].copy(), solver=(), arrivals=arrivals, targets=tuple(targets),
        start_region=source, tube_radius_m=float(claimed) if isinstance(claimed, int | float) else 0.0, sigma=0.0,
        seed=seed, disturbance=dist.kind, disturbance_params=dist.params, mocap_noise_m=mocap_noise_m, ok=ok,
        reason=reason)


def _advance(x: np.ndarray, u: np.ndarray, *, scenario: Scenario, plant: Plant, model_step: ca.Function | None,
             x_hat: np.ndarray, worst: bool, deltas: np.ndarray | None, j: int, dist: DisturbanceLike,
             dt: float) -> tuple[np.ndarray, Any]:
    """The state after one sample under the body-frame command ``u``, and the applied input as a world-frame
    velocity (for a nonlinear model: the model's input, mapped through g(x) after the run)."""
    model = plant.model
    if model is None:
        if worst:
            delta = dist.bound * _towards_nearest_obstacle(scenario, x, np.asarray(dist.direction, dtype=float))
        else:
            assert deltas is not None
            delta = deltas[j]
        return _rk4(x, u, delta, dt), _velocity(x, u, np.zeros(3))
    if worst:
        q = x - x_hat
        norm = math.sqrt(float(q.dot(q)))
        delta = dist.bound * (q / norm if norm > 1e-15 else np.asarray(dist.direction, dtype=float))
    else:
        assert deltas is not None
        delta = deltas[j]
    if model_step is None:  # the linear world model: world-frame velocity input, exact over the sample
        c, s = math.cos(x[2]), math.sin(x[2])
        u_world = np.array([c * u[0] - s * u[1], s * u[0] + c * u[1], u[2]])
        return x + dt * (u_world + delta), u_world
    return np.asarray(model_step(x, u, delta), dtype=float).ravel(), u
