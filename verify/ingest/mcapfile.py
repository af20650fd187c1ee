"""MCAP logs as the format defines them: a bare ``.mcap`` file or an MCAP bag folder -> the wanted topics' messages.

input: a path (a ``.mcap`` file, or a ROS2 bag folder whose storage is MCAP) and topic names -> output: an
``McapLog`` (per wanted topic present: message type, whether the file carries its definition, log times in ns and
payloads, in log-time order; every topic of the log with its type).

Every storage file is read in one of two ways that give the same messages in the same order:
- **indexed** (``fast``, the default): our chunk reader (``verify.ingest.mcap``) driven by the summary rosbags reads,
  used only when that summary describes the whole file: a chunk index for every chunk, with message indexes; every
  channel of those indexes declared in the summary with its schema; the statistics' message count equal to what
  the chunk indexes hold. Anything else is read the second way.
- **scan** (``TUBEMPC_FAST_INGEST=0``, and every file the indexed reader declines): the record layer's scan over
  the whole file (``verify.ingest.mcaprecords``), which finds schemas and channels wherever the file has them
  (summary or data section), reads unchunked and chunked messages alike (none / lz4 / zstd), skips attachments,
  metadata and padding; the messages are sorted stably by log time (the order indexed reading gives: log time,
  then file position).

Never silently empty: a file (statistics) or bag (metadata.yaml) that declares more messages on a topic than can be
read is refused naming the topic; a wanted channel whose schema is missing or whose encoding is not CDR is refused
naming the channel. A storage file that ends inside a record is ``TruncatedLogError`` naming that file
(``--salvage`` reads its complete records).
"""

from __future__ import annotations

import mmap
import os
import stat
import struct
import tempfile
from collections.abc import Callable, Collection, Iterable, Mapping
from dataclasses import dataclass
from operator import itemgetter
from pathlib import Path, PurePath
from typing import Any

import numpy as np
import numpy.typing as npt
import yaml
from rosbags.rosbag2.errors import ReaderError
from rosbags.rosbag2.storage_mcap import ChunkInfo, McapReader

from verify.errors import LogReadError, TruncatedLogError
from verify.ingest.mcap import read_mcap_storage
from verify.ingest.mcaprecords import (
    CHUNK_FIXED,
    FOOTER_RECORD,
    MAGIC,
    RECORD_HEAD,
    ChannelRecord,
    CutError,
    MalformedError,
    Op,
    Scan,
    chunk_layout,
    declares_counts,
    record_messages,
    scan,
    zstd,
)
from verify.ingest.readerrors import DECOMPRESS_ERRORS, check_declared_counts, in_words, one_type_per_topic
from verify.ingest.ros1 import PayloadBuffer

__all__ = ["BagMetadata", "McapLog", "McapTopic", "check_channels_declared", "check_declared_topics",
           "declared_by_topic", "read_bag_metadata", "read_mcap_log", "regular_file"]

IntArray = npt.NDArray[np.int64]
#: libyaml's safe loader when PyYAML has it, else the pure-Python one
_SAFE_LOADER: type[yaml.SafeLoader] = getattr(yaml, "CSafeLoader", yaml.SafeLoader)
_METADATA_MAX_BYTES = 64 << 20
_SCHEMALESS = "__schemaless__"  # rosbags' message type for a channel whose schema it did not find
_MAX_VERSION = 9  # the newest rosbag2 metadata version rosbags reads


@dataclass(slots=True)
class McapTopic:
    msgtype: str
    has_definition: bool
    log_ns: list[int] | IntArray
    payloads: list[bytes] | PayloadBuffer


@dataclass(frozen=True, slots=True)
class McapLog:
    topics: dict[str, McapTopic]
    available: dict[str, str]


@dataclass(frozen=True, slots=True)
class BagMetadata:
    """What a ROS2 bag folder's metadata.yaml says: storage files, compression, per topic its type and count."""

    files: tuple[Path, ...]
    compression_mode: str | None  # None, "file" or "message" (rosbag2's modes; zstd is the one format rosbags reads)
    types: dict[str, str]
    counts: dict[str, int]


