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

import numpy as np
import numpy.typing as npt
from rosbags.typesys.msg import normalize_msgtype

from verify.ingest.records import ROS1, CutError, MalformedError, lz4_decompress, walk_chain

__all__ = [
    "DAMAGE",
    "INDEX_ENTRY",
    "MAGIC",
    "BagState",
    "CutError",
    "MalformedError",
    "Op",
    "Record",
    "Ros1Message",
    "Ros1Stream",
    "bag_state",
    "chunk_info_of",
    "connection_of",
    "decompress",
    "header_fields",
    "index_data",
    "record_at",
    "topic_name",
]

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


#: what reading a complete record raises when its bytes are damaged: malformed fields, or a chunk that does not
#: decompress (bz2: OSError, ValueError, EOFError; lz4: RuntimeError)
DAMAGE: tuple[type[Exception], ...] = (MalformedError, struct.error, ValueError, EOFError, OSError, RuntimeError)


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
    data = bytes(raw)
    out: dict[str, bytes] = {}
    pos, size = 0, len(data)
    while pos < size:
        if pos + 4 > size:
            raise MalformedError("a header field is cut")
        stop = pos + 4 + int.from_bytes(data[pos : pos + 4], "little")
        if stop > size:
            raise MalformedError("a header field runs past its header")
        eq = data.find(b"=", pos + 4, stop)
        if eq < 0:
            raise MalformedError("a header field without '='")
        out[data[pos + 4 : eq].decode("ascii", "replace")] = data[eq + 1 : stop]
        pos = stop
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


def _u64(header: dict[str, bytes], name: str) -> int:
    value = header.get(name)
    if value is None or len(value) != 8:
        raise MalformedError(f"header field {name!r} is not a u64")
    return int(struct.unpack("<Q", value)[0])


#: an index data record's entries: the log time (sec, nsec) and offset in the chunk's records of each message
INDEX_ENTRY = np.dtype([("sec", "<u4"), ("nsec", "<u4"), ("offset", "<u4")])


def index_data(header: dict[str, bytes], data: bytes | memoryview) -> tuple[int, npt.NDArray[np.void]]:
    """An index data record (version 1: one per connection after each chunk) -> (connection id, its entries as
    ``INDEX_ENTRY`` rows); ``MalformedError`` on another version or a length that is not its count's."""
    if _u32(header, "ver") != 1:
        raise MalformedError("an index data record that is not version 1")
    cid, count = _u32(header, "conn"), _u32(header, "count")
    if len(data) != INDEX_ENTRY.itemsize * count:
        raise MalformedError(f"an index data record of connection {cid} holds {len(data)} bytes for {count} entries")
    return cid, np.frombuffer(data, dtype=INDEX_ENTRY)


#: the string fields of a connection record's data, read (and decoded) by every ROS1 reader
_STRING_FIELDS = ("type", "md5sum", "message_definition", "callerid")
#: ... of which every connection record must have these (the message definition may be empty)
_REQUIRED_FIELDS = ("type", "md5sum", "message_definition")


def connection_of(header: dict[str, bytes], data: bytes | memoryview) -> tuple[int, str, str, bool]:
    """A connection record -> (id, topic, type as pkg/msg/Name, whether it carries the message definition)."""
    cid = _u32(header, "conn")
    topic = header.get("topic")
    if topic is None:
        raise MalformedError("a connection record without a topic")
    fields = header_fields(data)
    for name in _REQUIRED_FIELDS:
        if name not in fields:  # rosbags reads each of them and refuses the bag without it
            raise MalformedError(f"a connection record without its {name} field")
    for name, value in (("topic", topic), *((k, fields[k]) for k in _STRING_FIELDS if k in fields)):
        try:  # as rosbags reads them: a field that is not UTF-8 makes the connection (and the bag) unreadable
            value.decode()
        except UnicodeDecodeError:
            raise MalformedError(f"a connection record whose {name} field is not UTF-8 text") from None
    typ = fields.get("type", b"").decode()
    has_def = bool(fields.get("message_definition", b"").strip())
    # ROS1 names are pkg/Name; rosbags names them pkg/msg/Name (its own rule, so every reader names a type alike)
    return cid, topic_name(topic.decode()), normalize_msgtype(typ) if typ else typ, has_def


