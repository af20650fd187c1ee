"""Scenario model: validated, frozen values for the workspace, regions, robot, limits, controller and spec.

input: a mapping (from YAML) -> output: a ``Scenario`` whose every field has been checked; errors raise
``ScenarioError`` naming the source file, the field path (``regions[3].radius``) and what is wrong.
Geometry helpers here are plain data queries; the certifier keeps its own membership semantics. What keeps the
planner from using a valid scenario, and the geometry the certifier warns about, are judged in
``tubempc.scenario.review``.
"""

from __future__ import annotations

import hashlib
import json
import math
from typing import Annotated, Any, Literal

from pydantic import BaseModel, ConfigDict, Field, field_validator, model_validator

from tubempc.errors import ScenarioError
from tubempc.mitl import Formula, atoms, parse
from tubempc.scenario.polygon import polygon_bounds, polygon_problem
from tubempc.scenario.review import certification_warnings, planning_problems

__all__ = [
    "CHECK_NAMES",
    "DEFAULT_TOPICS",
    "DisturbanceSpec",
    "DynamicsSpec",
    "FleetRobot",
    "InputLimits",
    "MocapSpec",
    "MpcSpec",
    "ProximitySpec",
    "Region",
    "RobotSpec",
    "Scenario",
    "SeparationPair",
    "SeparationSpec",
    "SignalSpec",
    "Topics",
    "TubeSpec",
    "Workspace",
]

PositiveFloat = Annotated[float, Field(gt=0, allow_inf_nan=False)]
NonNegFloat = Annotated[float, Field(ge=0, allow_inf_nan=False)]
FiniteFloat = Annotated[float, Field(allow_inf_nan=False)]
Triple = tuple[PositiveFloat, PositiveFloat, PositiveFloat]
Point = tuple[FiniteFloat, FiniteFloat]

_ATOM_PATTERN = r"^[A-Za-z_][A-Za-z0-9_]*$"


class _Frozen(BaseModel):
    # defer_build: a model's validator is built on first use, not at import (loading a scenario builds only the
    # Scenario's, which holds its nested models' schemas; the same checks, a quicker start for every command)
    model_config = ConfigDict(frozen=True, extra="forbid", strict=False, populate_by_name=True, defer_build=True)


class Workspace(_Frozen):
    """Axis-aligned box ``x in [x0, x1], y in [y0, y1]`` in metres, or a simple polygon ``polygon: [[x, y], ...]``.

    ``x`` and ``y`` always read as the bounding box (the box itself for a box workspace)."""

    box_x: tuple[FiniteFloat, FiniteFloat] | None = Field(None, alias="x")
    box_y: tuple[FiniteFloat, FiniteFloat] | None = Field(None, alias="y")
    polygon: tuple[Point, ...] | None = None

    @model_validator(mode="after")
    def _shape(self) -> Workspace:
        if self.polygon is not None:
            if self.box_x is not None or self.box_y is not None:
                raise ValueError("give either a box (x, y) or a polygon, not both")
            problem = polygon_problem(self.polygon)
            if problem:
                raise ValueError(f"polygon: {problem}")
            return self
        if self.box_x is None or self.box_y is None:
            raise ValueError("give a box (both x: [x0, x1] and y: [y0, y1]) or a polygon: [[x, y], ...]")
        for axis, (lo, hi) in (("x", self.box_x), ("y", self.box_y)):
            if not lo < hi:
                raise ValueError(f"{axis}: lower bound {lo} must be below upper bound {hi}")
        return self

    @property
    def is_box(self) -> bool:
        return self.polygon is None

    @property
    def bounds(self) -> tuple[float, float, float, float]:
        """``(x_min, y_min, x_max, y_max)``."""
        if self.polygon is not None:
            return polygon_bounds(self.polygon)
        if self.box_x is None or self.box_y is None:  # excluded by the validator
            raise ScenarioError("neither a box nor a polygon", field="workspace")
        return self.box_x[0], self.box_y[0], self.box_x[1], self.box_y[1]

    @property
    def x(self) -> tuple[float, float]:
        b = self.bounds
        return b[0], b[2]

    @property
    def y(self) -> tuple[float, float]:
        b = self.bounds
        return b[1], b[3]

    def contains_disc(self, center: tuple[float, float], radius_m: float) -> bool:
        """Box workspaces only (the planner's rule); a polygon workspace is refused by ``planning_problems``."""
        cx, cy = center
        return (self.x[0] + radius_m <= cx <= self.x[1] - radius_m) and (
            self.y[0] + radius_m <= cy <= self.y[1] - radius_m
        )


