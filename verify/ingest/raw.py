"""Raw message access for every log format: a path -> the raw payloads of the wanted topics, never modifying input.

input: a log path (ROS1 ``.bag``, bare ``.mcap`` / ``.db3``, or a ROS2 bag directory) and topic names -> output: a
``RawLog`` (per topic: message type, whether the bag carries its definition, log times in ns, raw payloads).

An indexed ROS1 bag is read by our own chunk reader (``verify.ingest.ros1``: index records, chunk decompression,
numpy slicing of the message records) when it is well-formed; anything unusual goes to ``rosbags``. MCAP files and
MCAP bag folders are read as the format defines them (``verify.ingest.mcapfile``). Otherwise opening uses
``rosbags`` readers (``rosbags.rosbag1.Reader``, ``rosbags.rosbag2.Reader``; sqlite3 with ``immutable=1`` so a
``-wal`` file is neither read nor checkpointed). A truncated or unindexed file raises ``TruncatedLogError``; with
``salvage=True`` the complete records are read by a stream walk (``verify.ingest.salvage``) and the result is marked
partial. A log path or bag folder holding a FIFO, device or socket is refused before it is opened.

``TUBEMPC_FAST_INGEST=0`` (``fast_ingest``) turns our own fast readers off: ROS1 and sqlite3 logs are then opened
and read by plain ``rosbags`` (its ``Reader.messages``), MCAP by the record scan, and every payload decoded by one
``deserialize`` per message (``verify.ingest.decode``, ``.fields``). The format of a log is decided by rosbags' own
dispatch (``detect_format``). What only some formats need (``rosbags.rosbag2`` and the YAML library it loads, the
MCAP, sqlite3 and salvage readers) is imported when a log of that format is read.
"""

from __future__ import annotations

import contextlib
import mmap
import os
import sqlite3
import stat
import struct
from collections.abc import Collection, Iterable, Iterator
from dataclasses import dataclass, field
from itertools import repeat
from operator import attrgetter, itemgetter
from pathlib import Path
from typing import TYPE_CHECKING

import apsw  # rosbags reads sqlite3 bags through apsw; its errors must be wrapped like sqlite3's
import numpy as np
import numpy.typing as npt
import yaml
from rosbags.interfaces import Connection, MessageDefinitionFormat
from rosbags.rosbag1 import Reader as Reader1
from rosbags.rosbag1 import ReaderError as ReaderError1
from rosbags.serde import SerdeError

from runkit.gcpause import gc_paused
from verify.errors import LogReadError, TruncatedLogError
from verify.ingest.readerrors import (
    DECOMPRESS_ERRORS,
    check_declared_counts,
    in_words,
    one_type_per_topic,
    rosbag2_errors,
    sqlite_row_readable,
    unreadable_row,
)
from verify.ingest.ros1 import PayloadBuffer, read_ros1_fast
from verify.ingest.ros1records import BagState, bag_state

if TYPE_CHECKING:
    from rosbags.rosbag2 import Reader as Reader2

    from verify.ingest.mcap import TopicMessages
    from verify.ingest.salvage import SalvagedMessage
    from verify.ingest.sqlite import QuickReader

__all__ = ["FAST_INGEST_ENV", "RawLog", "RawTopic", "check_bag_folder", "check_log_path", "detect_format",
           "fast_ingest", "read_raw", "special_file_kind"]

#: environment variable: "0" (or "false", "no", "off") reads every log through plain rosbags
FAST_INGEST_ENV = "TUBEMPC_FAST_INGEST"
_OFF = frozenset({"0", "false", "no", "off"})

_ROS1_TRUNCATION_HINTS = ("not indexed", "index looks damaged", "Got only", "could not be read", "Could not read")
_MCAP_TRUNCATION_HINTS = ("end magic", "Truncated record", "footer", "summary offset", "seems to be empty")


