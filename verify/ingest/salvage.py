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

from verify.ingest.mcap import zstd
from verify.ingest.readerrors import DECOMPRESS_ERRORS

__all__ = ["SalvagedMessage", "Walk", "walk_mcap", "walk_ros1"]

_MCAP_MAGIC = b"\x89MCAP0\r\n"
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


def _lz4(data: bytes) -> bytes:
    from lz4.frame import decompress  # type: ignore[import-untyped]  # a rosbags dependency

    out: bytes = decompress(data)
    return out


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
                        inner = _lz4(data)
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
def _mcap_string(rec: bytes, pos: int) -> tuple[str, int]:
    (n,) = struct.unpack_from("<I", rec, pos)
    return _take(rec, pos + 4, n).decode(), pos + 4 + n


def _mcap_decompress(data: bytes, compression: str, size: int) -> bytes:
    if compression == "":
        return data
    if compression == "zstd":
        return zstd.ZstdDecompressor().decompress(data, max_length=size)
    if compression == "lz4":
        return _lz4(data)
    raise ValueError(f"unsupported MCAP chunk compression {compression!r}")


def _mcap_records(buf: bytes, pos: int, end: int) -> Iterator[tuple[int, bytes, int]]:
    while pos < end:
        op = _take(buf, pos, 1)[0]
        (size,) = struct.unpack("<Q", _take(buf, pos + 1, 8))
        rec = _take(buf, pos + 9, size)
        yield op, rec, pos + 9 + size
        pos += 9 + size


def walk_mcap(path: Path) -> Walk:
    walk = Walk(path)
    buf = path.read_bytes()

    def gen() -> Iterator[SalvagedMessage]:
        if not buf.startswith(_MCAP_MAGIC):
            walk.reason, walk.stopped_at = "not an MCAP file (bad magic)", 0
            return
        schemas: dict[int, tuple[str, bool]] = {}
        channels: dict[int, tuple[str, str, bool]] = {}
        pos = len(_MCAP_MAGIC)

        def handle(op: int, rec: bytes) -> Iterator[SalvagedMessage]:
            if op == 0x03:
                (sid,) = struct.unpack_from("<H", rec, 0)
                name, p = _mcap_string(rec, 2)
                _enc, p = _mcap_string(rec, p)
                (dlen,) = struct.unpack_from("<I", rec, p)
                schemas[sid] = (name, dlen > 0)
            elif op == 0x04:
                cid, sid = struct.unpack_from("<HH", rec, 0)
                topic, _ = _mcap_string(rec, 4)
                name, has_def = schemas.get(sid, ("", False))
                channels[cid] = (topic, name, has_def)
            elif op == 0x05:
                cid, _seq, log_time, _pub = struct.unpack_from("<HIQQ", rec, 0)
                if cid in channels:
                    topic, name, has_def = channels[cid]
                    yield SalvagedMessage(topic, name, has_def, log_time, rec[22:])

        def inner_messages(inner: bytes) -> tuple[list[SalvagedMessage], bool]:
            """Messages of the complete records of a chunk's content; flag: the content ended mid-record."""
            got: list[SalvagedMessage] = []
            try:
                for iop, irec, _ in _mcap_records(inner, 0, len(inner)):
                    got.extend(handle(iop, irec))
            except (_IncompleteError, struct.error):
                return got, True
            return got, False

        try:
            while pos < len(buf):
                op = _take(buf, pos, 1)[0]
                (size,) = struct.unpack("<Q", _take(buf, pos + 1, 8))
                if op == 0x06 and pos + 9 + size > len(buf):
                    # a truncated chunk: an uncompressed one still holds complete records up to the cut
                    rec = buf[pos + 9 :]
                    comp, p = _mcap_string(rec, 28)
                    if comp != "":
                        raise _IncompleteError
                    got, _ = inner_messages(rec[p + 8 :])
                    yield from got
                    raise _IncompleteError
                rec = _take(buf, pos + 9, size)
                if op == 0x06:
                    _start, _end, usize, _crc = struct.unpack_from("<QQQI", rec, 0)
                    comp, p = _mcap_string(rec, 28)
                    (clen,) = struct.unpack_from("<Q", rec, p)
                    got, cut = inner_messages(_mcap_decompress(_take(rec, p + 8, clen), comp, usize))
                    yield from got
                    if cut:
                        raise _IncompleteError
                elif op == 0x02:  # footer: the stream is complete
                    break
                else:
                    yield from list(handle(op, rec))
                pos += 9 + size
        except _STOPS as err:
            walk.reason = f"stopped at an incomplete record ({err.__class__.__name__})"
            walk.stopped_at = pos
            return
        walk.reason, walk.stopped_at = "reached the end of the data", None

    walk.messages = gen()
    return walk
