"""A log file -> the certifier's view of it: pose, nominal, inputs, solver status, metadata and data quality.

input: a log path, the scenario (topic names, rates, speed bound), the time base (``auto``, ``header``, ``log``:
``verify.ingest.timebase``) and the salvage flag -> output: a frozen ``LogData`` whose streams are sorted by time,
with times in integer ns (absolute) and ``time0_ns`` (first pose sample unless overridden). No sample is dropped:
duplicates that agree are merged, duplicates that disagree are kept for the per-sample checks (``pose_samples``) and
are unknown (NaN) to the formula; the counts are in ``samples``. Unusable input raises ``UnusableInputError``.
"""

from __future__ import annotations

import json
import stat
from collections.abc import Callable, Mapping
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, TypeVar

import numpy as np
import numpy.typing as npt

from tubempc.scenario import Scenario
from verify.errors import LogReadError, MissingTopicError, UnusableInputError, VerifyError
from verify.ingest.clocks import clock_report, median_offset_s
from verify.ingest.decode import decode_pose, decode_strings, decode_twist
from verify.ingest.digest import (
    DEFAULT_DIGEST,
    DIGESTS,
    MESSAGES_DIGEST,
    DigestJob,
    LogDigest,
    digest_path,
    messages_digest,
    start_digest,
)
from verify.ingest.fields import SignalStream, outside_span, read_signals
from verify.ingest.quality import NEAR_1970_NS, clean_order, pose_findings, stream_findings, yaw_from_quaternion
from verify.ingest.raw import RawLog, check_bag_folder, read_raw, special_file_kind
from verify.ingest.readerrors import in_words, read_errors
from verify.ingest.rules import TF_TOPIC, ReadingRules
from verify.ingest.timebase import JudgedSamples, TimeBase, judged_samples

__all__ = ["LogData", "PoseStream", "file_sha256", "log_digest", "read_log", "wanted_topics"]

FloatArray = npt.NDArray[np.float64]
IntArray = npt.NDArray[np.int64]
T = TypeVar("T")


def _optional_errors() -> tuple[type[BaseException], ...]:
    """What makes an optional stream a finding instead of an error: ours, and the readers' (``read_errors``)."""
    return (VerifyError, *read_errors())


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
    log_digest: str  # hex digest of the messages read or of the log's bytes (verify.ingest.digest)
    digest_algorithm: str  # "blake3-messages", "blake3" or "sha256"
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
    pose_samples: PoseStream  # every pose sample sorted by time (duplicates that disagree kept): per-sample checks
    time_base_requested: str = "auto"
    time_base_note: str | None = None
    samples: dict[str, dict[str, int]] = field(default_factory=dict)  # per stream: read, judged, merged, ...
    stream_problems: dict[str, str] = field(default_factory=dict)  # stream -> why nothing judged on it can pass
    signals: dict[str, SignalStream] = field(default_factory=dict)  # signal atoms (verify.ingest.fields)



def _json_objects(raw: RawLog, topic: str) -> tuple[list[dict[str, Any]], int]:
    """The JSON objects carried by a std_msgs/String topic (solver status, run metadata), and how many messages
    could not be decoded or parsed (an optional topic: counted as a finding, never an error)."""
    out: list[dict[str, Any]] = []
    bad = 0
    if topic in raw.topics:
        texts = decode_strings(raw.topics[topic], raw.ros1)
        bad = len(raw.topics[topic].payloads) - len(texts)
        for _, text in texts:
            try:
                item = json.loads(text)
            except (json.JSONDecodeError, RecursionError):
                bad += 1
                continue
            if isinstance(item, dict):
                out.append(item)
    return out, bad

def file_sha256(path: Path) -> str:
    """SHA-256 of a file, or of a bag directory (every file's relative name and bytes, in name order)."""
    got = digest_path(path, "sha256")
    if got is None:  # only a cancelled digest has no value
        raise RuntimeError(f"sha256 of {path} was not computed")
    return got.hex


def _pose_topic(raw: RawLog, rules: ReadingRules, path: str) -> str:
    topic = rules.pose_topic(raw.topics)
    if topic is None:
        raise rules.missing_pose(raw.available, path)
    return topic


