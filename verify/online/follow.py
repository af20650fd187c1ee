"""Logs that are still being written: a path -> the messages of the records completed since the last poll.

input: an MCAP file, a ROS2 bag folder (MCAP or sqlite3 storage, ``metadata.yaml`` written when the recorder
stops) or a ROS1 ``.bag`` that a recorder is appending to -> output: a ``Follower`` whose ``poll`` returns the
``SalvagedMessage`` values of every record completed since the previous poll, in file order, and whose ``finished``
says that the recorder closed the log (MCAP footer, ROS1 header pointing to its index, ROS2 ``metadata.yaml``).

A record (an MCAP chunk, a ROS1 chunk) that is not complete yet is left for a later poll: only its bytes are
re-read, never what was consumed. Files are opened read-only. ``rest`` reads, after the last poll, what
``--salvage`` reads from a file that will not be completed (the complete records of a cut uncompressed chunk).
"""

from __future__ import annotations

import sqlite3
import struct
from collections.abc import Collection, Iterable, Iterator, Mapping
from operator import itemgetter
from pathlib import Path
from typing import Any, Protocol

from verify.errors import LogReadError, TruncatedLogError
from verify.ingest.mcapfile import check_channels_declared, check_declared_topics, declared_by_topic, read_bag_metadata
from verify.ingest.mcaprecords import MAGIC as MCAP_MAGIC
from verify.ingest.mcaprecords import CutError, MalformedError, Scan, record_messages
from verify.ingest.mcaprecords import Op as McapOp
from verify.ingest.mcaprecords import walk as mcap_walk
from verify.ingest.raw import EVERY_STORAGE, check_log_path, read_topics_by_storage
from verify.ingest.readerrors import (
    DECOMPRESS_ERRORS,
    check_declared_counts,
    in_words,
    sqlite_row_readable,
    unreadable_row,
)
from verify.ingest.ros1records import DAMAGE as _ROS1_DAMAGE
from verify.ingest.ros1records import MAGIC as ROS1_MAGIC
from verify.ingest.ros1records import Ros1Message, Ros1Stream
from verify.ingest.salvage import SalvagedMessage, mcap_message, ros1_message, walk_mcap, walk_ros1

__all__ = ["Follower", "log_bytes", "open_follower"]

#: what a complete MCAP record raises when its bytes are damaged
_MCAP_DAMAGE: tuple[type[Exception], ...] = (MalformedError, struct.error, ValueError, ImportError, *DECOMPRESS_ERRORS)


class Follower(Protocol):
    path: Path
    format: str  # "mcap" | "ros1" | "sqlite3"
    finished: bool
    delivered: int
    #: topics the log declares (name -> type) whose messages are not all delivered: a sqlite3 storage's topics table
    #: (only the wanted topics' rows are read, as certify reads them); empty where every message is delivered
    declared_topics: dict[str, str]

    def poll(self) -> list[SalvagedMessage]: ...

    def rest(self) -> list[SalvagedMessage]: ...


def _read_from(path: Path, pos: int) -> bytes:
    try:
        with path.open("rb") as fh:
            fh.seek(pos)
            return fh.read()
    except OSError as err:
        raise LogReadError(f"cannot read ({err.strerror or err})", path=str(path)) from err


