"""Fast ROS2 sqlite3 message reader: an opened ``rosbags`` sqlite3 storage + its wanted topics -> their messages as
one packed byte buffer, in exactly the order ``rosbags`` yields them.

input: a ``rosbags.rosbag2.storage_sqlite3.Sqlite3Reader`` that ``rosbags`` has opened (read-only, ``immutable=1``
URI: the database is never written and a ``-wal`` file beside it is not read) and the storage connections to read
-> output: topic ids, log times (int64 ns) and payloads (one byte buffer + offsets + lengths); or ``None`` when
anything is unusual (then the caller iterates ``rosbags``' own reader).

The rows come from ``rosbags``' own query, character for character, on its own connection (the same SQLite build,
hence the same query plan and the same order of rows with equal timestamps): ``SELECT topics.id, messages.timestamp,
messages.data FROM messages JOIN topics ... WHERE topics.id IN (...) ORDER BY timestamp``. Instead of a generator
yielding one tuple per row through two layers, the rows are fetched at once (``fetchall``) and split into columns
with C-level ``map``/``b"".join`` (no Python statement per row).
"""

from __future__ import annotations

from collections.abc import Collection, Iterable
from itertools import compress
from operator import itemgetter
from pathlib import Path
from typing import Any

import apsw
import numpy as np
import numpy.typing as npt
from rosbags.interfaces import Connection, ConnectionExtRosbag2, MessageDefinition, MessageDefinitionFormat, Qos
from rosbags.rosbag2 import Reader as Reader2
from rosbags.rosbag2.errors import ReaderError
from rosbags.rosbag2.metadata import ReaderMetadata, parse_qos
from rosbags.rosbag2.reader import DirectoryReader
from rosbags.rosbag2.storage_mcap import McapReader
from rosbags.rosbag2.storage_sqlite3 import Sqlite3Reader

from verify.ingest.mcap import TopicMessages

__all__ = ["QuickReader", "QuickSqlite3Reader", "read_sqlite_storage", "rosbags_query"]

U8Array = npt.NDArray[np.uint8]
IntArray = npt.NDArray[np.int64]


_MSGDEF_FORMATS = {"ros2msg": MessageDefinitionFormat.MSG, "ros2idl": MessageDefinitionFormat.IDL}


class QuickSqlite3Reader(Sqlite3Reader):
    """``Sqlite3Reader`` whose ``open`` reads the schema version, ``message_definitions`` and ``topics`` exactly as
    rosbags 0.11 does, but skips its two full scans of ``messages`` (per-topic ``count(messages.id)`` and the
    ``MIN/MAX/COUNT`` of the timestamps): connections carry ``msgcount=0`` and ``metadata`` stays rosbags' empty
    default. Only for reading the messages of selected topics; a damaged table surfaces when the messages are read
    (the caller then reopens with rosbags' own reader, which reports the error as before)."""

    def open(self) -> None:
        if not isinstance(self.path, Path):
            raise ReaderError(f"not a filesystem path: {self.path!r}")
        _check_size(self.path)
        self.dbconn = apsw.Connection(f"file:{self.path}?mode=ro&immutable=1",
                                      flags=apsw.SQLITE_OPEN_READONLY | apsw.SQLITE_OPEN_URI)
        try:
            self._read_schema(self.dbconn)
        except BaseException:
            self.close()
            raise

    def _read_schema(self, conn: apsw.Connection) -> None:
        cur = conn.cursor()
        got = cur.execute('SELECT count(*) FROM sqlite_master WHERE type="table" AND name IN ("messages", "topics")'
                          ).fetchone()
        if got is None or got[0] != 2:
            raise ReaderError(f"database {self.path} misses tables")
        if cur.execute("PRAGMA table_info(schema)").fetchall():
            row = cur.execute("SELECT schema_version FROM schema").fetchone()
            schema = int(row[0]) if row is not None else -1
        elif any(x[1] == "offered_qos_profiles" for x in cur.execute("PRAGMA table_info(topics)")):
            schema = 2
        else:
            schema = 1
        msgtypes: list[dict[str, str]] = []
        if schema >= 4:
            msgtypes = [{"name": x[0], "encoding": x[1], "msgdef": x[2], "digest": x[3]} for x in cur.execute(
                "SELECT topic_type, encoding, encoded_message_definition, type_description_hash "
                "FROM message_definitions ORDER BY id")]

        def msgdef_of(name: str) -> MessageDefinition:  # rosbags: the first definition row of that type
            if (m := next((x for x in msgtypes if x["name"] == name), None)) is not None:
                return MessageDefinition(_MSGDEF_FORMATS[m["encoding"]], m["msgdef"])
            return MessageDefinition(MessageDefinitionFormat.NONE, "")

        for query in rosbags_open_queries(schema):  # compiled, not run: what they name must exist, as for rosbags
            cur.execute(f"EXPLAIN {query}").fetchall()
        columns = ["topics.id", "name", "type", "serialization_format"]
        if schema >= 2:
            columns.append("offered_qos_profiles")
        if schema >= 4:
            columns.append("type_description_hash")
        query = f"SELECT {', '.join(columns)} FROM topics ORDER BY topics.id"
        rows: list[tuple[Any, ...]] = cur.execute(query).fetchall()
        if len({r[0] for r in rows}) != len(rows):
            raise ReaderError(f"database {self.path}: topic ids are not unique")  # rosbags groups them
        self.connections = [
            Connection(r[0], r[1], r[2], msgdef_of(r[2]), r[5] if schema >= 4 else "", 0,
                       ConnectionExtRosbag2(r[3], _parse_qos(r[4]) if schema >= 2 else []), self)
            for r in rows]
        self.schema, self.msgtypes = schema, msgtypes
        self.metadata = ReaderMetadata(0, 2**63 - 1, 0, 0, None, None, None, None)


