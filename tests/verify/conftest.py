"""Fixtures for the certifier tests: synthetic trajectories and logs written with ``rosbags`` writers.

``make_log(tmp_path, fmt, traj, ...)`` writes a log in one of the formats (``bag``, ``mcap`` bare file, ``db3`` bare
file, ``dir-mcap``, ``dir-sqlite3``) with the topics of the log contract, in any pose type (``PoseStamped``,
``Odometry``, ``TF``).
"""

from __future__ import annotations

import json
import math
import shutil
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np
import pytest
from rosbags.rosbag1 import Writer as Writer1
from rosbags.rosbag2 import StoragePlugin
from rosbags.rosbag2 import Writer as Writer2
from rosbags.typesys import Stores, get_types_from_msg, get_typestore

from tubempc.scenario import Scenario, builtin_scenario

TIME0_NS = 1_767_225_600 * 10**9


@dataclass
class Traj:
    t_s: np.ndarray
    x: np.ndarray
    y: np.ndarray
    theta: np.ndarray
    nominal: tuple[np.ndarray, np.ndarray] | None = None
    cmd: np.ndarray | None = None  # (n, 3) body-frame


def paper_like_traj(scenario: Scenario, *, rate_hz: float = 20.0, end_s: float = 100.0) -> Traj:
    """A run that satisfies the paper's formula in the built-in scenario: R1 -> R3 by t=40 s -> R1 by t=95 s,
    going around the obstacles (waypoints in free space), at constant speed below the speed bound."""
    r1, r3 = scenario.region("R1").center, scenario.region("R3").center
    legs = [r1, (-0.6, -0.5), r3, r3, (-0.6, -0.5), r1, r1]
    # timing: the disc is inside R3 from ~33 s to ~57 s and back inside R1 from ~86 s (both windows met in
    # the pointwise timed-run semantics too, whose positions are the entry times)
    knots_t = [0.0, 18.0, 36.0, 55.0, 70.0, 88.0, end_s]
    t = np.arange(0.0, end_s + 1e-9, 1.0 / rate_hz)
    x = np.interp(t, knots_t, [p[0] for p in legs])
    y = np.interp(t, knots_t, [p[1] for p in legs])
    theta = np.zeros_like(t)
    vx = np.gradient(x, t)
    vy = np.gradient(y, t)
    cmd = np.stack([vx, vy, np.zeros_like(t)], axis=1)
    return Traj(t, x, y, theta, nominal=(x.copy(), y.copy()), cmd=cmd)


@pytest.fixture
def scenario() -> Scenario:
    return builtin_scenario()


def _quat(theta: float) -> tuple[float, float, float, float]:
    return 0.0, 0.0, math.sin(theta / 2), math.cos(theta / 2)


