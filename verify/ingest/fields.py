"""Signal atoms' data: one message field of one topic -> time-sorted numeric samples (``SignalSamples``).

input: a ``RawTopic``, a field path (``twist.twist.linear.x``, ``position[2]``, ``status.levels[0].value``) and the
time base the pose stream uses -> output: the field's values with their times (header stamps when the message has a
``header`` and the pose is on the header time base, else log time), sorted, exact duplicates of a stamp merged.

Fast path (``_bulk_field``): the field's byte offset in every message is computed with numpy by walking the type's
definition (rosbags' ``fielddefs``) over all payloads at once: fixed-size fields and arrays advance by their size,
strings and sequences of numbers by their per-message length words, with CDR alignment relative to the
encapsulation header; the value is then read in one gather. Anything the walk cannot follow (a sequence or array of
strings or messages before the field, big-endian CDR, a payload too short) declines, and the field is read with
``rosbags``' typestore ``deserialize_*`` once per message (always, with ``TUBEMPC_FAST_INGEST=0``). The first and
last messages are always also deserialized, and the fast values must agree with them. A path that does not resolve
on the first message, or resolves to something that is not a number, raises ``UnusableInputError`` naming the topic
and the field. Message types outside the standard ROS type store (custom messages) are refused with exit 3 naming
the type.
"""

from __future__ import annotations

import re
from dataclasses import dataclass
from typing import Any

import numpy as np
import numpy.typing as npt

from tubempc.scenario import SignalSpec
from verify.errors import LogReadError, MissingTopicError, ScenarioInputError, UnusableInputError
from verify.ingest.decode import _joined, _size_ok, _strings_ok, typestore
from verify.ingest.quality import DROPOUT_FACTOR
from verify.ingest.raw import RawLog, RawTopic, fast_ingest
from verify.ingest.rules import ReadingRules
from verify.ingest.stats import median
from verify.ingest.timebase import TimeBase, judged_samples

__all__ = ["HOLD_FOREVER_NS", "RATE_HZ_RANGE", "FieldSamples", "SignalStream", "decode_field", "median_period_ns",
           "outside_span", "parse_field_path", "read_signals", "signal_margin", "signal_period_ns"]

FloatArray = npt.NDArray[np.float64]
IntArray = npt.NDArray[np.int64]

#: the hold of a signal on the pose topic: no gap between two pose samples expires it
HOLD_FOREVER_NS = 2**62

_TOKEN = re.compile(r"([A-Za-z_][A-Za-z0-9_]*)((?:\[\d+\])*)")


@dataclass(frozen=True, slots=True)
class FieldSamples:
    """Values of one field in reading order: header stamps (None when the message has no header), log times."""

    stamp_ns: IntArray | None
    log_ns: IntArray
    value: FloatArray
    fast: bool = False  # read by the layout walk (else one deserialize per message)


@dataclass(frozen=True, slots=True)
class SignalStream:
    """One atom's data: absolute times (ns, sorted, unique, on the pose's time base), values in the field's unit."""

    name: str
    spec: SignalSpec
    t_ns: IntArray
    value: FloatArray
    period_ns: int  # expected period: the spec's rate_hz, else the stream's median spacing (0: unknown)
    time_base: str  # "header" or "log"
    follows_pose: bool = False  # read from the pose topic: known wherever the pose is (its gaps are the pose's)

    @property
    def hold_ns(self) -> int:
        """How long a value holds after its message: 1.5 expected periods; on the pose topic, until the next
        message (the pose's own gaps are bridged by the speed bound, the signal's by its last value)."""
        if self.follows_pose:
            return HOLD_FOREVER_NS
        return int(DROPOUT_FACTOR * self.period_ns)


def signal_margin(spec: SignalSpec, value: FloatArray) -> FloatArray:
    """The atom's margin in the field's unit: ``value - threshold`` for ``>``/``>=``, ``threshold - value`` else."""
    if spec.op in (">", ">="):
        return value - spec.value
    return spec.value - value


