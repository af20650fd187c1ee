"""Your controller in the loop: a small protocol, its loader, and the closed loop that runs it on a kinematic plant.

input: a ``Scenario``, a controller (``load_controller("package.module:factory")``, or any object with the protocol),
the targets, a disturbance model and a seed -> output: the same ``ClosedLoopResult`` the tube MPC's loop gives
(so logging, certification, regress and falsify treat both alike).

The protocol (``Controller``), called at the MoCap rate:

- ``input_model``: ``"holonomic"`` (commands ``(vx, vy, wz)`` in the body frame) or ``"unicycle"`` (``(v, w)``);
- ``reset(scenario, plan)`` before a run: the scenario and the ``ControllerPlan`` (start region and pose, the
  targets in order, the waypoints: the start region's centre then each target's);
- ``step(t_s, state, reference) -> command``: ``state`` is the measured ``(x, y, theta)`` (MoCap, with its noise),
  ``reference`` the current ``Reference`` (target region, its centre and radius, how long to hold there);
- optional ``tube_radius_m``: the tube radius the controller claims (recorded in the log's metadata);
  optional ``nominal() -> (x, y, theta)``: the controller's nominal state after the last step (logged on the
  nominal topic, so that the certifier's tube check can judge the claim; without it the nominal topic is NaN and
  the tube check cannot pass).

The loop is ``tubempc.control.loop.drive``, the one the tube MPC runs in too (``TubeMPC`` implements this
protocol, with the optional ``period_s`` and ``arrived(t_s, reference)``). For a user's controller the plant is
kinematic: holonomic ``p' = R(theta) (vx, vy), theta' = wz``; unicycle ``p' = v (cos theta, sin theta),
theta' = w``; plus the scenario's disturbance ``delta`` (``|delta| <= disturbance.bound``, on x, y and theta),
integrated with 4 RK4 substeps per MoCap sample, the command held over the sample. The disturbance models are the
tube MPC's; ``worst`` pushes towards the nearest unsafe region (the tube MPC's worst case pushes along the tube
error, which a controller without a nominal state does not have). A target is reached when the robot disc is
inside its region (real state) and, if the controller has ``arrived``, that says so too; the reference moves to
the next target once the hold time has passed. Commands are applied as given: a controller that exceeds the input
box is a violation the certifier finds.

Optional members the loop uses: ``tube_radius_m``, ``nominal()``, ``period_s`` (the decision period, a whole
number of MoCap samples: references switch, the disturbance's ``worst_at`` is decided and the noise and
disturbance are drawn at its multiples; default one sample), ``arrived(t_s, reference) -> bool`` (the controller's
own arrival condition, asked at each period start before ``step``).
"""

from __future__ import annotations

import importlib
import math
from collections.abc import Sequence
from dataclasses import dataclass
from typing import Any, Literal, Protocol, runtime_checkable

import numpy as np

from tubempc.control.closed_loop import ClosedLoopResult, Target
from tubempc.control.disturbance import DisturbanceLike, InvalidArgumentError, make_disturbance
from tubempc.errors import ControllerError
from tubempc.scenario import Scenario

__all__ = ["Controller", "ControllerPlan", "Reference", "checked_controller", "load_controller", "run_controller"]

InputModel = Literal["holonomic", "unicycle"]


@dataclass(frozen=True, slots=True)
class Reference:
    """The current target: its index in the plan, region name, centre and radius, and the hold-until time."""

    index: int
    region: str
    center_xy: tuple[float, float]
    radius_m: float
    depart_after_s: float | None


@dataclass(frozen=True, slots=True)
class ControllerPlan:
    start_region: str
    start_pose: tuple[float, float, float]
    targets: tuple[Reference, ...]

    @property
    def waypoints(self) -> tuple[tuple[float, float], ...]:
        return (self.start_pose[:2], *(t.center_xy for t in self.targets))


@runtime_checkable
class Controller(Protocol):
    input_model: InputModel

    def reset(self, scenario: Scenario, plan: ControllerPlan) -> None: ...

    def step(self, t_s: float, state: np.ndarray, reference: Reference) -> Sequence[float] | np.ndarray: ...


def load_controller(spec: str) -> Controller:
    """``package.module:factory`` -> ``factory()`` (a controller); every failure is one ``ControllerError``."""
    module_name, sep, attr = spec.partition(":")
    if not sep or not module_name or not attr:
        raise ControllerError(f"--controller {spec!r}: expected package.module:factory")
    try:
        module = importlib.import_module(module_name)
    except ImportError as err:
        raise ControllerError(f"--controller {spec!r}: cannot import {module_name} ({err})") from None
    factory = getattr(module, attr, None)
    if not callable(factory):
        raise ControllerError(f"--controller {spec!r}: {module_name} has no callable {attr!r}")
    controller = factory()
    if not isinstance(controller, Controller):
        raise ControllerError(f"--controller {spec!r}: {attr}() returned {type(controller).__name__}, which lacks "
                              f"input_model, reset(scenario, plan) or step(t_s, state, reference)")
    if getattr(controller, "input_model", None) not in ("holonomic", "unicycle"):
        raise ControllerError(f"--controller {spec!r}: input_model must be 'holonomic' or 'unicycle', not "
                              f"{getattr(controller, 'input_model', None)!r}")
    return controller


