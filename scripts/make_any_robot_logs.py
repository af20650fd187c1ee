"""Logs of a robot that is not the Nexus: a differential-drive base that records only ``nav_msgs/Odometry``.

input: waypoints, the unicycle's speed limits and a rate -> output: a ROS1 bag or a ROS2 MCAP with one Odometry topic
(pose and body-frame twist) and, optionally, a ``sensor_msgs/BatteryState`` topic. Deterministic (no randomness).
Run ``python3 scripts/make_any_robot_logs.py`` to regenerate ``logs/diffdrive_odom.bag`` (the walkthrough in
docs/certify-your-log.md uses it with ``logs/diffdrive_room.yaml``). Tests import ``unicycle_run`` and
``write_messages`` from this file.
"""

from __future__ import annotations

import math
import shutil
from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np
from rosbags.rosbag1 import Writer as Writer1
from rosbags.rosbag2 import StoragePlugin
from rosbags.rosbag2 import Writer as Writer2
from rosbags.typesys import Stores, get_typestore

LOGS = Path(__file__).resolve().parent.parent / "logs"
TIME0_NS = 1_767_225_600 * 10**9  # 2026-01-01T00:00:00Z


@dataclass(frozen=True)
class UnicycleRun:
    """Samples of a unicycle: time (s), pose, and the body-frame twist (v, w) it was driven with."""

    t_s: np.ndarray
    x: np.ndarray
    y: np.ndarray
    theta: np.ndarray
    v: np.ndarray
    w: np.ndarray


def unicycle_run(waypoints: Sequence[tuple[float, float]], *, v_mps: float, w_radps: float, rate_hz: float,
                 theta0: float = 0.0, pauses: dict[int, float] | None = None) -> UnicycleRun:
    """Turn in place towards each waypoint at ``w_radps``, then drive straight to it at ``v_mps``; ``pauses``:
    seconds to stand still on arrival at waypoint ``k``. Exact kinematics, sampled at ``rate_hz``."""
    dt = 1.0 / rate_hz
    xs, ys, ths, vs, ws = [waypoints[0][0]], [waypoints[0][1]], [theta0], [0.0], [0.0]
    x, y, th = waypoints[0][0], waypoints[0][1], theta0
    for k, (gx, gy) in enumerate(waypoints[1:], start=1):
        target = math.atan2(gy - y, gx - x)
        turn = (target - th + math.pi) % (2 * math.pi) - math.pi
        for _ in range(math.ceil(abs(turn) / (w_radps * dt))):
            step = max(-w_radps * dt, min(w_radps * dt, turn))
            th += step
            turn -= step
            xs.append(x), ys.append(y), ths.append(th), vs.append(0.0), ws.append(step / dt)
        dist = math.hypot(gx - x, gy - y)
        for _ in range(math.ceil(dist / (v_mps * dt))):
            step = min(v_mps * dt, math.hypot(gx - x, gy - y))
            x += step * math.cos(th)
            y += step * math.sin(th)
            xs.append(x), ys.append(y), ths.append(th), vs.append(step / dt), ws.append(0.0)
        for _ in range(round((pauses or {}).get(k, 0.0) * rate_hz)):
            xs.append(x), ys.append(y), ths.append(th), vs.append(0.0), ws.append(0.0)
    n = len(xs)
    return UnicycleRun(np.arange(n) * dt, np.array(xs), np.array(ys), np.array(ths), np.array(vs), np.array(ws))


def odometry_messages(run: UnicycleRun, topic: str, *, ros1: bool, time0_ns: int = TIME0_NS,
                      frame_id: str = "odom", header_offset_ns: int = 0) -> list[tuple[str, str, int, Any]]:
    """``(topic, type, log time ns, message)`` for every sample; header stamps = log time + ``header_offset_ns``."""
    T = _store(ros1).types
    out = []
    zero = np.zeros(36)
    for t, x, y, th, v, w in zip(run.t_s, run.x, run.y, run.theta, run.v, run.w, strict=True):
        t_ns = time0_ns + round(float(t) * 1e9)
        stamp = t_ns + header_offset_ns
        header = T["std_msgs/msg/Header"](**({"seq": 0} if ros1 else {}), frame_id=frame_id,
                                         stamp=T["builtin_interfaces/msg/Time"](sec=stamp // 10**9,
                                                                                nanosec=stamp % 10**9))
        pose = T["geometry_msgs/msg/Pose"](
            position=T["geometry_msgs/msg/Point"](x=float(x), y=float(y), z=0.0),
            orientation=T["geometry_msgs/msg/Quaternion"](x=0.0, y=0.0, z=math.sin(th / 2), w=math.cos(th / 2)))
        V3 = T["geometry_msgs/msg/Vector3"]
        twist = T["geometry_msgs/msg/Twist"](linear=V3(x=float(v), y=0.0, z=0.0), angular=V3(x=0.0, y=0.0, z=float(w)))
        odom = T["nav_msgs/msg/Odometry"](
            header=header, child_frame_id="base_link",
            pose=T["geometry_msgs/msg/PoseWithCovariance"](pose=pose, covariance=zero),
            twist=T["geometry_msgs/msg/TwistWithCovariance"](twist=twist, covariance=zero))
        out.append((topic, "nav_msgs/msg/Odometry", t_ns, odom))
    return out