@dataclass(slots=True)
class RawTopic:
    """Raw payloads of one topic in the order of reading (rosbags' order: by log time for indexed logs).

    ``log_ns`` is a list or an int64 array, ``payloads`` a list of bytes or a ``PayloadBuffer`` (the fast ROS1
    reader's packed buffer, which indexes like a list)."""

    topic: str
    msgtype: str
    has_definition: bool
    log_ns: list[int] | npt.NDArray[np.int64] = field(default_factory=list)
    payloads: list[bytes] | PayloadBuffer = field(default_factory=list)


@dataclass(frozen=True, slots=True)
class RawLog:
    """What a log holds for the wanted topics, plus how it was read."""

    path: str
    format: str  # "ros1", "mcap", "sqlite3"
    ros1: bool
    topics: dict[str, RawTopic]  # wanted topics that exist in the log
    available: dict[str, str]  # every topic in the log -> its message type
    partial: bool
    notes: tuple[str, ...]


def fast_ingest() -> bool:
    """Whether our own readers and bulk decoders may be used (the default; read at every call, so a test or a
    process can switch). Off (``TUBEMPC_FAST_INGEST=0``), every read goes through plain rosbags: the same
    certificate, only slower (the reader tests run both ways)."""
    return os.environ.get(FAST_INGEST_ENV, "1").strip().lower() not in _OFF


def detect_format(path: Path) -> str:
    """"ros1", "mcap" or "sqlite3", decided as rosbags decides which reader opens the log (``AnyReader``: ``.bag``
    is ROS1; ``rosbags.rosbag2.Reader.STORAGE_PLUGINS``: a file by its suffix; ``DirectoryReader.STORAGE_PLUGINS``:
    a bag folder by the ``storage_identifier`` of its metadata.yaml). A folder whose metadata.yaml cannot say (not
    YAML, no such key) is named by its storage files, so the error rosbags then raises names the right format."""
    if path.is_dir():
        meta = path / "metadata.yaml"
        if not meta.exists():
            raise LogReadError("a directory without metadata.yaml is not a ROS2 bag", path=str(path))
        storage_id = _storage_identifier(meta)
        if storage_id is None:
            return _format_from_files(path)
        from rosbags.rosbag2.reader import DirectoryReader  # ROS2 logs only (module docstring)

        plugin = DirectoryReader.STORAGE_PLUGINS.get(storage_id)
        if plugin is None or plugin not in _plugin_formats():
            raise LogReadError(f"metadata.yaml names the storage plugin {storage_id!r}; rosbags reads "
                               f"{' and '.join(sorted(DirectoryReader.STORAGE_PLUGINS))} bags", path=str(path))
        return _plugin_formats()[plugin]
    if path.suffix.lower() == ".bag":  # rosbags' ROS1 reader opens any file name
        return "ros1"
    from rosbags.rosbag2 import Reader as Reader2  # ROS2 logs only (module docstring)

    formats = _plugin_formats()
    plugin = Reader2.STORAGE_PLUGINS.get(path.suffix)
    if plugin in formats:
        return formats[plugin]
    known = sorted({".bag", *(k for k, v in Reader2.STORAGE_PLUGINS.items() if v in formats)})
    if path.suffix.lower() in known:
        raise LogReadError(f"extension {path.suffix!r}: rosbags recognizes {path.suffix.lower()!r} in lower case "
                           f"only (rename the file)", path=str(path))
    raise LogReadError(f"unrecognized log type {path.suffix or '(no extension)'!r}: expected "
                       f"{', '.join(known)} or a ROS2 bag directory", path=str(path))


def _plugin_formats() -> dict[object, str]:
    """rosbags' storage reader classes -> our format names."""
    from rosbags.rosbag2.storage_mcap import McapReader  # ROS2 logs only (module docstring)
    from rosbags.rosbag2.storage_sqlite3 import Sqlite3Reader

    return {McapReader: "mcap", Sqlite3Reader: "sqlite3"}


#: libyaml's safe loader when PyYAML has it (10x faster on a bag's metadata.yaml), else the pure-Python one
_SAFE_LOADER: type[yaml.SafeLoader] = getattr(yaml, "CSafeLoader", yaml.SafeLoader)
_METADATA_MAX_BYTES = 64 << 20  # a metadata.yaml is a few KiB; a bigger one is damage (files decide)


