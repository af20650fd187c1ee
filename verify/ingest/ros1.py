"""Fast ROS1 bag reader: an indexed ``.bag`` + wanted topics -> their payloads packed into one numpy buffer per topic.

input: a ROS1 bag (format 2.0) and topic names -> output: ``RawTopic`` values whose ``payloads`` is a
``PayloadBuffer`` (packed payload bytes + offsets + lengths), ``available`` topics, or ``None`` when the bag is in any
way unusual (then the caller reads it with ``rosbags``, which also decides truncation and salvage).

Reading follows the format (wiki.ros.org/Bags/Format/2.0): the bag header record gives ``index_pos``; there the
connection records (topic, type, definition) and chunk info records (chunk position, message count per connection)
are read; each chunk record (compression none / bz2 / lz4, uncompressed size) is followed by one index data record
per connection listing ``(time, offset)`` of its messages inside the uncompressed chunk. A bag repeats these heads
from chunk to chunk with other values (a chunk's position, size, times, entries): a chunk info record, chunk head or
run of index data records whose bytes repeat one read in full before, but for those values, is matched by one
compiled pattern (``_Shape``, ``_Layout``) instead of parsed field by field; what the full reading decides of it is
decided by the match (the test draws damaged bytes across both). For the wanted connections
the message data records are located at those offsets and checked with numpy (same header layout, ``op`` = 2, the
right connection id, time equal to the index), and the payloads are copied out with strided views (no per-message
Python object). Messages are ordered as ``rosbags`` yields them (``_ordered``: by time, then connection, chunk
and index entry as rosbags lists them). The file is
opened read-only and read with positioned reads; chunks without a wanted connection are not read. When every
chunk with a wanted connection is uncompressed, the wanted records of all chunks are read in one pass at their file
positions (``verify.ingest.records.read_records``: nothing else of the chunks is read or kept). Otherwise chunks
are read and decompressed whole a few ahead in threads (``verify.ingest.records.in_order``) while this thread
parses the index records and copies the wanted records out of each chunk, which is then dropped (an uncompressed
chunk among them is read record by record). Either way the records are parsed once per topic, and the working set
is a few chunks plus the wanted records, whatever the file's size.
"""

from __future__ import annotations

import itertools
import os
import re
import struct
from collections.abc import Iterable, Iterator, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import overload

import numpy as np
import numpy.typing as npt

from verify.errors import FastPathError as _UnusualError  # the fast path declines: fall back
from verify.ingest.readerrors import one_type_per_topic
from verify.ingest.records import (
    ROS1,
    WORKERS,
    SpanError,
    gather,
    in_order,
    read_records,
    read_scratch,
    retain_freed_memory,
    ros1_records_back_to_back,
)
from verify.ingest.ros1records import (
    INDEX_ENTRY,
    MAGIC,
    CutError,
    MalformedError,
    Op,
    chunk_info_of,
    connection_of,
    decompress,
    header_fields,
    index_data,
    record_at,
)

__all__ = ["PayloadBuffer", "Ros1Index", "read_ros1_fast"]

U8Array = npt.NDArray[np.uint8]
IntArray = npt.NDArray[np.int64]

_MAGIC = MAGIC
#: the wanted records of some chunks: (bytes of the records back to back, each record's position in them, its
#: connection id, its log time, its place in rosbags' order among equal log times: the chunk's rank in the index's
#: list of chunks times 2**32 plus the record's rank in its connection's index data record of that chunk)
Records = tuple[U8Array, IntArray, IntArray, IntArray, IntArray]
_OP_MSG, _OP_BAG, _OP_INDEX = int(Op.MESSAGE_DATA), int(Op.BAG_HEADER), int(Op.INDEX_DATA)
_OP_CHUNK, _OP_CHUNK_INFO, _OP_CONN = int(Op.CHUNK), int(Op.CHUNK_INFO), int(Op.CONNECTION)
_BATCH = 4  # chunks a thread reads, decompresses and copies from per task
_PARSE_BLOCK = 8192  # records parsed together: index temporaries of at most a few MB
_ENTRY_FORMAT = "<3I"  # an index entry (``INDEX_ENTRY``): time sec, time nsec, offset in the chunk


class PayloadBuffer(Sequence[bytes]):
    """Payloads of one topic packed in one byte buffer: payload i is ``data[offsets[i] : offsets[i] + lengths[i]]``
    (offsets are the running sum of the lengths). Indexing yields ``bytes`` like a list of payloads."""

    __slots__ = ("data", "lengths", "offsets")

    def __init__(self, data: U8Array, offsets: IntArray, lengths: IntArray) -> None:
        if offsets.shape != lengths.shape:
            raise ValueError("offsets and lengths must have the same shape")
        self.data = data
        self.offsets = offsets
        self.lengths = lengths

    def __len__(self) -> int:
        return int(self.offsets.shape[0])

    @overload
    def __getitem__(self, i: int) -> bytes: ...

    @overload
    def __getitem__(self, i: slice) -> list[bytes]: ...

    def __getitem__(self, i: int | slice) -> bytes | list[bytes]:
        if isinstance(i, slice):
            return [self[k] for k in range(*i.indices(len(self)))]
        o = int(self.offsets[i])
        return self.data[o : o + int(self.lengths[i])].tobytes()