def regular_file(path: Path, what: str) -> None:
    """Refuse anything but a regular file (a FIFO or device would block or never end) before it is opened."""
    try:
        mode = path.stat().st_mode
    except OSError as err:
        raise LogReadError(f"{what} {path.name} cannot be read ({err.strerror or err.__class__.__name__})",
                           path=str(path.parent)) from None
    if not stat.S_ISREG(mode):
        raise LogReadError(f"{what} {path.name} is not a regular file (a FIFO, device, socket or folder)",
                           path=str(path.parent))


def check_declared_topics(folder: Path, meta: BagMetadata, stored: Collection[str]) -> None:
    """One rule for a bag folder whose metadata.yaml and storage disagree (certify's two read paths and ``watch``
    when the recorder has written metadata.yaml): a topic metadata.yaml declares with messages that the storage does
    not hold is damage, named with both sides (rosbags takes a folder's topics from metadata.yaml, the storage keys
    its messages by its own topic names: read either way alone, the run would be judged without that topic)."""
    missing = sorted(t for t, n in meta.counts.items() if n > 0 and t not in stored)
    if missing:
        t = missing[0]
        held = ", ".join(sorted(stored)) or "no topics"
        raise LogReadError(f"damaged ROS2 bag: metadata.yaml declares {meta.counts[t]} messages on {t}, a topic its "
                           f"storage does not hold (the storage holds: {held})", path=str(folder))


def read_bag_metadata(folder: Path) -> BagMetadata:
    """The metadata.yaml of a bag folder (the keys rosbags requires), without opening any storage file."""
    meta = folder / "metadata.yaml"
    regular_file(meta, "metadata file")

    def bad(why: str) -> LogReadError:
        return LogReadError(f"unreadable ROS2 bag: its metadata.yaml is incomplete or malformed ({why})",
                            path=str(folder))

    try:
        if meta.stat().st_size > _METADATA_MAX_BYTES:
            raise bad("larger than 64 MiB")
        doc = yaml.load(meta.read_text(encoding="utf-8"), Loader=_SAFE_LOADER)
    except (OSError, UnicodeDecodeError, yaml.YAMLError, RecursionError, ValueError) as err:
        raise bad(f"{err.__class__.__name__}: {' '.join(str(err).split())[:160]}") from err
    info = doc.get("rosbag2_bagfile_information") if isinstance(doc, dict) else None
    if not isinstance(info, dict):
        raise bad("no rosbag2_bagfile_information")
    version = info.get("version")
    if not isinstance(version, int) or isinstance(version, bool):
        raise bad("no integer version")
    if version > _MAX_VERSION:
        raise LogReadError(f"unreadable ROS2 bag: metadata version {version} is newer than rosbags reads "
                           f"({_MAX_VERSION})", path=str(folder))
    rel = info.get("relative_file_paths")
    if not isinstance(rel, list) or not all(isinstance(x, str) for x in rel):
        raise bad("relative_file_paths is not a list of file names")
    mode = _compression_mode(info, folder, bad)
    types: dict[str, str] = {}
    counts: dict[str, int] = {}
    entries = info.get("topics_with_message_count", [])
    if not isinstance(entries, list):
        raise bad("topics_with_message_count is not a list")
    for entry in entries:
        tm = entry.get("topic_metadata") if isinstance(entry, dict) else None
        name = tm.get("name") if isinstance(tm, dict) else None
        typ = tm.get("type") if isinstance(tm, dict) else None
        count = entry.get("message_count", 0) if isinstance(entry, dict) else None
        if not isinstance(name, str) or not isinstance(typ, str) or not isinstance(count, int) or count < 0:
            raise bad("a topics_with_message_count entry lacks its name, type or count")
        types.setdefault(name, typ)
        counts[name] = counts.get(name, 0) + count
    files = tuple(folder / PurePath(x).name for x in rel)
    for f in files:
        if not f.exists():
            raise LogReadError(f"unreadable ROS2 bag: storage file {f.name} named by metadata.yaml is missing",
                               path=str(folder))
        regular_file(f, "storage file")
    return BagMetadata(files, mode, types, counts)


