"""Closed-loop results -> the ROS logs the real robot would record (the log contract), written with rosbags.

input: a ``ClosedLoopResult``, its ``Scenario`` and an output path -> output: the path written.
``.mcap``: one bare MCAP file (ROS2, cdr); ``.bag``: a ROS1 bag; ``.db3``: one bare ROS2 sqlite3 file; any other
path: a ROS2 bag directory (``storage="mcap"`` or ``"sqlite3"``). Topics (names from ``scenario.topics``):
MoCap pose and nominal pose (PoseStamped, frame ``world``), the body-frame command (Twist), the solver status per
MPC step and the run's metadata (std_msgs/String, JSON). Time 0 is the first pose stamp, at ``TIME0_NS``.
"""

from __future__ import annotations

import json
import math
import shutil
import tempfile
from collections.abc import Callable, Mapping
from pathlib import Path
from typing import Any, Literal

import numpy as np
from rosbags.rosbag1 import Writer as Writer1
from rosbags.rosbag2 import StoragePlugin
from rosbags.rosbag2 import Writer as Writer2
from rosbags.typesys import Stores, get_typestore

from tubempc import __version__
from tubempc.control.closed_loop import ClosedLoopResult
from tubempc.errors import LogWriteError
from tubempc.scenario import DEFAULT_TOPICS, Scenario, dump_scenario

__all__ = ["POSE_FRAME", "TIME0_NS", "metadata_document", "stamps_ns", "write_log"]

TIME0_NS = 1_767_225_600 * 10**9  # 2026-01-01T00:00:00Z: simulated runs start here
POSE_FRAME = "world"
_PROTECTED = ("generator", "scenario_sha256", "scenario_yaml", "time0_ns")
_ROS2_VERSION: Literal[8, 9] = 9


def stamps_ns(t_s: np.ndarray) -> np.ndarray:
    """Header stamps (int ns) of samples at ``t_s`` seconds from the start of a simulated run."""
    return TIME0_NS + np.rint(np.asarray(t_s, dtype=float) * 1e9).astype(np.int64)


def metadata_document(result: ClosedLoopResult, scenario: Scenario,
                      extra: Mapping[str, Any] | None = None) -> dict[str, Any]:
    """The JSON document of the metadata topic."""
    doc: dict[str, Any] = {
        "generator": f"tubempc {__version__}",
        "scenario_sha256": scenario.sha256(),
        "scenario_yaml": dump_scenario(scenario),
        "seed": result.seed,
        "disturbance": {**result.disturbance_params, "mocap_noise_m": result.mocap_noise_m},
        "tube": {"sigma": result.sigma, "radius_m": result.tube_radius_m},
        "targets": [{"region": t.region, "depart_after_s": t.depart_after_s} for t in result.targets],
        "start_region": result.start_region,
        "arrivals": [{"region": a.region, "departed_s": a.departed_s, "t_ij_s": a.t_ij_s,
                      "entered_terminal_s": a.entered_terminal_s, "inside_s": a.inside_s,
                      "departure_s": a.departure_s} for a in result.arrivals],
        "time0_ns": TIME0_NS,
    }
    for key, value in (extra or {}).items():
        if key in _PROTECTED:
            raise LogWriteError(f"metadata key {key!r} is reserved by the log contract")
        doc[key] = value
    return doc


_Serialize = Callable[[Any, str], bytes | memoryview]