def _stream(t_ns: IntArray, x_m: FloatArray, y_m: FloatArray, theta_rad: FloatArray
            ) -> tuple[PoseStream, PoseStream, JudgedSamples]:
    """(formula stream: one sample per time, NaN where duplicates disagree; every sample sorted; the accounting)."""
    js = judged_samples(t_ns, np.column_stack([x_m, y_m, theta_rad]))
    i = js.index
    conflict = js.conflict
    x, y, th = x_m[i].copy(), y_m[i].copy(), theta_rad[i].copy()
    x[conflict] = np.nan
    y[conflict] = np.nan
    th[conflict] = np.nan
    one = PoseStream(js.t_ns, x, y, th)
    if js.all_index.shape[0] == i.shape[0]:
        return one, one, js
    a = js.all_index
    return one, PoseStream(t_ns[a], x_m[a], y_m[a], theta_rad[a]), js


def _check_path(p: Path) -> None:
    """A log is a regular file or a folder: a FIFO, device or socket would block or never end (refused)."""
    try:
        mode = p.stat().st_mode
    except FileNotFoundError:
        raise LogReadError("no such file or directory", path=str(p)) from None
    except OSError as err:
        raise LogReadError(f"cannot be read ({err.strerror or err.__class__.__name__})", path=str(p)) from None
    if stat.S_ISDIR(mode):
        check_bag_folder(p)  # and every file inside it
        return
    if (kind := special_file_kind(mode)) is not None:
        raise LogReadError(f"is {kind}: a log must be a regular file or a ROS2 bag folder", path=str(p))


def read_log(path: str | Path, scenario: Scenario, *, time_base: str = "auto", salvage: bool = False,
             time0_ns: int | None = None, digest: str = DEFAULT_DIGEST,
             clock_offsets: Mapping[str, float] | None = None) -> LogData:
    """Read and judge-ready the log at ``path``; any error of the readers on damaged bytes is a ``LogReadError``
    (exit 3) naming the file and the problem in words, never an internal error. Its digest (``digest``:
    "blake3-messages", of the messages read; "blake3" or "sha256", of the file, computed in a thread beside the
    reading: ``verify.ingest.digest``). ``clock_offsets`` (topic -> seconds, added to that topic's
    times) extends and overrides the scenario's ``clock_offsets`` (``verify.ingest.clocks``)."""
    rules = ReadingRules.of(scenario, time_base, clock_offsets)  # the offsets' ranges, before the log is read
    p = Path(path)
    _check_path(p)
    if digest not in DIGESTS:
        raise UnusableInputError(f"digest={digest!r}: expected one of {', '.join(DIGESTS)}")
    job = None if digest == MESSAGES_DIGEST else start_digest(p, digest)
    try:
        return _read_log(p, rules, salvage=salvage, time0_ns=time0_ns, job=job)
    except BaseException as err:
        if job is not None:
            job.cancel()  # the file digest of a log that cannot be certified is not needed
        if isinstance(err, read_errors()) and not isinstance(err, VerifyError):
            raise _unreadable(p, err) from err
        if isinstance(err, LogReadError) and err.path is None:  # a reader's error that could not name the file
            raise LogReadError(err.reason, path=str(p)) from err
        raise


def _unreadable(p: Path, err: BaseException) -> LogReadError:
    """A reader's error on damaged bytes, as one line naming the file and the problem in words."""
    fmt = p.suffix.lstrip(".") or ("ROS2 bag" if p.is_dir() else "")
    return LogReadError(f"unreadable {fmt} log: {in_words(err)}".replace("  ", " "), path=str(p))


def log_digest(path: str | Path, scenario: Scenario, algorithm: str = DEFAULT_DIGEST, *, salvage: bool = False
               ) -> LogDigest:
    """The digest ``read_log`` puts in the certificate, alone: of the messages certification reads
    (``blake3-messages``) or of the file; errors as ``read_log``'s (one ``VerifyError`` naming the file)."""
    p = Path(path)
    _check_path(p)
    if algorithm not in DIGESTS:
        raise UnusableInputError(f"digest={algorithm!r}: expected one of {', '.join(DIGESTS)}")
    try:
        if algorithm == MESSAGES_DIGEST:
            raw = read_raw(p, wanted_topics(scenario), salvage=salvage)
            # as certify: a log without the pose topic has nothing to digest
            _pose_topic(raw, ReadingRules.of(scenario), str(p))
            got: LogDigest | None = messages_digest(raw)
        else:
            got = digest_path(p, algorithm)
    except VerifyError:
        raise
    except read_errors() as err:
        raise _unreadable(p, err) from err
    if got is None:  # only a cancelled digest has no value
        raise RuntimeError(f"digest of {p} was not computed")
    return got


