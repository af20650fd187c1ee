"""A starting scenario from a log: ``LogInfo`` (``verify.info``) -> commented scenario YAML (``scenario init``).

input: what a log holds (topics, pose extents and speeds, command magnitudes) and an optional pose topic (or
``TOPIC#CHILD_FRAME`` for a /tf child frame) -> output: YAML text that loads as a ``Scenario`` and certifies that
log with a pass or an inconclusive verdict before any edit: the pose (and command) topics found; a workspace box
around the data with a margin; one region covering it and the formula ``G in_lab`` ("the robot stays in the
lab") as a marked placeholder; the robot radius as a marked placeholder; the speed bound and the input box from the
data with a margin (the input model from the command message: ``unicycle`` when no command moves sideways).
"""

from __future__ import annotations

import math

from tubempc.errors import ScenarioError
from verify.info import CommandInfo, LogInfo, PoseInfo

__all__ = ["PLACEHOLDER_RADIUS_M", "choose_pose", "scenario_text"]

#: the robot radius written before the user measures theirs (metres); the workspace margin exceeds it
PLACEHOLDER_RADIUS_M = 0.3
_MARGIN_FRACTION = 0.1  # workspace margin: this fraction of the data's extent ...
_MARGIN_MIN_M = 1.0  # ... and at least this (more than the placeholder radius)
_SPEED_FACTOR = 1.25  # the speed bound and input box: the largest value seen, times this
_SIDEWAYS_MPS = 1e-3  # commands never above this sideways: a differential drive (unicycle)
_TF_CHILD_PREFERENCE = ("base_link", "base_footprint")
#: pose-like topics whose name says they are not the measured pose (a plan, a goal, an MPC's nominal state)
_NOT_MEASURED = ("nominal", "goal", "target", "reference", "setpoint", "plan", "desired", "cmd", "waypoint")


def _pose_name(p: PoseInfo) -> str:
    return p.topic if p.child_frame is None else f"{p.topic}#{p.child_frame}"


def choose_pose(info: LogInfo, pose_topic: str | None) -> PoseInfo:
    """The pose stream the scenario names: ``pose_topic`` (``/tf#base_link`` for a child frame), else the first
    PoseStamped, else Odometry, else a /tf child frame (``base_link`` or ``base_footprint`` first); most samples
    first within a kind; a topic whose name says it is a plan, goal or nominal state comes after the others."""
    if not info.poses:
        types = ", ".join(f"{t.topic} ({t.msgtype})" for t in info.topics) or "no topics"
        raise ScenarioError(f"no pose-like topic (PoseStamped, Odometry, /tf) with a finite position; the log has: "
                            f"{types}", source=info.path)
    if pose_topic is not None:
        for p in info.poses:
            if pose_topic in (_pose_name(p), p.topic):
                return p
        known = ", ".join(_pose_name(p) for p in info.poses)
        raise ScenarioError(f"--pose-topic {pose_topic}: not a pose-like topic of the log (pose-like: {known})",
                            source=info.path)
    rank = {"geometry_msgs/msg/PoseStamped": 0, "nav_msgs/msg/Odometry": 1}

    def key(p: PoseInfo) -> tuple[bool, int, int, int]:
        preferred = 0 if p.child_frame in _TF_CHILD_PREFERENCE else 1
        planned = any(word in p.topic.lower() for word in _NOT_MEASURED)
        return planned, rank.get(p.msgtype, 2), preferred, -p.samples

    return min(info.poses, key=key)


def _command(info: LogInfo) -> CommandInfo | None:
    if not info.commands:
        return None
    return min(info.commands, key=lambda c: ("cmd_vel" not in c.topic, -c.samples))


def _up(value: float, floor: float) -> float:
    """``value * _SPEED_FACTOR`` rounded up to 2 significant digits, at least ``floor``."""
    v = max(value * _SPEED_FACTOR, floor)
    digits = 1 - math.floor(math.log10(v))
    return float(math.ceil(v * 10**digits) / 10**digits)


def _r(v: float) -> str:
    return f"{round(v, 3):g}"


