"""Closed-loop results -> the certifier's view of the log ``write_log`` would write, without writing it.

input: a ``ClosedLoopResult`` and its ``Scenario`` -> output: a ``verify.ingest.LogData`` with the streams a reader
gets back from the written log: the measured pose (MoCap) and the nominal pose at the header stamps of
``stamps_ns``, the body-frame command at the same stamps, the solver status per MPC step and the run's metadata.
Positions and commands are the same float64 values the writer stores; the yaw goes through the same
quaternion and back, so the streams equal a read-back log's to rounding (a round-trip test keeps them so).

Used where many runs are judged and none is kept (the falsifier): ``verify.certify_data`` judges this value with
the same code that judges a file.
"""

from __future__ import annotations

import hashlib
from typing import Any

import numpy as np

from tubempc.control.closed_loop import ClosedLoopResult
from tubempc.rosio.writer import metadata_document, stamps_ns
from tubempc.scenario import Scenario
from verify.ingest import LogData, PoseStream
from verify.ingest.quality import yaw_from_quaternion

__all__ = ["IN_MEMORY_FORMAT", "in_memory_log"]

IN_MEMORY_FORMAT = "in-memory"


def _yaw_via_quaternion(theta: np.ndarray) -> np.ndarray:
    """The writer stores the quaternion (0, 0, sin(theta/2), cos(theta/2)); the reader's yaw of it."""
    half = 0.5 * np.asarray(theta, dtype=float)
    quat = np.zeros((half.shape[0], 4))
    quat[:, 2], quat[:, 3] = np.sin(half), np.cos(half)
    yaw, _ = yaw_from_quaternion(quat)
    return yaw


def _digest(*arrays: np.ndarray) -> str:
    """SHA-256 of the streams' bytes (there is no file to hash)."""
    h = hashlib.sha256()
    for a in arrays:
        h.update(np.ascontiguousarray(a).tobytes())
    return h.hexdigest()


def in_memory_log(result: ClosedLoopResult, scenario: Scenario, *, name: str = "<simulated run>",
                  metadata: dict[str, Any] | None = None) -> LogData:
    """The log of ``result`` as the certifier would read it (``log`` field ``name``; format ``in-memory``)."""
    t_ns = stamps_ns(result.t_s)
    pose = PoseStream(t_ns, result.x_measured[:, 0].copy(), result.x_measured[:, 1].copy(),
                      _yaw_via_quaternion(result.x_measured[:, 2]))
    nominal = PoseStream(t_ns.copy(), result.x_hat[:, 0].copy(), result.x_hat[:, 1].copy(),
                         _yaw_via_quaternion(result.x_hat[:, 2]))
    statuses = tuple({"t_s": r.t_s, "status": r.status, "success": r.success, "iterations": r.iterations,
                      "solve_time_s": r.solve_time_s, "backup": r.backup, "target": r.target} for r in result.solver)
    quality: dict[str, Any] = {
        "notes": ["streams taken from the simulation in memory (no log file was written)"],
        "missing_definitions": [],
        "solver": {"count": len(statuses), "failed": sum(1 for s in statuses if not s["success"]),
                   "backup": sum(1 for s in statuses if s["backup"])},
    }
    meta = metadata_document(result, scenario, metadata)
    time0 = int(t_ns[0]) if t_ns.size else 0
    n = int(t_ns.size)
    counts = {"read": n, "judged": n, "merged_duplicates": 0, "conflicting_duplicates": 0}
    return LogData(name, IN_MEMORY_FORMAT, _digest(t_ns, result.x_measured, result.x_hat, result.u_body), "sha256",
                   "header", time0, pose, {"topic": scenario.topics.pose, "type": "geometry_msgs/msg/PoseStamped"},
                   nominal, t_ns.copy(), result.u_body.copy(), statuses, meta, quality, False, pose_samples=pose,
                   time_base_requested="header", samples={"pose": {**counts, "retimed": 0}, "nominal": {**counts,
                   "retimed": 0}, "cmd_vel": dict(counts)})