@dataclass(frozen=True, slots=True)
class _Conn:
    cid: int
    topic: str
    msgtype: str
    has_definition: bool


@dataclass(frozen=True, slots=True)
class Ros1Index:
    """What the fast reader found: per wanted topic its type, definition flag, log times and payloads."""

    topics: dict[str, tuple[str, bool, IntArray, PayloadBuffer]]
    available: dict[str, str]


def _fields(raw: bytes | memoryview) -> dict[str, bytes]:
    """A record header's fields (the record layer's ``header_fields``); a malformed header is unusual here."""
    try:
        return header_fields(raw)
    except MalformedError as err:
        raise _UnusualError(str(err)) from None


class _File:
    """Positioned reads (``os.pread``) of a file opened read-only; a short read means the file is cut."""

    #: small reads are served from one block read ahead (record headers and index records come in runs)
    BLOCK_B = 8192

    def __init__(self, fd: int) -> None:
        self.fd = fd
        self.size = os.fstat(fd).st_size
        self._block = b""
        self._block_pos = 0

    def fork(self) -> _File:
        """Another reader of the same file with its own read-ahead block (one per thread)."""
        other = object.__new__(_File)
        other.fd, other.size, other._block, other._block_pos = self.fd, self.size, b"", 0
        return other

    def read(self, pos: int, n: int) -> bytes:
        """The ``n`` bytes at ``pos``: from the read-ahead block (``block``), or read apart when they are a block or
        more and not in it (the block is kept)."""
        rel = pos - self._block_pos
        if n >= self.BLOCK_B and not (rel >= 0 and rel + n <= len(self._block)):
            if pos < 0 or pos + n > self.size:
                raise _UnusualError("read past the end of the file")
            data = os.pread(self.fd, n, pos)
            if len(data) != n:
                raise _UnusualError("short read")
            return data
        buf, base = self.block(pos, n)
        return buf[pos - base : pos - base + n]

    def block(self, pos: int, n: int) -> tuple[bytes, int]:
        """(bytes, where they start in the file) holding the ``n`` bytes at ``pos``: the read-ahead block when it
        does, else a new one read from ``pos`` (at least ``n`` bytes)."""
        rel = pos - self._block_pos
        if rel < 0 or rel + n > len(self._block):
            if pos < 0 or n < 0 or pos + n > self.size:
                raise _UnusualError("read past the end of the file")
            self._block = os.pread(self.fd, min(max(n, self.BLOCK_B), self.size - pos), pos)
            self._block_pos = pos
            if len(self._block) < n:
                raise _UnusualError("short read")
        return self._block, self._block_pos

    def record(self, pos: int) -> tuple[dict[str, bytes], int, int, int]:
        """Record at ``pos`` -> (header fields, data start, data length, next position); data not read. The record
        layer's layout (``verify.ingest.ros1records.record_at``) over the header read from the file."""
        (hlen,) = struct.unpack("<I", self.read(pos, 4))
        head = self.read(pos, hlen + 8)
        try:
            rec = record_at(head, 0, len(head), head_only=True)
        except (CutError, MalformedError) as err:
            raise _UnusualError(f"record at byte {pos}: {err}") from None
        start = pos + rec.data_start
        if start + rec.data_len > self.size:
            raise _UnusualError("cut record")
        return rec.header, start, rec.data_len, start + rec.data_len


def _u32(value: bytes, name: str) -> int:
    if len(value) != 4:
        raise _UnusualError(f"field {name} is not uint32")
    return int(struct.unpack("<I", value)[0])


def _u64(value: bytes, name: str) -> int:
    if len(value) != 8:
        raise _UnusualError(f"field {name} is not uint64")
    return int(struct.unpack("<Q", value)[0])


def _op(header: dict[str, bytes], want: int) -> None:
    op = header.get("op", b"")
    if len(op) != 1 or op[0] != want:
        raise _UnusualError(f"expected op {want:#x}")


def _connections(f: _File, pos: int, count: int) -> tuple[list[_Conn], int]:
    conns: list[_Conn] = []
    for _ in range(count):
        header, start, dlen, pos = f.record(pos)
        _op(header, _OP_CONN)
        try:  # the record layer's rule (its fields there, as text): else rosbags decides
            cid, topic, typ, has_def = connection_of(header, f.read(start, dlen))
        except MalformedError as err:
            raise _UnusualError(str(err)) from None
        if not typ:
            raise _UnusualError("connection with an empty type")  # rosbags decides
        conns.append(_Conn(cid, topic, typ, has_def))
    return conns, pos


def _chunk_infos(f: _File, pos: int, count: int) -> Iterator[tuple[int, int, frozenset[int]]]:
    """(chunk position, number of connections in it, their ids) per chunk, in the index's order (read as they are
    needed: chunks are read while the rest of the index is parsed). A record whose bytes repeat one of the last
    ones read in full but for its chunk position, times and connection list (``_Shape``) is matched, not parsed
    again."""
    shapes: list[_Shape] = []  # newest first: chunks hold different sets of connections
    for _ in range(count):
        m = None
        for shape in shapes:
            if pos + shape.size <= f.size:
                buf, base = f.block(pos, shape.size)
                if (m := shape.pattern.match(buf, pos - base)) is not None:
                    break
        if m is not None:
            chunk_pos, data = m.group(1, 4)
            yield int.from_bytes(chunk_pos, "little"), shape.count, _connection_ids(data)
            pos += shape.size
            continue
        at = pos
        header, start, dlen, pos = f.record(pos)
        _op(header, _OP_CHUNK_INFO)
        try:  # the record layer's rule (rosbags refuses an index it breaks; then rosbags decides)
            info = chunk_info_of(header, f.read(start, dlen))
        except MalformedError as err:
            raise _UnusualError(str(err)) from None
        yield info
        if info[1] and (learnt := _Shape.learn(f.read(at, start - at), _CHUNK_INFO_OPEN, dlen)) is not None:
            learnt.count = info[1]
            shapes = [learnt, *shapes[:7]]