def _compression_mode(info: dict[str, Any], folder: Path, bad: Callable[[str], LogReadError]) -> str | None:
    """A metadata.yaml's compression: None, "file" or "message" (rosbag2's modes), in zstd, the one format read."""
    mode = info.get("compression_mode") or None
    if mode is not None and not isinstance(mode, str):
        raise bad("compression_mode is not a string")
    mode = None if mode is None or mode.lower() == "none" else mode.lower()
    if mode is None:
        return None
    fmt = info.get("compression_format")
    if mode not in ("file", "message"):
        raise LogReadError(f"unreadable ROS2 bag: metadata.yaml names the compression mode {mode!r}; rosbag2 "
                           f"writes 'file' or 'message'", path=str(folder))
    if not isinstance(fmt, str) or fmt.lower() != "zstd":
        raise LogReadError(f"unreadable ROS2 bag: metadata.yaml names the compression format {fmt!r}; only "
                           f"'zstd' is read", path=str(folder))
    return mode


def read_mcap_log(path: Path, wanted: Iterable[str], *, fast: bool) -> McapLog:
    """The wanted topics of an MCAP file or MCAP bag folder (see the module docstring)."""
    meta = read_bag_metadata(path) if path.is_dir() else None
    if meta is None or meta.compression_mode != "file":
        return _read_files(path, meta, meta.files if meta is not None else (path,), set(wanted), fast=fast)
    with tempfile.TemporaryDirectory(prefix="tubempc-mcap-") as tmp:
        files = tuple(_decompressed_file(f, Path(tmp), shown=str(path)) for f in meta.files)
        return _read_files(path, meta, files, set(wanted), fast=fast)


def _decompressed_file(file: Path, tmp: Path, *, shown: str) -> Path:
    """A storage file of a bag folder written with compression mode 'file' (one zstd stream of the whole MCAP
    file, ``name.mcap.zstd``) -> the MCAP file, decompressed into ``tmp`` under its own name (``name.mcap``), in
    pieces (never the whole file in memory)."""
    out = tmp / (file.name[: -len(".zstd")] if file.name.endswith(".zstd") else file.name)
    dec = zstd.ZstdDecompressor()
    try:
        with file.open("rb") as src, out.open("wb") as dst:
            while block := src.read(1 << 20):
                dst.write(dec.decompress(block))
                while dec.needs_input is False and not dec.eof:
                    dst.write(dec.decompress(b""))
        if not dec.eof:
            raise LogReadError(f"truncated mcap log: storage file {file.name} ends inside its zstd stream",
                               path=shown)
    except zstd.ZstdError as err:
        raise LogReadError(f"unreadable mcap log: storage file {file.name} cannot be decompressed ({err})",
                           path=shown) from err
    except OSError as err:
        raise LogReadError(f"unreadable mcap log: storage file {file.name} cannot be decompressed "
                           f"({err.strerror or err.__class__.__name__})", path=shown) from err
    return out


def _decompressed_messages(topics: dict[str, McapTopic], shown: str) -> None:
    """Compression mode 'message': every payload is one zstd frame (rosbag2 compresses each message's data)."""
    for topic, t in topics.items():
        out: list[bytes] = []
        for payload in t.payloads:
            try:
                out.append(zstd.decompress(bytes(payload)))
            except zstd.ZstdError as err:
                raise LogReadError(f"unreadable mcap log: a message on {topic} cannot be decompressed ({err})",
                                   path=shown) from err
        t.payloads = out


