"""What a log holds: a log path -> ``LogInfo`` (every topic's type, count, rate, gaps, span and clock; where the
robot went on every pose-like stream), for ``tubempc info`` and ``tubempc scenario init``.

input: a log path (any format ``verify.ingest`` reads) -> output: a frozen ``LogInfo``; ``info_dict`` is its JSON
form (``info_version``), ``info_lines`` its text. Unusable input raises the readers' ``LogReadError`` (exit 3).

Reading: the pose-like topics (``PoseStamped``, ``Odometry``, ``/tf``) go through the certifier's reader and
decoder (``verify.ingest.raw.read_raw``, ``verify.ingest.decode.decode_pose``), so the extents and speeds are the
ones certification sees. Every other topic is streamed message by message through rosbags' reader and only its log
time and header stamp are kept (16 bytes a message): a camera topic of many gigabytes costs its message count, not
its bytes. Rates and gaps use the header stamps when every message of the topic has a set one, else log time (the
``time`` field says which); a gap counts as a dropout past ``DROPOUT_FACTOR`` median periods (the data-quality rule).
"""

from __future__ import annotations

import dataclasses
import math
import re
import struct
from array import array
from collections.abc import Iterator
from dataclasses import asdict, dataclass
from pathlib import Path
from typing import Any

import numpy as np
import numpy.typing as npt

from verify.errors import LogReadError, VerifyError
from verify.ingest.decode import ODOMETRY, POSE_STAMPED, TF, TWIST, TWIST_STAMPED, decode_pose, decode_twist, typestore
from verify.ingest.fields import median_period_ns
from verify.ingest.quality import DROPOUT_FACTOR, NEAR_1970_NS, clean_order
from verify.ingest.raw import RawTopic, detect_format, read_raw
from verify.ingest.readerrors import READ_ERRORS, in_words
from verify.ingest.salvage import walk_mcap, walk_ros1

__all__ = ["INFO_SCHEMA_ID", "INFO_VERSION", "CommandInfo", "LogInfo", "PoseInfo", "TopicInfo", "info_dict",
           "info_lines", "info_schema", "log_info"]

INFO_VERSION = 1
#: ``$id`` of the published JSON Schema of ``tubempc info --json`` (``docs/info.schema.json``)
INFO_SCHEMA_ID = f"https://tubempc.invalid/schema/info-v{INFO_VERSION}.json"
CLOCK_TYPE = "rosgraph_msgs/msg/Clock"
POSE_TYPES = frozenset({POSE_STAMPED, ODOMETRY, TF})
COMMAND_TYPES = frozenset({TWIST, TWIST_STAMPED})
_GAPS_SHOWN = 3
_HEADER_FIRST = re.compile(r"^\s*(std_msgs/(msg/)?)?Header\s+\w+", re.MULTILINE)
IntArray = npt.NDArray[np.int64]
FloatArray = npt.NDArray[np.float64]


@dataclass(frozen=True, slots=True)
class Gap:
    """A gap between two consecutive messages of a topic."""

    after_s: float  # seconds from the log's first message to the message before the gap
    gap_s: float


@dataclass(frozen=True, slots=True)
class TopicInfo:
    """One topic: counts, span on log time and (when its messages carry one) on header time, rate and gaps."""

    topic: str
    msgtype: str
    count: int
    log_first_s: float | None
    log_last_s: float | None
    header_first_s: float | None
    header_last_s: float | None
    unset_stamps: int  # messages with a header whose stamp is 0
    time: str  # "header" or "log": the times the rate and gaps below are measured on
    rate_hz: float | None
    median_period_s: float | None
    dropouts: int  # gaps longer than DROPOUT_FACTOR median periods
    largest_gaps: tuple[Gap, ...]
    clock: str | None  # "wall" or "simulated" (of the header stamps, else of the log times)


@dataclass(frozen=True, slots=True)
class PoseInfo:
    """A pose-like stream (a topic, or one child frame of /tf): where it went and how fast."""

    topic: str
    child_frame: str | None
    msgtype: str
    samples: int
    x_min_m: float
    x_max_m: float
    y_min_m: float
    y_max_m: float
    speed_p50_mps: float | None
    speed_p90_mps: float | None
    speed_p99_mps: float | None
    speed_max_mps: float | None
    non_finite: int  # samples without a finite position (left out of the extents)


