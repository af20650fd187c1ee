"""The MCAP record layer: bytes of an MCAP file -> its records, as the format specification lays them out.

input: a buffer holding an MCAP file (or its first bytes, for a file still being written) -> output: the file's
records in file order (``walk``: opcode, content, next position) and, on top of it, the stream of what a reader
needs (``scan``: schemas, channels, messages and statistics found anywhere in the file, chunks decompressed and
walked) with where and why it stopped.

One place for the magic bytes, the opcodes and the record layouts (https://mcap.dev/spec): every MCAP reader of the
certifier (the plain read ``verify.ingest.mcapfile``, salvage ``verify.ingest.salvage``, the fast indexed reader
``verify.ingest.mcap`` and the follower ``verify.online.follow``) takes them from here. A record's fields are read
from the front of its content; bytes after the last known field (padding, fields added by later versions) are
skipped, as the specification asks.
"""

from __future__ import annotations

import struct
import sys
import zlib
from collections.abc import Iterator
from dataclasses import dataclass
from enum import IntEnum

import numpy as np
import numpy.typing as npt

from verify.ingest.records import MCAP, CutError, MalformedError, lz4_decompress, walk_chain

if sys.version_info >= (3, 14):
    from compression import zstd
else:
    from backports import zstd  # a rosbags dependency

__all__ = [
    "CHUNK_FIXED",
    "COMPRESSIONS",
    "FOOTER_RECORD",
    "MAGIC",
    "MESSAGE_HEAD",
    "RECORD_HEAD",
    "ChannelRecord",
    "CutError",
    "MalformedError",
    "MessageRecord",
    "Op",
    "Scan",
    "SchemaRecord",
    "chunk_content",
    "chunk_layout",
    "chunk_records",
    "declares_counts",
    "decompress",
    "indexed_channels",
    "lz4_decompress",
    "parse_channel",
    "parse_message",
    "parse_schema",
    "parse_statistics",
    "record_messages",
    "scan",
    "walk",
    "zstd",
]

#: the 8 bytes that open and close every MCAP file
MAGIC = b"\x89MCAP0\r\n"
#: a record: opcode u8, content length u64, content
RECORD_HEAD = 9
#: the footer record: opcode, length, summary start u64, summary offset start u64, summary crc u32
FOOTER_RECORD = RECORD_HEAD + 8 + 8 + 4
#: message content: channel id u16, sequence u32, log time u64, publish time u64, then the payload
MESSAGE_HEAD = 22
#: chunk content before its compression string: start time u64, end time u64, uncompressed size u64, crc u32
CHUNK_FIXED = 28


class Op(IntEnum):
    """MCAP record opcodes."""

    HEADER = 0x01
    FOOTER = 0x02
    SCHEMA = 0x03
    CHANNEL = 0x04
    MESSAGE = 0x05
    CHUNK = 0x06
    MESSAGE_INDEX = 0x07
    CHUNK_INDEX = 0x08
    ATTACHMENT = 0x09
    ATTACHMENT_INDEX = 0x0A
    STATISTICS = 0x0B
    METADATA = 0x0C
    METADATA_INDEX = 0x0D
    SUMMARY_OFFSET = 0x0E
    DATA_END = 0x0F


@dataclass(frozen=True, slots=True)
class SchemaRecord:
    id: int
    name: str
    encoding: str
    has_data: bool


@dataclass(frozen=True, slots=True)
class ChannelRecord:
    id: int
    schema_id: int
    topic: str
    message_encoding: str


@dataclass(frozen=True, slots=True)
class MessageRecord:
    """A message; ``payload`` a view of the scanned buffer (copy what is kept: ``bytes(payload)``)."""

    channel_id: int
    log_ns: int
    payload: memoryview


def _need(rec: bytes | memoryview, pos: int, size: int) -> None:
    if size < 0 or pos + size > len(rec):
        raise MalformedError("a field runs past the end of its record")


def _string(rec: bytes | memoryview, pos: int) -> tuple[str, int]:
    _need(rec, pos, 4)
    (n,) = struct.unpack_from("<I", rec, pos)
    _need(rec, pos + 4, n)
    try:
        return bytes(rec[pos + 4 : pos + 4 + n]).decode("utf-8"), pos + 4 + n
    except UnicodeDecodeError:
        raise MalformedError("a string field is not UTF-8") from None