def wanted_topics(scenario: Scenario) -> set[str]:
    """The topics certification reads from a log: the scenario's pose, nominal, command, solver status, metadata,
    signal topics and /tf."""
    t = scenario.topics
    wanted = {name for name in (t.pose, t.nominal, t.cmd_vel, t.solver, t.metadata, TF_TOPIC) if name is not None}
    return wanted | {sig.topic for sig in scenario.signals.values()}


def _decode_optional(what: str, topic: str, decode: Callable[[], T], quality: dict[str, Any]) -> T | None:
    """Decode an optional stream; a stream whose messages cannot be decoded becomes a finding (not an error)."""
    try:
        return decode()
    except _optional_errors() as err:
        words = err.reason if isinstance(err, UnusableInputError) else in_words(err)
        quality[what] = {"missing": True, "undecodable": True, "topic": topic, "error": words}
        quality["notes"].append(f"{topic}: messages cannot be decoded ({words}); the {what} stream is not used")
        return None


@dataclass(slots=True)
class _Reading:
    """What the streams of one log add up as they are read: quality findings, per-stream sample counts, the
    problems that make a stream unusable, and each topic's clock (time base, median offset to log time)."""

    p: Path
    raw: RawLog
    rules: ReadingRules
    quality: dict[str, Any]
    samples: dict[str, dict[str, int]] = field(default_factory=dict)
    problems: dict[str, str] = field(default_factory=dict)
    clock_streams: dict[str, tuple[str, float | None]] = field(default_factory=dict)

    def note_base(self, topic: str, stream: str, note: str | None, usable: bool) -> None:
        if note:
            self.quality["notes"].append(f"{topic}: {note}")
            if not usable:
                self.problems[stream] = note


@dataclass(frozen=True, slots=True)
class _Pose:
    topic: str
    msgtype: str
    child: str | None
    base: TimeBase
    t0: int
    stream: PoseStream
    samples: PoseStream


def _read_log(p: Path, rules: ReadingRules, *, salvage: bool, time0_ns: int | None, job: DigestJob | None
              ) -> LogData:
    scenario = rules.scenario
    raw = read_raw(p, wanted_topics(scenario), salvage=salvage)
    rules.check_offset_topics(raw.available, str(p))
    quality: dict[str, Any] = {"notes": list(raw.notes), "missing_definitions": []}
    for topic in raw.topics.values():
        if not topic.has_definition:
            quality["missing_definitions"].append(
                f"{topic.topic}: the bag has no definition of {topic.msgtype}; decoded with our own type store")
    r = _Reading(p, raw, rules, quality)
    pose = _read_pose(r, time0_ns)
    nominal = _read_nominal(r, pose)
    cmd_t, cmd_u = _read_cmd(r, pose)
    signals = _read_signals(r, pose)
    clocks = clock_report(pose.topic, r.clock_streams, rules.offsets_s)
    quality["clocks"] = clocks
    quality["notes"].extend(clocks["findings"])
    statuses, metadata = _read_json_topics(r)
    if raw.partial:
        quality["partial"] = True
    try:
        log_digest = messages_digest(raw) if job is None else job.result()
    except OSError as err:
        raise LogReadError(f"could not read the log to digest it ({err})", path=str(p)) from err
    return LogData(path=str(p), format=raw.format, log_digest=log_digest.hex, digest_algorithm=log_digest.algorithm,
                   time_base=pose.base.name, time0_ns=pose.t0, pose=pose.stream,
                   pose_source={"topic": pose.topic, "type": pose.msgtype,
                                **({"child_frame": pose.child} if pose.child else {})},
                   nominal=nominal, cmd_t_ns=cmd_t, cmd_u=cmd_u, statuses=statuses, metadata=metadata,
                   data_quality=quality, partial=raw.partial, pose_samples=pose.samples,
                   time_base_requested=rules.requested, time_base_note=pose.base.note, samples=r.samples,
                   stream_problems=r.problems, signals=signals)