def _read_files(path: Path, meta: BagMetadata | None, files: tuple[Path, ...], want: set[str], *, fast: bool
                ) -> McapLog:
    shown = str(path)
    per_file: list[tuple[McapLog, dict[str, int]]] | None = None
    if fast:
        got = [_read_indexed(f, want) for f in files]
        per_file = None if any(g is None or _short(g) for g in got) else [g for g in got if g is not None]
    if per_file is None:
        per_file = [_read_scanned(f, want, shown, named=meta is not None) for f in files]
    topics: dict[str, McapTopic] = {}
    available: dict[str, str] = dict(meta.types) if meta is not None else {}
    declared: dict[str, int] = {}
    for log, counts in per_file:
        for topic, typ in log.available.items():
            available.setdefault(topic, typ)
        for topic, n in counts.items():
            declared[topic] = declared.get(topic, 0) + n
        for topic, t in log.topics.items():
            topics[topic] = t if topic not in topics else _concat(topics[topic], t)
    if meta is not None:
        for topic, n in meta.counts.items():
            declared[topic] = max(declared.get(topic, 0), n)
    check_declared_counts(declared, {t: len(m.payloads) for t, m in topics.items()}, want, shown, fmt="mcap")
    if meta is not None and meta.compression_mode == "message":
        _decompressed_messages(topics, shown)
    return McapLog(topics, available)


def declared_by_topic(counts: Mapping[int, int], channels: Mapping[int, ChannelRecord]) -> dict[str, int]:
    """A file's Statistics (channel id -> messages) -> per topic, summed over its channels (as rosbags' connections
    carry them); a channel the file does not declare counts for no topic."""
    out: dict[str, int] = {}
    for cid, n in counts.items():
        if cid in channels:
            out[channels[cid].topic] = out.get(channels[cid].topic, 0) + int(n)
    return out


def _short(got: tuple[McapLog, dict[str, int]] | None) -> bool:
    """Whether the indexed read of a file holds fewer messages on a topic than the file declares: a damaged file,
    which the scan reads (and refuses, or salvages, saying where and why) as the plain path does."""
    if got is None:
        return False
    log, counts = got
    return any(n > (len(log.topics[t].payloads) if t in log.topics else 0) for t, n in counts.items())


def _concat(a: McapTopic, b: McapTopic) -> McapTopic:
    """One topic's messages of two storage files, the first file's first (as rosbags reads a folder's files)."""
    if isinstance(a.payloads, PayloadBuffer) and isinstance(b.payloads, PayloadBuffer):
        lengths = np.concatenate([a.payloads.lengths, b.payloads.lengths])
        offsets = np.zeros(lengths.shape[0], dtype=np.int64)
        if lengths.shape[0] > 1:
            np.cumsum(lengths[:-1], out=offsets[1:])
        return McapTopic(a.msgtype, a.has_definition and b.has_definition,
                         np.concatenate([np.asarray(a.log_ns, dtype=np.int64), np.asarray(b.log_ns, dtype=np.int64)]),
                         PayloadBuffer(np.concatenate([a.payloads.data, b.payloads.data]), offsets, lengths))
    return McapTopic(a.msgtype, a.has_definition and b.has_definition, [*a.log_ns, *b.log_ns],
                     [*a.payloads, *b.payloads])


#: what rosbags' MCAP storage raises on bytes it does not read (its summary reading checks state with ``assert``);
#: any of these only means "not read this way": the scan then reads the file and decides
_ROSBAGS_OPEN_ERRORS: tuple[type[BaseException], ...] = (
    ReaderError, AssertionError, struct.error, OSError, EOFError, ValueError, KeyError, IndexError, TypeError,
    OverflowError, MemoryError)


def _read_indexed(file: Path, want: set[str]) -> tuple[McapLog, dict[str, int]] | None:
    """The wanted topics through rosbags' summary and our chunk reader, when the summary describes the whole file
    (module docstring); None otherwise."""
    if not _has_summary(file):
        return None  # rosbags would scan the whole file to find what the scan finds anyway
    storage = McapReader(file)
    try:
        storage.open()
    except _ROSBAGS_OPEN_ERRORS:
        return None
    try:
        if not _summary_is_complete(storage) or not _records_chain(file, storage):
            return None
        conns = [c for c in storage.connections if c.topic in want]
        if any(c.msgtype == _SCHEMALESS for c in conns):
            return None
        one_type_per_topic(((c.topic, c.msgtype) for c in conns), path=str(file))
        got = read_mcap_storage(storage, conns) if conns else {}
        if got is None:
            return None
        topics: dict[str, McapTopic] = {}
        counts: dict[str, int] = {}
        for c in conns:
            counts[c.topic] = counts.get(c.topic, 0) + int(c.msgcount)
            has_def = bool(c.msgdef.data.strip())
            if c.topic in topics:
                topics[c.topic].has_definition &= has_def
                continue
            m = got[c.topic]
            topics[c.topic] = McapTopic(c.msgtype, has_def, m.log_ns, PayloadBuffer(m.data, m.offsets, m.lengths))
        available: dict[str, str] = {}
        for c in storage.connections:
            available.setdefault(c.topic, c.msgtype)
        return McapLog(topics, available), counts
    finally:
        storage.close()