class Region(_Frozen):
    """A region of interest: a disc ``M(center, radius)`` or a simple polygon. ``unsafe`` marks an obstacle."""

    name: Annotated[str, Field(pattern=_ATOM_PATTERN)]
    disc_center: tuple[FiniteFloat, FiniteFloat] | None = Field(None, alias="center")
    disc_radius: PositiveFloat | None = Field(None, alias="radius")
    polygon: tuple[Point, ...] | None = None
    labels: tuple[Annotated[str, Field(pattern=_ATOM_PATTERN)], ...] = ()
    unsafe: bool = False

    @model_validator(mode="after")
    def _shape(self) -> Region:
        if self.polygon is not None:
            if self.disc_center is not None or self.disc_radius is not None:
                raise ValueError("give either a disc (center, radius) or a polygon, not both")
            problem = polygon_problem(self.polygon)
            if problem:
                raise ValueError(f"polygon: {problem}")
        elif self.disc_center is None or self.disc_radius is None:
            raise ValueError("give a disc (center: [x, y] and radius) or a polygon: [[x, y], ...]")
        return self

    @property
    def is_disc(self) -> bool:
        return self.polygon is None

    @property
    def center(self) -> tuple[float, float]:
        """Centre of a disc region (the planner's regions are discs: ``Scenario.planning_problems``)."""
        if self.disc_center is None:
            raise ScenarioError("is a polygon: this part of tubempc (the planner, the controller, the online monitor) "
                                "takes disc regions only", field=f"regions.{self.name}")
        return self.disc_center

    @property
    def radius(self) -> float:
        if self.disc_radius is None:
            raise ScenarioError("is a polygon: this part of tubempc (the planner, the controller, the online monitor) "
                                "takes disc regions only", field=f"regions.{self.name}")
        return self.disc_radius

    @property
    def radius_m(self) -> float:
        return self.radius

    @property
    def bounds(self) -> tuple[float, float, float, float]:
        """``(x_min, y_min, x_max, y_max)`` of the region."""
        if self.polygon is not None:
            return polygon_bounds(self.polygon)
        (cx, cy), r = self.center, self.radius
        return cx - r, cy - r, cx + r, cy + r


class RobotSpec(_Frozen):
    """The robot disc ``M(x, eta)`` and the speed bound used to reason about motion between samples."""

    radius: PositiveFloat
    max_speed: PositiveFloat | None = None  # m/s; default: the norm of the linear input bounds


class InputLimits(_Frozen):
    """The input model and its box.

    ``holonomic`` (default): ``|u_i| <= max_abs[i]`` for (vx, vy, wz) in the body frame (the paper's mecanum robot);
    ``unicycle`` (differential drive): ``max_abs = [v, w]`` bounds linear.x and angular.z, and a linear.y beyond
    ``lateral_tolerance`` (m/s) is a violation (a differential drive cannot move sideways).
    """

    model: Literal["holonomic", "unicycle"] = "holonomic"
    max_abs: tuple[PositiveFloat, ...]
    lateral_tolerance: NonNegFloat = 0.001

    @model_validator(mode="after")
    def _arity(self) -> InputLimits:
        want = 3 if self.model == "holonomic" else 2
        names = "[vx, vy, wz]" if want == 3 else "[v, w]"
        if len(self.max_abs) != want:
            raise ValueError(f"max_abs: the {self.model} model takes {want} bounds {names}, got {len(self.max_abs)}")
        return self

    @property
    def linear_speed_mps(self) -> float:
        """Largest speed of the robot's centre the input box allows."""
        if self.model == "unicycle":
            return self.max_abs[0]
        return math.hypot(self.max_abs[0], self.max_abs[1])


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
    """Topic names. ``nominal`` and ``cmd_vel`` are optional: a check whose topic is not named is not selected.

    A scenario without a ``topics`` block gets the Nexus defaults (``DEFAULT_TOPICS``); inside a ``topics`` block,
    an omitted ``nominal`` or ``cmd_vel`` means "not logged"."""

    pose: str = "/qualisys/nexus/pose"
    cmd_vel: str | None = None
    nominal: str | None = None
    solver: str = "/nexus/mpc_status"
    metadata: str = "/tubempc/metadata"
    tf_child_frame: str | None = None  # when the pose comes from /tf: the child frame of the robot

    @field_validator("pose", "cmd_vel", "nominal", "solver", "metadata")
    @classmethod
    def _topic_name(cls, v: str | None) -> str | None:
        if v is not None:
            _check_topic(v)
        return v