def outside_span(stream: SignalStream, first_ns: int, last_ns: int) -> tuple[int, int, int | None]:
    """Messages of ``stream`` before ``first_ns`` or after ``last_ns`` (the pose's span, the run): how many, how many
    of them violate the atom's predicate, and the time of the first violating one (None: none)."""
    out = (stream.t_ns < first_ns) | (stream.t_ns > last_ns)
    bad = out & (signal_margin(stream.spec, stream.value) < 0)
    where = np.flatnonzero(bad)
    return int(np.count_nonzero(out)), int(where.size), (int(stream.t_ns[where[0]]) if where.size else None)


def parse_field_path(path: str) -> list[str | int]:
    """``"a.b[2].c"`` -> ``["a", "b", 2, "c"]``."""
    out: list[str | int] = []
    for part in path.split("."):
        m = _TOKEN.fullmatch(part)
        if m is None:
            raise UnusableInputError(f"field {path!r}: {part!r} is not a field name with optional [index]")
        out.append(m.group(1))
        out.extend(int(i) for i in re.findall(r"\[(\d+)\]", m.group(2)))
    return out


def _fields_of(obj: Any) -> list[str]:
    names = getattr(obj, "__dataclass_fields__", None)
    if names:
        return [n for n in names if n != "__msgtype__"]
    return []


def _resolve(msg: Any, steps: list[str | int], topic: str, field: str, msgtype: str) -> float:
    obj = msg
    for k, step in enumerate(steps):
        where = "".join(f"[{s}]" if isinstance(s, int) else ("." if i else "") + s for i, s in enumerate(steps[:k]))
        if isinstance(step, int):
            try:
                obj = obj[step]
            except (IndexError, TypeError, KeyError):
                size = len(obj) if hasattr(obj, "__len__") else None
                raise UnusableInputError(
                    f"topic {topic} ({msgtype}) has no field {field}: {where or 'the message'} "
                    f"{'has ' + str(size) + ' element(s)' if size is not None else 'is not an array'}") from None
        else:
            if not hasattr(obj, step) or step.startswith("_"):
                known = ", ".join(_fields_of(obj)) or "none"
                raise UnusableInputError(f"topic {topic} ({msgtype}) has no field {field}: "
                                         f"{where or 'the message'} has no {step!r} (its fields: {known})")
            obj = getattr(obj, step)
    if isinstance(obj, bool | int | float | np.integer | np.floating | np.bool_):
        return float(obj)
    raise UnusableInputError(f"topic {topic} ({msgtype}): field {field} is a {type(obj).__name__}, not a number")


_PRIMITIVES = {"bool": ("<u1", 1), "byte": ("<u1", 1), "char": ("<u1", 1), "int8": ("<i1", 1), "uint8": ("<u1", 1),
               "int16": ("<i2", 2), "uint16": ("<u2", 2), "int32": ("<i4", 4), "uint32": ("<u4", 4),
               "int64": ("<i8", 8), "uint64": ("<u8", 8), "float32": ("<f4", 4), "float64": ("<f8", 8)}


class _DeclineError(Exception):
    """The bulk walk cannot follow this layout: use the per-message path."""