#: a chunk info record's fields that differ from chunk to chunk (with their sizes)
_CHUNK_INFO_OPEN = {"chunk_pos": 8, "start_time": 8, "end_time": 8}


def _connection_ids(data: bytes) -> frozenset[int]:
    """A chunk info record's connection ids (its data: (connection, message count) u32 pairs)."""
    return frozenset(struct.unpack(f"<{len(data) // 4}I", data)[0::2])


class _Shape:
    """A record's head (header length, header, data length) whose bytes a later record repeats but for the values
    of some header fields (``open``, each of a fixed size): such a record parses as the one it was learned from
    with those values, so it is matched (one compiled pattern, no field parsing) instead of parsed. Groups: the open
    values in header order, then the data length (``dlen`` None: open) or the data (``dlen`` given: that many bytes).
    A header that names a field twice has no shape (its parse keeps the last)."""

    __slots__ = ("count", "pattern", "size")

    def __init__(self, pattern: re.Pattern[bytes], size: int) -> None:
        self.pattern, self.size, self.count = pattern, size, 0

    @staticmethod
    def learn(head: bytes, open_fields: dict[str, int], dlen: int | None) -> _Shape | None:
        """``head``: a record's bytes up to its data, read in full and accepted."""
        hlen = int.from_bytes(head[:4], "little")
        if len(head) != hlen + 8:
            return None
        parts, names, pos = [re.escape(head[:4])], set(), 4
        while pos < 4 + hlen:
            stop = pos + 4 + int.from_bytes(head[pos : pos + 4], "little")
            eq = head.find(b"=", pos + 4, stop)
            name = head[pos + 4 : eq]
            if eq < 0 or name in names:
                return None
            names.add(name)
            size = open_fields.get(name.decode("ascii", "replace"))
            if size is None:
                parts.append(re.escape(head[pos:stop]))
            elif stop - eq - 1 == size:
                parts.append(re.escape(head[pos : eq + 1]) + b"(.{%d})" % size)
            else:
                return None
            pos = stop
        if dlen is None:
            parts.append(b"(.{4})")
            return _Shape(re.compile(b"".join(parts), re.DOTALL), hlen + 8)
        parts.append(re.escape(head[-4:]) + b"(.{%d})" % dlen)
        return _Shape(re.compile(b"".join(parts), re.DOTALL), hlen + 8 + dlen)


def _chunk_head(f: _File, pos: int) -> tuple[str, int, int, int, int]:
    """The chunk record at ``pos``: (compression, uncompressed size, data start, data length, next position). A
    chunk record whose head repeats one read in full before but for its size and data length (``_Shape``) is
    matched, not parsed again."""
    for shape, compression in _CHUNK_HEADS:
        if pos + shape.size <= f.size:
            buf, base = f.block(pos, shape.size)
            m = shape.pattern.match(buf, pos - base)
            if m is not None:
                size, dlen = m.group(1, 2)
                start = pos + shape.size
                n = int.from_bytes(dlen, "little")
                if start + n > f.size:
                    raise _UnusualError("cut record")
                return compression, int.from_bytes(size, "little"), start, n, start + n
    header, start, dlen, nxt = f.record(pos)
    _op(header, _OP_CHUNK)
    compression = header.get("compression", b"").decode()
    size = _u32(header.get("size", b""), "size")
    if compression not in ("none", "bz2", "lz4"):
        raise _UnusualError(f"compression {compression!r}")
    learnt = _Shape.learn(f.read(pos, start - pos), {"size": 4}, None)
    if learnt is not None:
        if len(_CHUNK_HEADS) >= 8:
            _CHUNK_HEADS.pop()
        _CHUNK_HEADS.insert(0, (learnt, compression))
    return compression, size, start, dlen, nxt


#: chunk record heads read in full (newest first), with their compression: most bags repeat one
_CHUNK_HEADS: list[tuple[_Shape, str]] = []


def _chunk_body(f: _File, compression: str, size: int, start: int, dlen: int) -> bytes:
    """Uncompressed content of a chunk (read and decompressed whole)."""
    if start + dlen > f.size:
        raise _UnusualError("read past the end of the file")
    if compression == "none":
        inner = f.read(start, dlen)
    else:
        retain_freed_memory()
        try:
            raw = read_scratch(f.fd, start, dlen)
            inner = decompress(raw, compression)
        except (OSError, ValueError, RuntimeError, EOFError, SpanError, MalformedError) as err:
            raise _UnusualError(f"chunk does not decompress ({err})") from err
    if len(inner) != size:
        raise _UnusualError("chunk size differs from its header")
    return bytes(inner)


