"""Fast MCAP message reader: an opened ``rosbags`` MCAP storage + its wanted channels -> their messages as packed
numpy buffers, in exactly the order ``rosbags`` yields them.

input: a ``rosbags.rosbag2.storage_mcap.McapReader`` that ``rosbags`` has opened (summary read: schemas, channels,
chunk indexes) and the storage connections to read -> output: per storage connection id, log times (int64 ns) and
payloads (one byte buffer + offsets + lengths); or ``None`` when anything is unusual (then the caller iterates
``rosbags``' own reader, which also decides truncation and damage).

What ``rosbags`` 0.11 does, and this reproduces: only chunks whose index lists a message count for a wanted
channel are read; a chunk is read at the offsets its chunk index gives (CRC at ``start + 9 + 24``, compressed data
at ``start + 9 + 40 + len(compression)``), decompressed (none / lz4 / zstd) and checked (size, CRC when non-zero)
by ``rosbags``' own ``decompress``; its records (opcode u8, length u64, content) are walked from the start to the
end of the chunk; message records (opcode 5: channel u16, sequence u32, log time u64, publish time u64, payload) of
the wanted channels are kept (all of them, whatever their log time: as the scan ``verify.ingest.mcapfile`` and the
format's reference reader keep them, where rosbags also drops a message outside its chunk's indexed time range) and
sorted stably by log time; the chunks are merged by (log time, chunk offset). Hence the order is (log time, chunk
offset, record position).

Uncompressed chunks whose records are not all wanted are read message by message instead (``_sparse``): the wanted
channels' message index records give each message's offset; only those records are read and each must be a message
of the channel and log time its index entry names (the chunk CRC, covering bytes not read, is then not checked).

The record walk is the record layer's (``verify.ingest.mcaprecords.chunk_records``, the same walk the scan,
salvage and the follower take), vectorized: the message index records after each chunk give candidate record
starts; a run of candidates where each record ends exactly where the next candidate begins is taken in one step.
The message index itself is only a hint: nothing is read from it that the walk does not confirm.
"""

from __future__ import annotations

import itertools
import os
import struct
import zlib
from collections.abc import Collection, Iterable
from dataclasses import dataclass
from pathlib import Path

import numpy as np
import numpy.typing as npt
from rosbags.interfaces import Connection
from rosbags.rosbag2.errors import ReaderError
from rosbags.rosbag2.storage_mcap import ChunkInfo, McapReader
from rosbags.rosbag2.storage_mcap import decompress as rosbags_decompress

from verify.errors import FastPathError as _UnusualError  # the fast path declines: fall back
from verify.ingest.mcaprecords import (
    CHUNK_FIXED,
    MESSAGE_HEAD,
    RECORD_HEAD,
    MalformedError,
    Op,
    Scan,
    chunk_records,
    record_messages,
    zstd,
)
from verify.ingest.records import (
    MCAP,
    WORKERS,
    SpanError,
    gather,
    in_order,
    read_records,
    read_scratch,
    retain_freed_memory,
    walk_steps,
)

__all__ = ["TopicMessages", "gather", "read_mcap_storage"]

U8Array = npt.NDArray[np.uint8]
IntArray = npt.NDArray[np.int64]

_OP_MESSAGE = int(Op.MESSAGE)
_OP_MESSAGE_INDEX = int(Op.MESSAGE_INDEX)
_MSG_HEAD = MESSAGE_HEAD  # channel u16, sequence u32, log time u64, publish time u64
_CHUNK_CRC_AT = RECORD_HEAD + 24  # a chunk record's CRC: after its opcode, length and three u64 fields
_CHUNK_DATA_AT = RECORD_HEAD + CHUNK_FIXED + 4 + 8  # its records: after the compression string's length and theirs


@dataclass(frozen=True, slots=True)
class TopicMessages:
    """Messages of one topic in ``rosbags``' order: log times and payload ``i`` at
    ``data[offsets[i] : offsets[i] + lengths[i]]`` (packed: offsets are the running sum of the lengths)."""

    log_ns: IntArray
    data: U8Array
    offsets: IntArray
    lengths: IntArray


@dataclass(slots=True)
class _Part:
    """One topic's messages of one chunk, in the chunk's output order."""

    log_ns: IntArray
    data: U8Array  # packed payloads
    lengths: IntArray


