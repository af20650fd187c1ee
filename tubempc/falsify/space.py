"""The search space: a point ``z`` of the cube ``[-1, 1]^d`` -> one admissible perturbation of a run (``Candidate``).

input: a ``SearchSpace`` (family, knots/switches, bounds taken from the scenario) and ``z`` -> output: a frozen
``Candidate``: the disturbance signal (``|delta| <= bound`` at every sample), the start pose (inside the start
region's terminal set ``|e|_P <= eps``), the MoCap noise (standard deviation at most the scenario's, and its seed).

Every method searches the same cube, and ``z = 0`` is the unperturbed run (no disturbance, the region's centre, no
noise), so shrinking towards 0 (hypothesis) simplifies a counterexample towards "nothing happens". Vectors are
drawn in the cube and scaled onto the ball where they leave it, so full-magnitude disturbances are common.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any, Literal

import numpy as np

from tubempc.falsify.signals import SineSignal, StepSignal, SwitchSignal, into_ball
from tubempc.scenario import Scenario

__all__ = ["FAMILIES", "Candidate", "Family", "SearchSpace", "make_space"]

Family = Literal["steps", "sine", "switch"]
FAMILIES: tuple[Family, ...] = ("steps", "sine", "switch")
FREQUENCY_RANGE_HZ = (0.01, 1.0)  # sinusoids: log-uniform between these
_SEED_SPAN = 2**31 - 1


@dataclass(frozen=True, slots=True)
class Candidate:
    """One perturbed run: the point ``z`` and what it stands for."""

    z: tuple[float, ...]
    signal: StepSignal | SineSignal | SwitchSignal
    start_pose: tuple[float, float, float]
    noise_std_m: float
    noise_seed: int

    def describe(self) -> dict[str, Any]:
        return {"disturbance": self.signal.params, "start_pose": list(self.start_pose),
                "mocap_noise_std_m": self.noise_std_m, "mocap_noise_seed": self.noise_seed}


@dataclass(frozen=True, slots=True)
class SearchSpace:
    """Bounds of the search, all from the scenario (``bound_scale`` > 1 stress-tests past the stated bound)."""

    family: Family
    knots: int  # steps: values per axis
    switches: int  # switch: switching times
    bound: float  # delta_bar searched (the scenario's times bound_scale)
    horizon_s: float  # the run's length the knots and switching times spread over
    step_s: float  # MPC step h: switching times are multiples of it
    start_center: tuple[float, float, float]  # start region centre and initial heading
    start_semi_axes: tuple[float, float, float]  # eps / sqrt(P_i): the terminal set is an ellipsoid
    noise_std_max_m: float  # the scenario's MoCap noise std (0: no noise dimension)
    vary_start: bool = True

    def __post_init__(self) -> None:
        if self.family not in FAMILIES:
            raise ValueError(f"family={self.family!r} is not one of {', '.join(FAMILIES)}")
        if self.knots < 1 or self.switches < 1:
            raise ValueError(f"knots={self.knots!r} and switches={self.switches!r} must be at least 1")
        if not (math.isfinite(self.bound) and self.bound >= 0):
            raise ValueError(f"bound={self.bound!r} must be a finite non-negative number")
        if not (self.horizon_s > 0 and self.step_s > 0):
            raise ValueError(f"horizon_s={self.horizon_s!r} and step_s={self.step_s!r} must be positive")

    # ---- layout of z ------------------------------------------------------------------------------------------
    def _signal_names(self) -> list[str]:
        if self.family == "steps":
            return [f"steps[{j}].{a}" for j in range(self.knots) for a in "xyt"]
        if self.family == "sine":
            return [f"sine.{p}.{a}" for p in ("amplitude", "frequency", "phase") for a in "xyt"]
        return ([f"switch.time[{j}]" for j in range(self.switches)] + ["switch.first_outward"]
                + [f"switch.value[{j}].{a}" for j in range(self.switches + 1) for a in "xyt"])

    def names(self) -> list[str]:
        """One name per coordinate of ``z`` (``.t`` is the heading axis)."""
        out = self._signal_names()
        if self.vary_start:
            out += ["start.x", "start.y", "start.theta"]
        if self.noise_std_max_m > 0:
            out += ["noise.std", "noise.seed"]
        return out

    @property
    def dim(self) -> int:
        return len(self.names())

    def describe(self) -> dict[str, Any]:
        return {"family": self.family, "knots": self.knots if self.family == "steps" else None,
                "switches": self.switches if self.family == "switch" else None, "bound": self.bound,
                "horizon_s": self.horizon_s, "mpc_step_s": self.step_s, "start_center": list(self.start_center),
                "start_semi_axes": list(self.start_semi_axes), "vary_start": self.vary_start,
                "mocap_noise_std_max_m": self.noise_std_max_m, "dim": self.dim, "names": self.names(),
                "cube": "[-1, 1] per coordinate; 0 is the unperturbed run"}

    # ---- decoding -----------------------------------------------------------------------------------------------
    def decode(self, z: np.ndarray | tuple[float, ...] | list[float]) -> Candidate:
        v = np.asarray(z, dtype=float)
        if v.shape != (self.dim,) or not np.isfinite(v).all() or np.any(np.abs(v) > 1.0):
            raise ValueError(f"z must be {self.dim} numbers in [-1, 1], got {v.tolist()!r}")
        n_sig = len(self._signal_names())
        signal = self._signal(v[:n_sig])
        rest = v[n_sig:]
        cx, cy, ch = self.start_center
        pose = (cx, cy, ch)
        if self.vary_start:
            e = into_ball(rest[:3], 1.0) * np.asarray(self.start_semi_axes)
            pose = (cx + float(e[0]), cy + float(e[1]), ch + float(e[2]))
            rest = rest[3:]
        std, seed = 0.0, 0
        if self.noise_std_max_m > 0:
            std = abs(float(rest[0])) * self.noise_std_max_m
            seed = math.floor((float(rest[1]) + 1.0) / 2.0 * _SEED_SPAN)
        return Candidate(tuple(float(x) for x in v), signal, pose, std, seed)

    def _signal(self, v: np.ndarray) -> StepSignal | SineSignal | SwitchSignal:
        b = self.bound
        if self.family == "steps":
            return StepSignal(b, into_ball(v.reshape(self.knots, 3) * b, b), self.horizon_s)
        if self.family == "sine":
            lo, hi = FREQUENCY_RANGE_HZ
            freq = lo * (hi / lo) ** ((v[3:6] + 1.0) / 2.0)
            return SineSignal(b, v[0:3] * b, freq, v[6:9] * math.pi)
        m = self.switches
        fractions = np.sort((v[:m] + 1.0) / 2.0)
        times = tuple(float(round(f * self.horizon_s / self.step_s) * self.step_s) for f in fractions)
        values = into_ball(v[m + 1:].reshape(m + 1, 3) * b, b)
        return SwitchSignal(b, times, bool(v[m] >= 0.0), values)


#: without an MPC in the scenario (a user's controller): start heading spread and the disturbance's step
NO_MPC_HEADING_RAD = 0.1
NO_MPC_STEP_S = 0.1

def make_space(scenario: Scenario, start_region: str, *, family: Family = "steps", knots: int = 4,
               switches: int = 3, horizon_s: float, bound_scale: float = 1.0, vary_start: bool = True
               ) -> SearchSpace:
    """The search space of a run of ``scenario`` (the judged one: its bound, terminal set and noise)."""
    if not (math.isfinite(bound_scale) and bound_scale > 0):
        raise ValueError(f"bound_scale={bound_scale!r} must be a positive number")
    region = scenario.region(start_region)
    if scenario.mpc_spec is not None:  # the tube MPC's terminal set, and its step
        eps = scenario.mpc.eps
        axes = tuple(eps / math.sqrt(p) for p in scenario.mpc.P)
        step_s = scenario.mpc.h
    else:  # a user's controller (no MPC): a quarter of the room the robot disc has in its region, 0.1 rad, 0.1 s
        room = max((region.radius - scenario.robot.radius) / 4, 0.0) if region.disc_radius is not None else 0.0
        axes, step_s = (room, room, NO_MPC_HEADING_RAD), NO_MPC_STEP_S
    return SearchSpace(family=family, knots=knots, switches=switches,
                       bound=scenario.disturbance.bound * bound_scale, horizon_s=horizon_s, step_s=step_s,
                       start_center=(region.center[0], region.center[1], scenario.initial_heading),
                       start_semi_axes=(axes[0], axes[1], axes[2]), noise_std_max_m=scenario.mocap.noise_std,
                       vary_start=vary_start)