def _storage_identifier(meta: Path) -> str | None:
    """``rosbag2_bagfile_information.storage_identifier`` of a metadata.yaml; None when it cannot be read."""
    try:
        if meta.stat().st_size > _METADATA_MAX_BYTES:
            return None
        doc = yaml.load(meta.read_text(encoding="utf-8", errors="replace"), Loader=_SAFE_LOADER)
    except (OSError, yaml.YAMLError, RecursionError, ValueError):
        return None
    info = doc.get("rosbag2_bagfile_information") if isinstance(doc, dict) else None
    ident = info.get("storage_identifier") if isinstance(info, dict) else None
    return ident if isinstance(ident, str) else None


def _format_from_files(path: Path) -> str:
    suffixes = {p.suffix for p in path.iterdir()}
    return "sqlite3" if ".db3" in suffixes and ".mcap" not in suffixes else "mcap"


def _storage_files(path: Path, fmt: str) -> list[Path]:
    if not path.is_dir():
        return [path]
    ext = ".mcap" if fmt == "mcap" else ".db3"
    return sorted(p for p in path.iterdir() if p.suffix == ext)


def special_file_kind(mode: int) -> str | None:
    """What a file that is not regular (nor a folder) is, in words; None for a regular file or a folder."""
    if stat.S_ISREG(mode) or stat.S_ISDIR(mode):
        return None
    return ("a FIFO (named pipe)" if stat.S_ISFIFO(mode) else "a character device" if stat.S_ISCHR(mode)
            else "a block device" if stat.S_ISBLK(mode) else "a socket" if stat.S_ISSOCK(mode)
            else "not a regular file")


def check_bag_folder(folder: Path) -> None:
    """Refuse a bag folder holding a FIFO, device or socket (itself or as a symlink's target), before any file of
    it is opened: a reader, a digest or a follower would block on it for ever. Entries that vanish meanwhile or
    dangle are left to the reader (which names a missing storage file)."""
    try:
        entries = sorted(folder.iterdir())
    except OSError as err:
        raise LogReadError(f"cannot list the bag folder ({err.strerror or err.__class__.__name__})",
                           path=str(folder)) from None
    for entry in entries:
        try:
            mode = entry.stat().st_mode
        except OSError:
            continue
        if (kind := special_file_kind(mode)) is not None:
            raise LogReadError(f"{entry.name} inside the bag folder is {kind}: a ROS2 bag folder holds regular "
                               f"files", path=str(folder))


def check_log_path(path: Path) -> None:
    """A log is a regular file or a bag folder of regular files (``check_bag_folder``); refused otherwise, before
    it is opened."""
    try:
        mode = path.stat().st_mode
    except OSError as err:
        raise LogReadError(f"cannot be read ({err.strerror or err.__class__.__name__})", path=str(path)) from None
    if stat.S_ISDIR(mode):
        check_bag_folder(path)
    elif (kind := special_file_kind(mode)) is not None:
        raise LogReadError(f"is {kind}: a log must be a regular file or a ROS2 bag folder", path=str(path))


def read_raw(path: str | Path, topics: Iterable[str], *, salvage: bool = False) -> RawLog:
    """Read the raw payloads of ``topics`` (those present) from the log at ``path``."""
    p = Path(path)
    if not p.exists():
        raise LogReadError("no such file or directory", path=str(p))
    if p.is_dir():
        check_bag_folder(p)
    fmt = detect_format(p)
    wanted = set(topics)
    notes: list[str] = []
    if fmt == "sqlite3":
        for db in _storage_files(p, fmt):
            wal = db.with_name(db.name + "-wal")
            if wal.exists() and wal.stat().st_size > 0:
                notes.append(f"un-checkpointed write-ahead log {wal.name} ({wal.stat().st_size} bytes) beside "
                             f"{db.name}: the database is opened read-only and immutable, so messages still in the "
                             f"-wal file are not read")
        if p.is_dir():
            _check_folder_topics(p)
    if fmt == "ros1" and fast_ingest() and (fast := read_ros1_fast(p, wanted)) is not None:
        topics_out = {topic: RawTopic(topic, msgtype, has_def, log_ns, payloads)
                      for topic, (msgtype, has_def, log_ns, payloads) in fast.topics.items()}
        return RawLog(str(p), fmt, True, topics_out, fast.available, False, tuple(notes))
    try:
        with gc_paused():
            return _read_indexed(p, fmt, wanted, notes)
    except TruncatedLogError as err:
        if not salvage:
            raise
        if fmt == "sqlite3":
            raise TruncatedLogError(f"{err.reason}; --salvage supports ROS1 and MCAP logs only", path=str(p)) from err
        from verify.ingest.mcapfile import read_bag_metadata  # ROS2 logs only (module docstring)

        if p.is_dir() and read_bag_metadata(p).compression_mode is not None:
            raise TruncatedLogError(f"{err.reason}; --salvage does not read compressed bag folders", path=str(p)
                                    ) from err
        with gc_paused():
            return _salvage(p, fmt, wanted, [*notes, f"salvaged after: {err.reason}"])