def read_mcap_storage(storage: McapReader, connections: Collection[Connection]) -> dict[str, TopicMessages] | None:
    """Per topic, the messages of ``connections`` (storage connections) from an opened MCAP storage, in the order
    ``storage.messages(connections)`` yields them; None when unusual."""
    try:
        return _read(storage, connections)
    # lz4 / zstd: a damaged chunk; numpy: offsets out of range
    except (_UnusualError, SpanError, MalformedError, ReaderError, struct.error, ValueError, IndexError, KeyError,
            OSError, EOFError, MemoryError, RuntimeError, zstd.ZstdError):
        return None  # (a TypeError or AttributeError is a bug of ours: it is not caught here)


def _read(storage: McapReader, connections: Collection[Connection]) -> dict[str, TopicMessages] | None:
    if not isinstance(storage, McapReader) or not isinstance(storage.path, Path):
        return None
    chunks = list(storage.chunks)
    if not chunks:
        return None  # unindexed file: rosbags scans the data section (and checks the order); not reproduced here
    topic_of = {int(c.id): c.topic for c in connections}
    known = {int(cid): str(ch.topic) for cid, ch in storage.channels.items()}  # every channel of the summary
    wanted = set(topic_of)
    # the chunks rosbags reads, merged by chunk offset on equal log times
    selected = sorted((c for c in chunks if any(c.channel_count.get(cid, 0) for cid in wanted)),
                      key=lambda c: int(c.chunk_start_offset))
    if len({int(c.chunk_start_offset) for c in selected}) != len(selected):
        return None  # two index entries for one chunk: rosbags' merge would compare payloads
    topics = sorted(set(topic_of.values()))
    # per channel id (u16): whether the summary declares it, whether it is wanted, the index of its topic (-1: none)
    is_known, is_wanted = _channel_table(known), _channel_table(wanted)
    code_of = np.full(_CHANNEL_IDS, -1, dtype=np.int16)
    for cid, t in topic_of.items():
        if 0 <= cid < _CHANNEL_IDS:
            code_of[cid] = topics.index(t)
    pieces: list[tuple[npt.NDArray[np.int16], IntArray, U8Array, IntArray]] = []
    with storage.path.open("rb") as fh:
        fd = fh.fileno()
        size = os.fstat(fd).st_size
        # chunks are read (and decompressed) a few ahead in threads; here, in chunk order, each chunk's wanted
        # payloads are copied out at once (all topics together) and split by topic at the end, for all chunks
        whole = _sparse(fd, size, selected, wanted, known)
        if whole is not None:
            batches: Iterable[tuple[IntArray, IntArray, U8Array, IntArray]] = [_copied_out(whole)]
        else:
            workers = WORKERS if any(c.compression for c in selected) else 1  # threads only for decompression
            batches = in_order(lambda c: _copied_out(_chunk_messages(fd, size, c, wanted, known, is_known=is_known,
                                                                     is_wanted=is_wanted)), selected,
                               workers=workers)
        for channel, log_ns, data, lens in batches:
            pieces.append((code_of[channel], log_ns, data, lens))
    return {t: _merge(p) for t, p in _by_topic(pieces, len(topics), topics).items()}


def _copied_out(found: tuple[IntArray, IntArray, IntArray | None, IntArray, U8Array]
                ) -> tuple[IntArray, IntArray, U8Array, IntArray]:
    """A chunk's wanted messages (channel, log time, payload starts and lengths in ``u8``; no starts: ``u8`` holds
    just the payloads, back to back) -> the same with the payloads packed into their own buffer: done in the thread
    that decompressed the chunk, so the reading thread only collects, and the decompressed chunk is dropped where it
    was made."""
    channel, log_ns, starts, lens, u8 = found
    if starts is None:  # packed already (``_few_messages``)
        return channel, log_ns, u8, lens
    return channel, log_ns, gather(u8, starts, lens), lens


#: up to this many messages in a chunk (by the summary), its records are stepped over without the index's hints
#: (measured on 1 GB camera logs: ~25 records per chunk, 9 us stepped against 46 us with the hints read)
_STEP_RECORDS = 128

#: MCAP channel ids are u16
_CHANNEL_IDS = 1 << 16


