"""Logs of several robots in one file: each robot on a piecewise-linear path at constant speeds, its own topic, type
and rate (geometry_msgs/PoseStamped or nav_msgs/Odometry), optionally with a dropout.

input: per robot its knots ``(t_s, x, y)`` (straight lines between them), its topic, message type, rate and dropouts
-> output: a ROS1 bag or a ROS2 MCAP. The path is known in closed form (``Path.at``), so tests can compute distances
densely and independently of the certifier. Deterministic. Run ``python3 scripts/make_fleet_logs.py`` to regenerate
``logs/two_robots.bag`` (the two-robot walkthrough in docs/certify-your-log.md, with
``docs/examples/two-robots-warehouse.yaml``). Tests import this file.
"""

from __future__ import annotations

import importlib
import math
from collections.abc import Sequence
from dataclasses import dataclass, field
from pathlib import Path as FsPath
from types import ModuleType
from typing import Any

import numpy as np

ROOT = FsPath(__file__).resolve().parent.parent
LOGS = ROOT / "logs"
TIME0_NS = 1_767_225_600 * 10**9  # 2026-01-01T00:00:00Z


def _kit() -> ModuleType:
    """``make_any_robot_logs`` beside this file: a module of the ``scripts`` package when the tests import this one,
    else the script folder's module (``python3 scripts/make_fleet_logs.py`` puts the folder first on the path)."""
    if __package__:
        return importlib.import_module(".make_any_robot_logs", __package__)
    return importlib.import_module("make_any_robot_logs")


@dataclass(frozen=True)
class Path:
    """Straight lines at constant speed between knots ``(t_s, x, y)``; before the first / after the last: still."""

    knots: tuple[tuple[float, float, float], ...]

    def at(self, t_s: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        k = np.array(self.knots, dtype=np.float64)
        return np.interp(t_s, k[:, 0], k[:, 1]), np.interp(t_s, k[:, 0], k[:, 2])

    def velocity(self, t_s: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Velocity on the segment each instant lies in (0 outside the knots)."""
        k = np.array(self.knots, dtype=np.float64)
        seg = np.clip(np.searchsorted(k[:, 0], t_s, side="right") - 1, 0, len(k) - 2)
        dt = k[seg + 1, 0] - k[seg, 0]
        with np.errstate(divide="ignore", invalid="ignore"):
            vx = np.where(dt > 0, (k[seg + 1, 1] - k[seg, 1]) / dt, 0.0)
            vy = np.where(dt > 0, (k[seg + 1, 2] - k[seg, 2]) / dt, 0.0)
        outside = (t_s < k[0, 0]) | (t_s >= k[-1, 0])
        return np.where(outside, 0.0, vx), np.where(outside, 0.0, vy)


@dataclass(frozen=True)
class RobotLog:
    """One robot's stream: its path, topic, ``PoseStamped`` or ``Odometry``, rate, first sample and dropouts."""

    path: Path
    topic: str
    kind: str  # "pose" (geometry_msgs/PoseStamped) or "odom" (nav_msgs/Odometry)
    rate_hz: float
    start_s: float = 0.0
    end_s: float | None = None
    dropouts: tuple[tuple[float, float], ...] = field(default=())  # (from_s, to_s): no message in between

    def times(self) -> np.ndarray:
        end = self.end_s if self.end_s is not None else self.path.knots[-1][0]
        n = math.floor((end - self.start_s) * self.rate_hz + 1e-9) + 1
        t = self.start_s + np.arange(n) / self.rate_hz
        keep = np.ones(n, dtype=bool)
        for a, b in self.dropouts:
            keep &= ~((t > a) & (t < b))
        return np.round(t[keep], 9)


def robot_messages(robot: RobotLog, *, ros1: bool, time0_ns: int = TIME0_NS) -> list[tuple[str, str, int, Any]]:
    kit = _kit()
    t = robot.times()
    x, y = robot.path.at(t)
    vx, vy = robot.path.velocity(t)
    theta = np.arctan2(vy, vx)
    speed = np.hypot(vx, vy)
    run = kit.UnicycleRun(t, x, y, theta, speed, np.zeros_like(t))
    if robot.kind == "odom":
        return list(kit.odometry_messages(run, robot.topic, ros1=ros1, time0_ns=time0_ns))
    T = kit._store(ros1).types
    out = []
    for ti, xi, yi, th in zip(t, x, y, theta, strict=True):
        t_ns = time0_ns + round(float(ti) * 1e9)
        header = T["std_msgs/msg/Header"](**({"seq": 0} if ros1 else {}), frame_id="map",
                                         stamp=T["builtin_interfaces/msg/Time"](sec=t_ns // 10**9,
                                                                                nanosec=t_ns % 10**9))
        pose = T["geometry_msgs/msg/Pose"](
            position=T["geometry_msgs/msg/Point"](x=float(xi), y=float(yi), z=0.0),
            orientation=T["geometry_msgs/msg/Quaternion"](x=0.0, y=0.0, z=math.sin(th / 2), w=math.cos(th / 2)))
        out.append((robot.topic, "geometry_msgs/msg/PoseStamped", t_ns,
                    T["geometry_msgs/msg/PoseStamped"](header=header, pose=pose)))
    return out


def write_fleet_log(path: FsPath, robots: Sequence[RobotLog], *, time0_ns: int = TIME0_NS) -> FsPath:
    """Every robot's messages in one ROS1 bag (``.bag``) or ROS2 MCAP (``.mcap``)."""
    kit = _kit()
    ros1 = path.suffix == ".bag"
    messages = [m for r in robots for m in robot_messages(r, ros1=ros1, time0_ns=time0_ns)]
    return FsPath(kit.write_messages(path, messages))


#: the walkthrough: the Husky (motion capture, 50 Hz) crosses the doorway first and docks at dock_a; the Jackal
#: (odometry, 20 Hz) waits beside it, follows once the doorway is clear and docks at dock_b
HUSKY = Path(((0.0, 1.0, 3.0), (15.0, 8.5, 3.0), (18.0, 8.5, 4.5), (30.0, 8.5, 4.5)))
JACKAL = Path(((0.0, 1.0, 1.5), (8.0, 1.0, 1.5), (8.0 + math.hypot(1.5, 1.5) / 0.5, 2.5, 3.0),
               (8.0 + math.hypot(1.5, 1.5) / 0.5 + 9.0, 7.0, 3.0),
               (8.0 + 2 * math.hypot(1.5, 1.5) / 0.5 + 9.0, 8.5, 1.5), (30.0, 8.5, 1.5)))


def walkthrough_robots() -> list[RobotLog]:
    return [RobotLog(HUSKY, "/husky/pose", "pose", 50.0), RobotLog(JACKAL, "/jackal/odom", "odom", 20.0)]


def main() -> None:
    path = LOGS / "two_robots.bag"
    path.unlink(missing_ok=True)
    write_fleet_log(path, walkthrough_robots())
    print(f"wrote {path} ({path.stat().st_size} bytes)")


if __name__ == "__main__":
    main()
