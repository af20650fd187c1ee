"""Signal atoms' data: one message field of one topic -> time-sorted numeric samples (``SignalSamples``).

input: a ``RawTopic``, a field path (``twist.twist.linear.x``, ``position[2]``, ``status.levels[0].value``) and the
time base the pose stream uses -> output: the field's values with their times (header stamps when the message has a
``header`` and the pose is on the header time base, else log time), sorted, exact duplicates of a stamp merged.

Decoding goes through ``rosbags``' typestore ``deserialize_*`` once per message (no fixed-layout assumption: any
message type with a definition in the bag or in our type store). A path that does not resolve on the first message,
or resolves to something that is not a number, raises ``UnusableInputError`` naming the topic and the field.
"""

from __future__ import annotations

import re
from dataclasses import dataclass
from typing import Any

import numpy as np
import numpy.typing as npt

from tubempc.scenario import Scenario, SignalSpec
from verify.errors import LogReadError, MissingTopicError, UnusableInputError
from verify.ingest.decode import typestore
from verify.ingest.quality import DROPOUT_FACTOR
from verify.ingest.raw import RawLog, RawTopic

__all__ = ["FieldSamples", "SignalStream", "decode_field", "parse_field_path", "read_signals"]

FloatArray = npt.NDArray[np.float64]
IntArray = npt.NDArray[np.int64]

_TOKEN = re.compile(r"([A-Za-z_][A-Za-z0-9_]*)((?:\[\d+\])*)")


@dataclass(frozen=True, slots=True)
class FieldSamples:
    """Values of one field in reading order: header stamps (None when the message has no header), log times."""

    stamp_ns: IntArray | None
    log_ns: IntArray
    value: FloatArray


@dataclass(frozen=True, slots=True)
class SignalStream:
    """One atom's data: absolute times (ns, sorted, unique, on the pose's time base), values in the field's unit."""

    name: str
    spec: SignalSpec
    t_ns: IntArray
    value: FloatArray
    period_ns: int  # expected period: the spec's rate_hz, else the stream's median spacing (0: unknown)
    time_base: str  # "header" or "log"

    @property
    def hold_ns(self) -> int:
        """How long a value holds after its message (1.5 expected periods)."""
        return int(DROPOUT_FACTOR * self.period_ns)


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


def decode_field(raw: RawTopic, ros1: bool, field: str) -> FieldSamples:
    """Every message's ``field`` as float64 (bools as 0/1), with header stamps when the message has a header."""
    steps = parse_field_path(field)
    store = typestore(ros1)
    deser = store.deserialize_ros1 if ros1 else store.deserialize_cdr
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


def read_signals(raw: RawLog, scenario: Scenario, base_name: str, path: str,
                 offsets_ns: dict[str, int] | None = None) -> tuple[dict[str, SignalStream], dict[str, Any]]:
    """Every signal atom of the scenario from the raw log: streams on the pose's time base (header stamps when the
    message has a header and the pose uses them), with ``offsets_ns[topic]`` added; and their data-quality notes.
    A topic absent from the log (or without messages) or a field that does not resolve is exit 3 naming both."""
    streams: dict[str, SignalStream] = {}
    quality: dict[str, Any] = {}
    cache: dict[tuple[str, str], FieldSamples] = {}
    for name, spec in sorted(scenario.signals.items()):
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
        header = cols.stamp_ns is not None and base_name == "header"
        t = cols.stamp_ns if header and cols.stamp_ns is not None else cols.log_ns
        t = t + (offsets_ns or {}).get(spec.topic, 0)
        offset_vs_log = round(float(np.median((t - cols.log_ns).astype(np.float64))) * 1e-9, 9)
        order = np.argsort(t, kind="stable")
        t, v = t[order], cols.value[order]
        # one value per instant; duplicates of a stamp that disagree make the atom unknown there (NaN)
        t_unique, first = np.unique(t, return_index=True)
        lo = np.minimum.reduceat(v, first) if v.size else v
        hi = np.maximum.reduceat(v, first) if v.size else v
        conflict = lo != hi
        duplicates = int(t.shape[0] - t_unique.shape[0])
        conflicts = int(np.count_nonzero(conflict))
        t, v = t_unique, np.where(conflict, np.nan, v[first])
        if spec.rate_hz is not None:
            period = round(1e9 / spec.rate_hz)
        else:
            period = int(np.median(np.diff(t))) if t.shape[0] >= 2 else 0
        streams[name] = SignalStream(name, spec, t.astype(np.int64), v, period, "header" if header else "log")
        quality[name] = {"topic": spec.topic, "type": topic.msgtype, "messages": int(cols.value.shape[0]),
                         "time_base": "header" if header else "log", "offset_vs_log_s": offset_vs_log,
                         "duplicate_stamps": duplicates,
                         "conflicting_duplicates": conflicts, "nan_values": int(np.isnan(v).sum()),
                         "period_source": "signals.rate_hz" if spec.rate_hz is not None else "median spacing"}
    return streams, quality
