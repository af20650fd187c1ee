"""Salvage walks over damaged logs: a truncated or unindexed file -> the messages of its complete records.

input: a ROS1 ``.bag`` or an ``.mcap`` file -> output: a ``Walk`` whose ``messages`` iterator yields
``SalvagedMessage`` for every message in a *complete* record (ROS1: complete chunks, walked from the file start;
MCAP: complete top-level records and chunks, walked as a stream). The walk stops at the first incomplete or
malformed record, or chunk that does not decompress, and says where (``stop_reason``). Files are opened read-only.
"""

from __future__ import annotations

import bz2
import struct
from collections.abc import Iterator
from dataclasses import dataclass, field
from pathlib import Path

from verify.ingest.mcaprecords import MessageRecord, Scan, lz4_decompress, scan
from verify.ingest.readerrors import DECOMPRESS_ERRORS

__all__ = ["SalvagedMessage", "Walk", "mcap_message", "walk_mcap", "walk_ros1"]

_ROS1_MAGIC = b"#ROSBAG V2.0\n"


@dataclass(frozen=True, slots=True)
class SalvagedMessage:
    topic: str
    msgtype: str
    has_definition: bool
    log_ns: int
    payload: bytes


@dataclass(slots=True)
class Walk:
    """A lazy walk; ``stopped_at``/``reason`` are filled when the iterator ends."""

    path: Path
    messages: Iterator[SalvagedMessage] = field(default_factory=lambda: iter(()))
    stopped_at: int | None = None
    reason: str = "not walked"

    def stop_reason(self) -> str:
        where = "" if self.stopped_at is None else f" at byte {self.stopped_at}"
        return f"{self.reason}{where}"


class _IncompleteError(Exception):
    pass


def _take(buf: bytes, pos: int, size: int) -> bytes:
    if size < 0 or pos + size > len(buf):
        raise _IncompleteError
    return buf[pos : pos + size]


# ---- ROS1 ----------------------------------------------------------------------------------------------------------
def _ros1_header(raw: bytes) -> dict[str, bytes]:
    fields: dict[str, bytes] = {}
    pos = 0
    while pos < len(raw):
        (size,) = struct.unpack_from("<I", raw, pos)
        item = _take(raw, pos + 4, size)
        name, _, value = item.partition(b"=")
        fields[name.decode("ascii", "replace")] = value
        pos += 4 + size
    return fields


def _ros1_records(buf: bytes, pos: int) -> Iterator[tuple[int, dict[str, bytes], bytes, int]]:
    """Yield (op, header, data, next_pos); raises _IncompleteError on a partial record."""
    while pos < len(buf):
        (hlen,) = struct.unpack_from("<I", _take(buf, pos, 4))
        header = _ros1_header(_take(buf, pos + 4, hlen))
        (dlen,) = struct.unpack_from("<I", _take(buf, pos + 4 + hlen, 4))
        data = _take(buf, pos + 8 + hlen, dlen)
        nxt = pos + 8 + hlen + dlen
        op = header.get("op", b"\x00")[0]
        yield op, header, data, nxt
        pos = nxt


#: what ends a walk at a record: cut or malformed, or a chunk that does not decompress
_STOPS: tuple[type[BaseException], ...] = (_IncompleteError, struct.error, ValueError, EOFError, *DECOMPRESS_ERRORS)
_STOPS_ROS1: tuple[type[BaseException], ...] = (KeyError, *_STOPS)  # ROS1: also a message of a connection not seen yet


