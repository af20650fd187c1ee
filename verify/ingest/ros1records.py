"""The ROS1 bag record layer: bytes of a ROS1 bag (v2.0) -> its records and messages, as the format lays them out.

input: bytes of a bag file from some position (all of it, or what a recorder has written so far) -> output: the
records (``record_at``: op, header fields, data), and, through ``Ros1Stream``, the messages of every connection in
file order with where reading stopped. One place for the magic bytes, the named opcodes and the record layout
(http://wiki.ros.org/Bags/Format/2.0): the indexed reader ``verify.ingest.ros1``, salvage ``verify.ingest.salvage``
and the follower ``verify.online.follow`` take them from here; salvage and the follower drive one ``Ros1Stream``.

A record: header length u32, header (fields: length u32, ``name=value``), data length u32, data. ``rosbag record``
writes a chunk as it records: the chunk's header first with sizes 0 (rewritten when the chunk is closed), then the
chunk's records appended one by one (uncompressed: readable as they arrive; compressed: a stream only complete when
the chunk is closed), then the index data records after it; the bag header's ``index_pos`` is 0 until the bag is
closed. ``Ros1Stream`` reads the message records of an open uncompressed chunk as they are appended.
"""

from __future__ import annotations

import bz2
import struct
from dataclasses import dataclass, field
from enum import IntEnum

from verify.ingest.mcaprecords import lz4_decompress

__all__ = ["MAGIC", "CutError", "MalformedError", "Op", "Record", "Ros1Message", "Ros1Stream", "connection_of",
           "decompress", "header_fields", "record_at"]

#: the first 13 bytes of every ROS1 bag (format 2.0)
MAGIC = b"#ROSBAG V2.0\n"


class Op(IntEnum):
    """ROS1 bag record opcodes (the ``op`` header field)."""

    MESSAGE_DATA = 0x02
    BAG_HEADER = 0x03
    INDEX_DATA = 0x04
    CHUNK = 0x05
    CHUNK_INFO = 0x06
    CONNECTION = 0x07


class CutError(Exception):
    """The bytes end inside a record (a truncated bag, or one still being written)."""


class MalformedError(Exception):
    """A record's fields contradict its lengths or the format (damaged bytes)."""


@dataclass(frozen=True, slots=True)
class Record:
    op: int
    header: dict[str, bytes]
    data_start: int  # position of the data in the buffer
    data_len: int
    end: int  # position after the record


@dataclass(frozen=True, slots=True)
class Ros1Message:
    conn: int
    log_ns: int
    payload: bytes


def header_fields(raw: bytes | memoryview) -> dict[str, bytes]:
    """A record header -> its ``name=value`` fields."""
    out: dict[str, bytes] = {}
    pos, size = 0, len(raw)
    while pos < size:
        if pos + 4 > size:
            raise MalformedError("a header field is cut")
        (flen,) = struct.unpack_from("<I", raw, pos)
        if pos + 4 + flen > size:
            raise MalformedError("a header field runs past its header")
        name, eq, value = bytes(raw[pos + 4 : pos + 4 + flen]).partition(b"=")
        if not eq:
            raise MalformedError("a header field without '='")
        out[name.decode("ascii", "replace")] = value
        pos += 4 + flen
    return out


def record_at(buf: bytes | memoryview, pos: int, end: int, *, head_only: bool = False) -> Record:
    """The record at ``pos`` (bytes up to ``end``); ``CutError`` when it (or, ``head_only``, its header and data
    length) does not end by ``end``."""
    if pos + 4 > end:
        raise CutError(pos)
    (hlen,) = struct.unpack_from("<I", buf, pos)
    if pos + 8 + hlen > end:
        raise CutError(pos)
    header = header_fields(memoryview(buf)[pos + 4 : pos + 4 + hlen])
    (dlen,) = struct.unpack_from("<I", buf, pos + 4 + hlen)
    data_start = pos + 8 + hlen
    if not head_only and data_start + dlen > end:
        raise CutError(pos)
    op = header.get("op", b"")
    if len(op) != 1:
        raise MalformedError("a record without a one-byte op field")
    return Record(op[0], header, data_start, int(dlen), data_start + int(dlen))