def _check_topic(v: str) -> str:
    if not v.startswith("/") or any(c.isspace() for c in v):
        raise ValueError(f"topic {v!r} must start with '/' and contain no spaces")
    return v


DEFAULT_TOPICS = Topics(cmd_vel="/nexus/cmd_vel", nominal="/nexus/nominal_pose")

#: checks the certifier can run; ``spec`` covers both semantics (timed run and trajectory)
CHECK_NAMES = ("spec", "obstacle_clearance", "workspace", "tube", "input_box")
CheckName = Literal["spec", "obstacle_clearance", "workspace", "tube", "input_box"]


class SignalSpec(_Frozen):
    """An atomic proposition over a message field: ``field op value`` on ``topic`` (sample-and-hold).

    ``field``: a path into the message (``twist.twist.linear.x``, ``position[2]``); ``rate_hz``: the topic's
    expected rate (default: its median rate in the log); a gap longer than 1.5 periods makes the atom unknown."""

    topic: str
    field: Annotated[str, Field(pattern=r"^[A-Za-z_][A-Za-z0-9_]*(\[\d+\])*(\.[A-Za-z_][A-Za-z0-9_]*(\[\d+\])*)*$")]
    op: Literal["<", "<=", ">", ">="]
    value: FiniteFloat
    unit: str | None = None
    rate_hz: PositiveFloat | None = None

    @field_validator("topic")
    @classmethod
    def _topic_name(cls, v: str) -> str:
        return _check_topic(v)

    @model_validator(mode="after")
    def _ros_unit(self) -> SignalSpec:
        problem = unit_problem(self.field, self.unit, self.value)
        if problem:
            raise ValueError(problem)
        return self


#: units ROS conventions fix (REP 103: SI units, angles in radians), by the last two parts of a field path
_REP103_UNITS = {"angular_velocity": "rad/s", "angular": "rad/s", "linear": "m/s", "linear_acceleration": "m/s^2",
                 "position": "m", "translation": "m"}
_REP103_FIELDS = {"range": "m", "ranges": "m", "range_min": "m", "range_max": "m", "angle_min": "rad",
                  "angle_max": "rad", "angle_increment": "rad"}
_UNIT_ALIASES = {"rad/s": {"rad/s", "rads^-1", "rad*s^-1", "rad.s^-1"}, "m/s": {"m/s", "ms^-1", "m*s^-1", "m.s^-1"},
                 "m/s^2": {"m/s^2", "m/s2", "ms^-2", "m*s^-2", "m.s^-2"}, "m": {"m"}, "rad": {"rad"}}
_DEGREE_UNITS = {"deg": "rad", "deg/s": "rad/s", "degree": "rad", "degrees": "rad", "deg/sec": "rad/s",
                 "degrees/s": "rad/s", "°": "rad", "°/s": "rad/s"}


def ros_unit(field: str) -> str | None:
    """The unit ROS conventions (REP 103) fix for a message field path (``twist.twist.angular.z``: rad/s), if any."""
    parts = [p.split("[")[0] for p in field.split(".")]
    if parts[-1] in _REP103_FIELDS:
        return _REP103_FIELDS[parts[-1]]
    if len(parts) >= 2 and parts[-1] in ("x", "y", "z"):
        return _REP103_UNITS.get(parts[-2])
    return None


def unit_problem(field: str, unit: str | None, value: float) -> str | None:
    """Why ``unit`` cannot be the unit of ``field`` (ROS messages carry REP 103's units), with the conversion."""
    want = ros_unit(field)
    if unit is None or want is None:
        return None
    given = unit.strip().replace(" ", "")
    if given in _UNIT_ALIASES.get(want, {want}):
        return None
    if _DEGREE_UNITS.get(given.lower()) == want:
        return (f"unit: {unit}: ROS messages carry {field} in {want} (REP 103); write unit: {want} and value: "
                f"{math.radians(value):.6g} ({value:g} {unit} x pi/180)")
    return f"unit: {unit}: ROS messages carry {field} in {want} (REP 103); give the value in {want}"