_QOS_MEMO: dict[str, tuple[Qos, ...]] = {}
_QOS_MEMO_MAX = 256  # distinct profile texts kept (a process reading many logs sees a few)


def _parse_qos(text: Any) -> list[Qos]:
    """``parse_qos`` of a ``topics.offered_qos_profiles`` text, memoised per text: rosbags builds a new YAML parser
    for every topic, though a log's topics mostly share one profile text (``Qos`` is an immutable tuple). Errors are
    rosbags' own (raised by ``parse_qos`` and never memoised)."""
    if not isinstance(text, str):
        return parse_qos(text)
    hit = _QOS_MEMO.get(text)
    if hit is None:
        if len(_QOS_MEMO) >= _QOS_MEMO_MAX:
            _QOS_MEMO.clear()
        hit = _QOS_MEMO[text] = tuple(parse_qos(text))
    return list(hit)


def _check_size(path: Path) -> None:
    """Raise unless the file is exactly as long as its SQLite header says (page size x page count, when that count
    is valid): a truncated or grown file goes to rosbags, whose full scans report the damage."""
    with path.open("rb") as fh:
        head = fh.read(100)
        size_b = fh.seek(0, 2)
    if len(head) < 100 or not head.startswith(b"SQLite format 3\x00"):
        raise ReaderError(f"{path}: not an SQLite 3 file")
    page_b = int.from_bytes(head[16:18], "big")
    page_b = 65536 if page_b == 1 else page_b
    pages = int.from_bytes(head[28:32], "big")
    if head[24:28] != head[92:96] or pages == 0 or size_b != page_b * pages:
        raise ReaderError(f"{path}: {size_b} bytes, header says {pages} pages of {page_b} bytes")


class _QuickDirectoryReader(DirectoryReader):
    STORAGE_PLUGINS = {"mcap": McapReader, "sqlite3": QuickSqlite3Reader}  # noqa: RUF012  # rosbags' own mapping


class QuickReader(Reader2):
    """rosbags' ``Reader`` (bag directory or bare ``.db3``) with ``QuickSqlite3Reader`` storages: the same
    metadata.yaml checks, connections and message definitions, without the counting scans."""

    STORAGE_PLUGINS = {"dir": _QuickDirectoryReader, ".db3": QuickSqlite3Reader}  # noqa: RUF012