class McapFollower:
    """Top-level MCAP records from a byte offset, through the record layer (``verify.ingest.mcaprecords``); a chunk
    is read once it is complete."""

    def __init__(self, path: Path, wanted: Collection[str] | None = None, *, in_folder: bool = False) -> None:
        self.path = path
        self.format = "mcap"
        self.finished = False
        self.delivered = 0
        self.declared_topics: dict[str, str] = {}
        self.pos = 0
        self.found = Scan({}, {})
        self.wanted = wanted
        self.in_folder = in_folder  # a bag folder's file: the folder checks its counts (summed over its files)
        self.read_counts: dict[str, int] = {}  # messages delivered per topic
        self.channel_ids: set[int] = set()  # every channel a message referred to

    def poll(self) -> list[SalvagedMessage]:
        out: list[SalvagedMessage] = []
        if self.finished:
            return out
        buf = _read_from(self.path, self.pos)
        pos = 0
        if self.pos == 0:
            if len(buf) < len(MCAP_MAGIC):
                return out
            if not buf.startswith(MCAP_MAGIC):
                raise LogReadError("not an MCAP file (bad magic)", path=str(self.path))
            pos = len(MCAP_MAGIC)
        try:
            for op, rec, nxt in mcap_walk(buf, pos, len(buf)):
                if op == McapOp.FOOTER:  # the recorder closed the file (as the scan: its summary was read too)
                    self.finished = True
                else:
                    for msg in record_messages(op, rec, self.found):  # a chunk's CRC checked, as the scan does
                        self.channel_ids.add(msg.channel_id)
                        if (got := mcap_message(self.found, msg)) is not None:
                            out.append(got)
                pos = nxt
                if self.finished:
                    break
        except CutError:
            pass  # a record still being written: read it again next time
        except _MCAP_DAMAGE as err:
            raise LogReadError(f"malformed MCAP record at byte {self.pos + pos} ({err})", path=str(self.path)) from err
        self.pos += pos
        self.delivered += len(out)
        for m in out:
            self.read_counts[m.topic] = self.read_counts.get(m.topic, 0) + 1
        if self.finished:  # closed: every message's channel declared, as the scan requires
            shown = self.path.parent if self.in_folder else self.path
            check_channels_declared(self.channel_ids, self.found, str(shown),
                                    f"storage file {self.path.name}: " if self.in_folder else "")
        if self.finished and not self.in_folder:  # closed: the messages its Statistics declare, as certify reads it
            check_declared_counts(self.declared_counts(), self.read_counts,
                                  self.read_counts.keys() | self.declared_counts().keys()
                                  if self.wanted is None else self.wanted, str(self.path), fmt="mcap")
        return out

    def declared_counts(self) -> dict[str, int]:
        """Per topic, the messages the file's Statistics declare (empty without Statistics)."""
        return declared_by_topic(self.found.declared or {}, self.found.channels)

    def rest(self) -> list[SalvagedMessage]:
        return _rest_of_walk(walk_mcap(self.path).messages, self.delivered)


def _rest_of_walk(messages: Iterator[SalvagedMessage], delivered: int) -> list[SalvagedMessage]:
    """The salvage walk yields the messages of the complete records in file order, as the follower did; what it
    yields beyond them are the complete records of a cut uncompressed chunk."""
    return [m for k, m in enumerate(messages) if k >= delivered]


class Ros1Follower:
    """ROS1 records from a byte offset through the record layer's stream (``Ros1Stream``): the message records of an
    open uncompressed chunk are read as they are appended, a compressed chunk once it is closed; the file is
    finished when the bag header points to the index (rosbag writes it last)."""

    def __init__(self, path: Path) -> None:
        self.path = path
        self.format = "ros1"
        self.finished = False
        self.delivered = 0
        self.declared_topics: dict[str, str] = {}
        self.stream = Ros1Stream()

    def poll(self) -> list[SalvagedMessage]:
        if self.finished:
            return []
        base = self.stream.resume_at
        if base == len(ROS1_MAGIC):
            head = _read_from(self.path, 0)
            if len(head) < len(ROS1_MAGIC):
                return []
            if not head.startswith(ROS1_MAGIC):
                raise LogReadError("not a ROS1 bag (bad magic)", path=str(self.path))
            buf = head[base:]
        else:
            buf = _read_from(self.path, base)
        got: list[Ros1Message] = []
        try:
            self.stream.feed(buf, base, got)
        except _ROS1_DAMAGE as err:
            raise LogReadError(f"malformed ROS1 record at byte {self.stream.resume_at} ({err})",
                               path=str(self.path)) from err
        if not self.stream.closed:
            self._recheck_header(base + len(buf))
        self.finished = self.stream.closed
        out = [m for m in (ros1_message(self.stream, g) for g in got) if m is not None]
        self.delivered += len(out)
        return out

    def _recheck_header(self, fed: int) -> None:
        """The recorder rewrites the bag header's index_pos when it closes the bag (``fed``: where the bytes this
        poll read end)."""
        self.stream.reread_header(_read_from(self.path, 0)[:8192])
        try:
            if self.stream.index_pos and self.stream.chunk is None and self.stream.pos >= self.stream.index_pos:
                at = self.stream.resume_at  # closed once the whole index is there (the stream checks it)
                self.stream.feed(_read_from(self.path, at), at, [])
            else:  # a closed bag has no record still being written: one that does not end is damaged
                self.stream.check_not_cut(fed)
        except _ROS1_DAMAGE as err:
            raise LogReadError(f"malformed ROS1 record at byte {self.stream.resume_at} ({err})",
                               path=str(self.path)) from err

    def rest(self) -> list[SalvagedMessage]:
        return _rest_of_walk(walk_ros1(self.path).messages, self.delivered)