def _has_summary(file: Path) -> bool:
    """Whether the footer (the file's last record before its closing magic) points to a summary section."""
    tail = FOOTER_RECORD + len(MAGIC)
    try:
        with file.open("rb") as fh:
            size = os.fstat(fh.fileno()).st_size
            if size < len(MAGIC) + tail:
                return False
            fh.seek(size - tail)
            footer = fh.read(tail)
    except OSError:
        return False
    if footer[0] != Op.FOOTER or footer[-len(MAGIC) :] != MAGIC:
        return False
    (summary_start,) = struct.unpack_from("<Q", footer, 9)
    return bool(summary_start)


def _summary_is_complete(storage: McapReader) -> bool:
    chunks = storage.chunks
    if not chunks or storage.statistics is None:
        return False
    indexed = 0
    for chunk in chunks:
        if not chunk.message_index_offsets:
            return False  # a chunk index without message indexes: what the chunk holds is not known
        if any(int(cid) not in storage.channels for cid in chunk.message_index_offsets):
            return False  # a channel declared only in the data section
        indexed += sum(int(n) for n in chunk.channel_count.values())
    if any(ch.schema == _SCHEMALESS for ch in storage.channels.values()):
        return False
    # messages outside the chunks (or missing from their message indexes) are counted by the statistics
    return int(storage.statistics.message_count) == indexed


#: top-level records whose content the scan parses (``mcaprecords.record_messages``); every other record (indexes,
#: attachments, metadata, summary offsets) is only stepped over
_PARSED = frozenset({Op.SCHEMA, Op.CHANNEL, Op.MESSAGE, Op.STATISTICS})


def _records_chain(file: Path, storage: McapReader) -> bool:
    """Whether the file's top-level records are what the scan reads without stopping, as far as it can be told
    without reading the chunks' contents: from the header on, every record's length ends by the file's end and the
    next record follows it, up to the footer; schema, channel, message and statistics records parse; each chunk's
    fixed fields and compression string fit its record; and every chunk of the chunk index is a chunk record of that
    length where the index puts it. The indexed reader reads the chunks at the index's offsets, so a damaged record
    length, or a damaged record between the chunks, would otherwise be read past where the scan (the plain read, and
    salvage) stops. What this does not check is inside the chunks the indexed reader does not read (their
    decompression and CRC, and the records of an uncompressed chunk it reads message by message)."""
    chunks = {int(c.chunk_start_offset): c for c in storage.chunks}
    seen = 0
    found = Scan({}, {})
    try:
        with file.open("rb") as fh:
            fd = fh.fileno()
            size = os.fstat(fd).st_size
            pread = _Ahead(fd).pread
            pos = len(MAGIC)
            while True:
                head = pread(RECORD_HEAD + CHUNK_FIXED + 4, pos)
                if len(head) < RECORD_HEAD:
                    return False
                op = head[0]
                (length,) = struct.unpack_from("<Q", head, 1)
                nxt = pos + RECORD_HEAD + length
                if nxt > size:
                    return False
                if op == Op.FOOTER:
                    return seen == len(chunks) and _same_channels(found, storage)
                if op == Op.CHUNK:
                    info = chunks.get(pos)
                    if info is None or int(info.chunk_length) != RECORD_HEAD + length:
                        return False
                    seen += 1
                    if not _chunk_as_indexed(pread, pos, length, info):
                        return False
                elif op in _PARSED:
                    content = pread(length, pos + RECORD_HEAD)
                    if len(content) != length:
                        return False
                    record_messages(op, memoryview(content), found)
                pos = nxt
    except (OSError, struct.error, MalformedError, ValueError, MemoryError, OverflowError):
        return False