def walk_ros1(path: Path) -> Walk:
    walk = Walk(path)
    buf = path.read_bytes()

    def gen() -> Iterator[SalvagedMessage]:
        if not buf.startswith(_ROS1_MAGIC):
            walk.reason, walk.stopped_at = "not a ROS1 bag (bad magic)", 0
            return
        conns: dict[int, tuple[str, str, bool]] = {}
        pos = len(_ROS1_MAGIC)
        def chunk_messages(inner: bytes) -> tuple[list[SalvagedMessage], bool]:
            got: list[SalvagedMessage] = []
            try:
                for iop, ih, idata, _ in _ros1_records(inner, 0):
                    if iop == 0x07:
                        _add_ros1_conn(conns, ih, idata)
                    elif iop == 0x02:
                        cid = struct.unpack("<I", ih["conn"])[0]
                        sec, nsec = struct.unpack("<II", ih["time"])
                        if cid in conns:
                            topic, typ, has_def = conns[cid]
                            got.append(SalvagedMessage(topic, typ, has_def, sec * 10**9 + nsec, idata))
            except (_IncompleteError, struct.error, KeyError):
                return got, True
            return got, False

        try:
            while pos < len(buf):
                (hlen,) = struct.unpack_from("<I", _take(buf, pos, 4))
                header = _ros1_header(_take(buf, pos + 4, hlen))
                (dlen,) = struct.unpack_from("<I", _take(buf, pos + 4 + hlen, 4))
                op = header.get("op", b"\x00")[0]
                compression = header.get("compression", b"none").decode()
                if pos + 8 + hlen + dlen > len(buf):
                    if op == 0x05 and compression == "none":  # a cut uncompressed chunk: its complete records
                        got, _ = chunk_messages(buf[pos + 8 + hlen :])
                        yield from got
                    raise _IncompleteError
                data = buf[pos + 8 + hlen : pos + 8 + hlen + dlen]
                if op == 0x05:
                    if compression == "bz2":
                        inner = bz2.decompress(data)
                    elif compression == "lz4":
                        inner = lz4_decompress(data)
                    else:
                        inner = data
                    got, cut = chunk_messages(inner)
                    yield from got
                    if cut:
                        raise _IncompleteError
                elif op == 0x07:
                    _add_ros1_conn(conns, header, data)
                pos += 8 + hlen + dlen
        except _STOPS_ROS1 as err:
            walk.reason = f"stopped at an incomplete record ({err.__class__.__name__})"
            walk.stopped_at = pos
            return
        walk.reason, walk.stopped_at = "reached the end of the file", None

    walk.messages = gen()
    return walk


def _add_ros1_conn(conns: dict[int, tuple[str, str, bool]], header: dict[str, bytes], data: bytes) -> None:
    cid = struct.unpack("<I", header["conn"])[0]
    topic = header["topic"].decode()
    fields = _ros1_header(data)
    typ = fields.get("type", b"").decode()
    has_def = bool(fields.get("message_definition", b"").strip())
    # ROS1 type names are pkg/Name; use the ROS2-style pkg/msg/Name as rosbags does
    if typ.count("/") == 1:
        pkg, name = typ.split("/")
        typ = f"{pkg}/msg/{name}"
    conns[cid] = (topic, typ, has_def)


# ---- MCAP ----------------------------------------------------------------------------------------------------------
def mcap_message(found: Scan, msg: MessageRecord) -> SalvagedMessage | None:
    """An MCAP message of a channel declared so far, as a salvaged message (None: its channel is not known)."""
    channel = found.channels.get(msg.channel_id)
    if channel is None:
        return None
    schema = found.schemas.get(channel.schema_id)
    name, has_def = (schema.name, schema.has_data) if schema is not None else ("", False)
    return SalvagedMessage(channel.topic, name, has_def, msg.log_ns, bytes(msg.payload))


def walk_mcap(path: Path) -> Walk:
    """The record layer's scan (``verify.ingest.mcaprecords.scan``) as a salvage walk: the messages of channels
    declared before them, in file order, up to the first record that is cut, malformed or does not decompress."""
    walk = Walk(path)
    buf = path.read_bytes()

    def gen() -> Iterator[SalvagedMessage]:
        found = Scan({}, {})
        for msg in scan(buf, found):
            if (got := mcap_message(found, msg)) is not None:
                yield got
        walk.stopped_at = found.stopped_at
        walk.reason = "reached the end of the data" if found.complete else found.reason

    walk.messages = gen()
    return walk