def command_messages(run: UnicycleRun, topic: str, *, ros1: bool, stamped: bool, time0_ns: int = TIME0_NS,
                     lateral: np.ndarray | None = None, header_offset_ns: int = 0,
                     frame_id: str = "base_link") -> list[tuple[str, str, int, Any]]:
    """The run's commands as Twist or TwistStamped (linear.x = v, angular.z = w, linear.y = ``lateral`` or 0)."""
    T = _store(ros1).types
    V3 = T["geometry_msgs/msg/Vector3"]
    side = np.zeros_like(run.v) if lateral is None else lateral
    out = []
    for t, v, w, vy in zip(run.t_s, run.v, run.w, side, strict=True):
        t_ns = time0_ns + round(float(t) * 1e9)
        twist = T["geometry_msgs/msg/Twist"](linear=V3(x=float(v), y=float(vy), z=0.0),
                                             angular=V3(x=0.0, y=0.0, z=float(w)))
        if not stamped:
            out.append((topic, "geometry_msgs/msg/Twist", t_ns, twist))
            continue
        stamp = t_ns + header_offset_ns
        header = T["std_msgs/msg/Header"](**({"seq": 0} if ros1 else {}), frame_id=frame_id,
                                         stamp=T["builtin_interfaces/msg/Time"](sec=stamp // 10**9,
                                                                                nanosec=stamp % 10**9))
        out.append((topic, "geometry_msgs/msg/TwistStamped", t_ns,
                    T["geometry_msgs/msg/TwistStamped"](header=header, twist=twist)))
    return out


def battery_messages(times_s: Sequence[float], percentage: Sequence[float], topic: str, *, ros1: bool,
                     cells: Sequence[Sequence[float]] | None = None, time0_ns: int = TIME0_NS,
                     header_offset_ns: int = 0) -> list[tuple[str, str, int, Any]]:
    """``sensor_msgs/BatteryState`` at ``times_s`` with ``percentage`` (0..1) and optional per-cell voltages."""
    T = _store(ros1).types
    out = []
    for k, (t, pct) in enumerate(zip(times_s, percentage, strict=True)):
        t_ns = time0_ns + round(float(t) * 1e9)
        stamp = t_ns + header_offset_ns
        header = T["std_msgs/msg/Header"](**({"seq": 0} if ros1 else {}), frame_id="battery",
                                         stamp=T["builtin_interfaces/msg/Time"](sec=stamp // 10**9,
                                                                                nanosec=stamp % 10**9))
        volts = np.asarray(cells[k] if cells is not None else [], dtype=np.float32)
        msg = T["sensor_msgs/msg/BatteryState"](
            header=header, voltage=float(volts.sum()), temperature=25.0, current=-1.0, charge=float("nan"),
            capacity=float("nan"), design_capacity=float("nan"), percentage=float(pct), power_supply_status=2,
            power_supply_health=1, power_supply_technology=2, present=True, cell_voltage=volts,
            cell_temperature=np.zeros(volts.shape[0], dtype=np.float32), location="base", serial_number="")
        out.append((topic, "sensor_msgs/msg/BatteryState", t_ns, msg))
    return out


def _store(ros1: bool) -> Any:
    return get_typestore(Stores.ROS1_NOETIC if ros1 else Stores.ROS2_HUMBLE)


def write_messages(path: Path, messages: Sequence[tuple[str, str, int, Any]]) -> Path:
    """Write messages to ``path``: a ROS1 bag for ``.bag``, else a single-file ROS2 MCAP (``.mcap``)."""
    ros1 = path.suffix == ".bag"
    store = _store(ros1)
    ser = store.serialize_ros1 if ros1 else store.serialize_cdr
    ordered = sorted(messages, key=lambda m: m[2])
    if ros1:
        with Writer1(path) as w:
            conns: dict[str, Any] = {}
            for topic, typ, t, msg in ordered:
                if topic not in conns:
                    conns[topic] = w.add_connection(topic, typ, typestore=store)
                w.write(conns[topic], t, ser(msg, typ))
        return path
    bag_dir = path.with_suffix("")
    with Writer2(bag_dir, version=9, storage_plugin=StoragePlugin.MCAP) as w:
        conns = {}
        for topic, typ, t, msg in ordered:
            if topic not in conns:
                conns[topic] = w.add_connection(topic, typ, typestore=store)
            w.write(conns[topic], t, ser(msg, typ))
    (inner,) = [p for p in bag_dir.iterdir() if p.suffix == ".mcap"]
    shutil.move(inner, path)
    shutil.rmtree(bag_dir)
    return path


#: the walkthrough's run: out of the room's door corner, around the table, to the dock, and back
EXAMPLE_WAYPOINTS = ((0.5, 0.5), (2.5, 0.5), (2.5, 2.5), (4.4, 3.3), (4.4, 3.3), (1.0, 3.0))


def example_run() -> UnicycleRun:
    return unicycle_run(EXAMPLE_WAYPOINTS, v_mps=0.4, w_radps=0.8, rate_hz=10.0, pauses={3: 5.0})


def main() -> None:
    path = LOGS / "diffdrive_odom.bag"
    path.unlink(missing_ok=True)
    write_messages(path, odometry_messages(example_run(), "/odom", ros1=True))
    print(f"wrote {path}")


if __name__ == "__main__":
    main()
