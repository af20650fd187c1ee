"""A log file -> the certifier's view of it: pose, nominal, inputs, solver status, metadata and data quality.

input: a log path, the scenario (topic names, rates, speed bound), the time base and the salvage flag -> output: a
frozen ``LogData`` whose streams are sorted by time, de-duplicated, with times in integer ns (absolute) and
``time0_ns`` (first pose sample unless overridden). Unusable input raises ``UnusableInputError`` subclasses.
"""

from __future__ import annotations

import json
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np
import numpy.typing as npt

from tubempc.scenario import Scenario
from verify.errors import LogReadError, MissingTopicError, UnusableInputError
from verify.ingest.decode import TF, TRANSFORM_STAMPED, decode_pose, decode_strings, decode_twist
from verify.ingest.digest import DEFAULT_DIGEST, DigestJob, digest_path, start_digest
from verify.ingest.quality import clean_order, pose_findings, stream_findings, yaw_from_quaternion
from verify.ingest.raw import RawLog, read_raw

__all__ = ["LogData", "PoseStream", "file_sha256", "read_log"]

FloatArray = npt.NDArray[np.float64]
IntArray = npt.NDArray[np.int64]
TF_TOPIC = "/tf"


@dataclass(frozen=True, slots=True)
class PoseStream:
    """Sorted, de-duplicated poses: absolute time (ns, in the chosen time base), x, y (m), yaw (rad)."""

    t_ns: IntArray
    x_m: FloatArray
    y_m: FloatArray
    theta_rad: FloatArray


@dataclass(frozen=True, slots=True)
class LogData:
    path: str
    format: str
    log_digest: str  # hex digest of the log's bytes (verify.ingest.digest)
    digest_algorithm: str  # "blake3" or "sha256"
    time_base: str
    time0_ns: int
    pose: PoseStream
    pose_source: dict[str, str]
    nominal: PoseStream | None
    cmd_t_ns: IntArray | None
    cmd_u: FloatArray | None
    statuses: tuple[dict[str, Any], ...]
    metadata: dict[str, Any] | None
    data_quality: dict[str, Any]
    partial: bool



def _json_objects(raw: RawLog, topic: str) -> list[dict[str, Any]]:
    """The JSON objects carried by a std_msgs/String topic (solver status, run metadata); other strings skipped."""
    out: list[dict[str, Any]] = []
    if topic in raw.topics:
        for _, text in decode_strings(raw.topics[topic], raw.ros1):
            try:
                item = json.loads(text)
            except json.JSONDecodeError:
                continue
            if isinstance(item, dict):
                out.append(item)
    return out

def file_sha256(path: Path) -> str:
    """SHA-256 of a file, or of a bag directory (every file's relative name and bytes, in name order)."""
    got = digest_path(path, "sha256")
    if got is None:  # only a cancelled digest has no value
        raise RuntimeError(f"sha256 of {path} was not computed")
    return got.hex


def _pose_topic(raw: RawLog, scenario: Scenario, path: str) -> str:
    topics = scenario.topics
    if topics.pose in raw.topics:
        return topics.pose
    if TF_TOPIC in raw.topics and topics.tf_child_frame:
        return TF_TOPIC
    hint = "" if TF_TOPIC not in raw.available else " (/tf is present: set topics.tf_child_frame in the scenario)"
    raise MissingTopicError(f"pose topic {topics.pose} is absent{hint}; the log has: "
                            f"{', '.join(sorted(raw.available)) or 'no topics'}", path=path)


def read_log(path: str | Path, scenario: Scenario, *, time_base: str = "header", salvage: bool = False,
             time0_ns: int | None = None, digest: str = DEFAULT_DIGEST) -> LogData:
    """The log at ``path`` as the certifier sees it; its digest (``digest``: "blake3" or "sha256") is computed in
    a thread beside the reading."""
    if time_base not in ("header", "log"):
        raise UnusableInputError(f"time_base={time_base!r} must be 'header' or 'log'")
    p = Path(path)
    if not p.exists():
        raise LogReadError("no such file or directory", path=str(p))
    try:
        job = start_digest(p, digest)
    except ValueError as err:
        raise UnusableInputError(str(err)) from err
    try:
        return _read_log(p, scenario, time_base=time_base, salvage=salvage, time0_ns=time0_ns, job=job)
    except BaseException:
        job.cancel()
        raise