def _channel_table(ids: Collection[int]) -> npt.NDArray[np.bool_]:
    """Per channel id (u16), whether it is one of ``ids`` (an id outside u16 names no channel of a message)."""
    table = np.zeros(_CHANNEL_IDS, dtype=bool)
    table[[cid for cid in ids if 0 <= cid < _CHANNEL_IDS]] = True
    return table


def _by_topic(pieces: list[tuple[npt.NDArray[np.int16], IntArray, U8Array, IntArray]], n_topics: int,
              topics: list[str]) -> dict[str, list[_Part]]:
    """Chunks' wanted messages (per chunk: topic index, log time, packed payloads, lengths; in chunk order) -> per
    topic its messages as one part, in chunk order and each chunk's output order."""
    if not pieces:
        return {t: [] for t in topics}
    code = np.concatenate([x[0] for x in pieces])
    log_ns = np.concatenate([x[1] for x in pieces])
    data = np.concatenate([x[2] for x in pieces])
    lens = np.concatenate([x[3] for x in pieces])
    if n_topics == 1:
        return {topics[0]: [_Part(log_ns, data, lens)]}
    byte_code = np.repeat(code, lens)  # the topic of every payload byte
    out: dict[str, list[_Part]] = {}
    for k, t in enumerate(topics):
        mine = code == k
        out[t] = [_Part(log_ns[mine], data[byte_code == k], lens[mine])]
    return out


def _pread(fd: int, size: int, pos: int, n: int) -> bytes:
    if pos < 0 or n < 0 or pos + n > size:
        raise _UnusualError("read past the end of the file")
    data = os.pread(fd, n, pos)
    if len(data) != n:
        raise _UnusualError("short read")
    return data


def _decompress(data: bytes | memoryview, compression: str, usize: int, crc: int) -> bytes:
    """``rosbags``' ``decompress`` (same output, same checks), with one-shot zstd decoding into a buffer of the
    known size (``zstd.decompress`` without a size grows its output step by step: ~10x slower here); anything
    unusual (several frames, a size mismatch) goes to ``rosbags``' own function."""
    retain_freed_memory()
    if compression == "zstd":
        dec = zstd.ZstdDecompressor()
        try:
            raw = dec.decompress(data, max_length=usize)
        except zstd.ZstdError:
            raw = b""
        if len(raw) == usize and dec.eof and not dec.unused_data and (not crc or zlib.crc32(raw) == crc):
            return raw
    return rosbags_decompress(bytes(data), compression, usize, crc)


def _chunk_messages(fd: int, size: int, chunk: ChunkInfo, wanted: set[int], known: dict[int, str], *,
                    is_known: npt.NDArray[np.bool_], is_wanted: npt.NDArray[np.bool_]
                    ) -> tuple[IntArray, IntArray, IntArray | None, IntArray, U8Array]:
    """The wanted messages of one chunk in rosbags' order: channel, log time, payload start and length in the
    returned bytes (the decompressed chunk, or only its wanted records: ``_sparse``). ``is_known``, ``is_wanted``:
    per channel id, whether the summary declares it, whether it is wanted (``_channel_table``)."""
    start = int(chunk.chunk_start_offset)
    usize = int(chunk.uncompressed_size)
    if not chunk.compression and (sparse := _sparse(fd, size, [chunk], wanted, known)) is not None:
        return sparse  # only its wanted records read
    at, csize = start + _CHUNK_DATA_AT + len(chunk.compression), int(chunk.compressed_size)
    if at + csize > size:
        raise _UnusualError("read past the end of the file")
    # uncompressed: its own buffer (kept while parsed); compressed: read into a reused buffer (from its CRC on: one
    # read), then decompressed
    if not chunk.compression:
        (crc,) = struct.unpack("<I", _pread(fd, size, start + _CHUNK_CRC_AT, 4))
        compressed: bytes | memoryview = _pread(fd, size, at, csize)
    else:
        head = at - (start + _CHUNK_CRC_AT)
        stored = read_scratch(fd, start + _CHUNK_CRC_AT, head + csize)
        (crc,) = struct.unpack_from("<I", stored)
        compressed = stored[head:]
    raw = _decompress(compressed, chunk.compression, usize, crc)
    del compressed
    if sum(int(n) for n in chunk.channel_count.values()) <= _STEP_RECORDS:
        return _few_messages(raw, known, wanted)
    # the message index as hints where the chunk holds many records (a hint never changes the walk's result)
    return _walked_messages(raw, _index_hints(fd, size, chunk, usize), known, is_known=is_known, is_wanted=is_wanted)