@dataclass(frozen=True, slots=True)
class CommandInfo:
    """A velocity command topic (Twist, TwistStamped): the largest magnitude of each component it carries."""

    topic: str
    msgtype: str
    samples: int
    max_abs_linear_x: float
    max_abs_linear_y: float
    max_abs_angular_z: float
    non_finite: int


@dataclass(frozen=True, slots=True)
class LogInfo:
    """What a log holds (``tubempc info``): its format and clock, every topic, the pose-like and command streams."""

    path: str
    format: str
    log_clock: str  # "wall" or "simulated"
    clock_note: str
    start_s: float | None
    end_s: float | None
    topics: tuple[TopicInfo, ...]
    poses: tuple[PoseInfo, ...]
    commands: tuple[CommandInfo, ...]
    partial: bool = False  # read by a salvage walk (--salvage): what complete records remain
    notes: tuple[str, ...] = ()


def _clock(first_ns: int | None) -> str | None:
    if first_ns is None:
        return None
    return "simulated" if first_ns < NEAR_1970_NS else "wall"


def _has_header(msgdef_text: str, msgtype: str, ros1: bool) -> bool:
    """Whether the message's first field is a ``Header`` (its stamp sits at a fixed place in the payload)."""
    text = "\n".join(line for line in msgdef_text.splitlines() if line.strip() and not line.lstrip().startswith("#"))
    if text:
        first = text.splitlines()[0]
        return _HEADER_FIRST.match(first) is not None
    fields = typestore(ros1).fielddefs.get(msgtype)  # no definition in the log: the standard type's
    if not fields or not fields[1]:
        return False
    first_type = fields[1][0][1][1]
    return str(first_type) in ("std_msgs/msg/Header", "std_msgs/Header")


def _stamp_ns(payload: bytes | memoryview, ros1: bool) -> int | None:
    """The header stamp of a payload whose message starts with a ``Header`` (ROS1: after the seq; CDR: after the
    4-byte encapsulation header; big-endian CDR when its second byte is 0)."""
    if len(payload) < 12:
        return None
    if ros1:
        sec, nsec = struct.unpack_from("<II", payload, 4)
    else:
        sec, nsec = struct.unpack_from(">iI" if payload[1] == 0 else "<iI", payload, 4)
    return int(sec) * 10**9 + int(nsec)


class _Times:
    """Per topic: log times and header stamps, in compact arrays."""

    def __init__(self) -> None:
        self.log = array("q")
        self.stamp = array("q")


def _topic_info(topic: str, msgtype: str, log_ns: IntArray, stamp_ns: IntArray | None, start_ns: int
                ) -> TopicInfo:
    n = int(log_ns.shape[0])
    unset = int(np.count_nonzero(stamp_ns == 0)) if stamp_ns is not None else 0
    use_header = stamp_ns is not None and n > 0 and unset == 0
    t = stamp_ns if use_header and stamp_ns is not None else log_ns
    t = t[clean_order(t).index] if n else t
    period = median_period_ns(t)
    gaps: tuple[Gap, ...] = ()
    dropouts = 0
    if t.shape[0] >= 2:
        dt = np.diff(t)
        order = np.argsort(-dt, kind="stable")[:_GAPS_SHOWN]  # the largest first; equal gaps: the earliest first
        base = int(t[0]) if use_header else start_ns
        gaps = tuple(Gap(round((int(t[i]) - base) * 1e-9, 6), round(int(dt[i]) * 1e-9, 6)) for i in order)
        if period > 0:
            dropouts = int(np.count_nonzero(dt > DROPOUT_FACTOR * period))
    set_stamps = stamp_ns[stamp_ns != 0] if stamp_ns is not None else None
    has_set = set_stamps is not None and set_stamps.shape[0] > 0
    return TopicInfo(
        topic=topic, msgtype=msgtype, count=n,
        log_first_s=_s(int(log_ns.min())) if n else None, log_last_s=_s(int(log_ns.max())) if n else None,
        header_first_s=_s(int(set_stamps.min())) if has_set and set_stamps is not None else None,
        header_last_s=_s(int(set_stamps.max())) if has_set and set_stamps is not None else None,
        unset_stamps=unset, time="header" if use_header else "log",
        rate_hz=round(1e9 / period, 6) if period > 0 else None,
        median_period_s=_s(period) if period > 0 else None, dropouts=dropouts, largest_gaps=gaps,
        clock=_clock(int(t[0]) if t.shape[0] else None))