class SqliteFollower:
    """rosbag2 sqlite3 storage: the rows of ``messages`` with an id above the last one read (read-only). With
    ``wanted`` (topic names), as certify reads a sqlite3 storage: only the rows of the topics table's wanted topics
    are selected, and no column of any other row is read (a damaged page holding another topic's data, or a row
    whose topic id is no topic's, is no part of the reading: certify's query never reads it)."""

    def __init__(self, path: Path, wanted: Collection[str] | None = None) -> None:
        self.path = path
        self.format = "sqlite3"
        self.finished = False
        self.delivered = 0
        self.last_id = 0
        self.topic_names: set[str] = set()
        self.declared_topics: dict[str, str] = {}
        self.wanted = None if wanted is None else frozenset(wanted)
        self.read_counts: dict[str, int] = {}  # messages delivered per topic
        self.topics: dict[int, tuple[str, str]] = {}  # the topics table: id -> (name, type)

    def poll(self) -> list[SalvagedMessage]:
        try:
            con = sqlite3.connect(f"file:{self.path}?mode=ro", uri=True, timeout=1.0)
            try:
                topics = {int(i): (str(n), str(t)) for i, n, t in con.execute("SELECT id, name, type FROM topics")}
                self.topics = topics
                self.topic_names = {n for n, _ in topics.values()}
                for name, typ in topics.values():
                    self.declared_topics.setdefault(name, typ)
                read = sorted(i for i, (n, _t) in topics.items() if self.wanted is None or n in self.wanted)
                con.text_factory = bytes  # a damaged text value is a wrong type below (as certify sees it), not UTF-8
                rows = _rows(con, read, self.last_id)
                indexed = _index_times(con, {int(r[0]) for r in rows},
                                       min((r[2] for r in rows if isinstance(r[2], int)), default=None))
            finally:
                con.close()
        except sqlite3.OperationalError as err:
            if "no such table" in str(err) or "locked" in str(err):
                return []  # the recorder has not created its tables yet, or holds the lock: next poll
            raise LogReadError(f"cannot read the sqlite3 storage ({err})", path=str(self.path)) from err
        except sqlite3.DatabaseError as err:
            raise LogReadError(f"not a sqlite3 database ({err})", path=str(self.path)) from err
        placed: list[tuple[Any, SalvagedMessage]] = []  # (place in certify's order, message)
        for mid, tid, row_stamp, data in rows:
            # once per index entry that names the row (none: certify's reading yields no other row; two, where a
            # damaged entry names a row another entry names: certify's query reads it twice, at both entries' times)
            for place, stamp in [((row_stamp, mid), row_stamp)] if indexed is None else indexed.get(mid, []):
                name, typ = topics[tid]
                if not sqlite_row_readable(stamp, data):  # certify's readers refuse the row alike
                    raise unreadable_row("sqlite3", name, str(self.path))
                placed.append((place, SalvagedMessage(name, typ, False, stamp, data)))
                self.read_counts[name] = self.read_counts.get(name, 0) + 1
            self.last_id = max(self.last_id, int(mid))
        # in certify's order: the index walk's (without an index, its query sorts the rows by timestamp)
        out = [m for _place, m in sorted(placed, key=itemgetter(0))]
        self.delivered += len(out)
        return out

    def check_as_certify_reads(self) -> None:
        """At the close of its folder: the wanted rows read by certify's query (rosbags': the timestamp index walked,
        each row looked up) must be readable; a damaged page on that path (where the rows read here, in row order,
        are not) makes certify refuse the log, and watch refuses it too (``TruncatedLogError``, as certify's)."""
        from verify.ingest.sqlite import rosbags_query  # a closed sqlite3 folder only

        ids = tuple(sorted(i for i, (n, _t) in self.topics.items() if self.wanted is None or n in self.wanted))
        if not ids:
            return
        try:
            con = sqlite3.connect(f"file:{self.path}?mode=ro", uri=True, timeout=1.0)
            try:
                con.text_factory = bytes
                for _row in con.execute(rosbags_query(ids), ids):
                    pass
            finally:
                con.close()
        except sqlite3.DatabaseError as err:
            raise TruncatedLogError(f"unreadable sqlite3 database: {in_words(err)}", path=str(self.path)) from err

    def rest(self) -> list[SalvagedMessage]:
        return []