def parse_schema(rec: bytes | memoryview) -> SchemaRecord:
    _need(rec, 0, 2)
    (sid,) = struct.unpack_from("<H", rec, 0)
    name, p = _string(rec, 2)
    encoding, p = _string(rec, p)
    _need(rec, p, 4)
    (dlen,) = struct.unpack_from("<I", rec, p)
    _need(rec, p + 4, dlen)
    return SchemaRecord(sid, name, encoding, dlen > 0)


def parse_channel(rec: bytes | memoryview) -> ChannelRecord:
    _need(rec, 0, 4)
    cid, sid = struct.unpack_from("<HH", rec, 0)
    topic, p = _string(rec, 4)
    encoding, p = _string(rec, p)
    _need(rec, p, 4)
    (mlen,) = struct.unpack_from("<I", rec, p)
    _need(rec, p + 4, mlen)
    return ChannelRecord(cid, sid, topic, encoding)


def parse_message(rec: bytes | memoryview) -> MessageRecord:
    _need(rec, 0, MESSAGE_HEAD)
    cid, _seq, log_ns, _pub = struct.unpack_from("<HIQQ", rec, 0)
    return MessageRecord(cid, log_ns, memoryview(rec)[MESSAGE_HEAD:])


def parse_statistics(rec: bytes | memoryview) -> dict[int, int]:
    """Statistics -> per channel id its declared message count (the ``channel_message_counts`` map)."""
    fixed = 8 + 2 + 4 * 4 + 8 + 8
    _need(rec, 0, fixed + 4)
    (mlen,) = struct.unpack_from("<I", rec, fixed)
    _need(rec, fixed + 4, mlen)
    if mlen % 10:
        raise MalformedError("statistics channel counts are not (u16, u64) pairs")
    return {int(c): int(n) for c, n in struct.iter_unpack("<HQ", bytes(rec[fixed + 4 : fixed + 4 + mlen]))}


def decompress(data: bytes | memoryview, compression: str, usize: int) -> bytes:
    """A chunk's records from its stored bytes; raises the decompressor's own error on damaged data, and
    ``MalformedError`` on an unknown compression or a size that disagrees with the chunk's."""
    if compression == "":
        raw = bytes(data)
    elif compression == "zstd":
        dec = zstd.ZstdDecompressor()
        raw = dec.decompress(data, max_length=usize)
    elif compression == "lz4":
        raw = lz4_decompress(data)
    else:
        raise MalformedError(f"unknown chunk compression {compression!r}")
    if len(raw) != usize:
        raise MalformedError(f"a chunk holds {len(raw)} bytes where its header says {usize}")
    return raw


#: the chunk compressions the format defines
COMPRESSIONS = ("", "lz4", "zstd")


def chunk_layout(rec: bytes | memoryview, length: int | None = None) -> tuple[str, int, int, int, int]:
    """A chunk record's content (or its first bytes, up to and with its stored size field; ``length``: the whole
    content's length) -> (compression, uncompressed size, crc, where its stored records start, their size): the
    structural check of a chunk, whether it is then read or not. ``MalformedError`` when a field runs past the
    record or the compression is not one the format defines."""
    size = len(rec) if length is None else length
    _need(rec, 0, CHUNK_FIXED)
    _start, _end, usize, crc = struct.unpack_from("<QQQI", rec, 0)
    compression, p = _string(rec, CHUNK_FIXED)
    _need(rec, p, 8)
    (clen,) = struct.unpack_from("<Q", rec, p)
    if p + 8 + clen > size:
        raise MalformedError("a chunk's stored records run past the end of its record")
    if compression not in COMPRESSIONS:
        raise MalformedError(f"unknown chunk compression {compression!r}")
    return compression, int(usize), int(crc), p + 8, int(clen)


def chunk_content(rec: bytes | memoryview) -> tuple[str, int, int, memoryview]:
    """A chunk record's content -> (compression, uncompressed size, crc, stored records)."""
    compression, usize, crc, at, clen = chunk_layout(rec)
    return compression, usize, crc, memoryview(rec)[at : at + clen]