def _s(ns: int) -> float:
    return round(ns * 1e-9, 9)


def _pose_info(topic: str, msgtype: str, child: str | None, *, stamp_ns: IntArray, x: FloatArray, y: FloatArray
               ) -> PoseInfo | None:
    finite = np.isfinite(x) & np.isfinite(y)
    if not finite.any():
        return None
    t, xf, yf = stamp_ns[finite], x[finite], y[finite]
    order = clean_order(t).index
    t, xf, yf = t[order], xf[order], yf[order]
    speeds = np.empty(0)
    if t.shape[0] >= 2:
        dt = np.diff(t) * 1e-9
        speeds = np.hypot(np.diff(xf), np.diff(yf)) / dt
    pct = [round(float(np.percentile(speeds, q)), 6) for q in (50, 90, 99, 100)] if speeds.size else [None] * 4
    return PoseInfo(topic=topic, child_frame=child, msgtype=msgtype, samples=int(x.shape[0]),
                    x_min_m=float(xf.min()), x_max_m=float(xf.max()), y_min_m=float(yf.min()),
                    y_max_m=float(yf.max()), speed_p50_mps=pct[0], speed_p90_mps=pct[1], speed_p99_mps=pct[2],
                    speed_max_mps=pct[3], non_finite=int(np.count_nonzero(~finite)))


def _tf_poses(raw: RawTopic, ros1: bool) -> dict[str, tuple[IntArray, FloatArray, FloatArray]]:
    """Per child frame of a /tf topic (first-seen order): header stamps and translations, in one decoding pass."""
    store = typestore(ros1)
    deser = store.deserialize_ros1 if ros1 else store.deserialize_cdr
    rows: dict[str, tuple[list[int], list[float], list[float]]] = {}
    for payload in raw.payloads:
        for tf in deser(payload, raw.msgtype).transforms:
            t, x, y = rows.setdefault(str(tf.child_frame_id).lstrip("/"), ([], [], []))
            t.append(int(tf.header.stamp.sec) * 10**9 + int(tf.header.stamp.nanosec))
            x.append(float(tf.transform.translation.x))
            y.append(float(tf.transform.translation.y))
    return {k: (np.asarray(t, dtype=np.int64), np.asarray(x), np.asarray(y)) for k, (t, x, y) in rows.items()}


def _decoded(path: Path, topics: dict[str, str]
             ) -> tuple[list[PoseInfo], list[CommandInfo], dict[str, tuple[IntArray, IntArray | None]]]:
    """Pose-like and command topics through the certifier's reader and decoders; also their times for the table."""
    wanted = [t for t, ty in topics.items() if ty in POSE_TYPES | COMMAND_TYPES]
    if not wanted:
        return [], [], {}
    raw = read_raw(path, wanted)
    return _decoded_topics(raw.topics, raw.ros1)