def _entries(plan_item: dict[int, bytes], start: int = 0) -> tuple[IntArray, IntArray, IntArray, IntArray]:
    """A chunk's wanted index entries by offset: (offset + ``start``, connection id, log time, rank in its
    connection's index data record)."""
    rows = {c: np.frombuffer(x, dtype=INDEX_ENTRY) for c, x in plan_item.items()}
    offs = np.concatenate([x["offset"].astype(np.int64) for x in rows.values()]) + start
    cid = np.concatenate([np.full(x.shape[0], c, dtype=np.int64) for c, x in rows.items()])
    times = np.concatenate([_index_times(x) for x in rows.values()])
    rank = np.concatenate([np.arange(x.shape[0], dtype=np.int64) for x in rows.values()])
    order = np.argsort(offs, kind="stable")
    offs, cid, times, rank = offs[order], cid[order], times[order], rank[order]
    if offs.shape[0] > 1 and np.any(np.diff(offs) == 0):
        raise _UnusualError("two index entries for one record")
    return offs, cid, times, rank


def _fetch(f: _File, head: tuple[str, int, int, int], mine: dict[int, bytes], total: int
           ) -> Records | bytes:
    """A chunk's wanted records read one by one (an uncompressed chunk whose records are not all wanted), else the
    whole chunk read and decompressed (bytes; the caller copies the records out)."""
    compression, size, start, dlen = head
    if compression == "none" and dlen == size and sum(len(x) for x in mine.values()) // INDEX_ENTRY.itemsize < total:
        offs, cid, times, rank = _entries(mine)
        try:
            u8, pos = read_records(f.fd, start, size, offs, ROS1)
        except SpanError:
            pass
        else:
            return u8, pos, cid, times, rank
    return _chunk_body(f, compression, size, start, dlen)


def _copy_records(chunk: bytes, mine: dict[int, bytes]) -> _Copied:
    """The wanted records copied out of a whole chunk, by offset: plain Python (a chunk holds a few dozen wanted
    records; numpy's per-call cost would exceed the work; ``_joined`` makes the arrays once for all chunks). Each
    record must end before the next wanted one (or the chunk) ends
    (``verify.ingest.records.ros1_records_back_to_back``)."""
    entries = sorted((o, sec * 1_000_000_000 + nsec, cid, k) for cid, index in mine.items()
                     for k, (sec, nsec, o) in enumerate(struct.iter_unpack(_ENTRY_FORMAT, index)))
    if not entries:
        return b"", [], (), (), ()
    offs, times, cids, ranks = zip(*entries, strict=True)
    try:
        sizes = ros1_records_back_to_back(chunk, list(offs))
    except SpanError:
        raise _UnusualError("index offset outside its chunk or records overlap") from None
    return b"".join([chunk[o : o + n] for o, n in zip(offs, sizes, strict=True)]), sizes, cids, times, ranks


#: a chunk's wanted records as ``_copy_records`` copies them: the records back to back, their sizes, connection
#: ids, log times and ranks in their connection's index data record of the chunk
_Copied = tuple[bytes, Sequence[int], Sequence[int], Sequence[int], Sequence[int]]


def _as_copied(records: Records) -> _Copied:
    """Records read one by one (an uncompressed chunk among compressed ones) in ``_copy_records``' form."""
    u8, pos, cid, times, rank = records
    return u8.tobytes(), np.diff(pos, append=u8.shape[0]).tolist(), cid.tolist(), times.tolist(), rank.tolist()


def _joined(pieces: list[_Copied]) -> Records:
    """The chunks' copied records as one buffer, with each record's position, in the index's order of chunks (each
    record's order key gains its chunk's rank): one array per field for all chunks."""
    if not pieces:
        empty = np.zeros(0, dtype=np.int64)
        return np.zeros(0, dtype=np.uint8), empty, empty, empty, empty

    def column(k: int) -> IntArray:
        return np.fromiter(itertools.chain.from_iterable(piece[k] for piece in pieces), dtype=np.int64)

    sizes = column(1)
    pos = np.zeros(sizes.shape[0], dtype=np.int64)
    if sizes.shape[0] > 1:
        np.cumsum(sizes[:-1], out=pos[1:])
    chunk_rank = np.repeat(np.arange(len(pieces), dtype=np.int64) << 32, [len(piece[1]) for piece in pieces])
    data = np.frombuffer(b"".join([piece[0] for piece in pieces]), dtype=np.uint8)
    return data, pos, column(2), column(3), column(4) + chunk_rank


@dataclass(slots=True)
class _Parts:
    """Per topic, the pieces gathered chunk by chunk."""

    times: list[IntArray]
    blocks: list[U8Array]  # packed payloads of a chunk
    lengths: list[IntArray]
    keys: list[IntArray]  # Records' order keys
    conns: list[IntArray]  # the connection's rank in the index's list of connections


def _index_times(index: npt.NDArray[np.void]) -> IntArray:
    return index["sec"].astype(np.int64) * 1_000_000_000 + index["nsec"].astype(np.int64)