def chunk_info_of(header: dict[str, bytes], data: bytes | memoryview) -> tuple[int, int, frozenset[int]]:
    """A chunk info record of the bag index, checked as rosbags reads it -> (its chunk's position, how many
    connections it lists, their ids): version 1, a u32 count, the u64 start and end times when it lists any
    connection, and exactly count (connection, message count) u32 pairs; else ``MalformedError`` (rosbags refuses
    the bag's index). The one rule for every reader of the index (the fast reader, and the stream at a bag's
    close)."""
    if _u32(header, "ver") != 1:
        raise MalformedError("a chunk info record of a version other than 1")
    n = _u32(header, "count")
    if n and any(len(header.get(name, b"")) != 8 for name in ("start_time", "end_time")):
        raise MalformedError("a chunk info record without its time fields")
    if len(data) != 8 * n:
        raise MalformedError(f"a chunk info record of {len(data)} bytes for {n} connections")
    return _u64(header, "chunk_pos"), n, frozenset(np.frombuffer(data, dtype="<u4")[0::2].tolist())


def topic_name(name: str) -> str:
    """A connection's topic as rosbags names it: repeated slashes made single, a leading one kept (every reader of
    a ROS1 bag -- indexed, salvage, follower -- names a topic alike)."""
    if not name:
        raise MalformedError("a connection record with an empty topic")
    return f"{'/' * (name[0] == '/')}{'/'.join(x for x in name.split('/') if x)}"


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
    #: per connection, the log times and the offsets in the chunk's records of its message records read so far
    entries: dict[int, tuple[list[int], list[int]]] = field(default_factory=dict)


@dataclass(slots=True)
class _ChunkIndex:
    """A closed chunk whose index data records (one per connection in it, right after the chunk) are being read."""

    pos: int
    entries: dict[int, tuple[list[int], list[int]]]
    indexed: set[int] = field(default_factory=set)

    def check(self, header: dict[str, bytes], data: bytes | memoryview) -> None:
        """An index data record -> ``MalformedError`` unless it lists exactly the chunk's message records of its
        connection (their log times and offsets)."""
        cid, entries = index_data(header, data)
        if cid in self.indexed:
            raise MalformedError(f"the chunk at byte {self.pos} has two index data records for connection {cid}")
        self.indexed.add(cid)
        order = np.argsort(entries["offset"], kind="stable")  # the records were read in offset order
        times = entries["sec"].astype(np.int64)[order] * 10**9 + entries["nsec"].astype(np.int64)[order]
        read_times, read_offsets = self.entries.get(cid, ([], []))
        if not (np.array_equal(entries["offset"][order], np.array(read_offsets, dtype=np.int64))
                and np.array_equal(times, np.array(read_times, dtype=np.int64))):
            raise MalformedError(f"the index data of the chunk at byte {self.pos} disagrees with its message records "
                                 f"of connection {cid}")

    def complete(self) -> None:
        """The chunk's index data records are over: every connection with messages in it must have had one."""
        missing = sorted(set(self.entries) - self.indexed)
        if missing:
            raise MalformedError(f"the chunk at byte {self.pos} has no index data record for connection {missing[0]}")