def _check_folder_topics(folder: Path) -> None:
    """A sqlite3 bag folder: the topics its metadata.yaml declares against those its storage files hold
    (``verify.ingest.mcapfile.check_declared_topics``, the rule ``watch`` applies too). Where either side cannot be
    read, the readers below report it as before."""
    from verify.ingest.mcapfile import check_declared_topics, read_bag_metadata  # ROS2 logs only

    try:
        meta = read_bag_metadata(folder)
        stored: set[str] = set()
        for db in _storage_files(folder, "sqlite3"):
            con = apsw.Connection(f"file:{db}?mode=ro&immutable=1",
                                  flags=apsw.SQLITE_OPEN_READONLY | apsw.SQLITE_OPEN_URI)
            try:
                stored |= {str(name) for (name,) in con.execute("SELECT name FROM topics")}
            finally:
                con.close()
    except (LogReadError, apsw.Error, OSError, ValueError, TypeError):
        return
    check_declared_topics(folder, meta, stored)


#: What rosbags' readers raise on a damaged file, caught only around their calls (open, messages): rosbags checks
#: its index with ``assert`` and indexes its records unguarded, so KeyError, IndexError, TypeError, AttributeError
#: and AssertionError from it mean damaged bytes (apsw: rosbags' sqlite3 driver, e.g. CorruptError on a truncated
#: .db3). rosbags.rosbag2's ReaderError joins them once that package is loaded (``_read_errors``).
_BASE_READ_ERRORS: tuple[type[Exception], ...] = (
    ReaderError1, OSError, sqlite3.DatabaseError, apsw.Error, struct.error, EOFError, ValueError,
    KeyError, IndexError, TypeError, AttributeError, AssertionError, UnicodeDecodeError, OverflowError, MemoryError,
    RecursionError, NotImplementedError, SerdeError, *DECOMPRESS_ERRORS)


def _read_errors() -> tuple[type[Exception], ...]:
    return (*_BASE_READ_ERRORS, *rosbag2_errors())


def _ros1_state(path: Path) -> BagState | None:
    """The record layer's word on a ROS1 bag rosbags could not read (``verify.ingest.ros1records.bag_state``):
    the file mapped, not read into memory; None when it cannot be mapped."""
    try:
        with path.open("rb") as fh:
            if os.fstat(fh.fileno()).st_size == 0:
                return BagState(False)
            buf = mmap.mmap(fh.fileno(), 0, access=mmap.ACCESS_READ)
    except (OSError, ValueError):
        return None
    view = memoryview(buf)
    try:
        return bag_state(view)
    finally:
        view.release()
        with contextlib.suppress(BufferError):
            buf.close()