def _index_times(con: sqlite3.Connection, rows: set[int], lo: int | None
                 ) -> dict[int, list[tuple[int, object]]] | None:
    """Row id -> (place in the walk, timestamp) of each entry of the storage's timestamp index that names it (in
    index order), for the rows ``rows`` (``lo``: the least of their own timestamps, None when none is an integer); a
    row the index does not hold is left out. Certify's query (rosbags') walks that index, reads each message's time
    there and yields the messages in the walk's order, so a damaged index entry is the message's time and place for
    both (a timestamp changed in place leaves its entry where it was: the walk is then not in time order); an entry
    whose row id a damaged byte turned into another row's names that row a second time, and the query reads it
    twice. None when the storage has no timestamp index (certify's query then reads the rows' own times). The new
    rows' entries are sought from their least time on; a row not found so (a damaged index is out of order) has the
    whole index walked."""
    if not rows:
        return {}
    query = "SELECT rowid, timestamp FROM messages INDEXED BY timestamp_idx"  # rowid: see _rows

    def entries(cursor: Iterable[tuple[Any, object]]) -> dict[int, list[tuple[int, object]]]:
        got: dict[int, list[tuple[int, object]]] = {}
        for k, (i, t) in enumerate(cursor):
            if i in rows:
                got.setdefault(i, []).append((k, t))
        return got

    try:
        got = {} if lo is None else entries(con.execute(f"{query} WHERE timestamp >= ?", (lo,)))
        if len(got) < len(rows):
            got = entries(con.execute(query))
    except sqlite3.OperationalError as err:
        if "no such index" in str(err):
            return None
        raise
    return got


def _rows(con: sqlite3.Connection, ids: list[int], after: int) -> list[tuple[Any, ...]]:
    """The rows of topic ``ids`` after row id ``after``, in row order: no other row's columns are read (a damaged
    row of another topic, even its topic id, is no part of the reading, as in certify's query). Read by a scan of
    the table; where that meets a damaged page, as certify's query reads (the timestamp index walked, each row looked
    up), which may not meet it; the scan's error when that fails too."""
    marks = ",".join("?" * len(ids)) or "NULL"
    where = f"WHERE id > ? AND topic_id IN ({marks}) ORDER BY id"
    try:
        return con.execute(f"SELECT id, topic_id, timestamp, data FROM messages {where}", (after, *ids)).fetchall()
    except sqlite3.DatabaseError as err:
        if isinstance(err, sqlite3.OperationalError):
            raise  # not damage (a lock, a table not created yet): the poll decides
        try:  # (the row id as rowid, filtered here: on such a damaged table SQLite has read ``id`` as NULL there)
            rows = con.execute(f"SELECT rowid, topic_id, timestamp, data FROM messages INDEXED BY timestamp_idx "
                               f"WHERE topic_id IN ({marks})", ids).fetchall()
        except sqlite3.DatabaseError:
            raise err from None
        return sorted((r for r in rows if isinstance(r[0], int) and r[0] > after), key=lambda r: r[0])


