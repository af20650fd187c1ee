"""Bulk decoding: raw payloads of one topic -> numpy columns, without one ``deserialize`` call per message.

input: a ``RawTopic`` (message type, raw CDR or ROS1 payloads) -> output: ``PoseColumns`` (header stamp, x, y,
quaternion) or ``TwistColumns`` (vx, vy, wz; and the header stamp of ``TwistStamped``).

Fast path for fixed-layout types (geometry_msgs PoseStamped and Twist, nav_msgs Odometry): the payloads are joined
into one buffer and the fields are read with ``np.frombuffer`` at per-message offsets computed from the frame-id
string lengths (CDR alignment is relative to the end of the 4-byte encapsulation header). When all messages have one
length (the usual case: a constant frame id) the buffer is viewed as an ``(n, size)`` byte matrix and the columns
are sliced directly. Anything else (big-endian CDR, TFMessage, a type whose definition differs from the standard
one) goes through ``rosbags``' typestore ``deserialize_*``; so does everything when ``TUBEMPC_FAST_INGEST=0``
(``verify.ingest.raw.fast_ingest``).
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass
from functools import lru_cache
from typing import Any

import numpy as np
import numpy.typing as npt
from rosbags.typesys import Stores, get_types_from_msg, get_typestore

from verify.errors import LogReadError
from verify.ingest.raw import RawTopic, fast_ingest
from verify.ingest.readerrors import LibraryError, deserialize, in_words
from verify.ingest.ros1 import PayloadBuffer

__all__ = [
    "FAST_TYPES",
    "PoseColumns",
    "TwistColumns",
    "decode_pose",
    "decode_strings",
    "decode_twist",
    "typestore",
]

FloatArray = npt.NDArray[np.float64]
IntArray = npt.NDArray[np.int64]

POSE_STAMPED = "geometry_msgs/msg/PoseStamped"
ODOMETRY = "nav_msgs/msg/Odometry"
TWIST = "geometry_msgs/msg/Twist"
TWIST_STAMPED = "geometry_msgs/msg/TwistStamped"
TF = "tf2_msgs/msg/TFMessage"
TRANSFORM_STAMPED = "geometry_msgs/msg/TransformStamped"
STRING = "std_msgs/msg/String"
FAST_TYPES = frozenset({POSE_STAMPED, ODOMETRY, TWIST, TWIST_STAMPED})


@dataclass(frozen=True, slots=True)
class PoseColumns:
    """Poses in reading order: header stamp (ns), log time (ns), position and orientation quaternion."""

    stamp_ns: IntArray
    log_ns: IntArray
    x_m: FloatArray
    y_m: FloatArray
    quat_xyzw: FloatArray  # (n, 4)
    fast: bool


@dataclass(frozen=True, slots=True)
class TwistColumns:
    """Commands in reading order; ``stamp_ns`` is the header stamp of ``TwistStamped`` (None for ``Twist``)."""

    log_ns: IntArray
    u: FloatArray  # (n, 3): linear.x, linear.y, angular.z
    fast: bool
    stamp_ns: IntArray | None = None


@lru_cache(maxsize=2)
def typestore(ros1: bool) -> Any:
    """Our own type store (used when a bag lacks a definition, and for non-fixed-layout types).

    ROS1 Noetic's store lacks tf2_msgs; its one-line definition is registered here.
    """
    store = get_typestore(Stores.ROS1_NOETIC if ros1 else Stores.ROS2_HUMBLE)
    if TF not in store.types:
        store.register(get_types_from_msg("geometry_msgs/TransformStamped[] transforms", TF))
    return store


def _joined(payloads: Sequence[bytes]) -> tuple[npt.NDArray[np.uint8], IntArray, IntArray]:
    """Payloads -> one byte buffer, offsets, lengths (a ``PayloadBuffer`` already is one: no copy)."""
    if isinstance(payloads, PayloadBuffer):
        return payloads.data, payloads.offsets, payloads.lengths
    lens = np.fromiter(map(len, payloads), dtype=np.int64, count=len(payloads))
    offs = np.zeros(len(payloads), dtype=np.int64)
    if len(payloads) > 1:
        np.cumsum(lens[:-1], out=offs[1:])
    return np.frombuffer(b"".join(payloads), dtype=np.uint8), offs, lens


def _u32(u8: npt.NDArray[np.uint8], at: IntArray, size: int | None = None) -> IntArray:
    """uint32 at byte offsets ``at``; ``size``: all payloads have this length and are packed (column read)."""
    if size is not None and at.shape[0] and np.all(at - np.arange(at.shape[0]) * size == at[0]):
        rel = int(at[0])
        if rel + 4 <= size:
            cols = u8.reshape(-1, size)[:, rel : rel + 4]
            return np.ascontiguousarray(cols).view("<u4").ravel().astype(np.int64)
    cols = u8[at[:, None] + np.arange(4)]
    return np.ascontiguousarray(cols).view("<u4").ravel().astype(np.int64)


def _f64_block(u8: npt.NDArray[np.uint8], at: IntArray, count: int) -> FloatArray:
    cols = u8[at[:, None] + np.arange(8 * count)]
    return np.ascontiguousarray(cols).view("<f8").reshape(at.shape[0], count)


def _f64_block_uniform(u8: npt.NDArray[np.uint8], size: int, start: int, count: int) -> FloatArray:
    mat = u8.reshape(-1, size)
    return np.ascontiguousarray(mat[:, start : start + 8 * count]).view("<f8").reshape(mat.shape[0], count)


def _utf8_strings(u8: npt.NDArray[np.uint8], start: IntArray, length: IntArray, packed: int | None = None) -> bool:
    """Whether every string ``u8[start:start+length]`` is valid UTF-8, as rosbags' deserializer requires (ASCII
    is checked in bulk; only strings with bytes >= 0x80 are decoded one by one). ``packed``: every message has this
    length and they are back to back (then equal strings at one offset are a column of the byte matrix)."""
    if start.shape[0] == 0:
        return True
    if np.any(length < 0):
        return False
    n = start.shape[0]
    if packed is not None and np.all(length == length[0]) and u8.shape[0] == n * packed:
        rel = start - np.arange(n, dtype=np.int64) * packed
        if np.all(rel == rel[0]) and int(rel[0]) >= 0 and int(rel[0] + length[0]) <= packed:
            column = u8.reshape(n, packed)[:, int(rel[0]) : int(rel[0] + length[0])]
            if not np.any(column >= 0x80):
                return True
    total = int(length.sum())
    if total == 0:
        return True
    owner = np.repeat(np.arange(start.shape[0]), length)
    within = np.arange(total) - np.repeat(np.cumsum(length) - length, length)
    high = u8[start[owner] + within] >= 0x80
    if not high.any():
        return True  # ASCII only (and np.unique, which imports numpy.ma on first use, is not needed)
    for k in np.unique(owner[high]).tolist():
        a = int(start[k])
        try:
            u8[a : a + int(length[k])].tobytes().decode("utf-8")
        except UnicodeDecodeError:
            return False
    return True


def _strings_ok(u8: npt.NDArray[np.uint8], len_at: IntArray, str_len: IntArray, end: IntArray, ros1: bool, *,
                packed: int | None = None) -> bool:
    """Whether the length-prefixed strings at ``len_at`` are what rosbags' deserializer accepts (``check_string``):
    inside the message, in CDR at least one byte long and ending with the NUL terminator, UTF-8 before it."""
    stop = len_at + 4 + str_len
    if np.any(stop > end):
        return False
    if not ros1:
        if np.any(str_len < 1) or np.any(u8[stop - 1] != 0):
            return False
        return _utf8_strings(u8, len_at + 4, str_len - 1, packed)
    return _utf8_strings(u8, len_at + 4, str_len, packed)


def _size_ok(after: IntArray, end: IntArray, ros1: bool) -> bool:
    """Whether a message ends where its layout does, as rosbags requires (ROS1 exactly; CDR up to 3 padding bytes)."""
    extra = end - after
    return bool(np.all(extra == 0)) if ros1 else bool(np.all((extra >= 0) & (extra <= 3)))


#: bytes after Odometry's pose position/orientation: pose covariance, twist, twist covariance (float64s)
_ODOMETRY_TAIL = 8 * (36 + 6 + 36)


def _align(pos: IntArray, base: int, to: int) -> IntArray:
    rel = pos - base
    return base + (rel + (to - 1)) // to * to


def _pose_fast(raw: RawTopic, ros1: bool) -> PoseColumns | None:
    """Vectorized PoseStamped/Odometry decode; None when the layout check fails (then use the slow path)."""
    n = len(raw.payloads)
    u8, offs, lens = _joined(raw.payloads)
    base = 0 if ros1 else 4
    if np.any(lens < base + 16):
        return None
    packed = int(lens[0]) if np.all(lens == lens[0]) and u8.shape[0] == n * int(lens[0]) else None
    if not ros1:
        # CDR little-endian encapsulation header: 0x00 0x01
        enc = u8.reshape(n, packed)[:, :2] if packed is not None else u8[offs[:, None] + np.arange(2)]
        if not (np.all(enc[:, 0] == 0) and np.all(enc[:, 1] == 1)):
            return None
    sec_at = offs + 4  # ROS1: after seq; CDR: after the encapsulation header
    len_at = offs + 12
    str_len = _u32(u8, len_at, packed)
    pos = len_at + 4 + str_len  # after header.frame_id
    end = offs + lens
    if not _strings_ok(u8, len_at, str_len, end, ros1, packed=packed):
        return None  # the slow path decides (and rejects) a cut message or a frame id rosbags refuses
    if raw.msgtype == ODOMETRY:
        if not ros1:
            pos = offs + _align(pos - offs, base, 4)
        if np.any(pos + 4 > end):
            return None
        child_len = _u32(u8, pos, packed)
        if not _strings_ok(u8, pos, child_len, end, ros1):
            return None
        pos = pos + 4 + child_len
    if not ros1:
        pos = offs + _align(pos - offs, base, 8)
    if np.any(pos + 56 > end):
        return None
    if not _size_ok(pos + 56 + (_ODOMETRY_TAIL if raw.msgtype == ODOMETRY else 0), end, ros1):
        return None  # bytes the layout does not explain: rosbags refuses the message, so the slow path decides
    start_rel = pos - offs
    if np.all(lens == lens[0]) and np.all(start_rel == start_rel[0]):
        size = int(lens[0])
        block = _f64_block_uniform(u8, size, int(start_rel[0]), 7)
        mat = u8.reshape(-1, size)
        s0 = int(sec_at[0] - offs[0])
        stamps = np.ascontiguousarray(mat[:, s0 : s0 + 8]).view("<u4").reshape(n, 2).astype(np.int64)
    else:
        block = _f64_block(u8, pos, 7)
        stamps = np.stack([_u32(u8, sec_at), _u32(u8, sec_at + 4)], axis=1)
    # builtin_interfaces/Time.sec is int32, also as rosbags reads ROS1's time (the plain path: the same stamps)
    sec = stamps[:, 0]
    sec = np.where(sec >= 2**31, sec - 2**32, sec)
    stamp_ns = sec * 10**9 + stamps[:, 1]
    return PoseColumns(stamp_ns, np.asarray(raw.log_ns, dtype=np.int64), block[:, 0].copy(), block[:, 1].copy(),
                       block[:, 3:7].copy(), True)


def _stamp(header: Any) -> int:
    return int(header.stamp.sec) * 10**9 + int(header.stamp.nanosec)


def decode_pose(raw: RawTopic, ros1: bool, *, child_frame: str | None = None, fast: bool | None = None
                ) -> PoseColumns:
    """PoseStamped / Odometry (fast path) or TFMessage / TransformStamped filtered by ``child_frame`` (slow path).
    ``fast``: whether the bulk decoder may be used (default: ``fast_ingest()``)."""
    if fast is None:
        fast = fast_ingest()
    if fast and raw.msgtype in (POSE_STAMPED, ODOMETRY) and raw.payloads:
        out = _pose_fast(raw, ros1)
        if out is not None:
            return out
    store = typestore(ros1)
    deser = store.deserialize_ros1 if ros1 else store.deserialize_cdr
    stamps: list[int] = []
    logs: list[int] = []
    rows: list[tuple[float, float, float, float, float, float]] = []
    try:
        for log_ns, payload in zip(raw.log_ns, raw.payloads, strict=True):
            msg = deserialize(deser, payload, raw.msgtype)
            if raw.msgtype == POSE_STAMPED:
                items = [(msg.header, msg.pose.position, msg.pose.orientation)]
            elif raw.msgtype == ODOMETRY:
                items = [(msg.header, msg.pose.pose.position, msg.pose.pose.orientation)]
            elif raw.msgtype in (TF, TRANSFORM_STAMPED):
                tfs = msg.transforms if raw.msgtype == TF else [msg]
                items = [(tf.header, tf.transform.translation, tf.transform.rotation) for tf in tfs
                         if child_frame is None or tf.child_frame_id.lstrip("/") == child_frame.lstrip("/")]
            else:
                raise LogReadError(f"topic {raw.topic} has type {raw.msgtype}, which is not a pose type "
                                   f"(PoseStamped, Odometry, TFMessage)", path=None)
            for header, p, q in items:
                stamps.append(_stamp(header))
                logs.append(log_ns)
                rows.append((p.x, p.y, q.x, q.y, q.z, q.w))
    except LibraryError as err:
        raise LogReadError(f"topic {raw.topic}: cannot decode {raw.msgtype} ({in_words(err)})") from err
    arr = np.asarray(rows, dtype=np.float64).reshape(-1, 6)
    return PoseColumns(np.asarray(stamps, dtype=np.int64), np.asarray(logs, dtype=np.int64), arr[:, 0].copy(),
                       arr[:, 1].copy(), arr[:, 2:6].copy(), False)


def _twist_stamped_fast(raw: RawTopic, ros1: bool) -> TwistColumns | None:
    """Vectorized TwistStamped decode for messages of one length (one frame id); None: use the slow path."""
    u8, _offs, lens = _joined(raw.payloads)
    n = len(raw.payloads)
    size = int(lens[0])
    if not (np.all(lens == size) and u8.shape[0] == n * size and size >= 16):
        return None
    mat = u8.reshape(n, size)
    if not ros1 and not (np.all(mat[:, 0] == 0) and np.all(mat[:, 1] == 1)):
        return None  # not little-endian CDR
    str_len = np.ascontiguousarray(mat[:, 12:16]).view("<u4").ravel().astype(np.int64)
    if not np.all(str_len == str_len[0]):
        return None
    offs = np.arange(n, dtype=np.int64) * size
    if not _strings_ok(u8, offs + 12, str_len, offs + size, ros1, packed=size):
        return None
    start = 16 + int(str_len[0])
    if not ros1:
        start = 4 + (start - 4 + 7) // 8 * 8  # float64 alignment, relative to the encapsulation header
    if start + 48 != size:
        return None
    stamps = np.ascontiguousarray(mat[:, 4:12]).view("<u4").reshape(n, 2).astype(np.int64)
    sec = stamps[:, 0]
    sec = np.where(sec >= 2**31, sec - 2**32, sec)  # int32, as in _pose_fast
    block = _f64_block_uniform(u8, size, start, 6)
    return TwistColumns(np.asarray(raw.log_ns, dtype=np.int64), block[:, [0, 1, 5]].copy(), True,
                        sec * 10**9 + stamps[:, 1])


def decode_twist(raw: RawTopic, ros1: bool, *, fast: bool | None = None) -> TwistColumns:
    """geometry_msgs Twist or TwistStamped (detected from the topic's type) -> (linear.x, linear.y, angular.z).
    ``fast``: whether the bulk decoder may be used (default: ``fast_ingest()``)."""
    if fast is None:
        fast = fast_ingest()
    log_ns = np.asarray(raw.log_ns, dtype=np.int64)
    size = 48 if ros1 else 52
    if fast and raw.msgtype == TWIST and raw.payloads:
        u8, _offs, lens = _joined(raw.payloads)
        ok = bool(np.all(lens == size))
        if ok and not ros1:
            mat = u8.reshape(-1, size)
            ok = bool(np.all(mat[:, 0] == 0) and np.all(mat[:, 1] == 1))
        if ok:
            block = _f64_block_uniform(u8, size, 0 if ros1 else 4, 6)
            return TwistColumns(log_ns, block[:, [0, 1, 5]].copy(), True)
    if fast and raw.msgtype == TWIST_STAMPED and raw.payloads:
        cols = _twist_stamped_fast(raw, ros1)
        if cols is not None:
            return cols
    if raw.msgtype not in (TWIST, TWIST_STAMPED):
        raise LogReadError(f"topic {raw.topic} has type {raw.msgtype}, expected geometry_msgs/msg/Twist or "
                           "geometry_msgs/msg/TwistStamped")
    store = typestore(ros1)
    deser = store.deserialize_ros1 if ros1 else store.deserialize_cdr
    try:
        msgs = [deserialize(deser, p, raw.msgtype) for p in raw.payloads]
    except LibraryError as err:
        raise LogReadError(f"topic {raw.topic}: cannot decode {raw.msgtype} ({in_words(err)})") from err
    stamps = None
    if raw.msgtype == TWIST_STAMPED:
        stamps = np.array([_stamp(m.header) for m in msgs], dtype=np.int64)
        msgs = [m.twist for m in msgs]
    u = np.array([(m.linear.x, m.linear.y, m.angular.z) for m in msgs], dtype=np.float64).reshape(-1, 3)
    return TwistColumns(log_ns, u, False, stamps)


def decode_strings(raw: RawTopic, ros1: bool, *, fast: bool | None = None) -> list[tuple[int, str]]:
    """std_msgs/String payloads -> (log time ns, text); undecodable messages are skipped (the caller counts them).
    ``fast``: whether the bulk decoder may be used (default: ``fast_ingest()``)."""
    if fast is None:
        fast = fast_ingest()
    if fast and raw.msgtype == STRING and raw.payloads:
        got = _strings_fast(raw, ros1)
        if got is not None:
            return got
    store = typestore(ros1)
    deser = store.deserialize_ros1 if ros1 else store.deserialize_cdr
    out: list[tuple[int, str]] = []
    for log_ns, payload in zip(raw.log_ns, raw.payloads, strict=True):
        try:
            out.append((log_ns, str(deserialize(deser, payload, raw.msgtype).data)))
        except LibraryError:
            continue
    return out


def _strings_fast(raw: RawTopic, ros1: bool) -> list[tuple[int, str]] | None:
    """Vectorized std_msgs/String decode: the layout of every message checked at once as rosbags checks it (CDR
    little-endian header, the string inside the message, NUL-terminated and UTF-8, nothing after it but CDR
    padding), then one slice per message; None when any message fails a check (the slow path then decides each)."""
    n = len(raw.payloads)
    u8, offs, lens = _joined(raw.payloads)
    base = 0 if ros1 else 4
    if np.any(lens < base + 4):
        return None
    packed = int(lens[0]) if np.all(lens == lens[0]) and u8.shape[0] == n * int(lens[0]) else None
    if not ros1:
        enc = u8[offs[:, None] + np.arange(2)]
        if not (np.all(enc[:, 0] == 0) and np.all(enc[:, 1] == 1)):
            return None
    len_at = offs + base
    str_len = _u32(u8, len_at, packed)
    end = offs + lens
    if not _strings_ok(u8, len_at, str_len, end, ros1, packed=packed):
        return None
    if not _size_ok(len_at + 4 + str_len, end, ros1):
        return None
    start = (len_at + 4).tolist()
    stop = (len_at + 4 + str_len - (0 if ros1 else 1)).tolist()
    blob = u8.tobytes()
    return [(log_ns, blob[a:b].decode("utf-8")) for log_ns, a, b in zip(raw.log_ns, start, stop, strict=True)]