def _wrap_error(path: Path, fmt: str, err: Exception) -> LogReadError:
    """A reader's error on a log -> the error the user reads. For a ROS1 bag the record layer decides, as for
    salvage and ``watch``: a malformed record is damage (exit 3, never salvaged: ``--salvage`` reads logs that
    were cut, as for MCAP), bytes that end before the bag is closed by its recorder are a truncated or unindexed
    log (``--salvage`` reads its complete records)."""
    text = " ".join(str(err).split()) or err.__class__.__name__
    state = _ros1_state(path) if fmt == "ros1" and path.is_file() else None
    if state is not None and state.damage is not None:
        return LogReadError(f"damaged ros1 log: {state.damage} (the record at byte {state.at})", path=str(path))
    if state is not None and not state.closed:
        return TruncatedLogError(f"truncated or unindexed {fmt} log ({text[:160]}); --salvage reads its complete "
                                 f"records", path=str(path))
    hints = _ROS1_TRUNCATION_HINTS if fmt == "ros1" else _MCAP_TRUNCATION_HINTS
    if isinstance(err, struct.error | EOFError) or any(h in text for h in hints):
        return TruncatedLogError(f"truncated or unindexed {fmt} log ({text[:160]}); --salvage reads its complete "
                                 f"records", path=str(path))
    if isinstance(err, sqlite3.DatabaseError | apsw.Error):
        return TruncatedLogError(f"unreadable sqlite3 database: {in_words(err)}", path=str(path))
    return LogReadError(f"unreadable {fmt} log: {in_words(err)}", path=str(path))


def _read_indexed(path: Path, fmt: str, wanted: set[str], notes: list[str]) -> RawLog:
    own = fast_ingest()
    if fmt == "mcap":
        from verify.ingest.mcapfile import read_mcap_log  # MCAP logs only (module docstring)

        got = read_mcap_log(path, wanted, fast=own)
        out = {topic: RawTopic(topic, t.msgtype, t.has_definition, t.log_ns, t.payloads)
               for topic, t in got.topics.items()}
        return RawLog(str(path), fmt, False, out, got.available, False, tuple(notes))
    if fmt == "sqlite3" and own and (quick := _read_sqlite_quick(path, wanted, notes)) is not None:
        return quick
    reader: Reader1 | Reader2
    if fmt != "ros1":
        from rosbags.rosbag2 import Reader as Reader2  # ROS2 logs only (module docstring)
    try:
        reader = Reader1(path) if fmt == "ros1" else Reader2(path)
        reader.open()
    except _read_errors() as err:
        if path.is_dir() and isinstance(err, (KeyError, TypeError, AttributeError, *rosbag2_errors())) and not \
                isinstance(err, sqlite3.DatabaseError | apsw.Error) and not isinstance(err.__cause__, apsw.Error):
            # (an apsw error under rosbags' ReaderError: its storage file, not its metadata.yaml, is unreadable)
            raise LogReadError(f"unreadable {fmt} ROS2 bag: its metadata.yaml is incomplete or malformed "
                               f"({err.__class__.__name__}: {' '.join(str(err).split())[:160]})",
                               path=str(path)) from err
        raise _wrap_error(path, fmt, err) from err
    try:
        conns = list(reader.connections)
        available = {c.topic: c.msgtype for c in conns}
        selected = [c for c in conns if c.topic in wanted]
        out = _topics_from(selected)
        rows: list[tuple[Connection, int, bytes | memoryview]] = []
        fast = _read_rosbag2_fast(reader, selected) if own and selected and not isinstance(reader, Reader1) else None
        if selected and fast is None:
            try:
                rows = list(reader.messages(connections=selected))
            except _read_errors() as err:
                raise _wrap_error(path, fmt, err) from err
    finally:
        reader.close()
    if fast is not None:
        for topic, raw_topic in out.items():
            m = fast.get(topic)
            if m is not None:
                raw_topic.log_ns, raw_topic.payloads = m.log_ns, PayloadBuffer(m.data, m.offsets, m.lengths)
        _check_counts(path, fmt, selected, out)
        return RawLog(str(path), fmt, False, out, available, False, tuple(notes))
    _check_rows(path, fmt, rows, list(out))
    for topic, (log_ns, payloads) in _split_by_topic(rows, list(out)).items():
        out[topic].log_ns, out[topic].payloads = log_ns, payloads
    _check_counts(path, fmt, selected, out)
    return RawLog(str(path), fmt, fmt == "ros1", out, available, False, tuple(notes))