def _decoded_topics(raw_topics: dict[str, RawTopic], ros1: bool
                    ) -> tuple[list[PoseInfo], list[CommandInfo], dict[str, tuple[IntArray, IntArray | None]]]:
    out: list[PoseInfo] = []
    commands: list[CommandInfo] = []
    times: dict[str, tuple[IntArray, IntArray | None]] = {}
    for topic in sorted(raw_topics):
        rt = raw_topics[topic]
        log_ns = np.asarray(rt.log_ns, dtype=np.int64)
        if rt.msgtype in COMMAND_TYPES:
            tw = decode_twist(rt, ros1)
            times[topic] = (tw.log_ns, tw.stamp_ns)
            ok = np.isfinite(tw.u).all(axis=1)
            top = np.abs(tw.u[ok]).max(axis=0) if ok.any() else np.zeros(3)
            commands.append(CommandInfo(topic, rt.msgtype, int(tw.u.shape[0]), float(top[0]), float(top[1]),
                                        float(top[2]), int(np.count_nonzero(~ok))))
            continue
        if rt.msgtype == TF:
            times[topic] = (log_ns, None)
            for child, (stamp_ns, x_m, y_m) in _tf_poses(rt, ros1).items():
                info = _pose_info(topic, rt.msgtype, child, stamp_ns=stamp_ns, x=x_m, y=y_m)
                if info is not None:
                    out.append(info)
            continue
        cols = decode_pose(rt, ros1)
        times[topic] = (cols.log_ns, cols.stamp_ns)
        info = _pose_info(topic, rt.msgtype, None, stamp_ns=cols.stamp_ns, x=cols.x_m, y=cols.y_m)
        if info is not None:
            out.append(info)
    return out, commands, times


def _stream(path: Path, fmt: str, skip: set[str] | None) -> tuple[dict[str, str], dict[str, _Times]]:
    """Every topic's type and, for the topics not in ``skip``, the log times and header stamps of its messages
    (``skip=None``: the types only)."""
    from rosbags.rosbag1 import Reader as Reader1
    from rosbags.rosbag2 import Reader as Reader2

    ros1 = fmt == "ros1"
    reader: Reader1 | Reader2 = Reader1(path) if ros1 else Reader2(path)
    reader.open()
    try:
        conns = list(reader.connections)
        types = {c.topic: c.msgtype for c in conns}
        selected = [] if skip is None else [c for c in conns if c.topic not in skip]
        header = {c.id: _has_header(c.msgdef.data, c.msgtype, ros1) for c in selected}
        times: dict[str, _Times] = {c.topic: _Times() for c in selected}
        if selected:
            for conn, log_ns, payload in reader.messages(connections=selected):
                slot = times[conn.topic]
                slot.log.append(log_ns)
                if header[conn.id]:
                    stamp = _stamp_ns(payload, ros1)
                    slot.stamp.append(-1 if stamp is None else stamp)
        for c in selected:
            if not header[c.id]:
                times[c.topic].stamp = array("q")
    finally:
        reader.close()
    return types, times


def log_info(path: str | Path, *, salvage: bool = False) -> LogInfo:
    """Read the log at ``path`` and describe it; a damaged log is one ``LogReadError`` naming the file.
    ``salvage``: walk the complete records of a truncated or unindexed ROS1 or MCAP log instead (``partial``)."""
    p = Path(path)
    if not p.exists():
        raise LogReadError("no such file or directory", path=str(p))
    if not (p.is_file() or p.is_dir()):
        raise LogReadError("not a regular file or a bag folder", path=str(p))
    fmt = detect_format(p)
    try:
        if salvage:
            return _salvaged(p, fmt)
        types, _ = _stream(p, fmt, skip=None)
        return _describe(p, fmt, types)
    except VerifyError:
        raise
    except READ_ERRORS as err:
        hint = "" if salvage or fmt == "sqlite3" else \
            " (if the recorder was killed, `info --salvage` describes the complete records)"
        raise LogReadError(f"unreadable {fmt} log: {in_words(err)}{hint}", path=str(p)) from err