def _walked_messages(raw: bytes, hints: IntArray | None, known: dict[int, str], *, is_known: npt.NDArray[np.bool_],
                     is_wanted: npt.NDArray[np.bool_]) -> tuple[IntArray, IntArray, IntArray, IntArray, U8Array]:
    """A decompressed chunk's wanted messages (``_chunk_messages``), its records walked with numpy (``hints``:
    record starts from its message index)."""
    u8 = np.frombuffer(raw, dtype=np.uint8)
    pos, op, length = chunk_records(raw, hints)
    _parse_others(raw, pos, op, length, known)
    is_msg = op == _OP_MESSAGE
    pos, length = pos[is_msg], length[is_msg]
    if np.any(length < _MSG_HEAD):
        raise _UnusualError("message record shorter than its fixed fields")  # rosbags: struct.error
    channel = _read_u(u8, pos + 9, 2)
    if not np.all(is_known[channel]):
        raise _UnusualError("a message on a channel the summary does not declare")  # the scan refuses it
    log_ns = _read_u(u8, pos + 9 + 6, 8)
    keep = is_wanted[channel]
    pos, length, channel, log_ns = pos[keep], length[keep], channel[keep], log_ns[keep]
    if log_ns.shape[0] > 1 and np.any(np.diff(log_ns) < 0):
        perm = np.argsort(log_ns, kind="stable")  # rosbags: sorted(..., key=timestamp), stable
        pos, length, channel, log_ns = pos[perm], length[perm], channel[perm], log_ns[perm]
    return channel, log_ns, pos + 9 + _MSG_HEAD, length - _MSG_HEAD, u8


def _few_messages(raw: bytes, known: dict[int, str], wanted: set[int]
                  ) -> tuple[IntArray, IntArray, None, IntArray, U8Array]:
    """``_chunk_messages`` for a chunk of few records (``_STEP_RECORDS``), in plain Python: numpy's per-call cost
    exceeds the work on a few dozen records. The same walk (the record layer's steps, ``walk_steps``), the same
    checks (other records parse, messages hold their fixed fields on a declared channel, log times below 2**63)
    and the same result, its payloads already packed (no starts: ``_copied_out`` passes them on)."""
    starts, ends = walk_steps(raw, MCAP)
    view = memoryview(raw)
    unpack = struct.unpack_from
    found: list[tuple[int, int, int, int]] = []
    for pos, end in zip(starts, ends, strict=True):
        op = raw[pos]
        if op == _OP_MESSAGE:
            n = end - pos - RECORD_HEAD
            if n < _MSG_HEAD:
                raise _UnusualError("message record shorter than its fixed fields")  # rosbags: struct.error
            channel, log_ns = unpack("<H4xQ", raw, pos + RECORD_HEAD)
            if channel not in known:
                raise _UnusualError("a message on a channel the summary does not declare")  # the scan refuses it
            if log_ns >= 1 << 63:
                raise _UnusualError("value beyond int64")
            if channel in wanted:
                found.append((log_ns, channel, pos + RECORD_HEAD + _MSG_HEAD, n - _MSG_HEAD))
        elif op in _PARSED_OPS and not _parses(op, view[pos + RECORD_HEAD : end], known):
            raise _UnusualError("a malformed record in a chunk")
    if any(a[0] > b[0] for a, b in itertools.pairwise(found)):
        found.sort(key=lambda m: m[0])  # rosbags: sorted(..., key=timestamp), stable
    data = np.frombuffer(b"".join([raw[s : s + n] for _t, _c, s, n in found]), dtype=np.uint8)
    lens = np.array([m[3] for m in found], dtype=np.int64)
    return (np.array([m[1] for m in found], dtype=np.int64), np.array([m[0] for m in found], dtype=np.int64),
            None, lens, data)