def _check_rows(path: Path, fmt: str, rows: list[tuple[Connection, int, bytes | memoryview]], topics: list[str]
                ) -> None:
    """Every row a reader yields is of a topic asked for (a damaged ROS1 index or message record can make rosbags
    yield a message of another connection) and has an integer log time and a payload: a damaged sqlite3 page can hold
    a message row whose columns read as NULL (its NOT NULL constraint is only checked when rows are written), which
    rosbags yields as it is."""
    stray = set(map(attrgetter("topic"), map(itemgetter(0), rows))).difference(topics)
    if stray:
        raise LogReadError(f"damaged {fmt} log: reading the wanted topics yields messages of {min(stray)}, which was "
                           f"not asked for (a damaged index or message record)", path=str(path))
    if all(map(int.__instancecheck__, map(itemgetter(1), rows))) and \
            all(map(isinstance, map(itemgetter(2), rows), repeat(bytes | memoryview))) and \
            min(map(itemgetter(1), rows), default=0) >= 0:
        return
    bad = next(r for r in rows if not sqlite_row_readable(r[1], r[2]))
    raise unreadable_row(fmt, bad[0].topic, str(path))


def _check_counts(path: Path, fmt: str, selected: list[Connection], out: dict[str, RawTopic]) -> None:
    """Messages read vs the counts the file declares (MCAP statistics, metadata.yaml, the ROS1 index): a damaged
    index or chunk can make a reader stop early without an error, which would silently drop samples."""
    declared: dict[str, int] = {}
    for c in selected:
        declared[c.topic] = declared.get(c.topic, 0) + int(getattr(c, "msgcount", 0) or 0)
    check_declared_counts(declared, {t: len(r.payloads) for t, r in out.items()}, declared, str(path), fmt=fmt)


def _read_sqlite_quick(path: Path, wanted: set[str], notes: list[str]) -> RawLog | None:
    """The wanted topics of a sqlite3 log through our open (``QuickReader``: rosbags' checks, connections and
    definitions without its two counting scans of ``messages``) and our fast reader; None when no wanted topic is
    present, on any error and on anything the fast reader declines: then rosbags opens and reads the log as before
    (so errors, truncation and their messages are rosbags')."""
    from verify.ingest.sqlite import QuickReader  # sqlite3 logs only (module docstring)

    try:
        reader = QuickReader(path)
        reader.open()
    except _read_errors():  # what rosbags' open raises on a damaged log: rosbags' own open then decides and reports
        return None
    try:
        conns = list(reader.connections)
        selected = [c for c in conns if c.topic in wanted]
        fast = _read_rosbag2_fast(reader, selected) if selected else None
        if fast is not None:  # the counts rosbags' open declares (its count scan, for the selected topics only)
            selected = _with_counts(reader, selected)
    except _read_errors():  # as above
        fast = None
    finally:
        try:
            reader.close()
        except _read_errors():  # as above
            fast = None
    if fast is None:
        return None
    out = _topics_from(selected)
    for topic, raw_topic in out.items():
        m = fast.get(topic)
        if m is not None:
            raw_topic.log_ns, raw_topic.payloads = m.log_ns, PayloadBuffer(m.data, m.offsets, m.lengths)
    _check_counts(path, "sqlite3", selected, out)
    return RawLog(str(path), "sqlite3", False, out, {c.topic: c.msgtype for c in conns}, False, tuple(notes))


def _with_counts(reader: QuickReader, selected: list[Connection]) -> list[Connection]:
    """A bare ``.db3``'s selected connections with their message counts as rosbags' open counts them
    (``count(messages.id)`` of a left join of ``topics`` and ``messages``): a damaged table or index can make the
    ordered read return other rows than the table holds, which the count check then names, as on rosbags' own
    path."""
    from rosbags.rosbag2.storage_sqlite3 import Sqlite3Reader  # ROS2 logs only (module docstring)

    storage = reader.storage
    if not isinstance(storage, Sqlite3Reader) or storage.dbconn is None:
        return selected  # a bag folder: its metadata.yaml declares the counts
    ids = sorted({int(c.id) for c in selected})
    rows = storage.dbconn.execute(
        f"SELECT topics.id, count(messages.id) FROM topics LEFT JOIN messages ON topics.id == messages.topic_id "
        f"WHERE topics.id IN ({','.join('?' * len(ids))}) GROUP BY topics.id", ids).fetchall()
    counts = {int(cid): int(n) for cid, n in rows if isinstance(cid, int) and isinstance(n, int)}
    return [c._replace(msgcount=counts.get(int(c.id), 0)) for c in selected]