def _salvaged(p: Path, fmt: str) -> LogInfo:
    """One walk over the complete records (``verify.ingest.salvage``): times of every message, payloads of the
    pose and command topics only."""
    if fmt == "sqlite3":
        raise LogReadError("--salvage reads ROS1 and MCAP logs only", path=str(p))
    files = sorted(f for f in p.iterdir() if f.suffix == ".mcap") if p.is_dir() else [p]
    ros1 = fmt == "ros1"
    types: dict[str, str] = {}
    times: dict[str, _Times] = {}
    kept: dict[str, RawTopic] = {}
    header: dict[str, bool] = {}
    stops: list[str] = []
    for file in files:
        walk = walk_ros1(file) if ros1 else walk_mcap(file)
        for m in walk.messages:
            if m.topic not in types:
                types[m.topic] = m.msgtype
                times[m.topic] = _Times()
                header[m.topic] = _has_header("", m.msgtype, ros1)
                if m.msgtype in POSE_TYPES | COMMAND_TYPES:
                    kept[m.topic] = RawTopic(m.topic, m.msgtype, m.has_definition, [], [])
            slot = times[m.topic]
            slot.log.append(m.log_ns)
            if header[m.topic]:
                stamp = _stamp_ns(m.payload, ros1)
                slot.stamp.append(-1 if stamp is None else stamp)
            if m.topic in kept:
                rt = kept[m.topic]
                rt.log_ns.append(m.log_ns)  # type: ignore[union-attr]
                rt.payloads.append(m.payload)  # type: ignore[union-attr]
        stops.append(f"{file.name}: {walk.stop_reason()}")
    poses, commands, pose_times = _decoded_topics(kept, ros1)
    streamed = {t: slot for t, slot in times.items() if t not in pose_times}
    info = _assemble(p, fmt, types, poses, commands, pose_times, streamed)
    return dataclasses.replace(info, partial=True, notes=tuple(f"salvaged: {s}" for s in stops))


def _describe(p: Path, fmt: str, types: dict[str, str]) -> LogInfo:
    poses, commands, pose_times = _decoded(p, types)
    _, streamed = _stream(p, fmt, skip=set(pose_times))
    return _assemble(p, fmt, types, poses, commands, pose_times, streamed)


def _assemble(p: Path, fmt: str, types: dict[str, str], poses: list[PoseInfo],  # noqa: PLR0917
              commands: list[CommandInfo], pose_times: dict[str, tuple[IntArray, IntArray | None]],
              streamed: dict[str, _Times]) -> LogInfo:
    columns: dict[str, tuple[str, IntArray, IntArray | None]] = {}
    for topic, (log_ns, stamp_ns) in pose_times.items():
        columns[topic] = (types[topic], log_ns, stamp_ns)
    for topic, slot in streamed.items():
        stamps = np.frombuffer(slot.stamp, dtype=np.int64) if len(slot.stamp) else None
        if stamps is not None and np.any(stamps < 0):
            stamps = None  # a message too short for a header: no header time for this topic
        columns[topic] = (types[topic], np.frombuffer(slot.log, dtype=np.int64), stamps)
    firsts = [int(c[1].min()) for c in columns.values() if c[1].shape[0]]
    lasts = [int(c[1].max()) for c in columns.values() if c[1].shape[0]]
    start_ns = min(firsts) if firsts else 0
    topics = tuple(_topic_info(t, ty, log_ns, st, start_ns) for t, (ty, log_ns, st) in sorted(columns.items()))
    clock_topics = [t for t, ty in types.items() if ty == CLOCK_TYPE]
    log_clock = _clock(start_ns if firsts else None) or "wall"
    header_clocks = {t.clock for t in topics if t.time == "header"}
    if clock_topics:
        note = f"{', '.join(sorted(clock_topics))} is recorded: the robot ran on a simulated clock"
        log_clock = "simulated"
    elif log_clock == "simulated":
        note = "log times start near 1970: the recorder ran on a simulated clock"
    elif "simulated" in header_clocks:
        note = "log times are wall-clock times but some header stamps start near 1970 (a simulated clock)"
    else:
        note = "log times and header stamps are wall-clock times"
    return LogInfo(path=str(p), format=fmt, log_clock=log_clock, clock_note=note,
                   start_s=_s(start_ns) if firsts else None, end_s=_s(max(lasts)) if lasts else None,
                   topics=topics, poses=tuple(poses), commands=tuple(commands))


def info_dict(info: LogInfo) -> dict[str, Any]:
    """The JSON form of ``info`` (``tubempc info --json``): plain data, seconds and metres, ``info_version``."""
    return {"info_version": INFO_VERSION, **asdict(info)}


def _closed(node: Any) -> None:
    """Every object of the schema names all its fields: no field the model does not have is accepted."""
    if isinstance(node, dict):
        if node.get("type") == "object" and "properties" in node:
            node.setdefault("additionalProperties", False)
        for value in node.values():
            _closed(value)
    elif isinstance(node, list):
        for value in node:
            _closed(value)