class _Walk:
    """Per-message byte positions over one packed buffer (all messages advanced together)."""

    def __init__(self, store: Any, u8: npt.NDArray[np.uint8], offs: IntArray, lens: IntArray, ros1: bool) -> None:
        self.store, self.u8, self.ros1 = store, u8, ros1
        self.base = offs + (0 if ros1 else 4)
        self.end = offs + lens
        self.pos = self.base.copy()

    def align(self, size: int) -> None:
        if not self.ros1 and size > 1:
            rel = self.pos - self.base
            self.pos = self.base + (rel + size - 1) // size * size

    def read(self, dtype: str, size: int) -> npt.NDArray[Any]:
        if np.any(self.pos + size > self.end):
            raise _DeclineError
        cols = self.u8[self.pos[:, None] + np.arange(size)]
        return np.ascontiguousarray(cols).view(dtype).ravel()

    def u32(self) -> IntArray:
        self.align(4)
        out = self.read("<u4", 4).astype(np.int64)
        self.pos = self.pos + 4
        return out

    def skip(self, desc: tuple[Any, Any]) -> None:
        """Advance past one field of type ``desc`` (rosbags' field descriptor)."""
        kind, detail = int(desc[0]), desc[1]
        if kind == 1:  # BASE
            name = detail[0]
            if name == "string":
                n = self.u32()
                if not _strings_ok(self.u8, self.pos - 4, n, self.end, self.ros1):
                    raise _DeclineError  # cut, unterminated or not UTF-8: rosbags decides (and refuses)
                self.pos = self.pos + n
                return
            size = _PRIMITIVES.get(name, ("", 0))[1]
            if not size:
                raise _DeclineError
            self.align(size)
            self.pos = self.pos + size
        elif kind == 2:  # NAME: a nested message
            fields = self.store.fielddefs[detail][1]
            if not fields:
                raise _DeclineError
            for _, sub in fields:
                self.skip(sub)
        elif kind in (3, 4):  # ARRAY (fixed length) / SEQUENCE (length word)
            sub, length = detail
            if int(sub[0]) != 1 or sub[1][0] not in _PRIMITIVES:
                raise _DeclineError  # arrays of strings or messages: per-message lengths we do not follow
            size = _PRIMITIVES[sub[1][0]][1]
            count = self.u32() if kind == 4 else np.full(self.pos.shape[0], int(length), dtype=np.int64)
            self.align(size)
            self.pos = self.pos + count * size
            if np.any(self.pos > self.end):
                raise _DeclineError
        else:
            raise _DeclineError


def _bulk_field(raw: RawTopic, ros1: bool, steps: list[str | int]) -> FloatArray | None:
    """The field's values of every message by the layout walk, or None when it declines (see the module doc)."""
    store = typestore(ros1)
    u8, offs, lens = _joined(raw.payloads)
    if not ros1:
        if np.any(lens < 4):
            return None
        if not (np.all(u8[offs] == 0) and np.all(u8[offs + 1] == 1)):
            return None  # big-endian or other encapsulation
    if not _layout_explains(_Walk(store, u8, offs, lens, ros1), raw.msgtype, ros1):
        return None
    try:
        return _walk_to_field(_Walk(store, u8, offs, lens, ros1), raw.msgtype, steps)
    except (_DeclineError, KeyError, IndexError, ValueError):
        return None


def _layout_explains(whole: _Walk, msgtype: str, ros1: bool) -> bool:
    """Whether the type's layout, walked over every message, ends where each message ends (bytes the layout does
    not explain, or too few: rosbags refuses, the per-message path says so)."""
    try:
        for _, fdesc in whole.store.fielddefs[msgtype][1]:
            whole.skip(fdesc)
    except (_DeclineError, KeyError, IndexError, ValueError):
        return False
    return _size_ok(whole.pos, whole.end, ros1)


def _walk_to_field(walk: _Walk, msgtype: str, steps: list[str | int]) -> FloatArray | None:
    """Step through nested messages along ``steps`` to the field, then read it (a primitive, or one element of a
    primitive array); None where the walk declines."""
    k = 0
    while k < len(steps):
        desc = _skip_to(walk, msgtype, steps[k])
        if desc is None:
            return None
        kind = int(desc[0])
        last = k == len(steps) - 1
        if kind == 2 and not last:
            msgtype = desc[1]
            k += 1
            continue
        if kind == 1 and last and desc[1][0] in _PRIMITIVES:
            dtype, size = _PRIMITIVES[desc[1][0]]
            walk.align(size)
            return walk.read(dtype, size).astype(np.float64)
        if kind in (3, 4) and k == len(steps) - 2 and isinstance(steps[k + 1], int):
            return _array_element(walk, desc, kind, int(steps[k + 1]))
        return None
    return None


def _skip_to(walk: _Walk, msgtype: str, name: str | int) -> Any:
    """Skip the fields of ``msgtype`` before ``name`` -> its field description (None: no such field)."""
    for fname, fdesc in walk.store.fielddefs[msgtype][1]:
        if fname == name:
            return fdesc
        walk.skip(fdesc)
    return None