def _u32(header: dict[str, bytes], name: str) -> int:
    value = header.get(name)
    if value is None or len(value) != 4:
        raise MalformedError(f"header field {name!r} is not a u32")
    return int(struct.unpack("<I", value)[0])


def connection_of(header: dict[str, bytes], data: bytes | memoryview) -> tuple[int, str, str, bool]:
    """A connection record -> (id, topic, type as pkg/msg/Name, whether it carries the message definition)."""
    cid = _u32(header, "conn")
    topic = header.get("topic")
    if topic is None:
        raise MalformedError("a connection record without a topic")
    fields = header_fields(data)
    typ = fields.get("type", b"").decode("utf-8", "replace")
    has_def = bool(fields.get("message_definition", b"").strip())
    if typ.count("/") == 1:  # ROS1 names are pkg/Name; rosbags names them pkg/msg/Name
        pkg, name = typ.split("/")
        typ = f"{pkg}/msg/{name}"
    return cid, topic.decode("utf-8", "replace"), typ, has_def


def decompress(data: bytes | memoryview, compression: str) -> bytes:
    if compression == "none":
        return bytes(data)
    if compression == "bz2":
        return bz2.decompress(data)
    if compression == "lz4":
        return lz4_decompress(data)
    raise MalformedError(f"unknown chunk compression {compression!r}")


@dataclass(slots=True)
class _Chunk:
    pos: int  # the chunk record
    compression: str