class FolderFollower:
    """A ROS2 bag folder: its storage files in name order (a split starts a new file); finished when the recorder
    has written ``metadata.yaml``."""

    def __init__(self, path: Path, wanted: Collection[str] | None = None) -> None:
        self.path = path
        self.format = "mcap"
        self.finished = False
        self.delivered = 0
        self.declared_topics: dict[str, str] = {}
        self.wanted = wanted
        self.files: dict[Path, McapFollower | SqliteFollower] = {}

    def _storage(self) -> list[Path]:
        try:
            return sorted(p for p in self.path.iterdir() if p.suffix in (".mcap", ".db3"))
        except OSError as err:
            raise LogReadError(f"cannot list the bag folder ({err.strerror or err})", path=str(self.path)) from err

    def poll(self) -> list[SalvagedMessage]:
        done = (self.path / "metadata.yaml").is_file()
        out: list[SalvagedMessage] = []
        for f in self._storage():
            if f not in self.files:
                check_log_path(f)  # a FIFO would block the poll for ever
                self.files[f] = (McapFollower(f, self.wanted, in_folder=True) if f.suffix == ".mcap"
                                 else SqliteFollower(f, self.wanted))
                self.format = self.files[f].format
            out.extend(self.files[f].poll())
            for name, typ in self.files[f].declared_topics.items():
                self.declared_topics.setdefault(name, typ)
        self.finished = done and all(f.finished or f.format == "sqlite3" for f in self.files.values())
        sqlite = [f for f in self.files.values() if isinstance(f, SqliteFollower)]
        if self.finished and sqlite and len(sqlite) == len(self.files):
            self._check_sqlite(sqlite)
        mcaps = [f for f in self.files.values() if isinstance(f, McapFollower)]
        if self.finished and mcaps and len(mcaps) == len(self.files):
            self._check_counts(mcaps)
        self.delivered += len(out)
        return out

    def _check_sqlite(self, sqlite: list[SqliteFollower]) -> None:
        """A folder of sqlite3 storage whose recorder wrote metadata.yaml, read by certify's rules: its declared
        topics held, its declared counts read (only the rows certify's readers match to metadata.yaml's connections:
        a storage topic whose type, serialization, QoS or type hash differs is not read for that topic), the wanted
        rows readable by certify's query; a folder its readers do not open (or whose metadata.yaml is unreadable)
        is not closed as they read a closed one."""
        try:
            meta = read_bag_metadata(self.path)
        except LogReadError:
            self.finished = False  # certify's readers report an unreadable metadata.yaml; here not closed
            return
        check_declared_topics(self.path, meta, {n for f in sqlite for n in f.topic_names})
        want = meta.counts.keys() if self.wanted is None else self.wanted
        plan = read_topics_by_storage(self.path, want)
        if plan is None:
            self.finished = False
            return
        read = _summed({t: n for t, n in db.read_counts.items()
                        if plan is EVERY_STORAGE or t in plan.get(db.path.name, set())} for db in sqlite)
        check_declared_counts(meta.counts, read, want, str(self.path), fmt="sqlite3")
        for db in sqlite:
            db.check_as_certify_reads()

    def _check_counts(self, mcaps: list[McapFollower]) -> None:
        """A closed folder of MCAP files: the messages its files' Statistics (summed) and its metadata.yaml declare
        per topic, as certify reads it (``check_declared_counts``)."""
        try:
            meta = read_bag_metadata(self.path)
        except LogReadError:
            self.finished = False  # certify's readers report an unreadable metadata.yaml; here not closed yet
            return
        if read_topics_by_storage(self.path, meta.counts.keys() if self.wanted is None else self.wanted) is None:
            self.finished = False  # a folder certify's readers do not open (rosbags' metadata.yaml checks)
            return
        declared = _summed(f.declared_counts() for f in mcaps)
        read = _summed(f.read_counts for f in mcaps)
        for topic, n in meta.counts.items():
            declared[topic] = max(declared.get(topic, 0), n)
        check_declared_counts(declared, read, declared.keys() | read.keys() if self.wanted is None else self.wanted,
                              str(self.path), fmt="mcap")

    def rest(self) -> list[SalvagedMessage]:
        return [m for f in self.files.values() for m in f.rest()]


def _summed(parts: Iterable[Mapping[str, int]]) -> dict[str, int]:
    """Per-topic counts of a folder's files, summed."""
    out: dict[str, int] = {}
    for part in parts:
        for topic, n in part.items():
            out[topic] = out.get(topic, 0) + n
    return out


def log_bytes(path: Path) -> tuple[int, int]:
    """How the log stands now: its bytes and latest modification time (ns) -- a file's, or summed (latest) over a
    bag folder's files (storage, a sqlite3 ``-wal`` journal, metadata.yaml). What the idle timer watches: a recorder
    filling a chunk that cannot be read yet (MCAP, a compressed ROS1 chunk) or committing rows into the free pages
    of a sqlite3 database still counts as writing."""
    try:
        files = [f for f in path.iterdir() if f.is_file()] if path.is_dir() else [
            f for f in (path, path.with_name(path.name + "-wal")) if f.is_file()]
        stats = [f.stat() for f in files]
    except OSError:
        return (-1, -1)  # vanished or unreadable meanwhile: the next poll says what is wrong
    return (sum(st.st_size for st in stats), max((st.st_mtime_ns for st in stats), default=0))


def open_follower(path: Path, wanted: Collection[str] | None = None
                  ) -> McapFollower | Ros1Follower | SqliteFollower | FolderFollower:
    """The follower for ``path`` by its kind (a folder is a ROS2 bag; files by extension). ``wanted``: the topics
    the reading uses (``verify.ingest.log.wanted_topics``): a sqlite3 storage's other rows are not read (as certify
    does not read them); None reads every row."""
    if path.is_dir():
        return FolderFollower(path, wanted)
    suffix = path.suffix.lower()
    if suffix == ".mcap":
        return McapFollower(path, wanted)
    if suffix == ".bag":
        return Ros1Follower(path)
    if suffix == ".db3":
        return SqliteFollower(path, wanted)
    raise LogReadError(f"unrecognized log type {suffix or '(no extension)'!r}: expected .bag, .mcap, .db3 or a ROS2 "
                       f"bag folder", path=str(path))