#: ``read_topics_by_storage``: the folder opens, but its storages are not read storage by storage (per-message
#: compression): every wanted topic's rows are read
EVERY_STORAGE: dict[str, set[str]] = {}


def read_topics_by_storage(folder: Path, wanted: Collection[str]) -> dict[str, set[str]] | None:
    """A closed bag folder: per storage file (by name), the topics whose rows rosbags' reader reads for the wanted
    topics (metadata.yaml's connections matched to the storage's own by topic, type, serialization and QoS and type
    hash: ``_storage_plan``, the rule certify's readers read by); ``EVERY_STORAGE`` where the readers do not go
    storage by storage. None when the folder does not open as certify's readers open it (rosbags' metadata.yaml and
    storage checks: certify refuses such a folder)."""
    from verify.ingest.sqlite import QuickReader  # ROS2 bag folders only (module docstring)

    try:
        reader = QuickReader(folder)
        reader.open()
    except _read_errors():
        return None
    try:
        plan = _storage_plan(reader, [c for c in reader.connections if c.topic in wanted])
        if plan is None:
            return EVERY_STORAGE
        return {Path(str(getattr(st, "path", ""))).name: {c.topic for c in conns} for st, conns in plan}
    finally:
        with contextlib.suppress(*_read_errors()):
            reader.close()


def _storage_plan(reader: Reader2, selected: list[Connection]) -> list[tuple[object, list[Connection]]] | None:
    """(storage, its connections to read) in the order rosbags' ``Reader.messages(selected)`` reads them; None for
    what the fast readers do not reproduce (per-message compression, unknown storage)."""
    from rosbags.rosbag2.reader import DirectoryReader  # ROS2 logs only (module docstring)
    from rosbags.rosbag2.storage_mcap import McapReader
    from rosbags.rosbag2.storage_sqlite3 import Sqlite3Reader

    st = reader.storage
    if isinstance(st, McapReader | Sqlite3Reader):
        return [(st, selected)]
    if not isinstance(st, DirectoryReader) or st.metadata.compression_mode == "message":
        return None
    plan: list[tuple[object, list[Connection]]] = []
    for storage in st.storages:
        # DirectoryReader.messages: a storage connection is read when a selected connection matches it
        storage_conns = [x for x in storage.connections
                         if any(y.topic == x.topic and y.msgtype == x.msgtype and y.ext == x.ext
                                and (not x.digest or not y.digest or y.digest == x.digest) for y in selected)]
        if storage_conns:
            plan.append((storage, storage_conns))
    return plan


def _read_rosbag2_fast(reader: Reader2, selected: list[Connection]) -> dict[str, TopicMessages] | None:
    """The selected topics' messages through our MCAP / sqlite3 readers (verify.ingest.mcap, .sqlite), storage
    after storage as rosbags reads them; None when any storage declines (then rosbags reads the log)."""
    from rosbags.rosbag2.storage_mcap import McapReader  # ROS2 logs only (module docstring)
    from rosbags.rosbag2.storage_sqlite3 import Sqlite3Reader

    from verify.ingest.mcap import TopicMessages, read_mcap_storage
    from verify.ingest.sqlite import read_sqlite_storage

    plan = _storage_plan(reader, selected)
    if plan is None:
        return None
    per_storage: list[dict[str, TopicMessages]] = []
    for storage, conns in plan:
        got: dict[str, TopicMessages] | None
        if isinstance(storage, McapReader):
            got = read_mcap_storage(storage, conns)
        elif isinstance(storage, Sqlite3Reader):
            got = read_sqlite_storage(storage, conns)
        else:
            return None
        if got is None:
            return None
        per_storage.append(got)
    out: dict[str, TopicMessages] = {}
    for topic in {c.topic for c in selected}:
        pieces = [got[topic] for got in per_storage if topic in got]
        if not pieces:
            continue
        if len(pieces) == 1:
            out[topic] = pieces[0]
            continue
        lengths = np.concatenate([m.lengths for m in pieces])
        offsets = np.zeros(lengths.shape[0], dtype=np.int64)
        if lengths.shape[0] > 1:
            np.cumsum(lengths[:-1], out=offsets[1:])
        out[topic] = TopicMessages(np.concatenate([m.log_ns for m in pieces]),
                                   np.concatenate([m.data for m in pieces]), offsets, lengths)
    return out