def write_log(path: Path, fmt: str, traj: Traj, scenario: Scenario, *, pose_type: str = "PoseStamped",
              header_offset_ns: int = 0, time0_ns: int = TIME0_NS, metadata: bool = True,
              frame_id: str = "world", tf_child: str = "nexus", omit_definition: bool = False,
              extra_pose: list[tuple[float, float, float, float]] | None = None,
              pose_stamps_ns: dict[int, int] | None = None) -> Path:
    """Write ``traj`` as a log; ``header_offset_ns`` is added to every header stamp (log time = sample time);
    ``pose_stamps_ns``: pose sample index -> its header stamp (absolute ns), replacing the sample's own."""
    ros1 = fmt == "bag"
    store = get_typestore(Stores.ROS1_NOETIC if ros1 else Stores.ROS2_HUMBLE)
    if "tf2_msgs/msg/TFMessage" not in store.types:
        store.register(get_types_from_msg("geometry_msgs/TransformStamped[] transforms", "tf2_msgs/msg/TFMessage"))
    T = store.types
    ser = store.serialize_ros1 if ros1 else store.serialize_cdr
    topics = scenario.topics

    def header(t_ns: int, stamp_ns: int | None = None) -> Any:
        stamp = t_ns + header_offset_ns if stamp_ns is None else stamp_ns
        return T["std_msgs/msg/Header"](**({"seq": 0} if ros1 else {}),
                                       stamp=T["builtin_interfaces/msg/Time"](sec=stamp // 10**9,
                                                                              nanosec=stamp % 10**9),
                                       frame_id=frame_id)

    def pose_msg(t_ns: int, x: float, y: float, th: float, stamp_ns: int | None = None) -> Any:
        p = T["geometry_msgs/msg/Pose"](position=T["geometry_msgs/msg/Point"](x=x, y=y, z=0.0),
                                        orientation=T["geometry_msgs/msg/Quaternion"](*_quat(th)))
        return T["geometry_msgs/msg/PoseStamped"](header=header(t_ns, stamp_ns), pose=p)

    msgs: list[tuple[str, str, int, Any]] = []
    t_ns = (np.round(traj.t_s * 1e9)).astype(np.int64) + time0_ns
    pose_topic = "/tf" if pose_type == "TF" else topics.pose
    samples = [(int(t), float(x), float(y), float(th)) for t, x, y, th in zip(t_ns, traj.x, traj.y, traj.theta,
                                                                                 strict=True)]
    late: dict[int, int] = {}
    if extra_pose:  # header stamp t, received (log time) after the last sample: out of order in reading order
        for k, (t, x, y, th) in enumerate(extra_pose):
            late[len(samples)] = int(t_ns[-1]) + 1_000_000 * (k + 1)
            samples.append((time0_ns + round(t * 1e9), x, y, th))
    for k, (t_stamp, x, y, th) in enumerate(samples):
        ps = pose_msg(t_stamp, x, y, th, (pose_stamps_ns or {}).get(k))
        t = late.get(k, t_stamp)
        if pose_type == "PoseStamped":
            msgs.append((pose_topic, "geometry_msgs/msg/PoseStamped", t, ps))
        elif pose_type == "Odometry":
            cov = np.zeros(36)
            odom = T["nav_msgs/msg/Odometry"](
                header=ps.header, child_frame_id="nexus",
                pose=T["geometry_msgs/msg/PoseWithCovariance"](pose=ps.pose, covariance=cov),
                twist=T["geometry_msgs/msg/TwistWithCovariance"](
                    twist=T["geometry_msgs/msg/Twist"](linear=T["geometry_msgs/msg/Vector3"](x=0.0, y=0.0, z=0.0),
                                                       angular=T["geometry_msgs/msg/Vector3"](x=0.0, y=0.0, z=0.0)),
                    covariance=cov))
            msgs.append((pose_topic, "nav_msgs/msg/Odometry", t, odom))
        else:
            def tf(child: str, dx: float, ps: Any = ps) -> Any:
                return T["geometry_msgs/msg/TransformStamped"](
                    header=ps.header, child_frame_id=child,
                    transform=T["geometry_msgs/msg/Transform"](
                        translation=T["geometry_msgs/msg/Vector3"](x=ps.pose.position.x + dx,
                                                                   y=ps.pose.position.y, z=0.0),
                        rotation=ps.pose.orientation))
            msgs.append(("/tf", "tf2_msgs/msg/TFMessage", t,
                         T["tf2_msgs/msg/TFMessage"](transforms=[tf("other_robot", 0.5), tf(tf_child, 0.0)])))
    if traj.nominal is not None:
        for t, x, y in zip(t_ns, *traj.nominal, strict=True):
            msgs.append((topics.nominal, "geometry_msgs/msg/PoseStamped", int(t), pose_msg(int(t), x, y, 0.0)))
    if traj.cmd is not None:
        V3 = T["geometry_msgs/msg/Vector3"]
        for t, (u1, u2, u3) in zip(t_ns, traj.cmd, strict=True):
            msgs.append((topics.cmd_vel, "geometry_msgs/msg/Twist", int(t),
                         T["geometry_msgs/msg/Twist"](linear=V3(x=float(u1), y=float(u2), z=0.0),
                                                      angular=V3(x=0.0, y=0.0, z=float(u3)))))
    if metadata:
        meta = {"generator": "tests", "scenario_sha256": scenario.sha256(), "seed": 1, "time0_ns": time0_ns}
        msgs.append((topics.metadata, "std_msgs/msg/String", time0_ns, T["std_msgs/msg/String"](data=json.dumps(meta))))
        for k in range(0, len(t_ns), 10):
            status = {"t_s": float(traj.t_s[k]), "status": "Solve_Succeeded", "success": True, "iterations": 5,
                      "solve_time_s": 0.01, "backup": False, "target": "R3"}
            msgs.append((topics.solver, "std_msgs/msg/String", int(t_ns[k]),
                         T["std_msgs/msg/String"](data=json.dumps(status))))
    msgs.sort(key=lambda m: m[2])

    if ros1:
        with Writer1(path) as w:
            conns: dict[str, Any] = {}
            for topic, typ, t, msg in msgs:
                if topic not in conns:
                    kwargs: dict[str, Any] = {"typestore": store}
                    conns[topic] = w.add_connection(topic, typ, **kwargs)
                w.write(conns[topic], t, ser(msg, typ))
        return path
    storage = StoragePlugin.SQLITE3 if fmt in ("db3", "dir-sqlite3") else StoragePlugin.MCAP
    bag_dir = path if fmt.startswith("dir-") else path.with_suffix("")
    with Writer2(bag_dir, version=9, storage_plugin=storage) as w:
        conns = {}
        for topic, typ, t, msg in msgs:
            if topic not in conns:
                if omit_definition and topic == pose_topic:
                    conns[topic] = w.add_connection(topic, typ, msgdef="", rihs01="RIHS01_" + "0" * 64)
                else:
                    conns[topic] = w.add_connection(topic, typ, typestore=store)
            w.write(conns[topic], t, ser(msg, typ))
    if fmt.startswith("dir-"):
        return path
    ext = ".db3" if fmt == "db3" else ".mcap"
    (inner,) = [p for p in bag_dir.iterdir() if p.suffix == ext]
    shutil.move(inner, path)
    shutil.rmtree(bag_dir)
    return path


FORMAT_PATHS = {"bag": "run.bag", "mcap": "run.mcap", "db3": "run.db3", "dir-mcap": "run_mcap",
                "dir-sqlite3": "run_sqlite"}


@pytest.fixture
def make_log(tmp_path: Path, scenario: Scenario) -> Callable[..., Path]:
    counter = {"n": 0}

    def make(fmt: str, traj: Traj, **kwargs: Any) -> Path:
        counter["n"] += 1
        folder = tmp_path / f"log{counter['n']}"
        folder.mkdir()
        return write_log(folder / FORMAT_PATHS[fmt], fmt, traj, kwargs.pop("scenario", scenario), **kwargs)

    return make


@pytest.fixture
def paper_traj() -> Callable[..., Traj]:
    return paper_like_traj


@pytest.fixture
def traj_cls() -> type[Traj]:
    return Traj