def _array_element(walk: _Walk, desc: Any, kind: int, index: int) -> FloatArray | None:
    """Element ``index`` of a primitive array field (fixed length: kind 3; sequence: kind 4)."""
    sub, length = desc[1]
    if int(sub[0]) != 1 or sub[1][0] not in _PRIMITIVES:
        return None
    dtype, size = _PRIMITIVES[sub[1][0]]
    count = walk.u32() if kind == 4 else np.full(walk.pos.shape[0], int(length), dtype=np.int64)
    if np.any(count <= index):
        return None  # some message is too short: the per-message path names it
    walk.align(size)
    walk.pos = walk.pos + index * size
    return walk.read(dtype, size).astype(np.float64)


def decode_field(raw: RawTopic, ros1: bool, field: str, *, fast: bool | None = None) -> FieldSamples:
    """Every message's ``field`` as float64 (bools as 0/1), with header stamps when the message has a header.
    ``fast``: whether the bulk walk may be used (default: ``fast_ingest()``)."""
    if fast is None:
        fast = fast_ingest()
    steps = parse_field_path(field)
    store = typestore(ros1)
    if raw.msgtype not in store.types:
        raise UnusableInputError(f"topic {raw.topic} has type {raw.msgtype}, which is not in the standard ROS type "
                                 "store: signal atoms on custom message types are not supported")
    deser = store.deserialize_ros1 if ros1 else store.deserialize_cdr
    if fast and len(raw.payloads) > 2:
        bulk = _bulk_field(raw, ros1, steps)
        if bulk is not None:
            return _checked_bulk(raw, ros1, field, steps, values=bulk, deser=deser)
    values: list[float] = []
    stamps: list[int] = []
    has_header = True
    for k, payload in enumerate(raw.payloads):
        try:
            msg = deser(payload, raw.msgtype)
        except (ValueError, KeyError, IndexError, AttributeError, TypeError) as err:
            raise LogReadError(f"topic {raw.topic}: cannot decode {raw.msgtype} ({err.__class__.__name__}: {err})"
                               ) from err
        values.append(_resolve(msg, steps, raw.topic, field, raw.msgtype))
        header = getattr(msg, "header", None)
        if k == 0:
            has_header = header is not None and hasattr(header, "stamp")
        if has_header and header is not None:
            stamps.append(int(header.stamp.sec) * 10**9 + int(header.stamp.nanosec))
    return FieldSamples(np.asarray(stamps, dtype=np.int64) if has_header else None,
                        np.asarray(raw.log_ns, dtype=np.int64), np.asarray(values, dtype=np.float64))


def median_period_ns(t_ns: npt.NDArray[np.int64]) -> int:
    """A signal's expected period without ``rate_hz``: the median spacing of its (sorted, distinct) message times;
    0 (unknown) with fewer than two."""
    return int(median(np.diff(t_ns))) if t_ns.shape[0] >= 2 else 0


#: ``signals.<name>.rate_hz`` must lie in this range (Hz): its period (1 ns .. 11.6 days) is an int64 nanosecond count
RATE_HZ_RANGE = (1e-6, 1e9)


def signal_period_ns(name: str, spec: SignalSpec, t_ns: IntArray) -> int:
    """The expected period: ``rate_hz``'s (range-checked: ``ScenarioInputError`` naming the field), else the median
    spacing of the messages."""
    if spec.rate_hz is None:
        return median_period_ns(t_ns)
    lo, hi = RATE_HZ_RANGE
    if not (lo <= spec.rate_hz <= hi):  # also NaN
        raise ScenarioInputError(f"signals.{name}.rate_hz={spec.rate_hz!r} is out of range: expected {lo:g} to "
                                 f"{hi:g} Hz")
    return round(1e9 / spec.rate_hz)