def _sparse(fd: int, size: int, chunks: list[ChunkInfo], wanted: set[int], known: dict[int, str]
            ) -> tuple[IntArray, IntArray, IntArray, IntArray, U8Array] | None:
    """The wanted channels' message records of uncompressed chunks whose records are not all wanted, read message
    by message: the message index records of every chunk (one read per chunk) give each wanted message's file
    position; the records are read there (``verify.ingest.records``: one read per cluster of nearby records, each
    bounded by its chunk) and each must be a message of the channel and log time its index entry names; then kept
    and ordered as ``_chunk_messages`` keeps and orders a chunk's messages, for all chunks at once: (log time, file
    position), i.e. (log time, chunk offset, record position). Not checked, unlike a whole read: the chunks' CRCs,
    which cover bytes that are not read; messages missing from the message index (writers index every message; the
    summary's counts come from it). None when a chunk is compressed or has every record wanted, or anything
    disagrees with an index (then the chunks are walked whole)."""
    if not chunks or any(c.compression for c in chunks):
        return None
    pairs: list[npt.NDArray[np.uint64]] = []  # per (chunk, channel): its message index entries (log time, offset)
    meta: list[tuple[int, int, int, int]] = []  # ... and channel, count, base, limit
    try:
        for chunk in chunks:
            counts = {int(cid): int(n) for cid, n in chunk.channel_count.items()}
            mine = sorted(cid for cid in wanted if counts.get(cid, 0))
            if sum(counts[cid] for cid in mine) >= sum(counts.values()):
                return None
            lo = int(chunk.chunk_start_offset) + int(chunk.chunk_length)
            n = int(chunk.message_index_length)
            if lo + n > size:
                return None
            region = os.pread(fd, n, lo)
            base = int(chunk.chunk_start_offset) + _CHUNK_DATA_AT
            limit = base + int(chunk.uncompressed_size)
            if not _chunk_chains(fd, chunk, region, lo, base, known=known):
                return None
            for cid in mine:
                got = _index_record(region, int(chunk.message_index_offsets[cid]) - lo)
                if got is None or got[0] != cid:
                    return None
                pairs.append(got[1])
                meta.append((cid, got[1].shape[0], base, limit))
        flat = np.concatenate(pairs)
        if np.any(flat >= np.uint64(2**63)):
            return None
        m = np.array(meta, dtype=np.int64).reshape(-1, 4)
        k = m[:, 1]
        at = flat[:, 1].astype(np.int64) + np.repeat(m[:, 2], k)
        order = np.argsort(at, kind="stable")
        at, log_ns, chan = at[order], flat[:, 0].astype(np.int64)[order], np.repeat(m[:, 0], k)[order]
        lim = np.repeat(m[:, 3], k)[order]
        if at.shape[0] > 1 and np.any(np.diff(at) == 0):
            return None
        u8, pos = read_records(fd, 0, size, at, MCAP, limits=lim)
        if pos.shape[0] and (np.any(u8[pos] != _OP_MESSAGE) or np.any(_read_u(u8, pos + 1, 8) < _MSG_HEAD)):
            return None
        length = _read_u(u8, pos + 1, 8)
        if not (np.array_equal(_read_u(u8, pos + 9, 2), chan) and np.array_equal(_read_u(u8, pos + 15, 8), log_ns)):
            return None
    except (SpanError, _UnusualError, KeyError, OSError):
        return None
    if log_ns.shape[0] > 1 and np.any(np.diff(log_ns) < 0):
        perm = np.argsort(log_ns, kind="stable")
        pos, length, chan, log_ns = pos[perm], length[perm], chan[perm], log_ns[perm]
    return chan, log_ns, pos + 9 + _MSG_HEAD, length - _MSG_HEAD, u8


#: records inside a chunk that the scan parses besides messages: a damaged one stops the scan, so the fast read
#: parses them too (and declines when one does not parse)
_PARSED_OPS = (int(Op.SCHEMA), int(Op.CHANNEL), int(Op.STATISTICS))


def _parse_others(raw: bytes, pos: IntArray, op: IntArray, length: IntArray, known: dict[int, str]) -> None:
    """Parse a walked chunk's schema, channel and statistics records as the scan does (``_UnusualError`` when one
    is malformed, or a channel's topic is not the summary's: the scan then reads the file and decides)."""
    parsed = np.zeros(op.shape[0], dtype=bool)
    for code in _PARSED_OPS:  # (three comparisons: np.isin's fixed cost is ~10x theirs on a chunk's few records)
        parsed |= op == code
    for k in np.flatnonzero(parsed).tolist():
        at = int(pos[k]) + RECORD_HEAD
        if not _parses(int(op[k]), memoryview(raw)[at : at + int(length[k])], known):
            raise _UnusualError("a malformed record in a chunk")