def checked_controller(spec: str, scenario: Scenario) -> Controller:
    """``load_controller`` plus the check that its input model is the scenario's (``inputs.model``)."""
    controller = load_controller(spec)
    if controller.input_model != scenario.inputs.model:
        raise ControllerError(f"--controller {spec!r}: its input model is {controller.input_model}, scenario "
                              f"{scenario.name!r} has {scenario.inputs.model} (inputs.model)")
    return controller


def _command(raw: Any, model: InputModel, t_s: float) -> np.ndarray:
    """The body-frame command ``(vx, vy, wz)`` of a controller's output."""
    try:
        values = np.asarray(raw, dtype=float).ravel()
    except (TypeError, ValueError):
        raise ControllerError(f"step() at t={t_s:.2f} s returned {raw!r}, not numbers") from None
    size = 3 if model == "holonomic" else 2
    if values.size != size or not all(map(math.isfinite, values.tolist())):
        raise ControllerError(f"step() at t={t_s:.2f} s returned {values.tolist()}: a {model} command is "
                              f"{size} finite numbers")
    return values if model == "holonomic" else np.array([values[0], 0.0, values[1]])


def _velocity(state: np.ndarray, u_body: np.ndarray, delta: np.ndarray) -> np.ndarray:
    c, s = math.cos(state[2]), math.sin(state[2])
    out: np.ndarray = np.array([c * u_body[0] - s * u_body[1], s * u_body[0] + c * u_body[1], u_body[2]]) + delta
    return out


def _rk4(state: np.ndarray, u_body: np.ndarray, delta: np.ndarray, dt: float, sub: int = 4) -> np.ndarray:
    h = dt / sub
    for _ in range(sub):
        k1 = _velocity(state, u_body, delta)
        k2 = _velocity(state + h / 2 * k1, u_body, delta)
        k3 = _velocity(state + h / 2 * k2, u_body, delta)
        k4 = _velocity(state + h * k3, u_body, delta)
        state = state + h / 6 * (k1 + 2 * k2 + 2 * k3 + k4)
    return state


def _towards_nearest_obstacle(scenario: Scenario, p: np.ndarray, fallback: np.ndarray) -> np.ndarray:
    best, out = math.inf, fallback
    for r in scenario.unsafe_regions:
        if r.disc_center is None:
            continue
        d = np.array([r.center[0] - p[0], r.center[1] - p[1], 0.0])
        norm = float(np.linalg.norm(d))
        if 1e-12 < norm < best:
            best, out = norm, d / norm
    return out


def _reference(scenario: Scenario, k: int, target: Target) -> Reference:
    region = scenario.region(target.region)
    return Reference(k, region.name, (float(region.center[0]), float(region.center[1])), float(region.radius),
                     target.depart_after_s)


def run_controller(scenario: Scenario, controller: Controller, targets: Sequence[Target], *,
                   start_region: str | None = None, disturbance: str | DisturbanceLike = "random", seed: int = 0,
                   t_end_s: float | None = None, mocap_noise_m: float = 0.0,
                   start_pose: Sequence[float] | None = None) -> ClosedLoopResult:
    """Run ``controller`` through ``targets`` on the kinematic plant of its input model (see the module docstring)."""
    if not targets:
        raise InvalidArgumentError("targets: at least one target is required")
    if not (math.isfinite(mocap_noise_m) and mocap_noise_m >= 0):
        raise InvalidArgumentError(f"mocap_noise_m={mocap_noise_m!r} must be a finite non-negative number")
    source = start_region or scenario.initial_region
    names = {r.name for r in scenario.regions}
    for name in [source, *(t.region for t in targets)]:
        if name not in names:
            raise InvalidArgumentError(f"region={name!r} is not in scenario {scenario.name!r}")
    from tubempc.control.loop import Plant, drive

    rng = np.random.default_rng(seed)
    dist: DisturbanceLike = (make_disturbance(disturbance, scenario.disturbance.bound, rng)
                             if isinstance(disturbance, str) else disturbance)
    start = scenario.region(source)
    x = (start.center[0], start.center[1], scenario.initial_heading) if start_pose is None else tuple(start_pose)
    return drive(scenario, controller, targets, source=source, start=x, dist=dist, rng=rng, seed=seed,
                 t_end_s=t_end_s, mocap_noise_m=mocap_noise_m, plant=Plant(), budget_speed_mps=scenario.max_speed_mps)