def rosbags_open_queries(schema: int) -> tuple[str, str]:
    """The two queries ``Sqlite3Reader.open`` (rosbags 0.11) runs over ``messages`` for a storage of ``schema``: its
    connections with their message counts, and the time range. Not run here (each scans the table), only compiled
    (``EXPLAIN``): a table whose schema a damaged byte changed (a column no longer named ``id``) fails to compile
    them, and rosbags' open refuses the storage, so ours must too."""
    columns = ["topics.id", "name", "type", "count(messages.id)", "serialization_format"]
    if schema >= 2:
        columns.append("offered_qos_profiles")
    if schema >= 4:
        columns.append("type_description_hash")
    return (f"SELECT {', '.join(columns)} FROM topics LEFT JOIN messages ON topics.id == messages.topic_id "
            f"GROUP BY topics.id ORDER BY topics.id",
            "SELECT MIN(timestamp), MAX(timestamp) + 1, COUNT(*) FROM messages")


def rosbags_query(ids: tuple[int, ...]) -> str:
    """``Sqlite3Reader.messages``' query (rosbags 0.11) for topic ids ``ids``, without start/stop bounds."""
    return " ".join([
        "SELECT topics.id,messages.timestamp,messages.data",
        "FROM messages JOIN topics ON messages.topic_id=topics.id",
        f'WHERE topics.id IN ({",".join("?" for _ in ids)})',
        "ORDER BY timestamp",
    ])


def read_sqlite_storage(storage: Sqlite3Reader, connections: Collection[Connection]
                        ) -> dict[str, TopicMessages] | None:
    """Per topic, the messages of ``connections`` (storage connections) from an opened sqlite3 storage, in the order
    ``storage.messages(connections)`` yields them; None when unusual."""
    if not isinstance(storage, Sqlite3Reader) or storage.dbconn is None:
        return None
    ids = tuple({x.id for x in connections})  # built as rosbags builds it
    topic_of = {x.id: x.topic for x in connections}
    try:
        rows = storage.dbconn.execute(rosbags_query(ids), ids).fetchall()
    except apsw.Error:
        return None  # rosbags runs the same query and reports the error
    n = len(rows)
    try:
        stamps = list(map(itemgetter(1), rows))  # (zip(*rows) is five times slower on 200,000 rows)
        payloads = list(map(itemgetter(2), rows))
        if not all(map(int.__instancecheck__, stamps)) or not all(map(bytes.__instancecheck__, payloads)) or \
                min(stamps, default=0) < 0:
            return None  # rosbags' reading, checked by verify.ingest.readerrors.sqlite_row_readable, says why
        log_ns = np.fromiter(stamps, dtype=np.int64, count=n)
        lengths = np.fromiter(map(len, payloads), dtype=np.int64, count=n)
        topics = sorted(set(topic_of.values()))
        if len(topics) == 1:
            return {topics[0]: _packed(log_ns, _joined(payloads), lengths)}
        code = {tid: topics.index(t) for tid, t in topic_of.items()}
        codes = np.fromiter(map(code.__getitem__, map(itemgetter(0), rows)), dtype=np.int64, count=n)
    except (TypeError, OverflowError, ValueError, KeyError):
        return None
    out: dict[str, TopicMessages] = {}
    for k, t in enumerate(topics):
        mine = codes == k
        # each topic's payloads joined from the fetched rows (C-level compress + join: every payload byte copied
        # once, no per-byte index arrays)
        out[t] = _packed(log_ns[mine], _joined(compress(payloads, mine.tolist())), lengths[mine])
    return out


def _joined(payloads: Iterable[bytes]) -> U8Array:
    return np.frombuffer(b"".join(payloads), dtype=np.uint8)


def _packed(log_ns: IntArray, data: U8Array, lengths: IntArray) -> TopicMessages:
    """Back-to-back payloads of ``lengths`` in ``data`` -> their ``TopicMessages`` (offsets: the running sum)."""
    offsets = np.zeros(lengths.shape[0], dtype=np.int64)
    if lengths.shape[0] > 1:
        np.cumsum(lengths[:-1], out=offsets[1:])
    return TopicMessages(log_ns, data, offsets, lengths)