def _parses(op: int, content: memoryview, known: dict[int, str]) -> bool:
    """Whether a schema, channel or statistics record parses as the scan parses it, and a channel's topic is the
    one the summary gives its id (the scan takes a channel's first record, which may be this one)."""
    found = Scan({}, {})
    try:
        record_messages(op, content, found)
    except (MalformedError, struct.error):
        return False
    return all(known.get(cid) == ch.topic for cid, ch in found.channels.items())


_HEAD_CLUSTER_B = 4096  # record heads closer than this are read in one pread


def _chunk_chains(fd: int, chunk: ChunkInfo, region: bytes, lo: int, base: int, *, known: dict[int, str]) -> bool:
    """Whether an uncompressed chunk read message by message is one the scan reads without stopping: no CRC to
    check (a chunk with one is read whole and checked), every record from the chunk's start on ends where the next
    begins and the last exactly at the chunk's end, message records hold their fixed fields, and its schema,
    channel and statistics records parse. Only record heads are read (the message index of every channel gives
    where each message record starts; the records between them are stepped over one by one), not the unwanted
    payloads. False: read the chunk whole instead."""
    start, usize = int(chunk.chunk_start_offset), int(chunk.uncompressed_size)
    if os.pread(fd, 4, start + _CHUNK_CRC_AT) != b"\0\0\0\0":
        return False
    cand = _indexed_starts(chunk, region, lo)
    if cand is None or (cand and cand[-1] + RECORD_HEAD > usize):
        return False
    heads = _record_heads(fd, base, cand)
    return heads is not None and _heads_chain(fd, base, usize, heads, known)


def _indexed_starts(chunk: ChunkInfo, region: bytes, lo: int) -> list[int] | None:
    """Every record start the chunk's message index records give (sorted); None when one is not a well-formed
    message index record (``region``: the file's bytes from ``lo`` holding them)."""
    starts: set[int] = set()
    for off in chunk.message_index_offsets.values():  # small per chunk: struct, not numpy
        rel = int(off) - lo
        if rel < 0 or rel + 15 > len(region) or region[rel] != _OP_MESSAGE_INDEX:
            return None
        (rec_len, _channel, arr_len) = struct.unpack_from("<QHI", region, rel + 1)
        if arr_len % 16 or arr_len + 6 > rec_len or rel + 15 + arr_len > len(region):
            return None
        starts.update(struct.unpack_from(f"<{arr_len // 8}Q", region, rel + 15)[1::2])
    return sorted(starts)


def _record_heads(fd: int, base: int, cand: list[int]) -> dict[int, tuple[int, int, int]] | None:
    """The heads of the records at ``cand`` (chunk positions; the chunk's records start at file position ``base``):
    position -> (opcode, content length, first u16: a message's channel), nearby ones in one read; None when the
    file ends first."""
    heads: dict[int, tuple[int, int, int]] = {}
    i = 0
    while i < len(cand):
        j = i
        while j + 1 < len(cand) and cand[j + 1] - cand[i] < _HEAD_CLUSTER_B:
            j += 1
        n = cand[j] - cand[i] + RECORD_HEAD + 2
        piece = os.pread(fd, n, base + cand[i])
        if len(piece) != n:
            return None
        for k in range(i, j + 1):
            heads[cand[k]] = struct.unpack_from("<BQH", piece, cand[k] - cand[i])
        i = j + 1
    return heads


def _heads_chain(fd: int, base: int, usize: int, heads: dict[int, tuple[int, int, int]], known: dict[int, str]
                 ) -> bool:
    """The walk of a chunk's ``usize`` bytes of records by their heads (``heads``: those already read; the others
    read one by one): every record ends where the next begins, the last at the chunk's end, every indexed start is
    a record of the walk, messages hold their fixed fields on a declared channel, and schema, channel and
    statistics records parse."""
    pos = 0
    while pos < usize:
        head = heads.pop(pos, None)
        if head is None:
            raw = os.pread(fd, RECORD_HEAD + 2, base + pos)
            if len(raw) != RECORD_HEAD + 2:
                return False
            head = struct.unpack("<BQH", raw)
        op, n, channel = head
        end = pos + RECORD_HEAD + n
        if end > usize:
            return False
        if op == _OP_MESSAGE:
            if n < _MSG_HEAD or channel not in known:
                return False  # the scan refuses a message on a channel the file never declares
        elif op in _PARSED_OPS and not _parses(op, memoryview(os.pread(fd, n, base + pos + RECORD_HEAD)), known):
            return False
        pos = end
    return pos == usize and not heads  # every indexed record was a record of the walk