@dataclass(slots=True)
class Ros1Stream:
    """Reading state over a bag's bytes: ``feed`` the bytes from ``resume_at`` on (all of a file, or what a
    recorder has written so far) and get the messages of the records complete in them, in file order.

    ``pos`` is the next record to read (top level, or inside the chunk being read); ``connections`` maps ids to
    (topic, type, has definition); ``closed`` is set at the bag's index (its header's ``index_pos``) once the index
    is complete: the one rule of "closed by its recorder" for every reader.

    Each closed chunk's index data records (which follow it) must list exactly its message records, connection by
    connection (log time and offset): an index that disagrees with the records it indexes is damage
    (``MalformedError`` at the index record), whoever reads the bag -- the indexed reader reads messages through
    that index, so a bag whose index contradicts its records is never read as whole."""

    pos: int = len(MAGIC)
    connections: dict[int, tuple[str, str, bool]] = field(default_factory=dict)
    index_pos: int = 0
    index_records: int = 0  # connection + chunk info records the bag header says its index holds
    closed: bool = False
    chunk: _Chunk | None = None
    indexing: _ChunkIndex | None = None  # the last closed chunk, while its index data records are read
    chunk_positions: set[int] = field(default_factory=set)  # every chunk record read (the bag index must name them)
    #: connection id -> its rank in the bag index's list of connections (read at the close): the indexed readers'
    #: order among messages of equal log time (``verify.ingest.ros1``)
    index_rank: dict[int, int] = field(default_factory=dict)

    @property
    def resume_at(self) -> int:
        """Where the next ``feed`` must start: the open chunk's record (its header is re-read: a recorder rewrites
        its sizes when it closes the chunk), else ``pos``."""
        return self.chunk.pos if self.chunk is not None else self.pos

    def feed(self, buf: bytes | memoryview, base: int, out: list[Ros1Message] | None) -> None:
        """Append to ``out`` the messages of the records complete in ``buf`` (the file's bytes from ``base`` ==
        ``resume_at``); stops quietly at a record not complete yet (``pos`` stays there); raises one of ``DAMAGE``
        on damaged bytes (``out`` then holds the messages before). ``out`` None: the records are checked, no
        payload is copied."""
        end = base + len(buf)
        try:
            while not self.closed:
                if self.chunk is not None:
                    if not self._in_chunk(self.chunk, buf, base, end, out):
                        break
                    continue
                if self.index_pos and self.pos >= self.index_pos:
                    # closed once its whole index is there (an index still being written, or cut, is not a close)
                    self._chunk_indexed()
                    self.closed = self._index_complete(buf, base)
                    break
                if self.pos >= end:
                    break
                head = record_at(buf, self.pos - base, len(buf), head_only=True)
                if head.op != Op.INDEX_DATA:
                    self._chunk_indexed()
                if head.op == Op.CHUNK:
                    self.chunk = _Chunk(self.pos, head.header.get("compression", b"none").decode("ascii", "replace"))
                    self.chunk_positions.add(self.pos)
                    continue
                rec = record_at(buf, self.pos - base, len(buf))
                if rec.op == Op.BAG_HEADER:
                    self._bag_header(rec)
                elif rec.op == Op.CONNECTION:
                    self._connection(rec, buf)
                elif rec.op == Op.INDEX_DATA:
                    if self.indexing is None:
                        raise MalformedError(f"an index data record at byte {self.pos} follows no chunk")
                    self.indexing.check(rec.header, memoryview(buf)[rec.data_start : rec.end])
                self.pos = base + rec.end
        except CutError:
            pass

    def _bag_header(self, rec: Record) -> None:
        raw = rec.header.get("index_pos", b"")
        if len(raw) != 8:
            raise MalformedError("bag header without a u64 index_pos")
        records = _u32(rec.header, "conn_count") + _u32(rec.header, "chunk_count")
        self.index_pos, self.index_records = int(struct.unpack("<Q", raw)[0]), records

    def reread_header(self, head: bytes | memoryview) -> None:
        """The bag header again (``head``: the file's first bytes): a recorder rewrites its ``index_pos`` when it
        closes the bag. A header not all there, or not a bag header, changes nothing."""
        try:
            rec = record_at(head, len(MAGIC), len(head))
            if rec.op == Op.BAG_HEADER:
                self._bag_header(rec)
        except (CutError, MalformedError, struct.error):
            return

    def check_not_cut(self, fed: int) -> None:
        """``MalformedError`` when the top-level record at ``pos`` (where the last ``feed`` stopped, its bytes not
        all there) cannot be a record still being written: the bag header names its index (the recorder closed the
        bag), the bytes fed (up to file position ``fed``) reach it, and the record at ``pos`` lies before it, so it
        runs past the index (a damaged length). ``feed`` alone cannot tell this from a recorder still writing."""
        if self.closed or self.chunk is not None or not self.index_pos:
            return
        if self.pos < self.index_pos <= fed:
            raise MalformedError(f"the record at byte {self.pos} runs past the bag's index at byte {self.index_pos}")

    def _chunk_indexed(self) -> None:
        if self.indexing is not None:
            self.indexing.complete()
            self.indexing = None

    def _close_chunk(self, chunk: _Chunk, end: int) -> None:
        self.pos, self.chunk = end, None
        self.indexing = _ChunkIndex(chunk.pos, chunk.entries)

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
            if rec.op == Op.CONNECTION:  # read as the indexed readers read it (its text fields UTF-8), and the
                # connection as they name it: theirs is the index's record, not the copy inside a chunk
                cid = self._connection(rec, buf)
                self.index_rank.setdefault(cid, len(self.index_rank))
            else:
                try:
                    at, _n, _ids = chunk_info_of(rec.header, memoryview(buf)[rec.data_start : rec.end])
                except MalformedError:
                    # an index the indexed readers refuse: the bag is not closed as they read a closed bag (salvage
                    # reads its chunks; watch judges it as salvage does, never a pass)
                    return False
                if at not in self.chunk_positions:  # the indexed readers go there
                    raise MalformedError(f"the bag's index names a chunk at byte {at}, where the bag has none")
            pos = rec.end
        return True

    def _connection(self, rec: Record, buf: bytes | memoryview) -> int:
        cid, topic, typ, has_def = connection_of(rec.header, memoryview(buf)[rec.data_start : rec.end])
        self.connections[cid] = (topic, typ, has_def)
        return cid

    def _in_chunk(self, chunk: _Chunk, buf: bytes | memoryview, base: int, end: int,
                  out: list[Ros1Message] | None) -> bool:
        """Read on in ``chunk``; True when it is done (``pos`` after it), False to wait for more bytes."""
        head = record_at(buf, chunk.pos - base, len(buf), head_only=True)
        size = head.header.get("size", b"")
        open_chunk = head.data_len == 0 and size in (b"", b"\0\0\0\0")  # rosbag's placeholder while recording
        chunk_end = None if open_chunk else base + head.end
        self.pos = max(self.pos, base + head.data_start)
        if chunk_end is not None and chunk_end <= end:
            # closed and all here: its records walked whole (a compressed chunk decompressed first)
            if chunk.compression != "none":
                inner = decompress(memoryview(buf)[head.data_start : head.end], chunk.compression)
                self._walk_whole(chunk, inner, 0, len(inner), out, origin=0)
            else:
                self._walk_whole(chunk, buf, self.pos - base, head.end, out, origin=head.data_start)
            self._close_chunk(chunk, chunk_end)
            return True
        if chunk.compression != "none":
            return False  # a compressed chunk is read when it is complete
        limit = end if chunk_end is None else min(end, chunk_end)
        got, foreign = self._walk_open(chunk, buf, self.pos - base, limit - base, out, origin=head.data_start)
        self.pos = base + got
        if chunk_end is not None and foreign:
            raise MalformedError("a closed chunk holds a record that is not a message or connection")
        return False  # open (or not all here yet): wait for more bytes, re-reading the chunk's header

    def _walk_whole(self, chunk: _Chunk, buf: bytes | memoryview, lo: int, hi: int, out: list[Ros1Message] | None,
                    *, origin: int) -> None:
        """The records of a complete chunk from ``lo`` to its end ``hi`` in ``buf`` by the format's walk
        (``verify.ingest.records.walk_chain``): every record must end by the chunk's end and be a message or a
        connection."""
        starts, _ends = walk_chain(memoryview(buf)[lo:hi], ROS1)
        for at in starts.tolist():
            rec = record_at(buf, lo + at, hi)
            if not self._chunk_record(chunk, buf, rec, lo + at - origin, out):
                raise MalformedError("a chunk holds a record that is not a message or connection")

    def _walk_open(self, chunk: _Chunk, buf: bytes | memoryview, pos: int, limit: int, out: list[Ros1Message] | None,
                   *, origin: int) -> tuple[int, bool]:
        """The records of an open (or not yet complete) chunk from ``pos`` to ``limit``, as far as they are
        complete -> the position after the last one, and whether reading stopped at a record that is not a
        chunk's."""
        while pos < limit:
            try:
                rec = record_at(buf, pos, limit)
            except CutError:
                return pos, False
            if not self._chunk_record(chunk, buf, rec, pos - origin, out):
                return pos, True
            pos = rec.end
        return pos, False

    def _chunk_record(self, chunk: _Chunk, buf: bytes | memoryview, rec: Record, offset: int,
                      out: list[Ros1Message] | None) -> bool:
        """A record of ``chunk`` at ``offset`` in its records: a connection noted, a message appended to ``out``
        and to the chunk's entries; False when it is neither."""
        if rec.op == Op.CONNECTION:
            self._connection(rec, buf)
            return True
        if rec.op != Op.MESSAGE_DATA:
            return False
        cid = _u32(rec.header, "conn")
        raw = rec.header.get("time", b"")
        if len(raw) != 8:
            raise MalformedError("a message record without a u64 time")
        sec, nsec = struct.unpack("<II", raw)
        log_ns = sec * 10**9 + nsec
        times, offsets = chunk.entries.setdefault(cid, ([], []))
        times.append(log_ns)
        offsets.append(offset)
        if out is not None:
            out.append(Ros1Message(cid, log_ns, bytes(memoryview(buf)[rec.data_start : rec.end])))
        return True


@dataclass(frozen=True, slots=True)
class BagState:
    """How a bag's bytes stand by the record layer: ``closed`` by its recorder (its header points to a complete
    index, every record before it whole and every chunk's index data agreeing with its records); else ``damage``
    says what is malformed and ``at`` where, or both are None: the bytes end early (cut, or never indexed)."""

    closed: bool
    damage: str | None = None
    at: int | None = None


def bag_state(buf: bytes | memoryview) -> BagState:
    """The ``Ros1Stream`` over a whole bag, payloads not kept -> its ``BagState``."""
    if bytes(buf[: len(MAGIC)]) != MAGIC:
        return BagState(False, "not a ROS1 bag (bad magic)", 0)
    stream = Ros1Stream()
    try:
        stream.feed(buf, 0, None)
    except DAMAGE as err:
        return BagState(False, " ".join(str(err).split()) or err.__class__.__name__, stream.resume_at)
    return BagState(stream.closed)