class _Ahead:
    """``os.pread`` of one file, small reads served from a block read ahead (a chunk's head, the message index
    records after it and the next chunk's head come in one read): the same bytes as ``os.pread``, a short read
    included where the file ends."""

    BLOCK_B = 8192

    def __init__(self, fd: int) -> None:
        self.fd = fd
        self.block = b""
        self.at = 0

    def pread(self, n: int, pos: int) -> bytes:
        rel = pos - self.at
        if rel >= 0 and rel + n <= len(self.block):
            return self.block[rel : rel + n]
        if n >= self.BLOCK_B:
            return os.pread(self.fd, n, pos)
        self.block, self.at = os.pread(self.fd, self.BLOCK_B, pos), pos
        return self.block[:n]


def _chunk_as_indexed(pread: Callable[[int, int], bytes], pos: int, length: int, info: ChunkInfo) -> bool:
    """Whether the chunk record at ``pos`` (content ``length`` bytes) passes the record layer's structural check
    (``chunk_layout``: fields within the record, a compression the format defines) and is the chunk its index
    entry describes (the indexed reader reads it by the index): only its fixed fields and compression are read
    (``pread(n, pos)``: the file's bytes, as ``os.pread``)."""
    fixed = pread(min(length, CHUNK_FIXED + 4), pos + RECORD_HEAD)
    if len(fixed) < CHUNK_FIXED + 4:
        return False
    (name_len,) = struct.unpack_from("<I", fixed, CHUNK_FIXED)
    head = pread(min(length, CHUNK_FIXED + 4 + name_len + 8), pos + RECORD_HEAD)
    try:
        compression, usize, _crc, _at, stored = chunk_layout(head, length)
    except MalformedError:
        return False
    return (usize, stored, compression) == (int(info.uncompressed_size), int(info.compressed_size),
                                            str(info.compression))


def _same_channels(found: Scan, storage: McapReader) -> bool:
    """Whether the channels the scan takes (the first record of each id, wherever it is) are those rosbags took
    from the summary: same topic and same schema name."""
    for cid, ch in found.channels.items():
        theirs = storage.channels.get(cid)
        schema = found.schemas.get(ch.schema_id)
        if theirs is None or theirs.topic != ch.topic or schema is None or theirs.schema != schema.name:
            return False
    return True


def check_channels_declared(channel_ids: Iterable[int], found: Scan, shown: str, where: str = "") -> None:
    """Every channel a message of a whole file refers to is declared in it (a damaged channel id): else
    ``LogReadError`` naming the channel. The scan's rule, ``watch``'s at a file's close too."""
    for cid in sorted(set(channel_ids) - set(found.channels)):
        raise LogReadError(f"unreadable mcap log: {where}a message refers to channel {cid}, which the file never "
                           f"declares", path=shown)


def _read_scanned(file: Path, want: set[str], shown: str, *, named: bool) -> tuple[McapLog, dict[str, int]]:
    """The wanted topics of one storage file by a scan of all its records (module docstring)."""
    where = f"storage file {file.name}: " if named else ""
    found, kept, channel_ids = _scan_file(file, want, shown, where)
    _refuse_stop(found, shown, where)
    check_channels_declared(channel_ids, found, shown, where)
    one_type_per_topic(((ch.topic, found.schemas[ch.schema_id].name) for ch in found.channels.values()
                        if ch.topic in want and ch.schema_id in found.schemas), path=shown)
    topics = _scanned_topics(found, kept, want, shown, where)
    available: dict[str, str] = {}
    for ch in found.channels.values():
        schema = found.schemas.get(ch.schema_id)
        available.setdefault(ch.topic, schema.name if schema is not None else "")
    counts = {t: n for t, n in declared_by_topic(found.declared or {}, found.channels).items() if t in want}
    return McapLog(topics, available), counts