def _messages_in_chunk(chunk: U8Array, cid: int | IntArray, offs: IntArray, times: IntArray
                       ) -> tuple[IntArray, U8Array, IntArray]:
    """Log times, packed payloads and payload lengths of the message records at ``offs`` (sorted) in ``chunk``
    (a chunk, or the compact buffer of wanted records), each of connection ``cid`` (one id, or one per record) at
    log time ``times``. The records' headers are viewed as rows of a byte matrix and checked at once when they have
    one layout (the first record's: only the conn, time and data length values differ); else parsed one by one."""
    k = offs.shape[0]
    size = chunk.shape[0]
    if k == 0:
        return times, np.zeros(0, dtype=np.uint8), np.zeros(0, dtype=np.int64)
    o0 = int(offs[0])
    if o0 + 8 > size:
        raise _UnusualError("index offset outside its chunk")
    (h,) = struct.unpack("<I", chunk[o0 : o0 + 4].tobytes())
    if o0 + 8 + h > size:
        raise _UnusualError("index offset outside its chunk")
    raw0 = chunk[o0 + 4 : o0 + 4 + h].tobytes()
    first = _fields(raw0)
    if first.get("op") != bytes([_OP_MSG]) or set(first) != {"op", "conn", "time"}:
        raise _UnusualError("indexed record is not plain message data")
    if int(offs[-1]) + 8 + h > size:
        return _messages_varied(chunk, cid, offs, times)
    heads = chunk[offs[:, None] + np.arange(8 + h)]
    # every record: the first one's header bytes except the conn and time values, then its own data length
    conn_at = 4 + raw0.index(b"conn=") + 5
    time_at = 4 + raw0.index(b"time=") + 5
    fixed = np.ones(4 + h, dtype=bool)
    fixed[conn_at : conn_at + 4] = False
    fixed[time_at : time_at + 8] = False
    if not bool((heads[:, : 4 + h] == heads[0, : 4 + h])[:, fixed].all()):
        return _messages_varied(chunk, cid, offs, times)
    conn = np.ascontiguousarray(heads[:, conn_at : conn_at + 4]).view("<u4").ravel()
    stamp = np.ascontiguousarray(heads[:, time_at : time_at + 8]).view("<u4").reshape(k, 2).astype(np.int64)
    if np.any(conn != cid) or not np.array_equal(stamp[:, 0] * 1_000_000_000 + stamp[:, 1], times):
        raise _UnusualError("index and message records disagree")
    lengths = np.ascontiguousarray(heads[:, 4 + h :]).view("<u4").ravel().astype(np.int64)
    starts = offs + (8 + h)
    if int((starts + lengths).max()) > size:
        raise _UnusualError("message data outside its chunk")
    # a copy, never a view: a view (e.g. of a single record) would keep the whole decompressed chunk alive
    return times, gather(chunk, starts, lengths), lengths


def _messages_varied(chunk: U8Array, cid: int | IntArray, offs: IntArray, times: IntArray
                     ) -> tuple[IntArray, U8Array, IntArray]:
    """Records of different lengths (e.g. frame ids of different lengths): parsed one by one (through a memoryview:
    no copy of the chunk)."""
    buf = chunk.data
    cids = np.broadcast_to(np.asarray(cid, dtype=np.int64), offs.shape).tolist()
    pieces: list[memoryview] = []
    lengths = np.empty(offs.shape[0], dtype=np.int64)
    for i, o in enumerate(offs.tolist()):
        (hlen,) = struct.unpack_from("<I", buf, o)
        header = _fields(buf[o + 4 : o + 4 + hlen])
        (dlen,) = struct.unpack_from("<I", buf, o + 4 + hlen)
        start = o + 8 + hlen
        if start + dlen > len(buf):
            raise _UnusualError("message data outside its chunk")
        _op(header, _OP_MSG)
        sec, nsec = struct.unpack("<II", header["time"])
        if _u32(header["conn"], "conn") != cids[i] or sec * 1_000_000_000 + nsec != int(times[i]):
            raise _UnusualError("index and message records disagree")
        pieces.append(buf[start : start + dlen])
        lengths[i] = dlen
    return times, np.frombuffer(b"".join(pieces), dtype=np.uint8), lengths


def _wanted_index(f: _File, after: int, n_conns: int, ids: frozenset[int], selected: dict[int, _Conn]
                  ) -> tuple[dict[int, bytes], int]:
    """A chunk's index data records (right after the chunk record; the record layer's ``index_data``) -> the wanted
    connections' entries and the number of records in the chunk; the connections must be those its chunk info
    names, each once. Index records whose heads repeat, in order, those of an earlier chunk with these connections
    (``_Layout``: their header bytes and data lengths) are matched in one call; else each record is read: a header
    seen before (the same bytes) is not parsed again (what its fields decide -- op, version, connection, count -- is
    known); the data length, the record's end and the entries' size are checked for every record, as
    ``index_data`` does (read from the read-ahead block: a chunk's index records are a few hundred bytes)."""
    for layout in _INDEX_LAYOUTS.get(ids, ()):
        if after + layout.size <= f.size:
            buf, base = f.block(after, layout.size)
            m = layout.pattern.match(buf, after - base)
            if m is not None:
                return {cid: m.group(g) for g, cid in layout.groups if cid in selected}, layout.total
    mine: dict[int, bytes] = {}
    seen: set[int] = set()
    heads: list[tuple[bytes, int, int]] = []  # each record's head bytes, connection id and data length
    total, pos = 0, after
    for _ in range(n_conns):
        buf, base = f.block(pos, 4)
        (hlen,) = struct.unpack_from("<I", buf, pos - base)
        buf, base = f.block(pos, hlen + 8)
        rel = pos - base
        head = buf[rel : rel + hlen + 8]
        known = _INDEX_HEADS.get(head[4 : 4 + hlen])
        if known is None:
            cid, entries, pos = _index_record(f, pos)
            n = len(entries) // INDEX_ENTRY.itemsize
        else:
            cid, n = known
            (dlen,) = struct.unpack_from("<I", buf, rel + 4 + hlen)
            start = pos + 8 + hlen
            if start + dlen > f.size:
                raise _UnusualError("cut record")
            if dlen != INDEX_ENTRY.itemsize * n:
                raise _UnusualError(f"an index data record of connection {cid} holds {dlen} bytes for {n} entries")
            if cid in selected:
                buf, base = f.block(start, dlen)
                entries = buf[start - base : start - base + dlen]
            pos = start + dlen
        if cid in seen:
            raise _UnusualError("two index records for one connection in a chunk")
        seen.add(cid)
        heads.append((head, cid, n * INDEX_ENTRY.itemsize))
        total += n
        if cid in selected:
            mine[cid] = entries
    if seen != ids:
        raise _UnusualError("chunk info and index records disagree")
    _Layout.learn(ids, heads)
    return mine, total