def _split_by_topic(rows: list[tuple[Connection, int, bytes | memoryview]], topics: list[str]
                    ) -> dict[str, tuple[list[int], list[bytes]]]:
    """(connection, log time, payload) rows in reading order -> per topic its log times and payloads (bytes), in
    the same order; column-wise (no per-row Python statement)."""
    if not rows:
        return {t: ([], []) for t in topics}
    logs: list[int] = list(map(itemgetter(1), rows))
    raws = list(map(itemgetter(2), rows))
    payloads: list[bytes] = raws if all(map(isinstance, raws, repeat(bytes))) else list(map(bytes, raws))
    if len(topics) == 1:
        return {topics[0]: (logs, payloads)}
    names = list(map(attrgetter("topic"), map(itemgetter(0), rows)))
    if len(set(names)) == 1:
        return {t: (logs, payloads) if t == names[0] else ([], []) for t in topics}
    code = {t: k for k, t in enumerate(topics)}
    codes = np.fromiter(map(code.__getitem__, names), dtype=np.int64, count=len(names))
    out: dict[str, tuple[list[int], list[bytes]]] = {}
    for t, k in code.items():
        idx = np.flatnonzero(codes == k).tolist()
        out[t] = ([logs[i] for i in idx], [payloads[i] for i in idx])
    return out


def _topics_from(conns: Iterable[Connection]) -> dict[str, RawTopic]:
    out: dict[str, RawTopic] = {}
    conns = list(conns)
    one_type_per_topic((c.topic, c.msgtype) for c in conns)
    for c in conns:
        has_def = c.msgdef.format != MessageDefinitionFormat.NONE and bool(c.msgdef.data.strip())
        if c.topic not in out:
            out[c.topic] = RawTopic(c.topic, c.msgtype, has_def)
        elif not has_def:
            out[c.topic].has_definition = False
    return out


def _salvage(path: Path, fmt: str, wanted: set[str], notes: list[str]) -> RawLog:
    from verify.ingest.salvage import walk_mcap, walk_ros1  # --salvage only (module docstring)

    messages: Iterator[SalvagedMessage]
    out: dict[str, RawTopic] = {}
    logs: dict[str, list[int]] = {}
    payloads: dict[str, list[bytes]] = {}
    available: dict[str, str] = {}
    stops: list[str] = []
    files = _storage_files(path, fmt)
    for file in files:
        walk = walk_ros1(file) if fmt == "ros1" else walk_mcap(file)
        messages = walk.messages
        for m in messages:
            available[m.topic] = m.msgtype
            if m.topic not in wanted:
                continue
            if m.topic not in out:
                out[m.topic] = RawTopic(m.topic, m.msgtype, m.has_definition)
                logs[m.topic], payloads[m.topic] = [], []
            elif m.msgtype != out[m.topic].msgtype:
                one_type_per_topic([(m.topic, out[m.topic].msgtype), (m.topic, m.msgtype)])
            logs[m.topic].append(m.log_ns)
            payloads[m.topic].append(m.payload)
        stops.append(f"{file.name}: {walk.stop_reason()}")
    for topic, t in out.items():
        t.log_ns, t.payloads = logs[topic], payloads[topic]
    return RawLog(str(path), fmt, fmt == "ros1", out, available, True, tuple(notes + stops))