#: the motion-capture rates accepted (Hz): periods from 1000 s down to 1 microsecond (integer nanoseconds)
MOCAP_RATE_HZ = (1e-3, 1e6)


#: the largest position noise accepted (m, one standard deviation): far beyond any positioning system, and small
#: enough that the tube check's stated tolerance (3 sigma) stays a finite number
MOCAP_NOISE_STD_M = 1e3


class MocapSpec(_Frozen):
    rate_hz: Annotated[float, Field(ge=MOCAP_RATE_HZ[0], le=MOCAP_RATE_HZ[1], allow_inf_nan=False)] = 100.0
    noise_std: Annotated[float, Field(ge=0, le=MOCAP_NOISE_STD_M, allow_inf_nan=False)] = 0.0  # metres, optional


AtomName = Annotated[str, Field(pattern=_ATOM_PATTERN)]


class FleetRobot(_Frozen):
    """One robot of a multi-robot scenario (``robots:``): its name (the qualifier of its atoms, ``husky.dock``), its
    topics, its disc, its input model and its own signal atoms. Workspace, regions and formula are shared."""

    name: AtomName
    topics: Topics
    radius: PositiveFloat
    max_speed: PositiveFloat | None = None  # m/s; default: the norm of the linear input bounds
    inputs: InputLimits
    signals: dict[AtomName, SignalSpec] = Field(default_factory=dict)
    rate_hz: Annotated[float, Field(ge=MOCAP_RATE_HZ[0], le=MOCAP_RATE_HZ[1], allow_inf_nan=False)] | None = None
    # ^ the pose topic's expected rate (dropout detection); default: mocap.rate_hz

    @field_validator("topics", mode="before")
    @classmethod
    def _pose_named(cls, v: Any) -> Any:
        if isinstance(v, dict) and "pose" not in v:
            raise ValueError("name the robot's pose topic (topics.pose)")
        return v

    @property
    def max_speed_mps(self) -> float:
        return self.max_speed if self.max_speed is not None else self.inputs.linear_speed_mps


class SeparationPair(_Frozen):
    robots: tuple[AtomName, AtomName]
    min_m: NonNegFloat


class SeparationSpec(_Frozen):
    """The least distance the robot discs keep (metres between their edges): ``min_m`` for every pair, or the
    pair's own in ``pairs``."""

    min_m: NonNegFloat
    pairs: tuple[SeparationPair, ...] = ()


class ProximitySpec(_Frozen):
    """A proximity atom: holds while the discs of the two robots are within ``within_m`` of each other (metres
    between their edges); its margin is ``within_m`` minus that distance."""

    robots: tuple[AtomName, AtomName]
    within_m: NonNegFloat


#: top-level fields a multi-robot scenario gives per robot instead (under ``robots:``)
_PER_ROBOT_FIELDS = ("robot", "inputs", "topics", "signals")