def indexed_channels(buf: bytes | memoryview, pos: int) -> set[int] | None:
    """The channels the message index records at ``pos`` (right after a chunk) list with at least one message;
    None when no complete message index record is there (a chunk without message indexes: what it holds is not
    known without reading it)."""
    view = memoryview(buf)
    ids: set[int] = set()
    seen = False
    while pos + RECORD_HEAD + 6 <= len(view) and view[pos] == Op.MESSAGE_INDEX:
        (size,) = struct.unpack_from("<Q", view, pos + 1)
        if size < 6 or pos + RECORD_HEAD + size > len(view):
            break
        cid, entries = struct.unpack_from("<HI", view, pos + RECORD_HEAD)
        if entries:
            ids.add(int(cid))
        seen = True
        pos += RECORD_HEAD + size
    return ids if seen else None


def declares_counts(buf: bytes | memoryview) -> bool:
    """Whether the file's summary (found through its footer) holds a Statistics record: per-channel message counts,
    which a reader checks what it read against."""
    view = memoryview(buf)
    footer = len(view) - len(MAGIC) - FOOTER_RECORD
    if footer < len(MAGIC) or bytes(view[-len(MAGIC) :]) != MAGIC or view[footer] != Op.FOOTER:
        return False
    (start,) = struct.unpack_from("<Q", view, footer + RECORD_HEAD)
    if not len(MAGIC) <= start < footer:
        return False
    try:
        return any(op == Op.STATISTICS for op, _rec, _next in walk(view, int(start), footer))
    except CutError:
        return False


IntArray = npt.NDArray[np.int64]


def chunk_records(buf: bytes | memoryview, hints: IntArray | None = None) -> tuple[IntArray, IntArray, IntArray]:
    """A chunk's records (``buf``: its decompressed records) -> (start, opcode, content length) of every record, in
    order, by the vectorised walk (``verify.ingest.records.walk_chain``; ``hints``: record starts its message index
    gives); ``MalformedError`` when a record runs past the chunk's end."""
    pos, end = walk_chain(buf, MCAP, hints)
    u8 = np.frombuffer(buf, dtype=np.uint8)
    return pos, u8[pos].astype(np.int64), end - pos - RECORD_HEAD


def walk(buf: bytes | memoryview, pos: int, end: int) -> Iterator[tuple[int, memoryview, int]]:
    """Records from ``pos`` to ``end`` -> (opcode, content, position after the record); ``CutError`` when a record
    does not end by ``end``."""
    view = memoryview(buf)
    while pos < end:
        if pos + RECORD_HEAD > end:
            raise CutError(pos)
        op = view[pos]
        (size,) = struct.unpack_from("<Q", view, pos + 1)
        nxt = pos + RECORD_HEAD + size
        if nxt > end:
            raise CutError(pos)
        yield op, view[pos + RECORD_HEAD : nxt], nxt
        pos = nxt


@dataclass(slots=True)
class Scan:
    """What ``scan`` found: schemas and channels wherever they were; the declared per-channel counts (Statistics);
    whether the footer was reached; where and why the scan stopped early (``stopped_at``, ``reason``)."""

    schemas: dict[int, SchemaRecord]
    channels: dict[int, ChannelRecord]
    declared: dict[int, int] | None = None
    complete: bool = False
    stopped_at: int | None = None
    reason: str = "not scanned"
    error: BaseException | None = None


#: what ends a scan at a record: cut or malformed, or a chunk that does not decompress (lz4: RuntimeError)
_STOPS: tuple[type[BaseException], ...] = (CutError, MalformedError, struct.error, zlib.error, RuntimeError,
                                           zstd.ZstdError, ValueError)