def _scan_file(file: Path, want: set[str], shown: str, where: str
               ) -> tuple[Scan, list[tuple[int, int, bytes]], set[int]]:
    """The record layer's scan of one file -> what it found, the wanted messages (channel id, log time, payload;
    a message of a channel not declared yet is kept: its channel may come later) and every channel id messages
    refer to."""
    found = Scan({}, {})
    kept: list[tuple[int, int, bytes]] = []
    channel_ids: set[int] = set()
    try:
        with file.open("rb") as fh:
            size = os.fstat(fh.fileno()).st_size
            if size == 0:
                raise TruncatedLogError(f"truncated mcap log: {where}the file is empty", path=shown)
            # mapped, not read: the scan copies only the wanted payloads (the map is released with its last view)
            buf = mmap.mmap(fh.fileno(), 0, access=mmap.ACCESS_READ)
            view = memoryview(buf)
            # chunks holding no wanted topic: checked, not read (as indexed reading), where counts are declared
            skip = frozenset(want) if declares_counts(view) else None
            for msg in scan(view, found, wanted=skip):
                channel_ids.add(msg.channel_id)
                ch = found.channels.get(msg.channel_id)
                if ch is None or ch.topic in want:
                    kept.append((msg.channel_id, msg.log_ns, bytes(msg.payload)))
    except OSError as err:
        raise LogReadError(f"unreadable mcap log: {where}it cannot be read from disk ({err.strerror})",
                           path=shown) from err
    return found, kept, channel_ids


def _refuse_stop(found: Scan, shown: str, where: str) -> None:
    """A scan that stopped before the footer -> the error that says where and why (cut: ``TruncatedLogError``)."""
    stop = found.error
    if stop is None and found.complete:
        return
    at = f" at byte {found.stopped_at}" if found.stopped_at is not None else ""
    if isinstance(stop, CutError) or stop is None:
        raise TruncatedLogError(f"truncated or unindexed mcap log: {where}it ends inside a record{at} (a "
                                f"recorder that was killed; --salvage reads its complete records)", path=shown)
    if isinstance(stop, MalformedError) and str(stop) == "bad magic":
        raise LogReadError(f"unreadable mcap log: {where}not an MCAP file (its first bytes are not the MCAP "
                           f"magic)", path=shown)
    if isinstance(stop, DECOMPRESS_ERRORS):
        raise LogReadError(f"unreadable mcap log: {where}a compressed chunk{at} cannot be decompressed "
                           f"({stop.__class__.__name__})", path=shown)
    raise LogReadError(f"unreadable mcap log: {where}a record{at} is malformed: {in_words(stop)}", path=shown)


def _scanned_topics(found: Scan, kept: list[tuple[int, int, bytes]], want: set[str], shown: str, where: str
                    ) -> dict[str, McapTopic]:
    """The wanted channels' messages per topic, sorted stably by log time: indexed reading's order (log time, then
    file position); a wanted channel without its schema, or not CDR, is refused naming it."""
    topics: dict[str, McapTopic] = {}
    for cid, ch in sorted(found.channels.items()):
        if ch.topic not in want:
            continue
        schema = found.schemas.get(ch.schema_id)
        if schema is None:
            raise LogReadError(f"unreadable mcap log: {where}channel {cid} ({ch.topic}) has no schema record "
                               f"(schema id {ch.schema_id}): its message type is unknown", path=shown)
        if ch.message_encoding != "cdr":
            raise LogReadError(f"unreadable mcap log: {where}channel {cid} ({ch.topic}) is encoded as "
                               f"{ch.message_encoding!r}; ROS2 logs are CDR", path=shown)
        if ch.topic not in topics:
            topics[ch.topic] = McapTopic(schema.name, schema.has_data, [], [])
        else:
            topics[ch.topic].has_definition &= schema.has_data
    kept.sort(key=itemgetter(1))
    columns: dict[str, tuple[list[int], list[bytes]]] = {topic: ([], []) for topic in topics}
    for cid, log_ns, payload in kept:
        col = columns.get(found.channels[cid].topic)
        if col is None:
            continue  # a message before its channel's record, on a topic not wanted
        col[0].append(log_ns)
        col[1].append(payload)
    for topic, (logs, payloads) in columns.items():
        topics[topic].log_ns, topics[topic].payloads = logs, payloads
    return topics