class Scenario(_Frozen):
    """A whole mission: workspace, regions, robot, limits, tube and MPC parameters, the MITL spec, topics.

    ``disturbance``, ``tube``, ``mpc`` and ``initial_region`` are needed by the planner and the controller only:
    a scenario for certification may omit them (reading one that is absent raises ``ScenarioError`` naming it;
    ``require_planning`` checks them all at once)."""

    name: str
    workspace: Workspace
    robot: RobotSpec
    inputs: InputLimits
    disturbance_spec: DisturbanceSpec | None = Field(None, alias="disturbance")
    tube_spec: TubeSpec | None = Field(None, alias="tube")
    mpc_spec: MpcSpec | None = Field(None, alias="mpc")
    regions: tuple[Region, ...]
    initial_region_name: str | None = Field(None, alias="initial_region")
    spec: str
    topics: Topics = DEFAULT_TOPICS
    dynamics: DynamicsSpec = DynamicsSpec()
    mocap: MocapSpec = MocapSpec()
    initial_heading: FiniteFloat = 0.0  # radians
    checks: tuple[CheckName, ...] | None = None  # certifier checks to run (default: every check whose data is named)
    signals: dict[Annotated[str, Field(pattern=_ATOM_PATTERN)], SignalSpec] = Field(default_factory=dict)
    clock_offsets: dict[str, FiniteFloat] = Field(default_factory=dict)  # topic -> seconds added to its header
    robots: tuple[FleetRobot, ...] = ()  # several robots in one log (empty: the one robot above)
    separation: SeparationSpec | None = None
    proximity: dict[AtomName, ProximitySpec] = Field(default_factory=dict)

    @model_validator(mode="before")
    @classmethod
    def _fleet_fields(cls, data: Any) -> Any:
        """A multi-robot scenario gives robot, inputs, topics and signals per robot; ``robot`` and ``inputs`` then
        read the largest robot's disc and the first robot's input model (for code that reads one robot)."""
        if not isinstance(data, dict) or not data.get("robots"):
            return data
        robots = data["robots"]
        given = [k for k in _PER_ROBOT_FIELDS if k in data]
        if given:
            raise ValueError(f"{', '.join(given)}: a scenario with robots: gives these per robot (robots[i].radius, "
                             ".inputs, .topics, .signals)")
        if not isinstance(robots, list | tuple) or not all(isinstance(r, dict) for r in robots):
            return data
        radii = [r.get("radius") for r in robots if isinstance(r.get("radius"), int | float)]
        return {**data, "robot": {"radius": max(radii) if radii else robots[0].get("radius")},
                "inputs": robots[0].get("inputs")}

    @field_validator("spec")
    @classmethod
    def _spec_parses(cls, v: str) -> str:
        parse(v)  # SpecSyntaxError is a ValueError: pydantic reports it under the field "spec"
        return v

    @field_validator("clock_offsets")
    @classmethod
    def _offset_topics(cls, v: dict[str, float]) -> dict[str, float]:
        for topic in v:
            _check_topic(topic)
        return v

    @field_validator("checks")
    @classmethod
    def _checks_unique(cls, v: tuple[str, ...] | None) -> tuple[str, ...] | None:
        if v is not None and not v:
            raise ValueError("name at least one check (or leave checks out: every check whose data is named)")
        if v is not None and len(set(v)) != len(v):
            raise ValueError(f"a check is listed twice in {list(v)}")
        return v

    @model_validator(mode="after")
    def _consistent(self) -> Scenario:
        if not self.regions:
            raise ValueError("regions: at least one region is required")
        names = [r.name for r in self.regions]
        dupes = sorted({n for n in names if names.count(n) > 1})
        if dupes:
            raise ValueError(f"regions: duplicate region name(s) {', '.join(dupes)}")
        if self.initial_region_name is not None and self.initial_region_name not in names:
            raise ValueError(f"initial_region: {self.initial_region_name!r} is not one of the regions {names}")
        known = {lab for r in self.regions for lab in r.labels}
        clash = sorted(known & set(self.signals))
        if clash:
            raise ValueError(f"signals: {', '.join(clash)} is also a region label (an atom has one meaning)")
        known |= set(self.signals)
        if self.robots:
            self._check_fleet(known)
        elif self.separation is not None or self.proximity:
            raise ValueError("separation and proximity need a robots: block (two robots or more)")
        problem = self.atom_problem(self.formula)
        if problem:
            raise ValueError(f"spec: {problem}")
        if self.initial_region_name is not None and self.region(self.initial_region_name).unsafe:
            raise ValueError(f"initial_region: {self.initial_region_name} is unsafe")
        x0, y0, x1, y1 = self.workspace.bounds
        eta = self.robot.radius
        if min(x1 - x0, y1 - y0) < 2 * eta:
            degrees = max(abs(x0), abs(x1)) <= 180 and max(abs(y0), abs(y1)) <= 90 and max(x1 - x0, y1 - y0) < 0.05 \
                and max(abs(x0), abs(y0)) > 1
            hint = (": its bounds look like degrees of longitude/latitude; give the workspace in metres of a local "
                    "frame (the frame of the pose topic: odom, map, UTM/ENU)") if degrees else ""
            raise ValueError(f"workspace: {x1 - x0:g} m x {y1 - y0:g} m cannot contain the robot disc of radius "
                             f"{eta:g} m{hint}")
        return self

    def _check_fleet(self, labels: set[str]) -> None:
        names = [r.name for r in self.robots]
        if len(names) < 2:
            raise ValueError("robots: name two robots or more (one robot: give robot, inputs and topics instead)")
        dupes = sorted({n for n in names if names.count(n) > 1})
        if dupes:
            raise ValueError(f"robots: duplicate robot name(s) {', '.join(dupes)}")
        poses = [r.topics.pose for r in self.robots if r.topics.tf_child_frame is None]
        same = sorted({p for p in poses if poses.count(p) > 1})
        if same:
            raise ValueError(f"robots: pose topic(s) {', '.join(same)} named by two robots")
        for i, r in enumerate(self.robots):
            clash = sorted(labels & set(r.signals))
            if clash:
                raise ValueError(f"robots[{i}].signals: {', '.join(clash)} is also a region label (an atom has one "
                                 "meaning)")
        pairs = [(f"proximity.{k}", p.robots) for k, p in self.proximity.items()]
        if self.separation is not None:
            pairs += [(f"separation.pairs[{i}]", p.robots) for i, p in enumerate(self.separation.pairs)]
        for where, (a, b) in pairs:
            for n in (a, b):
                if n not in names:
                    raise ValueError(f"{where}: {n!r} is not one of the robots ({', '.join(names)})")
            if a == b:
                raise ValueError(f"{where}: name two different robots")
        clash = sorted((labels | set(names)) & set(self.proximity))
        if clash:
            raise ValueError(f"proximity: {', '.join(clash)} is also a region label or a robot name (an atom has "
                             "one meaning)")

    @property
    def robot_names(self) -> tuple[str, ...]:
        return tuple(r.name for r in self.robots)

    def fleet_robot(self, name: str) -> FleetRobot:
        for r in self.robots:
            if r.name == name:
                return r
        raise KeyError(f"robot={name!r} is not in scenario {self.name!r}")

    def atom_problem(self, formula: Formula) -> str | None:
        """Why ``formula``'s atoms are not all meaningful in this scenario (None: they are). One robot: each atom
        labels a region or names a signal. Several robots: each is a robot's own atom ``robot.label`` or
        ``robot.signal``, or a proximity atom; an unqualified region label or signal is refused naming the
        robots."""
        labels = {lab for r in self.regions for lab in r.labels}
        used = atoms(formula)
        if not self.robots:
            known = labels | set(self.signals)
            qualified = sorted(a for a in used if "." in a)
            if qualified:
                return (f"qualified atom(s) {', '.join(qualified)} need a robots: block (this scenario has one "
                        "robot: write the atom without the robot's name)")
            unknown = sorted(used - known)
            if unknown:
                return (f"atomic proposition(s) {', '.join(unknown)} label no region and name no signal "
                        f"(known: {', '.join(sorted(known)) or 'none'})")
            return None
        robots = {r.name: r for r in self.robots}
        listing = ", ".join(robots)
        plain = sorted(a for a in used if "." not in a and a not in self.proximity)
        if plain:
            return (f"unqualified atom(s) {', '.join(plain)} in a scenario with robots {listing}: name the robot "
                    f"({' or '.join(f'{r}.{plain[0]}' for r in robots)})")
        bad: list[str] = []
        for a in sorted(used - set(self.proximity)):
            who, what = a.split(".", 1)
            if who not in robots:
                bad.append(f"{a} ({who} is not one of the robots {listing})")
            elif what not in labels and what not in robots[who].signals:
                bad.append(f"{a} ({what} labels no region and names no signal of {who})")
        if bad:
            return f"atomic proposition(s) {'; '.join(bad)}"
        return None

    def robot_scenario(self, name: str) -> Scenario:
        """The one-robot scenario of robot ``name``: the shared workspace, regions, limits and clocks with its own
        disc, input model, topics and signals (its formula: ``true``; the fleet's formula is judged jointly)."""
        r = self.fleet_robot(name)
        data = self.to_dict()
        for key in ("robots", "separation", "proximity"):
            data.pop(key, None)
        data.update({"name": f"{self.name}/{r.name}", "spec": "true",
                     "robot": {"radius": r.radius, **({"max_speed": r.max_speed} if r.max_speed is not None else {})},
                     "inputs": r.inputs.model_dump(mode="json"),
                     "topics": r.topics.model_dump(mode="json"),
                     "signals": {k: v.model_dump(mode="json") for k, v in r.signals.items()}})
        if r.rate_hz is not None:
            data["mocap"] = {**data.get("mocap", {}), "rate_hz": r.rate_hz}
        return Scenario.model_validate(data)

    # ---- fields only the planner and the controller need ------------------------------------------------------
    def _required(self, field: str) -> ScenarioError:
        return ScenarioError("required for planning and simulation but missing from the scenario "
                             "(certification does not need it)", source=self.name, field=field)

    @property
    def disturbance(self) -> DisturbanceSpec:
        if self.disturbance_spec is None:
            raise self._required("disturbance")
        return self.disturbance_spec

    @property
    def tube(self) -> TubeSpec:
        if self.tube_spec is None:
            raise self._required("tube")
        return self.tube_spec

    @property
    def mpc(self) -> MpcSpec:
        if self.mpc_spec is None:
            raise self._required("mpc")
        return self.mpc_spec

    @property
    def initial_region(self) -> str:
        if self.initial_region_name is None:
            raise self._required("initial_region")
        return self.initial_region_name

    def planning_problems(self) -> list[tuple[str, str]]:
        """``(field, problem)`` for everything that keeps the planner and controller from using this scenario:
        missing fields, a unicycle input model, polygon shapes, overlapping regions, regions that do not fit inside
        the workspace or cannot contain the robot. Empty for a scenario the planner can abstract
        (``tubempc.scenario.review``)."""
        return planning_problems(self)

    def require_planning(self) -> None:
        """Raise ``ScenarioError`` naming the first field that keeps the planner from using this scenario."""
        problems = self.planning_problems()
        if problems:
            field, what = problems[0]
            more = f" (and {len(problems) - 1} more problem{'s' if len(problems) > 2 else ''})" \
                if len(problems) > 1 else ""
            raise ScenarioError(f"cannot plan or simulate on this scenario: {what}{more}", source=self.name,
                                field=field)

    def certification_warnings(self) -> list[str]:
        """Geometry the certifier accepts but a user may not mean, one line each naming the field: regions that
        reach outside the workspace, overlap or nest, or cannot contain the robot disc
        (``tubempc.scenario.review``)."""
        return certification_warnings(self)

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
        """Speed bound of the robot's centre (m/s): stated, or the one the input model allows (holonomic: the norm
        of the (vx, vy) bounds; unicycle: the v bound)."""
        if self.robot.max_speed is not None:
            return self.robot.max_speed
        return self.inputs.linear_speed_mps

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
        """The scenario as plain data with its file's field names. Optional fields at their defaults are left out,
        so a scenario written before they existed keeps its form (and its ``sha256``)."""
        data = self.model_dump(mode="json", by_alias=True)
        for key in ("disturbance", "tube", "mpc", "initial_region", "checks"):
            if data.get(key) is None:
                data.pop(key, None)
        for key in ("signals", "clock_offsets", "robots", "proximity"):
            if not data.get(key):
                data.pop(key, None)
        if data.get("separation") is None:
            data.pop("separation", None)
        if self.robots:  # given per robot: the top-level robot and inputs are derived, topics unused
            for key in ("robot", "inputs", "topics"):
                data.pop(key, None)
            for robot in data["robots"]:
                _drop_unset_robot_fields(robot)
        for key in ("nominal", "cmd_vel"):
            if "topics" in data and data["topics"].get(key) is None:
                data["topics"].pop(key, None)
        if "inputs" in data and data["inputs"]["model"] == "holonomic" and data["inputs"]["lateral_tolerance"] == 0.001:
            del data["inputs"]["model"], data["inputs"]["lateral_tolerance"]
        for shape in (data["workspace"], *data["regions"]):
            for key in ("x", "y", "center", "radius", "polygon"):
                if key in shape and shape[key] is None:
                    del shape[key]
        return data

    def __hash__(self) -> int:  # the signals and clock_offsets mappings are not hashable: hash the canonical form
        return hash(self.sha256())

    def sha256(self) -> str:
        """Hash of the canonical JSON form (key order and YAML formatting do not matter)."""
        blob = json.dumps(self.to_dict(), sort_keys=True, separators=(",", ":")).encode()
        return hashlib.sha256(blob).hexdigest()


def _drop_unset_robot_fields(robot: dict[str, Any]) -> None:
    """One fleet robot of ``Scenario.to_dict``: its optional fields at their defaults left out."""
    for key in ("nominal", "cmd_vel"):
        if robot["topics"].get(key) is None:
            robot["topics"].pop(key, None)
    for key in ("max_speed", "rate_hz"):
        if robot.get(key) is None:
            robot.pop(key, None)
    if not robot.get("signals"):
        robot.pop("signals", None)
