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

from collections.abc import Collection
from itertools import compress
from operator import itemgetter

import apsw
import numpy as np
import numpy.typing as npt
from rosbags.interfaces import Connection
from rosbags.rosbag2.storage_sqlite3 import Sqlite3Reader

from verify.ingest.mcap import TopicMessages

__all__ = ["read_sqlite_storage", "rosbags_query"]

U8Array = npt.NDArray[np.uint8]
IntArray = npt.NDArray[np.int64]


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
        stamps = list(map(itemgetter(1), rows))
        if not all(map(int.__instancecheck__, stamps)):
            return None
        log_ns = np.fromiter(stamps, dtype=np.int64, count=n)
        payloads = list(map(itemgetter(2), rows))
        if not all(map(bytes.__instancecheck__, payloads)):
            return None
        topics = sorted(set(topic_of.values()))
        if len(topics) == 1:
            return {topics[0]: _pack(log_ns, payloads)}
        code = {tid: topics.index(t) for tid, t in topic_of.items()}
        codes = np.fromiter(map(code.__getitem__, map(itemgetter(0), rows)), dtype=np.int64, count=n)
    except (TypeError, OverflowError, ValueError, KeyError):
        return None
    out: dict[str, TopicMessages] = {}
    for k, t in enumerate(topics):
        mine = codes == k
        out[t] = _pack(log_ns[mine], list(compress(payloads, mine.tolist())))
    return out


def _pack(log_ns: IntArray, payloads: list[bytes]) -> TopicMessages:
    n = len(payloads)
    lengths = np.fromiter(map(len, payloads), dtype=np.int64, count=n)
    offsets = np.zeros(n, dtype=np.int64)
    if n > 1:
        np.cumsum(lengths[:-1], out=offsets[1:])
    return TopicMessages(log_ns, np.frombuffer(b"".join(payloads), dtype=np.uint8), offsets, lengths)