def _messages(result: ClosedLoopResult, scenario: Scenario, typestore: Any, serialize: _Serialize,
              *, extra: Mapping[str, Any] | None, ros1: bool) -> list[tuple[str, str, int, bytes | memoryview]]:
    """(topic, msgtype, log time ns, serialized bytes), in time order per topic."""
    types = typestore.types
    header_t, time_t = types["std_msgs/msg/Header"], types["builtin_interfaces/msg/Time"]
    pose_t, pose_st = types["geometry_msgs/msg/Pose"], types["geometry_msgs/msg/PoseStamped"]
    point_t, quat_t = types["geometry_msgs/msg/Point"], types["geometry_msgs/msg/Quaternion"]
    twist_t, vec_t = types["geometry_msgs/msg/Twist"], types["geometry_msgs/msg/Vector3"]
    string_t = types["std_msgs/msg/String"]
    topics = scenario.topics
    stamps = stamps_ns(result.t_s)
    out: list[tuple[str, str, int, bytes | memoryview]] = []
    meta = json.dumps(metadata_document(result, scenario, extra), sort_keys=True)
    out.append((topics.metadata, "std_msgs/msg/String", int(stamps[0]) if len(stamps) else TIME0_NS,
                serialize(string_t(data=meta), "std_msgs/msg/String")))

    def pose(seq: int, stamp: int, state: np.ndarray) -> Any:
        sec, nsec = divmod(stamp, 10**9)
        stamp_msg = time_t(sec=sec, nanosec=nsec)
        header = header_t(seq=seq, stamp=stamp_msg, frame_id=POSE_FRAME) if ros1 else \
            header_t(stamp=stamp_msg, frame_id=POSE_FRAME)
        half = 0.5 * float(state[2])
        return pose_st(header=header, pose=pose_t(position=point_t(x=float(state[0]), y=float(state[1]), z=0.0),
                                                  orientation=quat_t(x=0.0, y=0.0, z=math.sin(half),
                                                                     w=math.cos(half))))

    # a simulated run always has a nominal state and commands: a scenario that names no topic for them gets the
    # default names (certifying the log with that scenario then leaves the tube and input checks unselected)
    nominal_topic = topics.nominal or DEFAULT_TOPICS.nominal or "/nexus/nominal_pose"
    cmd_topic = topics.cmd_vel or DEFAULT_TOPICS.cmd_vel or "/nexus/cmd_vel"
    for i, stamp in enumerate(stamps.tolist()):
        out.append((topics.pose, "geometry_msgs/msg/PoseStamped", stamp,
                    serialize(pose(i, stamp, result.x_measured[i]), "geometry_msgs/msg/PoseStamped")))
        out.append((nominal_topic, "geometry_msgs/msg/PoseStamped", stamp,
                    serialize(pose(i, stamp, result.x_hat[i]), "geometry_msgs/msg/PoseStamped")))
        ub = result.u_body[i]
        twist = twist_t(linear=vec_t(x=float(ub[0]), y=float(ub[1]), z=0.0), angular=vec_t(x=0.0, y=0.0,
                                                                                              z=float(ub[2])))
        out.append((cmd_topic, "geometry_msgs/msg/Twist", stamp, serialize(twist, "geometry_msgs/msg/Twist")))
    for rec in result.solver:
        doc = {"t_s": rec.t_s, "status": rec.status, "success": rec.success, "iterations": rec.iterations,
               "solve_time_s": rec.solve_time_s, "backup": rec.backup, "target": rec.target}
        stamp = int(stamps_ns(np.array([rec.t_s]))[0])
        out.append((topics.solver, "std_msgs/msg/String", stamp,
                    serialize(string_t(data=json.dumps(doc)), "std_msgs/msg/String")))
    out.sort(key=lambda m: m[2])  # stable: per-topic order is kept
    return out


def _write_all(writer: Any, messages: list[tuple[str, str, int, bytes | memoryview]], typestore: Any) -> None:
    """One connection per topic (in first-message order), then every message; the same for ROS1 and ROS2 writers."""
    conns: dict[str, Any] = {}
    for topic, msgtype, _, _ in messages:
        if topic not in conns:
            conns[topic] = writer.add_connection(topic, msgtype, typestore=typestore)
    for topic, _, stamp, data in messages:
        writer.write(conns[topic], stamp, data)


def _write_ros2(messages: list[tuple[str, str, int, bytes | memoryview]], directory: Path, plugin: StoragePlugin,
                typestore: Any) -> None:
    with Writer2(directory, version=_ROS2_VERSION, storage_plugin=plugin) as writer:
        _write_all(writer, messages, typestore)


def write_log(result: ClosedLoopResult, scenario: Scenario, path: str | Path, *, storage: str = "mcap",
              metadata: Mapping[str, Any] | None = None) -> Path:
    """Write ``result`` as the robot's log at ``path`` (format chosen by the suffix; see the module docstring)."""
    target = Path(path)
    if storage not in ("mcap", "sqlite3"):
        raise LogWriteError(f"storage={storage!r} must be 'mcap' or 'sqlite3' (writing {target})")
    if target.exists():
        raise LogWriteError(f"{target}: exists already, not overwriting")
    if not target.parent.exists():
        raise LogWriteError(f"{target}: the directory {target.parent} does not exist")
    suffix = target.suffix.lower()
    try:
        if suffix == ".bag":
            store = get_typestore(Stores.ROS1_NOETIC)
            msgs = _messages(result, scenario, store, store.serialize_ros1, extra=metadata, ros1=True)
            with Writer1(target) as writer:
                _write_all(writer, msgs, store)
            return target
        store = get_typestore(Stores.ROS2_HUMBLE)
        msgs = _messages(result, scenario, store, store.serialize_cdr, extra=metadata, ros1=False)
        if suffix in (".mcap", ".db3"):
            plugin = StoragePlugin.MCAP if suffix == ".mcap" else StoragePlugin.SQLITE3
            with tempfile.TemporaryDirectory(dir=target.parent, prefix=".tubempc-") as tmp:
                bag_dir = Path(tmp) / "bag"
                _write_ros2(msgs, bag_dir, plugin, store)
                (storage_file,) = [p for p in bag_dir.iterdir() if p.suffix == suffix]
                shutil.move(str(storage_file), target)
            return target
        _write_ros2(msgs, target, StoragePlugin.MCAP if storage == "mcap" else StoragePlugin.SQLITE3, store)
        return target
    except LogWriteError:
        raise
    except Exception as err:  # rosbags raises its own WriterError family and OSError: wrap at the boundary
        raise LogWriteError(f"{target}: cannot write the log ({err.__class__.__name__}: {err})") from err
