"""Salvage walks over damaged logs: a truncated or unindexed file -> the messages of its complete records.

input: a ROS1 ``.bag`` or an ``.mcap`` file -> output: a ``Walk`` whose ``messages`` iterator yields
``SalvagedMessage`` for every message in a *complete* record (ROS1: complete chunks, walked from the file start;
MCAP: complete top-level records and chunks, walked as a stream). The walk stops at the first incomplete or
malformed record, or chunk that does not decompress, and says where (``stop_reason``). Files are opened read-only.
"""

from __future__ import annotations

from collections.abc import Iterator
from dataclasses import dataclass, field
from pathlib import Path

from verify.ingest.mcaprecords import MessageRecord, Scan, scan
from verify.ingest.ros1records import DAMAGE as ROS1_DAMAGE
from verify.ingest.ros1records import MAGIC as ROS1_MAGIC
from verify.ingest.ros1records import MalformedError as Ros1MalformedError
from verify.ingest.ros1records import Ros1Message, Ros1Stream

__all__ = ["SalvagedMessage", "Walk", "mcap_message", "ros1_message", "walk_mcap", "walk_ros1"]


@dataclass(frozen=True, slots=True)
class SalvagedMessage:
    topic: str
    msgtype: str
    has_definition: bool
    log_ns: int
    payload: bytes
    #: its place among messages of equal log time in certify's reading of the closed log, before the file order: a
    #: ROS1 message's connection's rank in the bag index's list of connections (rosbags merges its connections'
    #: lists, each sorted by time); 0 elsewhere
    tie: int = 0


@dataclass(slots=True)
class Walk:
    """A lazy walk; ``stopped_at``/``reason`` are filled when the iterator ends."""

    path: Path
    messages: Iterator[SalvagedMessage] = field(default_factory=lambda: iter(()))
    stopped_at: int | None = None
    reason: str = "not walked"

    def stop_reason(self) -> str:
        where = "" if self.stopped_at is None else f" at byte {self.stopped_at}"
        return f"{self.reason}{where}"


# ---- ROS1 ----------------------------------------------------------------------------------------------------------

def ros1_message(stream: Ros1Stream, msg: Ros1Message) -> SalvagedMessage | None:
    """A ROS1 message of a connection read so far, as a salvaged message (None: its connection is not known)."""
    conn = stream.connections.get(msg.conn)
    if conn is None:
        return None
    topic, typ, has_def = conn
    return SalvagedMessage(topic, typ, has_def, msg.log_ns, msg.payload, stream.index_rank.get(msg.conn, 0))


def walk_ros1(path: Path) -> Walk:
    """The record layer's stream (``verify.ingest.ros1records.Ros1Stream``) over the whole file as a salvage walk:
    the messages of complete records (and of the complete records of a cut or still open uncompressed chunk), in
    file order, up to the first record that is cut, malformed or does not decompress."""
    walk = Walk(path)
    buf = path.read_bytes()

    def gen() -> Iterator[SalvagedMessage]:
        if not buf.startswith(ROS1_MAGIC):
            walk.reason, walk.stopped_at = "not a ROS1 bag (bad magic)", 0
            return
        stream = Ros1Stream()
        got: list[Ros1Message] = []
        error: Exception | None = None
        try:
            stream.feed(buf, 0, got)
        except ROS1_DAMAGE as err:
            error = err
        for msg in got:
            if (m := ros1_message(stream, msg)) is not None:
                yield m
        if error is None and (stream.closed or (stream.chunk is None and stream.pos >= len(buf))):
            walk.reason, walk.stopped_at = "reached the end of the file", None
        else:
            if isinstance(error, Ros1MalformedError):
                walk.reason = f"stopped at a damaged record ({error})"
            else:
                name = error.__class__.__name__ if error is not None else "CutError"
                walk.reason = f"stopped at an incomplete record ({name})"
            walk.stopped_at = stream.resume_at

    walk.messages = gen()
    return walk


# ---- MCAP ----------------------------------------------------------------------------------------------------------
def mcap_message(found: Scan, msg: MessageRecord) -> SalvagedMessage | None:
    """An MCAP message of a channel declared so far, as a salvaged message (None: its channel is not known)."""
    channel = found.channels.get(msg.channel_id)
    if channel is None:
        return None
    schema = found.schemas.get(channel.schema_id)
    name, has_def = (schema.name, schema.has_data) if schema is not None else ("", False)
    return SalvagedMessage(channel.topic, name, has_def, msg.log_ns, bytes(msg.payload))


def walk_mcap(path: Path) -> Walk:
    """The record layer's scan (``verify.ingest.mcaprecords.scan``) as a salvage walk: the messages of channels
    declared before them, in file order, up to the first record that is cut, malformed or does not decompress."""
    walk = Walk(path)
    buf = path.read_bytes()

    def gen() -> Iterator[SalvagedMessage]:
        found = Scan({}, {})
        for msg in scan(buf, found):
            if (got := mcap_message(found, msg)) is not None:
                yield got
        walk.stopped_at = found.stopped_at
        walk.reason = "reached the end of the data" if found.complete else found.reason

    walk.messages = gen()
    return walk