def _read_pose(r: _Reading, time0_ns: int | None) -> _Pose:
    """The pose stream (required): decoded, its time base chosen, its findings in ``r.quality["pose"]``."""
    p, raw, rules, scenario = r.p, r.raw, r.rules, r.rules.scenario
    pose_topic = _pose_topic(raw, rules, str(p))
    praw = raw.topics[pose_topic]
    if not praw.payloads:
        raise MissingTopicError(f"pose topic {pose_topic} has no messages", path=str(p))
    child = rules.child_frame(praw.msgtype)
    try:
        cols = decode_pose(praw, raw.ros1, child_frame=child)
    except LogReadError as err:
        raise LogReadError(err.reason, path=str(p)) from err
    except read_errors() as err:
        raise LogReadError(f"pose topic {pose_topic}: {praw.msgtype} messages cannot be decoded: {in_words(err)}",
                           path=str(p)) from err
    if cols.stamp_ns.size == 0:
        raise MissingTopicError(f"no transform with child frame {child!r} on {pose_topic}", path=str(p))
    base, stamps = rules.pose_times(pose_topic, cols.stamp_ns, cols.log_ns)
    r.clock_streams[pose_topic] = (base.name, median_offset_s(stamps, cols.log_ns))
    yaw, bad_q = yaw_from_quaternion(cols.quat_xyzw)
    pose, pose_samples, pjs = _stream(stamps, cols.x_m, cols.y_m, yaw)
    t0 = int(pose.t_ns[0]) if time0_ns is None else int(time0_ns)
    order = clean_order(stamps)
    pq = stream_findings(stamps, cols.log_ns if base.name == "header" else None, order,
                         expected_rate_hz=scenario.mocap.rate_hz, time0_ns=t0)
    if base.name == "log":
        pq["header_vs_log_offset_s"] = stream_findings(cols.stamp_ns, cols.log_ns, clean_order(cols.stamp_ns),
                                                       expected_rate_hz=None, time0_ns=t0
                                                       ).get("header_vs_log_offset_s")
        header_order = clean_order(cols.stamp_ns)
        pq["duplicate_stamps"] = header_order.duplicates
        pq["out_of_order_stamps"] = header_order.out_of_order
    pq["stamps_near_1970"] = int(np.count_nonzero(cols.stamp_ns < NEAR_1970_NS))
    pq["retimed_stamps"] = base.retimed
    pq.update(pjs.counts())
    jump_tol_m = 0.01 + 6.0 * scenario.mocap.noise_std
    pq.update(pose_findings(pose_samples.t_ns, pose_samples.x_m, pose_samples.y_m,
                            bad_q[pjs.all_index], max_speed_mps=scenario.max_speed_mps,
                            jump_tolerance_m=jump_tol_m, time0_ns=t0))
    pq["fast_decode"] = cols.fast
    r.quality["pose"] = pq
    r.samples["pose"] = {**pjs.counts(), "retimed": base.retimed}
    r.note_base(pose_topic, "pose", base.note, base.usable)
    return _Pose(pose_topic, praw.msgtype, child, base, t0, pose, pose_samples)


def _read_nominal(r: _Reading, pose: _Pose) -> PoseStream | None:
    """The nominal pose stream (optional: undecodable or absent is a finding)."""
    raw, quality, scenario = r.raw, r.quality, r.rules.scenario
    nominal_topic = scenario.topics.nominal
    nraw = raw.topics.get(nominal_topic) if nominal_topic is not None else None
    ncols = None
    if nraw is not None and nraw.payloads and nominal_topic is not None:
        ncols = _decode_optional("nominal", nominal_topic, lambda: decode_pose(nraw, raw.ros1), quality)
    if ncols is None or nominal_topic is None:
        if "nominal" not in quality:
            quality["nominal"] = {"count": 0, "missing": True} if nominal_topic is not None else {"named": False}
        return None
    nbase, nst = r.rules.stream_times(nominal_topic, ncols.stamp_ns, ncols.log_ns, pose_base=pose.base.name)
    r.clock_streams[nominal_topic] = (nbase.name, median_offset_s(nst, ncols.log_ns))
    nyaw, _ = yaw_from_quaternion(ncols.quat_xyzw)
    nominal, _, njs = _stream(nst, ncols.x_m, ncols.y_m, nyaw)
    quality["nominal"] = {**stream_findings(nst, None, clean_order(nst), expected_rate_hz=scenario.mocap.rate_hz,
                                            time0_ns=pose.t0), **njs.counts(), "retimed_stamps": nbase.retimed}
    r.samples["nominal"] = {**njs.counts(), "retimed": nbase.retimed}
    r.note_base(nominal_topic, "nominal", nbase.note, nbase.usable)
    return nominal