def _read_log(p: Path, scenario: Scenario, *, time_base: str, salvage: bool, time0_ns: int | None,
              job: DigestJob) -> LogData:
    t = scenario.topics
    wanted = {t.pose, t.nominal, t.cmd_vel, t.solver, t.metadata, TF_TOPIC}
    raw = read_raw(p, wanted, salvage=salvage)
    quality: dict[str, Any] = {"notes": list(raw.notes), "missing_definitions": []}
    for topic in raw.topics.values():
        if not topic.has_definition:
            quality["missing_definitions"].append(
                f"{topic.topic}: the bag has no definition of {topic.msgtype}; decoded with our own type store")

    pose_topic = _pose_topic(raw, scenario, str(p))
    praw = raw.topics[pose_topic]
    if not praw.payloads:
        raise MissingTopicError(f"pose topic {pose_topic} has no messages", path=str(p))
    child = t.tf_child_frame if praw.msgtype in (TF, TRANSFORM_STAMPED) else None
    try:
        cols = decode_pose(praw, raw.ros1, child_frame=child)
    except LogReadError as err:
        raise LogReadError(err.reason, path=str(p)) from err
    if cols.stamp_ns.size == 0:
        raise MissingTopicError(f"no transform with child frame {child!r} on {pose_topic}", path=str(p))
    stamps = cols.stamp_ns if time_base == "header" else cols.log_ns
    order = clean_order(stamps)
    finite_t = stamps[order.index]
    t0 = int(finite_t[0]) if time0_ns is None else int(time0_ns)
    yaw, bad_q = yaw_from_quaternion(cols.quat_xyzw)
    idx = order.index
    pose = PoseStream(finite_t, cols.x_m[idx], cols.y_m[idx], yaw[idx])
    pq = stream_findings(stamps, cols.log_ns if time_base == "header" else None, order,
                         expected_rate_hz=scenario.mocap.rate_hz, time0_ns=t0)
    if time_base == "log":
        pq["header_vs_log_offset_s"] = stream_findings(cols.stamp_ns, cols.log_ns, clean_order(cols.stamp_ns),
                                                       expected_rate_hz=None, time0_ns=t0
                                                       ).get("header_vs_log_offset_s")
    jump_tol_m = 0.01 + 6.0 * scenario.mocap.noise_std
    pq.update(pose_findings(pose.t_ns, pose.x_m, pose.y_m, bad_q[idx], max_speed_mps=scenario.max_speed_mps,
                            jump_tolerance_m=jump_tol_m, time0_ns=t0))
    pq["fast_decode"] = cols.fast
    quality["pose"] = pq

    nominal = None
    if t.nominal in raw.topics and raw.topics[t.nominal].payloads:
        ncols = decode_pose(raw.topics[t.nominal], raw.ros1)
        nst = ncols.stamp_ns if time_base == "header" else ncols.log_ns
        norder = clean_order(nst)
        nyaw, _ = yaw_from_quaternion(ncols.quat_xyzw)
        ni = norder.index
        nominal = PoseStream(nst[ni], ncols.x_m[ni], ncols.y_m[ni], nyaw[ni])
        quality["nominal"] = stream_findings(nst, None, norder, expected_rate_hz=scenario.mocap.rate_hz,
                                             time0_ns=t0)
    else:
        quality["nominal"] = {"count": 0, "missing": True}

    cmd_t = cmd_u = None
    if t.cmd_vel in raw.topics and raw.topics[t.cmd_vel].payloads:
        tw = decode_twist(raw.topics[t.cmd_vel], raw.ros1)
        corder = clean_order(tw.log_ns)
        cmd_t, cmd_u = tw.log_ns[corder.index], tw.u[corder.index]
        cq = stream_findings(tw.log_ns, None, corder, expected_rate_hz=scenario.mocap.rate_hz, time0_ns=t0)
        cq["nan_inputs"] = int(np.count_nonzero(~np.isfinite(cmd_u).all(axis=1)))
        quality["cmd_vel"] = cq
    else:
        quality["cmd_vel"] = {"count": 0, "missing": True}

    statuses = _json_objects(raw, t.solver)
    failed = [s for s in statuses if s.get("success") is False]
    quality["solver"] = {"count": len(statuses), "failed": len(failed), "backup": sum(1 for s in statuses
                                                                                     if s.get("backup"))}
    documents = _json_objects(raw, t.metadata)
    metadata = documents[0] if documents else None
    if raw.partial:
        quality["partial"] = True
    try:
        log_digest = job.result()
    except OSError as err:
        raise LogReadError(f"could not read the log to digest it ({err})", path=str(p)) from err
    return LogData(str(p), raw.format, log_digest.hex, log_digest.algorithm, time_base, t0, pose,
                   {"topic": pose_topic, "type": praw.msgtype, **({"child_frame": child} if child else {})},
                   nominal, cmd_t, cmd_u, tuple(statuses), metadata, quality, raw.partial)