def read_signals(raw: RawLog, rules: ReadingRules, base: TimeBase, path: str, *, pose_topic: str | None = None,
                 ) -> tuple[dict[str, SignalStream], dict[str, Any]]:
    """Every signal atom of the scenario from the raw log: streams under the time rules of every stream
    (``verify.ingest.rules.ReadingRules.stream_times``; ``base``: the pose's), clock corrections added; and their
    data-quality notes (``problems``: why the stream's stamps cannot order it on an explicit header base). A signal
    on ``pose_topic`` shares the pose's samples (``SignalStream.follows_pose``).
    A topic absent from the log (or without messages) or a field that does not resolve is exit 3 naming both."""
    streams: dict[str, SignalStream] = {}
    quality: dict[str, Any] = {}
    cache: dict[tuple[str, str], FieldSamples] = {}
    for name, spec in sorted(rules.scenario.signals.items()):
        topic = raw.topics.get(spec.topic)
        if topic is None or not topic.payloads:
            why = "is absent from the log" if topic is None else "has no messages"
            raise MissingTopicError(f"signal {name}: topic {spec.topic} (field {spec.field}) {why}; the log has: "
                                    f"{', '.join(sorted(raw.available)) or 'no topics'}", path=path)
        key = (spec.topic, spec.field)
        if key not in cache:
            try:
                cache[key] = decode_field(topic, raw.ros1, spec.field)
            except UnusableInputError as err:
                raise type(err)(f"signal {name}: {err.reason}", path=path) from err
        cols = cache[key]
        tb, t = rules.stream_times(spec.topic, cols.stamp_ns, cols.log_ns, pose_base=base.name)
        offset_vs_log = round(float(median((t - cols.log_ns).astype(np.float64))) * 1e-9, 9)
        # one value per instant; duplicates of an instant that disagree make the atom unknown there (NaN)
        js = judged_samples(t, cols.value, agree_tol=0.0)
        v = cols.value[js.index].copy()
        v[js.conflict] = np.nan
        t = js.t_ns
        period = signal_period_ns(name, spec, t)
        follows = pose_topic is not None and spec.topic == pose_topic
        streams[name] = SignalStream(name, spec, t.astype(np.int64), v, period, tb.name, follows_pose=follows)
        quality[name] = {"topic": spec.topic, "type": topic.msgtype, "messages": int(cols.value.shape[0]),
                         "time_base": tb.name, "offset_vs_log_s": offset_vs_log,
                         "retimed_stamps": tb.retimed,
                         "duplicate_stamps": js.read - int(js.t_ns.shape[0]),
                         "conflicting_duplicates": int(np.count_nonzero(js.conflict)),
                         "nan_values": int(np.isnan(v).sum()),
                         "period_source": "pose samples (signal on the pose topic)" if follows
                         else "signals.rate_hz" if spec.rate_hz is not None else "median spacing",
                         **({"note": tb.note} if tb.note else {}),
                         **({"problem": tb.note} if tb.note and not tb.usable else {})}
    return streams, quality


def _checked_bulk(raw: RawTopic, ros1: bool, field: str, steps: list[str | int], *, values: FloatArray,
                  deser: Any) -> FieldSamples:
    """Bulk values, checked against ``deserialize`` on the first and last messages; header stamps in bulk too."""
    ends = (0, len(raw.payloads) - 1)
    for k in ends:
        try:
            msg = deser(raw.payloads[k], raw.msgtype)
        except (ValueError, KeyError, IndexError, AttributeError, TypeError) as err:
            raise LogReadError(f"topic {raw.topic}: cannot decode {raw.msgtype} ({err.__class__.__name__}: {err})"
                               ) from err
        want = _resolve(msg, steps, raw.topic, field, raw.msgtype)
        if not (want == values[k] or (np.isnan(want) and np.isnan(values[k]))):
            return decode_field(raw, ros1, field, fast=False)
    first = deser(raw.payloads[0], raw.msgtype)
    stamps: IntArray | None = None
    header = getattr(first, "header", None)
    if header is not None and hasattr(header, "stamp"):
        sec = _bulk_field(raw, ros1, ["header", "stamp", "sec"])
        nsec = _bulk_field(raw, ros1, ["header", "stamp", "nanosec"])
        if sec is None or nsec is None:
            return decode_field(raw, ros1, field, fast=False)
        stamps = sec.astype(np.int64) * 10**9 + nsec.astype(np.int64)
    return FieldSamples(stamps, np.asarray(raw.log_ns, dtype=np.int64), values, fast=True)