def scenario_text(info: LogInfo, *, pose_topic: str | None = None, name: str | None = None) -> str:
    """The commented starting scenario for the log ``info`` describes."""
    pose = choose_pose(info, pose_topic)
    cmd = _command(info)
    w, h = pose.x_max_m - pose.x_min_m, pose.y_max_m - pose.y_min_m
    margin = max(_MARGIN_MIN_M, _MARGIN_FRACTION * max(w, h))
    x0, x1 = math.floor((pose.x_min_m - margin) * 10) / 10, math.ceil((pose.x_max_m + margin) * 10) / 10
    y0, y1 = math.floor((pose.y_min_m - margin) * 10) / 10, math.ceil((pose.y_max_m + margin) * 10) / 10
    fastest = pose.speed_max_mps or 0.0
    speed = _up(fastest, 0.1)
    lines = [
        f"# Starting scenario written by `tubempc scenario init {info.path}`.",
        "# It certifies this log as it stands (pass or inconclusive); edit the lines marked EDIT, then run",
        f"#   tubempc scenario validate THIS_FILE --log {info.path}",
        f"#   tubempc certify {info.path} --scenario THIS_FILE",
        f"name: {name or 'my-lab'}",
        f"# the data span x {_r(pose.x_min_m)} .. {_r(pose.x_max_m)} m, y {_r(pose.y_min_m)} .. {_r(pose.y_max_m)} m"
        f" ({_pose_name(pose)}); the box adds a {_r(margin)} m margin. EDIT: your lab's walls (metres)",
        "workspace:",
        f"  x: [{_r(x0)}, {_r(x1)}]",
        f"  y: [{_r(y0)}, {_r(y1)}]",
        "robot:",
        f"  radius: {PLACEHOLDER_RADIUS_M}  # EDIT (placeholder): the radius of a disc that covers your robot, metres",
        f"  # the fastest step between two pose samples was {_r(fastest)} m/s; the bound between samples adds 25 %",
        f"  max_speed: {speed}",
    ]
    if cmd is not None:
        sideways = cmd.max_abs_linear_y > _SIDEWAYS_MPS
        lines.append(f"# from the commands on {cmd.topic} ({cmd.msgtype}): the largest values seen plus 25 %. "
                     "EDIT: your robot's limits")
        lines.append("inputs:")
        if sideways:
            lines.append("  model: holonomic  # the commands move sideways (linear.y): [vx, vy, wz]")
            lines.append(f"  max_abs: [{_up(cmd.max_abs_linear_x, 0.1)}, {_up(cmd.max_abs_linear_y, 0.1)}, "
                         f"{_up(cmd.max_abs_angular_z, 0.1)}]")
        else:
            lines.append("  model: unicycle  # no command moves sideways (linear.y = 0): a differential drive [v, w]")
            lines.append(f"  max_abs: [{_up(cmd.max_abs_linear_x, 0.1)}, {_up(cmd.max_abs_angular_z, 0.1)}]")
    else:
        lines += [
            "# no command topic (Twist, TwistStamped) in the log: the input check is not selected; these bounds only",
            "# give the speed bound's default. EDIT: your robot's limits [v, w] (m/s, rad/s)",
            "inputs:",
            "  model: unicycle",
            f"  max_abs: [{speed}, 1.0]",
        ]
    others = [_pose_name(p) for p in info.poses if p is not pose]
    if others:
        lines.append(f"# other pose-like streams in the log: {', '.join(others)} (`scenario init --pose-topic`)")
    lines.append("topics:")
    lines.append(f"  pose: {pose.topic}")
    if pose.child_frame is not None:
        lines.append(f"  tf_child_frame: {pose.child_frame}")
    if cmd is not None:
        lines.append(f"  cmd_vel: {cmd.topic}")
    lines += [
        "# EDIT (placeholder): your regions: discs {name, center: [x, y], radius, labels} or polygons",
        "# {name, polygon: [[x, y], ...], labels}; `unsafe: true` marks an obstacle",
        "regions:",
        "  - name: lab",
        f"    polygon: [[{_r(x0)}, {_r(y0)}], [{_r(x1)}, {_r(y0)}], [{_r(x1)}, {_r(y1)}], [{_r(x0)}, {_r(y1)}]]",
        "    labels: [in_lab]",
        "# EDIT (placeholder): the MITL formula to certify, over the region labels (and signals: atoms on message",
        "# fields, see docs/certify-your-log.md); `G in_lab`: the robot stays in the lab",
        "spec: G in_lab",
    ]
    return "\n".join(lines) + "\n"
