"""Scenario model: validated, frozen values for the workspace, regions, robot, limits, controller and spec.

input: a mapping (from YAML) -> output: a ``Scenario`` whose every field has been checked; errors raise
``ScenarioError`` naming the source file, the field path (``regions[3].radius``) and what is wrong.
Geometry helpers here are plain data queries; the certifier keeps its own membership semantics.
"""

from __future__ import annotations

import hashlib
import json
import math
from typing import Annotated, Any, Literal

from pydantic import BaseModel, ConfigDict, Field, field_validator, model_validator

from tubempc.mitl import Formula, atoms, parse

__all__ = [
    "DisturbanceSpec",
    "DynamicsSpec",
    "InputLimits",
    "MocapSpec",
    "MpcSpec",
    "Region",
    "RobotSpec",
    "Scenario",
    "Topics",
    "TubeSpec",
    "Workspace",
]

PositiveFloat = Annotated[float, Field(gt=0, allow_inf_nan=False)]
NonNegFloat = Annotated[float, Field(ge=0, allow_inf_nan=False)]
FiniteFloat = Annotated[float, Field(allow_inf_nan=False)]
Triple = tuple[PositiveFloat, PositiveFloat, PositiveFloat]

_ATOM_PATTERN = r"^[A-Za-z_][A-Za-z0-9_]*$"


class _Frozen(BaseModel):
    model_config = ConfigDict(frozen=True, extra="forbid", strict=False)


class Workspace(_Frozen):
    """Axis-aligned box ``x in [x0, x1], y in [y0, y1]`` in metres."""

    x: tuple[FiniteFloat, FiniteFloat]
    y: tuple[FiniteFloat, FiniteFloat]

    @model_validator(mode="after")
    def _ordered(self) -> Workspace:
        for axis, (lo, hi) in (("x", self.x), ("y", self.y)):
            if not lo < hi:
                raise ValueError(f"{axis}: lower bound {lo} must be below upper bound {hi}")
        return self

    def contains_disc(self, center: tuple[float, float], radius_m: float) -> bool:
        cx, cy = center
        return (self.x[0] + radius_m <= cx <= self.x[1] - radius_m) and (
            self.y[0] + radius_m <= cy <= self.y[1] - radius_m
        )


class Region(_Frozen):
    """A circular region of interest ``M(center, radius)``. ``unsafe`` marks an obstacle."""

    name: Annotated[str, Field(pattern=_ATOM_PATTERN)]
    center: tuple[FiniteFloat, FiniteFloat]
    radius: PositiveFloat
    labels: tuple[Annotated[str, Field(pattern=_ATOM_PATTERN)], ...] = ()
    unsafe: bool = False

    @property
    def radius_m(self) -> float:
        return self.radius


class RobotSpec(_Frozen):
    """The robot disc ``M(x, eta)`` and the speed bound used to reason about motion between samples."""

    radius: PositiveFloat
    max_speed: PositiveFloat | None = None  # m/s; default: the norm of the linear input bounds


class InputLimits(_Frozen):
    """Box input set ``|u_i| <= max_abs[i]`` for (vx, vy, wz)."""

    max_abs: Triple


class DisturbanceSpec(_Frozen):
    bound: NonNegFloat  # delta_bar, Euclidean norm bound on the additive disturbance


class TubeSpec(_Frozen):
    sigma_low: PositiveFloat
    radius: PositiveFloat | None = None  # r_q; derived from the dynamics model when absent


class MpcSpec(_Frozen):
    """Nominal FHOCP parameters: sampling step h, horizon N (seconds), diagonal weights, terminal level eps."""

    h: PositiveFloat
    horizon: PositiveFloat
    Q: Triple
    R: Triple
    P: Triple
    eps: PositiveFloat = 0.07

    @model_validator(mode="after")
    def _horizon_vs_step(self) -> MpcSpec:
        steps = self.horizon / self.h
        if steps < 1 - 1e-9:
            raise ValueError(f"horizon={self.horizon} is shorter than the step h={self.h}")
        if abs(steps - round(steps)) > 1e-6:
            raise ValueError(f"horizon={self.horizon} is not a whole number of steps h={self.h}")
        return self

    @property
    def steps(self) -> int:
        return round(self.horizon / self.h)

    @property
    def terminal_radius_m(self) -> float:
        """Radius of the terminal ball: ``|e| <= eps / sqrt(lambda_min(P))`` (Algorithm 1)."""
        return self.eps / math.sqrt(min(self.P))


class DynamicsSpec(_Frozen):
    """Which dynamics model the controller uses. ``world``: g = I; ``body``: g = blockdiag(R(theta), 1)."""

    model: Literal["world", "body"] = "world"
    theta_max: Annotated[float, Field(gt=0, lt=math.pi / 2)] = math.pi / 3  # heading restriction for ``body``