@dataclass(slots=True)
class Ros1Stream:
    """Reading state over a bag's bytes: ``feed`` the bytes from ``resume_at`` on (all of a file, or what a
    recorder has written so far) and get the messages of the records complete in them, in file order.

    ``pos`` is the next record to read (top level, or inside the chunk being read); ``connections`` maps ids to
    (topic, type, has definition); ``closed`` is set at the bag's index (its header's ``index_pos``)."""

    pos: int = len(MAGIC)
    connections: dict[int, tuple[str, str, bool]] = field(default_factory=dict)
    index_pos: int = 0
    index_records: int = 0  # connection + chunk info records the bag header says its index holds
    closed: bool = False
    chunk: _Chunk | None = None

    @property
    def resume_at(self) -> int:
        """Where the next ``feed`` must start: the open chunk's record (its header is re-read: a recorder rewrites
        its sizes when it closes the chunk), else ``pos``."""
        return self.chunk.pos if self.chunk is not None else self.pos

    def feed(self, buf: bytes | memoryview, base: int, out: list[Ros1Message]) -> None:
        """Append to ``out`` the messages of the records complete in ``buf`` (the file's bytes from ``base`` ==
        ``resume_at``); stops quietly at a record not complete yet (``pos`` stays there); raises ``MalformedError``,
        ``struct.error`` or a decompressor's error on damaged bytes (``out`` then holds the messages before)."""
        end = base + len(buf)
        try:
            while not self.closed:
                if self.chunk is not None:
                    if not self._in_chunk(self.chunk, buf, base, end, out):
                        break
                    continue
                if self.index_pos and self.pos >= self.index_pos:
                    # closed once its whole index is there (an index still being written, or cut, is not a close)
                    self.closed = self._index_complete(buf, base)
                    break
                if self.pos >= end:
                    break
                head = record_at(buf, self.pos - base, len(buf), head_only=True)
                if head.op == Op.CHUNK:
                    self.chunk = _Chunk(self.pos, head.header.get("compression", b"none").decode("ascii", "replace"))
                    continue
                rec = record_at(buf, self.pos - base, len(buf))
                if rec.op == Op.BAG_HEADER:
                    raw = rec.header.get("index_pos", b"")
                    if len(raw) != 8:
                        raise MalformedError("bag header without a u64 index_pos")
                    self.index_pos = int(struct.unpack("<Q", raw)[0])
                    self.index_records = _u32(rec.header, "conn_count") + _u32(rec.header, "chunk_count")
                elif rec.op == Op.CONNECTION:
                    self._connection(rec, buf)
                self.pos = base + rec.end
        except CutError:
            pass

    def _index_complete(self, buf: bytes | memoryview, base: int) -> bool:
        """Whether the index the bag header announces (its connection and chunk info records) is complete in
        ``buf`` (the file's bytes from ``base``)."""
        pos = self.index_pos - base
        if pos < 0:
            return True  # read before: the stream only reaches the index once
        for _ in range(self.index_records):
            rec = record_at(buf, pos, len(buf))  # CutError: not all written yet
            if rec.op not in (Op.CONNECTION, Op.CHUNK_INFO):
                raise MalformedError("the bag's index holds a record that is not a connection or chunk info")
            pos = rec.end
        return True

    def _connection(self, rec: Record, buf: bytes | memoryview) -> None:
        cid, topic, typ, has_def = connection_of(rec.header, memoryview(buf)[rec.data_start : rec.end])
        self.connections[cid] = (topic, typ, has_def)

    def _in_chunk(self, chunk: _Chunk, buf: bytes | memoryview, base: int, end: int, out: list[Ros1Message]
                  ) -> bool:
        """Read on in ``chunk``; True when it is done (``pos`` after it), False to wait for more bytes."""
        head = record_at(buf, chunk.pos - base, len(buf), head_only=True)
        size = head.header.get("size", b"")
        open_chunk = head.data_len == 0 and size in (b"", b"\0\0\0\0")  # rosbag's placeholder while recording
        chunk_end = None if open_chunk else base + head.end
        self.pos = max(self.pos, base + head.data_start)
        if chunk.compression != "none":
            if chunk_end is None or chunk_end > end:
                return False  # a compressed chunk is read when it is complete
            inner = decompress(memoryview(buf)[head.data_start : head.end], chunk.compression)
            self._inner(inner, 0, len(inner), out, strict=True)
            self.pos, self.chunk = chunk_end, None
            return True
        limit = end if chunk_end is None else min(end, chunk_end)
        got, foreign = self._inner(buf, self.pos - base, limit - base, out, strict=False)
        self.pos = base + got
        if chunk_end is not None and self.pos >= chunk_end:
            self.chunk = None
            return True
        if chunk_end is not None and foreign:
            raise MalformedError("a closed chunk holds a record that is not a message or connection")
        return False  # open (or not all here yet): wait for more bytes, re-reading the chunk's header

    def _inner(self, buf: bytes | memoryview, pos: int, limit: int, out: list[Ros1Message], *, strict: bool
               ) -> tuple[int, bool]:
        """Records of a chunk from ``pos`` to ``limit``: connections noted, messages appended to ``out``; returns the
        position after the last complete record and whether reading stopped at a record that is not a chunk's
        (``strict``: every record must be complete and a chunk's)."""
        while pos < limit:
            try:
                rec = record_at(buf, pos, limit)
            except CutError:
                if strict:
                    raise MalformedError("a chunk ends inside a record") from None
                return pos, False
            if rec.op == Op.CONNECTION:
                self._connection(rec, buf)
            elif rec.op == Op.MESSAGE_DATA:
                cid = _u32(rec.header, "conn")
                raw = rec.header.get("time", b"")
                if len(raw) != 8:
                    raise MalformedError("a message record without a u64 time")
                sec, nsec = struct.unpack("<II", raw)
                out.append(Ros1Message(cid, sec * 10**9 + nsec, bytes(memoryview(buf)[rec.data_start : rec.end])))
            else:
                if strict:
                    raise MalformedError("a chunk holds a record that is not a message or connection")
                return pos, True
            pos = rec.end
        return pos, False