def scan(buf: bytes | memoryview, found: Scan, *, check_crc: bool = True, wanted: frozenset[str] | None = None
         ) -> Iterator[MessageRecord]:
    """Every message of the file in file order (a chunk's in its record order), filling ``found`` as the records
    pass. Stops at the footer, or at the first record that is cut, malformed or does not decompress: then
    ``found.stopped_at``/``reason``/``error`` say where and why (the messages of a cut uncompressed chunk's complete
    records are yielded first).

    ``wanted`` (topics): a chunk that holds none of them is checked structurally (``chunk_layout``) but neither
    decompressed nor walked -- the rule of the indexed reader, which reads only the chunks holding a wanted
    topic. A chunk holds none when the message index records right after it list only channels already declared,
    on other topics. The caller passes ``wanted`` only for a file whose statistics declare its message counts
    (``declares_counts``), so that a message index that hides a wanted message is caught by the count check."""
    view = memoryview(buf)
    if bytes(view[: len(MAGIC)]) != MAGIC:
        found.reason, found.stopped_at = "not an MCAP file (bad magic)", 0
        found.error = MalformedError("bad magic")
        return
    pos = len(MAGIC)
    try:
        while True:
            if pos + RECORD_HEAD > len(view):
                raise CutError(pos)
            op = view[pos]
            (size,) = struct.unpack_from("<Q", view, pos + 1)
            nxt = pos + RECORD_HEAD + size
            if nxt > len(view):
                if op == Op.CHUNK:  # a cut chunk: an uncompressed one still holds complete records up to the cut
                    yield from _cut_chunk(view[pos + RECORD_HEAD :], found)
                raise CutError(pos)
            if op == Op.FOOTER:
                found.complete = True
                found.reason, found.stopped_at = "reached the end of the file", None
                return
            if op == Op.CHUNK and wanted is not None and _holds_none_of(view, nxt, found, wanted):
                chunk_layout(view[pos + RECORD_HEAD : nxt])
            else:
                yield from record_messages(op, view[pos + RECORD_HEAD : nxt], found, check_crc=check_crc)
            pos = nxt
    except _STOPS as err:
        found.error = err.with_traceback(None)  # no frames (and their views of the buffer) kept alive
        found.stopped_at = pos
        found.reason = f"stopped at an incomplete record ({err.__class__.__name__})"


def _holds_none_of(view: memoryview, after: int, found: Scan, wanted: frozenset[str]) -> bool:
    """Whether the chunk that ends at ``after`` holds no message of a wanted topic, by its message index records."""
    ids = indexed_channels(view, after)
    if ids is None:
        return False
    channels = found.channels
    return all(cid in channels and channels[cid].topic not in wanted for cid in ids)


def _cut_chunk(rec: memoryview, found: Scan) -> Iterator[MessageRecord]:
    try:
        compression, p = _string(rec, CHUNK_FIXED)
    except MalformedError:
        return
    if compression != "":
        return
    inner = rec[p + 8 :]
    got: list[MessageRecord] = []
    try:
        for iop, irec, _ in walk(inner, 0, len(inner)):
            got.extend(_record(iop, irec, found))
    except (CutError, MalformedError, struct.error):
        pass
    yield from got


def record_messages(op: int, rec: memoryview, found: Scan, *, check_crc: bool = True) -> list[MessageRecord]:
    """One complete top-level record -> its messages (a chunk's, decompressed and walked), noting schemas,
    channels and statistics in ``found``; raises ``CutError``/``MalformedError``/a decompressor's error on damage."""
    if op != Op.CHUNK:
        return list(_record(op, rec, found))
    compression, usize, crc, stored = chunk_content(rec)
    inner = decompress(stored, compression, usize)
    if check_crc and crc and zlib.crc32(inner) != crc:
        raise MalformedError("a chunk's records do not match its CRC")
    out: list[MessageRecord] = []
    view = memoryview(inner)
    pos, ops, lengths = chunk_records(inner)
    for at, iop, n in zip(pos.tolist(), ops.tolist(), lengths.tolist(), strict=True):
        out.extend(_record(iop, view[at + RECORD_HEAD : at + RECORD_HEAD + n], found))
    return out


def _record(op: int, rec: memoryview, found: Scan) -> Iterator[MessageRecord]:
    if op == Op.MESSAGE:
        yield parse_message(rec)
    elif op == Op.SCHEMA:
        schema = parse_schema(rec)
        if schema.id not in found.schemas or not found.schemas[schema.id].has_data:
            found.schemas[schema.id] = schema
    elif op == Op.CHANNEL:
        channel = parse_channel(rec)
        found.channels.setdefault(channel.id, channel)
    elif op == Op.STATISTICS:
        found.declared = parse_statistics(rec)
    # every other record (header, indexes, attachments, metadata, summary offsets, data end, unknown opcodes) is
    # skipped: nothing of it is a message