class _Layout:
    """A chunk's index data records as an earlier chunk with the same connections had them, read record by record
    and accepted: their heads (header length, header, data length) in order, each followed by its entries. A
    chunk whose index region repeats those heads in that order (one compiled pattern, its entries as groups) holds
    the same records with other entries: what the record-by-record reading decides of it is decided (each header
    known, each data length its count's, each connection once, the chunk info's connections)."""

    __slots__ = ("groups", "pattern", "size", "total")

    def __init__(self, heads: list[tuple[bytes, int, int]]) -> None:
        self.pattern = re.compile(b"".join(re.escape(h) + b"(.{%d})" % n for h, _c, n in heads), re.DOTALL)
        self.groups = [(g, cid) for g, (_h, cid, _n) in enumerate(heads, start=1)]
        self.size = sum(len(h) + n for h, _c, n in heads)
        self.total = sum(n for _h, _c, n in heads) // INDEX_ENTRY.itemsize  # the chunk's records

    @staticmethod
    def learn(ids: frozenset[int], heads: list[tuple[bytes, int, int]]) -> None:
        """Remember the layout of a chunk's index records read record by record among the next to be tried for
        these connections. A layout is compiled once a second chunk repeats it (a pattern costs ~200 us, ten
        chunks' reading: a bag whose message counts never repeat from chunk to chunk compiles none), and kept
        compiled (a layout tried again later is not compiled again)."""
        key = tuple(heads)
        layout = _LAYOUTS_COMPILED.get(key)
        if layout is None:
            if _LAYOUTS_SEEN.pop(key, None) is None:
                if len(_LAYOUTS_SEEN) >= _INDEX_HEADS_MAX:
                    _LAYOUTS_SEEN.clear()
                _LAYOUTS_SEEN[key] = True
                return
            if len(_LAYOUTS_COMPILED) >= _LAYOUTS_COMPILED_MAX:
                _LAYOUTS_COMPILED.clear()
            layout = _LAYOUTS_COMPILED[key] = _Layout(heads)
        if len(_INDEX_LAYOUTS) > _INDEX_HEADS_MAX:
            _INDEX_LAYOUTS.clear()
        tried = _INDEX_LAYOUTS.setdefault(ids, [])
        if len(tried) >= _LAYOUTS_PER_CONNECTIONS:
            tried.pop()
        tried.insert(0, layout)


#: per set of connections (a chunk info's), the index data record layouts to try (newest first): message counts
#: per chunk vary a little, so a bag repeats a few
_INDEX_LAYOUTS: dict[frozenset[int], list[_Layout]] = {}
_LAYOUTS_PER_CONNECTIONS = 8
#: layouts read record by record once, not yet compiled; and those compiled
_LAYOUTS_SEEN: dict[tuple[tuple[bytes, int, int], ...], bool] = {}
_LAYOUTS_COMPILED: dict[tuple[tuple[bytes, int, int], ...], _Layout] = {}
_LAYOUTS_COMPILED_MAX = 256  # a compiled pattern holds a few kB


#: index data record header bytes -> (connection id, entry count), for headers that passed ``_index_record``'s
#: checks: a bag repeats a handful of them (one per connection and per-chunk message count) in every chunk
_INDEX_HEADS: dict[bytes, tuple[int, int]] = {}
_INDEX_HEADS_MAX = 4096


def _index_record(f: _File, pos: int) -> tuple[int, bytes, int]:
    """The index data record at ``pos``, its header parsed (the record layer's ``index_data``) -> (connection id,
    its entries' bytes, next position); its header bytes are then known (``_INDEX_HEADS``)."""
    header, start, dlen, nxt = f.record(pos)
    _op(header, _OP_INDEX)
    try:
        cid, entries = index_data(header, f.read(start, dlen))
    except MalformedError as err:
        raise _UnusualError(str(err)) from None
    (hlen,) = struct.unpack("<I", f.read(pos, 4))
    if len(_INDEX_HEADS) >= _INDEX_HEADS_MAX:
        _INDEX_HEADS.clear()
    _INDEX_HEADS[f.read(pos + 4, hlen)] = (cid, entries.shape[0])
    return cid, entries.tobytes(), nxt


