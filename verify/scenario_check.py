"""A scenario checked against a log: scenario + log -> problems (the scenario cannot be used on this log) and
findings (it can, but the user may not mean it), each one line naming the field.

input: a ``Scenario`` and a log path (``scenario_problems``, for ``tubempc scenario validate S --log LOG``), or the
pose samples the certifier already read (``data_findings``, which ``verify.certify`` adds to the certificate's
``scenario_warnings``) -> output: lists of lines.

Problems: a named topic that is absent or whose type cannot serve (the pose: PoseStamped, Odometry or /tf with
``topics.tf_child_frame``; commands: Twist or TwistStamped; the nominal pose: a pose type), a signal field that is
absent or not a number. Findings: pose data outside the workspace (how far, when first), coordinates that look like
degrees of latitude/longitude. Checks that need no log (units fixed by REP 103, a workspace smaller than the robot
disc, regions too small to contain it) live in the scenario model (``tubempc.scenario``).
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
import numpy.typing as npt

from tubempc.scenario import Scenario
from verify.errors import UnusableInputError
from verify.ingest.decode import ODOMETRY, POSE_STAMPED, TF, TRANSFORM_STAMPED, TWIST, TWIST_STAMPED
from verify.ingest.fields import decode_field
from verify.ingest.raw import read_raw

__all__ = ["data_findings", "scenario_problems"]

IntArray = npt.NDArray[np.int64]
FloatArray = npt.NDArray[np.float64]
POSE_TYPES = frozenset({POSE_STAMPED, ODOMETRY})
COMMAND_TYPES = frozenset({TWIST, TWIST_STAMPED})
#: data spread below this (in both axes) while inside [-180, 180] x [-90, 90]: degrees of longitude/latitude
_DEGREE_SPREAD = 0.05
_DEGREE_SPREAD_MIN = 1e-7  # a robot standing still is not a GPS fix


def _topic_problems(sc: Scenario, available: dict[str, str]) -> list[str]:
    t = sc.topics
    out: list[str] = []
    listed = ", ".join(f"{k} ({v})" for k, v in sorted(available.items())) or "no topics"
    pose_type = available.get(t.pose)
    if pose_type is None:
        if not ("/tf" in available and t.tf_child_frame):
            out.append(f"topics.pose: {t.pose} is absent from the log (it has: {listed})")
    elif pose_type not in POSE_TYPES | {TF, TRANSFORM_STAMPED}:
        out.append(f"topics.pose: {t.pose} is a {pose_type}, not a pose (PoseStamped, Odometry, or /tf with "
                   "topics.tf_child_frame)")
    elif pose_type == TF and not t.tf_child_frame:
        out.append(f"topics.pose: {t.pose} is a {TF}: name the robot's frame in topics.tf_child_frame")
    for field, name, usable in (("topics.cmd_vel", t.cmd_vel, COMMAND_TYPES), ("topics.nominal", t.nominal,
                                                                                POSE_TYPES)):
        if name is None:
            continue
        got = available.get(name)
        if got is None:
            out.append(f"{field}: {name} is absent from the log (it has: {listed})")
        elif got not in usable:
            out.append(f"{field}: {name} is a {got}, expected {' or '.join(sorted(usable))}")
    for sig_name, sig in sorted(sc.signals.items()):
        if sig.topic not in available:
            out.append(f"signals.{sig_name}.topic: {sig.topic} is absent from the log (it has: {listed})")
    return out


def _signal_problems(sc: Scenario, path: Path, available: dict[str, str]) -> list[str]:
    topics = {s.topic for s in sc.signals.values()} & set(available)
    if not topics:
        return []
    raw = read_raw(path, topics)
    out: list[str] = []
    for sig_name, sig in sorted(sc.signals.items()):
        rt = raw.topics.get(sig.topic)
        if rt is None:
            continue  # named by the topic check
        if not rt.payloads:
            out.append(f"signals.{sig_name}.topic: {sig.topic} has no messages")
            continue
        try:
            decode_field(rt, raw.ros1, sig.field)
        except UnusableInputError as err:
            out.append(f"signals.{sig_name}.field: {err.reason}")
    return out


def scenario_problems(sc: Scenario, path: str | Path) -> list[str]:
    """Every reason the scenario cannot be used to certify the log at ``path`` (empty: it can)."""
    p = Path(path)
    available = read_raw(p, []).available
    if sc.robots:  # several robots: each robot's topics and signals, named by robot
        out: list[str] = []
        for r in sc.robots:
            rsc = sc.robot_scenario(r.name)
            out += [f"robots.{r.name}: {problem}" for problem in _topic_problems(rsc, available)
                    + _signal_problems(rsc, p, available)]
        return out
    return _topic_problems(sc, available) + _signal_problems(sc, p, available)


def data_findings(sc: Scenario, t_ns: IntArray, x_m: FloatArray, y_m: FloatArray, time0_ns: int) -> list[str]:
    """What the pose data say about the scenario: data outside the workspace (centre outside its box or polygon's
    bounding box: how far, and when first, in seconds from time 0), and coordinates that look like degrees."""
    ok = np.isfinite(x_m) & np.isfinite(y_m)
    if not ok.any():
        return []
    t, x, y = t_ns[ok], x_m[ok], y_m[ok]
    out: list[str] = []
    wx0, wy0, wx1, wy1 = sc.workspace.bounds
    dx = np.maximum(np.maximum(wx0 - x, x - wx1), 0.0)
    dy = np.maximum(np.maximum(wy0 - y, y - wy1), 0.0)
    dist = np.hypot(dx, dy)
    outside = np.flatnonzero(dist > 0)
    if outside.size:
        worst = int(np.argmax(dist))
        first = int(outside[0])
        at_s, first_s = (t[worst] - time0_ns) * 1e-9, (t[first] - time0_ns) * 1e-9
        out.append(f"workspace: {outside.size} of {x.shape[0]} pose samples lie outside the workspace box "
                   f"[{wx0:g}, {wx1:g}] x [{wy0:g}, {wy1:g}], up to {dist[worst]:.3f} m (at {at_s:.3f} s, "
                   f"x={x[worst]:.3f}, y={y[worst]:.3f}); the first at {first_s:.3f} s")
    sx, sy = float(x.max() - x.min()), float(y.max() - y.min())
    in_range = bool(np.all(np.abs(x) <= 180) and np.all(np.abs(y) <= 90))
    if in_range and _DEGREE_SPREAD_MIN < max(sx, sy) < _DEGREE_SPREAD and max(abs(float(x[0])), abs(float(y[0]))) > 1:
        out.append(f"topics.pose: the positions look like degrees of longitude/latitude (x {x.min():.6f} .. "
                   f"{x.max():.6f}, y {y.min():.6f} .. {y.max():.6f}): the certifier works in metres; use a pose in "
                   "a local metric frame (odom, map, UTM/ENU)")
    return out