class Topics(_Frozen):
    pose: str = "/qualisys/nexus/pose"
    cmd_vel: str = "/nexus/cmd_vel"
    nominal: str = "/nexus/nominal_pose"
    solver: str = "/nexus/mpc_status"
    metadata: str = "/tubempc/metadata"
    tf_child_frame: str | None = None  # when the pose comes from /tf: the child frame of the robot

    @field_validator("pose", "cmd_vel", "nominal", "solver", "metadata")
    @classmethod
    def _topic_name(cls, v: str) -> str:
        if not v.startswith("/") or any(c.isspace() for c in v):
            raise ValueError(f"topic {v!r} must start with '/' and contain no spaces")
        return v


class MocapSpec(_Frozen):
    rate_hz: PositiveFloat = 100.0
    noise_std: NonNegFloat = 0.0  # metres, optional simulated MoCap noise


class Scenario(_Frozen):
    """A whole mission: workspace, regions, robot, limits, tube and MPC parameters, the MITL spec, topics."""

    name: str
    workspace: Workspace
    robot: RobotSpec
    inputs: InputLimits
    disturbance: DisturbanceSpec
    tube: TubeSpec
    mpc: MpcSpec
    regions: tuple[Region, ...]
    initial_region: str
    spec: str
    topics: Topics = Topics()
    dynamics: DynamicsSpec = DynamicsSpec()
    mocap: MocapSpec = MocapSpec()
    initial_heading: FiniteFloat = 0.0  # radians

    @field_validator("spec")
    @classmethod
    def _spec_parses(cls, v: str) -> str:
        parse(v)  # SpecSyntaxError is a ValueError: pydantic reports it under the field "spec"
        return v

    @model_validator(mode="after")
    def _consistent(self) -> Scenario:
        if not self.regions:
            raise ValueError("regions: at least one region is required")
        names = [r.name for r in self.regions]
        dupes = sorted({n for n in names if names.count(n) > 1})
        if dupes:
            raise ValueError(f"regions: duplicate region name(s) {', '.join(dupes)}")
        if self.initial_region not in names:
            raise ValueError(f"initial_region: {self.initial_region!r} is not one of the regions {names}")
        eta = self.robot.radius
        for i, r in enumerate(self.regions):
            cx, cy = r.center
            ws = self.workspace
            if not (ws.x[0] + r.radius <= cx <= ws.x[1] - r.radius and ws.y[0] + r.radius <= cy <= ws.y[1] - r.radius):
                raise ValueError(f"regions[{i}] ({r.name}): the region does not fit inside the workspace")
            if not r.unsafe and r.radius <= eta:
                raise ValueError(
                    f"regions[{i}] ({r.name}): radius {r.radius} m cannot contain the robot disc of radius {eta} m"
                )
        for i, a in enumerate(self.regions):
            for b in self.regions[i + 1 :]:
                d = math.dist(a.center, b.center)
                if d < a.radius + b.radius:
                    raise ValueError(f"regions: {a.name} and {b.name} overlap (centres {d:.3f} m apart)")
        known = {lab for r in self.regions for lab in r.labels}
        unknown = sorted(atoms(self.formula) - known)
        if unknown:
            raise ValueError(f"spec: atomic proposition(s) {', '.join(unknown)} label no region (known: "
                             f"{', '.join(sorted(known)) or 'none'})")
        if self.initial.unsafe:
            raise ValueError(f"initial_region: {self.initial_region} is unsafe")
        return self

    # ---- derived, read-only views -------------------------------------------------------------------------
    @property
    def formula(self) -> Formula:
        return parse(self.spec)

    @property
    def initial(self) -> Region:
        return self.region(self.initial_region)

    def region(self, name: str) -> Region:
        for r in self.regions:
            if r.name == name:
                return r
        raise KeyError(f"region={name!r} is not in scenario {self.name!r}")

    @property
    def safe_regions(self) -> tuple[Region, ...]:
        return tuple(r for r in self.regions if not r.unsafe)

    @property
    def unsafe_regions(self) -> tuple[Region, ...]:
        return tuple(r for r in self.regions if r.unsafe)

    @property
    def max_speed_mps(self) -> float:
        """Speed bound of the robot's centre (m/s): stated, or the norm of the linear input bounds."""
        if self.robot.max_speed is not None:
            return self.robot.max_speed
        return math.hypot(self.inputs.max_abs[0], self.inputs.max_abs[1])

    @property
    def g_min(self) -> float:
        """lambda_min of sym(g) over the admissible states of the dynamics model (1 for g = I)."""
        if self.dynamics.model == "body":
            return math.cos(self.dynamics.theta_max)
        return 1.0

    @property
    def tube_radius_m(self) -> float:
        """r_q: stated in the scenario, or ``delta_bar / (sigma_low * g_min)`` (the corrected lemma)."""
        if self.tube.radius is not None:
            return self.tube.radius
        return self.disturbance.bound / (self.tube.sigma_low * self.g_min)

    def labels(self) -> dict[str, tuple[str, ...]]:
        return {r.name: r.labels for r in self.regions}

    def to_dict(self) -> dict[str, Any]:
        return self.model_dump(mode="json")

    def sha256(self) -> str:
        """Hash of the canonical JSON form (key order and YAML formatting do not matter)."""
        blob = json.dumps(self.to_dict(), sort_keys=True, separators=(",", ":")).encode()
        return hashlib.sha256(blob).hexdigest()