@dataclass(frozen=True, slots=True)
class _Plan:
    """A chunk that holds wanted connections: its position, (compression, uncompressed size, data start, data
    length), the wanted connections' index entries and the number of records in it."""

    pos: int
    head: tuple[str, int, int, int]
    mine: dict[int, bytes]  # per wanted connection, its index entries (``INDEX_ENTRY`` rows)
    total: int


def _planned(f: _File, infos: Iterable[tuple[int, int, frozenset[int]]], selected: dict[int, _Conn]
             ) -> Iterator[_Plan]:
    """Every chunk's header and index records read (as rosbags' open() does); the chunks with wanted connections
    yielded, in the index's order."""
    for chunk_pos, n_conns, ids in infos:
        compression, size, start, dlen, after = _chunk_head(f, chunk_pos)
        mine, total = _wanted_index(f, after, n_conns, ids, selected)
        if mine:
            yield _Plan(chunk_pos, (compression, size, start, dlen), mine, total)


def read_ros1_fast(path: Path, topics: Iterable[str]) -> Ros1Index | None:
    """Read the wanted topics of an indexed, unencrypted ROS1 bag; None when anything is unusual."""
    try:
        return _read(path, set(topics))
    except (_UnusualError, KeyError, IndexError, UnicodeDecodeError, struct.error, ValueError, OSError, EOFError):
        return None


def _read(path: Path, wanted: set[str]) -> Ros1Index | None:
    with path.open("rb") as fh:
        return _read_file(_File(fh.fileno()), wanted)


def _read_file(f: _File, wanted: set[str]) -> Ros1Index | None:
    if f.size < len(_MAGIC) + 8 or f.read(0, len(_MAGIC)) != _MAGIC:
        return None
    header, _start, _dlen, _nxt = f.record(len(_MAGIC))
    _op(header, _OP_BAG)
    if header.get("encryptor"):
        return None
    index_pos = _u64(header["index_pos"], "index_pos")
    conn_count = _u32(header["conn_count"], "conn_count")
    chunk_count = _u32(header["chunk_count"], "chunk_count")
    if index_pos == 0 or chunk_count == 0 or index_pos >= f.size:
        return None
    conns, pos = _connections(f, index_pos, conn_count)
    if len({c.cid for c in conns}) != len(conns):
        return None
    available = {c.topic: c.msgtype for c in conns}
    selected = {c.cid: c for c in conns if c.topic in wanted}
    one_type_per_topic((c.topic, c.msgtype) for c in selected.values())
    parts: dict[str, _Parts] = {}
    for c in selected.values():
        parts.setdefault(c.topic, _Parts([], [], [], [], []))
    # like rosbags' open(), every chunk info, chunk header and index record is read; data only where it is wanted.
    # The index is read as the chunks are: the first chunks are being decompressed while the rest is parsed (read
    # whole first, ~8 ms on 1 GB of lz4 went by before the first decompression)
    planned = _planned(f, _chunk_infos(f.fork(), pos, chunk_count), selected)  # the index with its own read-ahead
    first: list[_Plan] = []
    for item in planned:
        first.append(item)
        compression, size, _start, dlen = item.head
        if compression != "none" or size != dlen:
            _parse_chunked(f, itertools.chain(first, planned), selected, parts)
            break
    else:  # every chunk with a wanted connection is stored uncompressed: its wanted records in one pass
        _parse_records(_records_uncompressed(f, first) if first else _joined([]), selected, parts)
    out: dict[str, tuple[str, bool, IntArray, PayloadBuffer]] = {}
    for topic, p in parts.items():
        tconns = [c for c in selected.values() if c.topic == topic]
        out[topic] = (tconns[0].msgtype, all(c.has_definition for c in tconns), *_ordered(p))
    return Ros1Index(out, available)


def _parse_chunked(f: _File, planned: Iterable[_Plan], selected: dict[int, _Conn], parts: dict[str, _Parts]) -> None:
    """The wanted records of chunks read whole (compressed ones) -> parsed into ``parts``. Chunk by chunk: here the
    index records are parsed (Python work), while threads read and decompress the next chunks (I/O and
    decompression release the GIL) and copy their wanted records out, so a decompressed chunk is freed in the thread
    that made it and its memory reused there (a first call faulted in ~10 MB more when the chunks were copied here:
    8,574 -> 6,180 page faults on 1 GB of lz4, first call 187 -> 176 ms). A thread takes ``_BATCH`` chunks at a time
    (the hand-over costs ~15 us of Python per task). The records are parsed once all are in: parsed here every 64
    chunks while the next were decompressed, a call took ~7 ms more (the parse competes with the decompressing
    threads for the two cores, and no chunk is handed over while it runs)."""
    def fetched(batch: list[_Plan]) -> list[_Copied]:
        g = f.fork()
        return [_wanted_records(g, item) for item in batch]

    def batches(items: Iterable[_Plan]) -> Iterator[list[_Plan]]:
        it = iter(items)
        while batch := list(itertools.islice(it, _BATCH)):
            yield batch

    pieces = [piece for got in in_order(fetched, batches(planned), workers=WORKERS) for piece in got]
    _parse_records(_joined(pieces), selected, parts)