def _read_cmd(r: _Reading, pose: _Pose) -> tuple[IntArray | None, FloatArray | None]:
    """The command stream (optional): every command is judged (worst case), duplicates included."""
    raw, quality, scenario = r.raw, r.quality, r.rules.scenario
    cmd_topic = scenario.topics.cmd_vel
    craw = raw.topics.get(cmd_topic) if cmd_topic is not None else None
    tw = None
    if craw is not None and craw.payloads and cmd_topic is not None:
        tw = _decode_optional("cmd_vel", cmd_topic, lambda: decode_twist(craw, raw.ros1), quality)
    if tw is None or craw is None or cmd_topic is None:
        if "cmd_vel" not in quality:
            quality["cmd_vel"] = {"count": 0, "missing": True} if cmd_topic is not None else {"named": False}
        return None, None
    cbase, cst = r.rules.stream_times(cmd_topic, tw.stamp_ns, tw.log_ns, pose_base=pose.base.name)  # TwistStamped/Twist
    header_cmd = cbase.name == "header"
    r.clock_streams[cmd_topic] = (cbase.name, median_offset_s(cst, tw.log_ns))
    corder = clean_order(cst)
    cjs = judged_samples(cst, tw.u)
    cmd_t, cmd_u = cst[cjs.all_index], tw.u[cjs.all_index]  # every command is judged (worst case)
    cq = stream_findings(cst, tw.log_ns if header_cmd else None, corder, expected_rate_hz=scenario.mocap.rate_hz,
                         time0_ns=pose.t0)
    cq["nan_inputs"] = int(np.count_nonzero(~np.isfinite(cmd_u).all(axis=1)))
    cq.update(cjs.counts())
    cq["type"] = craw.msgtype
    cq["time_base"] = cbase.name
    cq["retimed_stamps"] = cbase.retimed
    quality["cmd_vel"] = cq
    r.samples["cmd_vel"] = {**cjs.counts(), "retimed": cbase.retimed}
    r.note_base(cmd_topic, "cmd_vel", cbase.note, cbase.usable)
    return cmd_t, cmd_u


def _read_signals(r: _Reading, pose: _Pose) -> dict[str, SignalStream]:
    """The signal atoms' streams (``verify.ingest.fields``), their findings and their samples outside the run."""
    quality = r.quality
    signals, signal_quality = read_signals(r.raw, r.rules, pose.base, str(r.p), pose_topic=pose.topic)
    if signal_quality:
        quality["signals"] = signal_quality
        for name, sq in signal_quality.items():
            r.clock_streams.setdefault(sq["topic"], (sq["time_base"], sq["offset_vs_log_s"]))
            if "note" in sq:
                quality["notes"].append(f"signal {name} ({sq['topic']}): {sq['note']}")
            if "problem" in sq:
                r.problems[f"signal {name}"] = sq["problem"]
    first_ns, last_ns = int(pose.stream.t_ns[0]), int(pose.stream.t_ns[-1])
    for name, stream in signals.items():
        count, violating, at_ns = outside_span(stream, first_ns, last_ns)
        signal_quality[name]["outside_pose_span"] = count
        if count:
            quality["notes"].append(f"signal {name} ({stream.spec.topic}): {count} message(s) outside the pose's span "
                                    "(the run) are not judged")
        if at_ns is not None:  # judged in verify.certify (the formula's checks cannot pass where it uses the signal)
            signal_quality[name]["outside_pose_span_violating"] = violating
    return signals


def _read_json_topics(r: _Reading) -> tuple[tuple[dict[str, Any], ...], dict[str, Any] | None]:
    """The solver status and run metadata topics (JSON text): statuses, the first metadata document."""
    t, quality = r.rules.scenario.topics, r.quality
    statuses, bad_status = _json_objects(r.raw, t.solver)
    failed = [s for s in statuses if s.get("success") is False]
    quality["solver"] = {"count": len(statuses), "failed": len(failed), "backup": sum(1 for s in statuses
                                                                                     if s.get("backup")),
                         "undecodable": bad_status}
    documents, bad_meta = _json_objects(r.raw, t.metadata)
    if bad_meta:
        quality["notes"].append(f"{t.metadata}: {bad_meta} message(s) cannot be decoded as JSON text")
    return tuple(statuses), (documents[0] if documents else None)