def _read_u(u8: U8Array, at: IntArray, width: int) -> IntArray:
    """Little-endian unsigned integers of ``width`` bytes (2 or 8) at byte offsets ``at``, as int64 (a u64 value of
    2**63 or more raises ``_UnusualError``)."""
    cols = np.ascontiguousarray(u8[at[:, None] + np.arange(width)])
    if width == 2:
        return cols.view("<u2").ravel().astype(np.int64)
    values = cols.view("<u8").ravel()
    if np.any(values >= np.uint64(2**63)):
        raise _UnusualError("value beyond int64")
    return values.astype(np.int64)


def _index_record(region: bytes, rel: int) -> tuple[int, npt.NDArray[np.uint64]] | None:
    """The message index record at ``rel`` in ``region`` -> (channel, its (log time, record offset) pairs as rows);
    None when no well-formed message index record is there."""
    if rel < 0 or rel + 15 > len(region) or region[rel] != _OP_MESSAGE_INDEX:
        return None
    (rec_len, channel, arr_len) = struct.unpack_from("<QHI", region, rel + 1)
    if arr_len % 16 or arr_len + 6 > rec_len or rel + 15 + arr_len > len(region):
        return None
    return int(channel), np.frombuffer(region, dtype="<u8", count=arr_len // 8, offset=rel + 15).reshape(-1, 2)


def _index_hints(fd: int, size: int, chunk: ChunkInfo, usize: int) -> IntArray:
    """Candidate record starts from the chunk's message index records (sorted, unique, inside the chunk). The index
    is only a hint, so a message index that cannot be parsed just gives no candidates."""
    offsets = sorted(int(v) for v in chunk.message_index_offsets.values())
    if not offsets:
        return np.zeros(0, dtype=np.int64)
    end = int(chunk.chunk_start_offset) + int(chunk.chunk_length) + int(chunk.message_index_length)
    lo = offsets[0]
    if lo >= end or end > size:
        return np.zeros(0, dtype=np.int64)
    region = os.pread(fd, end - lo, lo)
    found: list[IntArray] = []
    for off in offsets:
        got = _index_record(region, off - lo)
        if got is not None:
            found.append(got[1][:, 1].astype(np.int64))
    if not found:
        return np.zeros(0, dtype=np.int64)
    cand = np.unique(np.concatenate(found))
    return cand[(cand >= 0) & (cand + 9 <= usize)]


def _packed_offsets(lengths: IntArray) -> IntArray:
    offsets = np.zeros(lengths.shape[0], dtype=np.int64)
    if lengths.shape[0] > 1:
        np.cumsum(lengths[:-1], out=offsets[1:])
    return offsets


def _merge(parts: list[_Part]) -> TopicMessages:
    """One topic's chunk parts (by chunk offset, each in the chunk's output order) -> ordered by (log time, chunk
    offset, position in the chunk's output): rosbags' heap merge of the chunks."""
    if not parts:
        empty = np.zeros(0, dtype=np.int64)
        return TopicMessages(empty, np.zeros(0, dtype=np.uint8), empty, empty)
    log_ns = np.concatenate([p.log_ns for p in parts])
    lengths = np.concatenate([p.lengths for p in parts])
    data = np.concatenate([p.data for p in parts]) if len(parts) > 1 else parts[0].data
    offsets = _packed_offsets(lengths)
    if log_ns.shape[0] > 1 and np.any(np.diff(log_ns) < 0):
        perm = np.argsort(log_ns, kind="stable")
        log_ns, lengths = log_ns[perm], lengths[perm]
        data = gather(data, offsets[perm], lengths)
        offsets = _packed_offsets(lengths)
    return TopicMessages(log_ns, data, offsets, lengths)