def _wanted_records(f: _File, item: _Plan) -> _Copied:
    """A chunk's wanted records (``_fetch``, then ``_copy_records`` for a chunk read whole): the decompressed chunk
    is freed on return, before the thread decompresses its next (held one chunk longer, a first call faulted in ~16
    MB more)."""
    piece = _fetch(f, item.head, item.mine, item.total)
    return _as_copied(piece) if isinstance(piece, tuple) else _copy_records(piece, item.mine)


def _records_uncompressed(f: _File, plan: list[_Plan]) -> Records:
    """Every wanted record of uncompressed chunks in one pass: the index entries of all chunks as file positions
    (one concatenation and sort for the file), the records read at them (``verify.ingest.records``: one ``pread``
    per cluster of nearby records, each record bounded by the end of its chunk) -> as ``_copy_records``, for the
    whole file (in file order; each record's order key as ``_joined`` makes it)."""
    items = [(item.head[2], item.head[2] + item.head[1], cid, np.frombuffer(index, dtype=INDEX_ENTRY), rank)
             for rank, item in enumerate(plan) for cid, index in item.mine.items()]
    counts = np.array([len(x[3]) for x in items], dtype=np.int64)
    index = np.concatenate([x[3] for x in items])
    at = index["offset"].astype(np.int64) + np.repeat(np.array([x[0] for x in items], dtype=np.int64), counts)
    order = np.argsort(at, kind="stable")
    at = at[order]
    if at.shape[0] > 1 and np.any(np.diff(at) <= 0):
        raise _UnusualError("two index entries for one record")
    cid = np.repeat(np.array([x[2] for x in items], dtype=np.int64), counts)[order]
    lim = np.repeat(np.array([x[1] for x in items], dtype=np.int64), counts)[order]
    first = np.cumsum(counts) - counts  # where each index data record's entries start in ``index``
    entry_rank = np.arange(index.shape[0], dtype=np.int64) - np.repeat(first, counts)
    key = (np.repeat(np.array([x[4] for x in items], dtype=np.int64), counts) << 32) + entry_rank
    try:
        u8, pos = read_records(f.fd, 0, f.size, at, ROS1, limits=lim)
    except SpanError as err:
        raise _UnusualError(str(err)) from err
    return u8, pos, cid, _index_times(index)[order], key[order]


def _parse_records(records: Records, selected: dict[int, _Conn], parts: dict[str, _Parts]) -> None:
    """Parse the wanted records (in file order within each chunk) per topic at once (a handful of numpy calls per
    topic, none per chunk): blocks per topic, which ``_ordered`` puts in rosbags' order. ``records``: compact bytes,
    positions, connection ids, log times, order keys."""
    u8, pos, cid, t, key = records
    conn_rank = {c: i for i, c in enumerate(selected)}  # the index's order of connections, as rosbags lists them
    for topic, p in parts.items():
        ids = np.array(sorted(c for c, conn in selected.items() if conn.topic == topic), dtype=np.int64)
        ranks = np.array([conn_rank[c] for c in ids.tolist()], dtype=np.int64)
        mine = np.flatnonzero(np.isin(cid, ids))
        for k in range(0, mine.shape[0], _PARSE_BLOCK):  # bounded temporaries (a byte matrix of the records)
            rows = mine[k : k + _PARSE_BLOCK]
            tt, packed, lens = _messages_in_chunk(u8, cid[rows], pos[rows], t[rows])
            p.times.append(tt)
            p.blocks.append(packed)
            p.lengths.append(lens)
            p.keys.append(key[rows])
            p.conns.append(ranks[np.searchsorted(ids, cid[rows])])


def _ordered(p: _Parts) -> tuple[IntArray, PayloadBuffer]:
    """Concatenate the pieces and put them in the order in which rosbags yields a topic's messages: by log time;
    among equal log times by connection (the order the bag's index lists them: rosbags merges its connections'
    message lists), then by the chunk's place in the index's list of chunks, then by the record's place in its
    connection's index data record of that chunk (rosbags sorts each connection's list by time alone, stably).
    Strictly increasing log times (the usual case) are that order already."""
    if not p.times:
        empty = np.zeros(0, dtype=np.int64)
        return empty, PayloadBuffer(np.zeros(0, dtype=np.uint8), empty, empty)
    times = np.concatenate(p.times)
    lengths = np.concatenate(p.lengths)
    data = np.concatenate(p.blocks) if len(p.blocks) > 1 else p.blocks[0]
    offsets = np.zeros(lengths.shape[0], dtype=np.int64)
    if lengths.shape[0] > 1:
        np.cumsum(lengths[:-1], out=offsets[1:])
    if bool(np.all(times[1:] > times[:-1])):
        return times, PayloadBuffer(data, offsets, lengths)
    perm = np.lexsort((np.concatenate(p.keys), np.concatenate(p.conns), times))
    times = times[perm]
    lengths_p = lengths[perm]
    d = int(lengths[0])
    if np.all(lengths == d):
        packed = data.reshape(-1, d)[perm].ravel()
    else:
        packed = np.frombuffer(b"".join(data[int(offsets[i]) : int(offsets[i] + lengths[i])].tobytes()
                                        for i in perm), dtype=np.uint8)
    new_offsets = np.zeros(lengths_p.shape[0], dtype=np.int64)
    if lengths_p.shape[0] > 1:
        np.cumsum(lengths_p[:-1], out=new_offsets[1:])
    return times, PayloadBuffer(packed, new_offsets, lengths_p)