def info_schema() -> dict[str, Any]:
    """The JSON Schema (draft 2020-12) of ``info_dict``: generated from the ``LogInfo`` dataclasses by pydantic,
    with ``info_version`` fixed to ``INFO_VERSION`` and closed objects (``docs/info.schema.json``, printed by
    ``tubempc schema info``)."""
    from pydantic import TypeAdapter  # only the schema command needs the generator

    schema = TypeAdapter(LogInfo).json_schema(mode="serialization")
    schema["properties"] = {"info_version": {"const": INFO_VERSION, "title": "Info Version", "type": "integer"},
                            **schema["properties"]}
    schema["required"] = ["info_version", *schema.get("required", [])]
    _closed(schema)
    return {"$schema": "https://json-schema.org/draft/2020-12/schema", "$id": INFO_SCHEMA_ID, **schema}


def _num(v: float | None, fmt: str = ".3f") -> str:
    return "-" if v is None or not math.isfinite(v) else format(v, fmt)


def info_lines(info: LogInfo) -> Iterator[str]:
    """The text of ``tubempc info``: the log, its clock, each topic (two or three lines), each pose-like stream and
    each command topic."""
    span = (info.end_s or 0.0) - (info.start_s or 0.0)
    n = len(info.topics)
    partial = " (salvaged: the complete records only)" if info.partial else ""
    yield (f"{info.path}: {info.format} log, {n} topic{'s' if n != 1 else ''}, {span:.3f} s of log time "
           f"({_num(info.start_s)} .. {_num(info.end_s)}){partial}")
    yield f"clock: {info.log_clock} ({info.clock_note})"
    for note in info.notes:
        yield f"note: {note}"
    yield "topics:"
    for t in info.topics:
        rate = (f"{_num(t.rate_hz, '.2f')} Hz (median period {_num(t.median_period_s, '.4f')} s on {t.time} time)"
                if t.rate_hz is not None else "no rate (fewer than two messages)")
        drop = (f"{t.dropouts} dropout{'s' if t.dropouts != 1 else ''} (gaps > {DROPOUT_FACTOR:g} periods)"
                if t.dropouts else "no dropouts")
        yield f"  {t.topic}  {t.msgtype}  {t.count} msgs, {rate}, {drop}"
        if t.largest_gaps:
            yield "    largest gaps: " + ", ".join(f"{g.gap_s:.3f} s after {g.after_s:.3f} s" for g in t.largest_gaps)
        hdr = (f"header time {_num(t.header_first_s)} .. {_num(t.header_last_s)}" if t.header_first_s is not None
               else "no header stamp")
        unset = f", {t.unset_stamps} unset stamps" if t.unset_stamps else ""
        yield f"    log time {_num(t.log_first_s)} .. {_num(t.log_last_s)}; {hdr}{unset}; clock {t.clock or '-'}"
    if info.poses:
        yield "pose-like streams:"
    for pi in info.poses:
        name = pi.topic + (f" child frame {pi.child_frame}" if pi.child_frame else "")
        bad = f", {pi.non_finite} non-finite" if pi.non_finite else ""
        yield (f"  {name} ({pi.msgtype}, {pi.samples} samples{bad}): x {pi.x_min_m:.3f} .. {pi.x_max_m:.3f} m, "
               f"y {pi.y_min_m:.3f} .. {pi.y_max_m:.3f} m")
        yield (f"    speed between samples: p50 {_num(pi.speed_p50_mps)}, p90 {_num(pi.speed_p90_mps)}, p99 "
               f"{_num(pi.speed_p99_mps)}, max {_num(pi.speed_max_mps)} m/s")
    if info.commands:
        yield "command topics:"
    for c in info.commands:
        bad = f", {c.non_finite} non-finite" if c.non_finite else ""
        yield (f"  {c.topic} ({c.msgtype}, {c.samples} samples{bad}): |linear.x| <= {c.max_abs_linear_x:.3f} m/s, "
               f"|linear.y| <= {c.max_abs_linear_y:.3f} m/s, |angular.z| <= {c.max_abs_angular_z:.3f} rad/s")
