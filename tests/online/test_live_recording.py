"""``watch --follow`` on a ROS1 bag written the way ``rosbag record`` writes it: the open chunk's header first with
sizes 0, its records appended one by one as messages arrive, the chunk closed at 768 KiB (header rewritten, index
records after it), connections, chunk infos and the final bag header at the end. A violation is reported within 1 s
of the violating sample reaching the file, and watching never stops while the file grows -- pose only at 100 Hz
(one chunk that stays open for the whole run) and a camera beside the pose (chunks closed every second or so)."""

from __future__ import annotations

import shutil
import sqlite3
import struct
import threading
import time
from pathlib import Path

import numpy as np
import pytest
from rosbags.rosbag1 import Reader as Reader1
from rosbags.rosbag1 import Writer as Writer1
from rosbags.rosbag2 import Reader as Reader2
from rosbags.rosbag2 import StoragePlugin
from rosbags.rosbag2 import Writer as Writer2
from rosbags.typesys import Stores, get_typestore

from tubempc.scenario import builtin_scenario
from verify.ingest.mcaprecords import MAGIC as MCAP_MAGIC
from verify.ingest.mcaprecords import Scan, record_messages
from verify.ingest.mcaprecords import walk as mcap_walk
from verify.ingest.ros1records import MAGIC, Op, record_at
from verify.online import Decision, OnlineMonitor
from verify.online.watch import watch_log

LOGS = Path(__file__).resolve().parents[2] / "logs"
POSE = "/qualisys/nexus/pose"
CHUNK_B = 768 * 1024  # rosbag record's default chunk size
SPEED = 3.0  # the recording is replayed 3x faster than it was recorded


def _source(dst: Path, *, camera: bool) -> Path:
    """obstacle_touch.bag's pose stream (100 Hz, 26 s; the obstacle is touched at 6.7 s), with a 30 Hz camera of
    30 KB images beside it when ``camera``, in uncompressed chunks of 768 KiB."""
    store = get_typestore(Stores.ROS1_NOETIC)
    image = "sensor_msgs/msg/Image"
    with Reader1(LOGS / "obstacle_touch.bag") as r, Writer1(dst) as w:
        w.chunk_threshold = CHUNK_B
        (src,) = [c for c in r.connections if c.topic == POSE]
        pose = w.add_connection(POSE, src.msgtype, msgdef=src.msgdef.data, md5sum=src.digest)
        cam = w.add_connection("/camera/image_raw", image, typestore=store) if camera else None
        next_frame = None
        for _c, t, data in r.messages(connections=[src]):
            if cam is not None:
                next_frame = t if next_frame is None else next_frame
                while next_frame <= t:
                    stamp = store.types["builtin_interfaces/msg/Time"](sec=next_frame // 10**9,
                                                                       nanosec=next_frame % 10**9)
                    msg = store.types[image](
                        header=store.types["std_msgs/msg/Header"](seq=0, stamp=stamp, frame_id="cam"),
                        height=100, width=100, encoding="rgb8", is_bigendian=0, step=300,
                        data=np.full(30_000, 7, dtype=np.uint8))
                    w.write(cam, next_frame, store.serialize_ros1(msg, image))
                    next_frame += 33_333_333
            w.write(pose, t, data)
    return dst


class RosbagRecord(threading.Thread):
    """Writes ``final`` (a closed bag) to ``target`` in the order and pace ``rosbag record`` writes it."""

    def __init__(self, final: bytes, target: Path) -> None:
        super().__init__(daemon=True)
        self.final, self.target = final, target
        self.written: list[tuple[float, int, int]] = []  # (monotonic time, conn, log time) per message record

    def run(self) -> None:
        data = self.final
        head = record_at(data, len(MAGIC), len(data))
        recording_header = bytearray(data[: head.end])
        at = recording_header.find(b"index_pos=") + len(b"index_pos=")
        recording_header[at : at + 8] = bytes(8)  # index_pos 0 until the bag is closed
        start, first_ns = time.monotonic(), None
        with self.target.open("wb") as fh:
            fh.write(recording_header)
            fh.flush()
            pos = head.end
            while pos < len(data):
                rec = record_at(data, pos, len(data))
                if rec.op != Op.CHUNK:
                    fh.write(data[pos : rec.end])
                    fh.flush()
                    pos = rec.end
                    continue
                real_head = data[pos : rec.data_start]
                open_head = bytearray(real_head)
                at = open_head.find(b"size=") + len(b"size=")
                open_head[at : at + 4] = bytes(4)
                open_head[-4:] = bytes(4)  # data length 0 while the chunk is open
                fh.write(open_head)
                fh.flush()
                inner = rec.data_start
                while inner < rec.end:
                    item = record_at(data, inner, rec.end)
                    if item.op == Op.MESSAGE_DATA:
                        sec, nsec = struct.unpack("<II", item.header["time"])
                        t_ns = sec * 10**9 + nsec
                        first_ns = t_ns if first_ns is None else first_ns
                        delay = start + (t_ns - first_ns) / 1e9 / SPEED - time.monotonic()
                        if delay > 0:
                            time.sleep(delay)
                    fh.write(data[inner : item.end])
                    fh.flush()
                    if item.op == Op.MESSAGE_DATA:
                        self.written.append((time.monotonic(), struct.unpack("<I", item.header["conn"])[0], t_ns))
                    inner = item.end
                fh.seek(pos)
                fh.write(real_head)  # the chunk is closed: its sizes
                fh.seek(rec.end)
                fh.flush()
                pos = rec.end
            fh.seek(0)
            fh.write(data[: head.end])  # the bag is closed: the header points to the index
            fh.flush()


@pytest.mark.parametrize("camera", [False, True])
def test_watch_follows_a_bag_as_rosbag_record_writes_it(tmp_path: Path, camera: bool) -> None:
    final = _source(tmp_path / "src.bag", camera=camera).read_bytes()
    target = tmp_path / "live.bag"
    target.write_bytes(b"")
    rec = RosbagRecord(final, target)
    seen: list[tuple[float, Decision]] = []
    rec.start()
    res = watch_log(target, OnlineMonitor(builtin_scenario()), follow=True, idle_timeout_s=2.0,
                    on_decision=lambda d: seen.append((time.monotonic(), d)))
    rec.join()
    # never stopped while the file grew (the pose-only bag's one chunk stays open for the whole run)
    assert res.finished and res.stop_reason == "the recorder closed the log", res.stop_reason
    when, decision = next((w, d) for w, d in seen if d.name == "obstacle_clearance")
    assert decision.verdict == "fail" and decision.first_violation_s is not None
    with Reader1(target) as r:
        pose_conn = next(c.id for c in r.connections if c.topic == POSE)
    pose_writes = [(w, t) for w, c, t in rec.written if c == pose_conn]
    t0 = pose_writes[0][1]
    # the violating sample (or the one just before it) reached the file at ``written``
    written = next(w for w, t in pose_writes if (t - t0) / 1e9 >= decision.first_violation_s - 0.011)
    assert when - written < 1.0, f"reported {when - written:.2f} s after the sample reached the file"
    assert when < rec.written[-1][0] - 1.0  # reported while the recording was under way


def _ros2(dst: Path, plugin: StoragePlugin) -> Path:
    """tube_breach.mcap (the tube is left during a 24 s run) as a ROS2 bag folder with ``plugin`` storage; MCAP in
    chunks of about 16 KiB (a chunk every ~0.4 s of the run)."""
    store = get_typestore(Stores.ROS2_HUMBLE)
    with Reader2(LOGS / "tube_breach.mcap") as r, Writer2(dst, version=9, storage_plugin=plugin) as w:
        conns = {c.id: w.add_connection(c.topic, c.msgtype, typestore=store) for c in r.connections}
        written = 0
        for c, t, data in r.messages():
            w.write(conns[c.id], t, data)
            written += len(data)
            if plugin == StoragePlugin.MCAP and written > 16 * 1024:
                w.storage.close_chunk()  # type: ignore[union-attr]
                written = 0
    return dst


class SqliteRecord(threading.Thread):
    """Inserts the rows of a closed sqlite3 bag into ``live`` (same schema, no rows) one by one at the run's pace,
    each committed, then writes metadata.yaml (the recorder's last act)."""

    def __init__(self, closed: Path, live: Path) -> None:
        super().__init__(daemon=True)
        self.closed, self.live = closed, live
        self.written: list[tuple[float, int, int]] = []  # (monotonic time, topic id, log time)

    def run(self) -> None:
        (db,) = self.closed.glob("*.db3")
        with sqlite3.connect(db) as src:
            rows = src.execute("SELECT id, topic_id, timestamp, data FROM messages ORDER BY id").fetchall()
        src.close()
        con = sqlite3.connect(self.live / db.name)
        con.execute("PRAGMA synchronous = OFF")  # as rosbag2's default sqlite3 preset writes
        start, first_ns = time.monotonic(), rows[0][2]
        for mid, tid, t_ns, data in rows:
            delay = start + (t_ns - first_ns) / 1e9 / SPEED - time.monotonic()
            if delay > 0:
                time.sleep(delay)
            con.execute("INSERT INTO messages (id, topic_id, timestamp, data) VALUES (?, ?, ?, ?)",
                        (mid, tid, t_ns, data))
            con.commit()
            self.written.append((time.monotonic(), tid, t_ns))
        con.close()
        shutil.copyfile(self.closed / "metadata.yaml", self.live / "metadata.yaml")


class McapRecord(threading.Thread):
    """Appends the top-level records of a closed MCAP file as a recorder writes them: each chunk when its last
    message is due, the summary and footer at the end."""

    def __init__(self, closed: Path, live: Path) -> None:
        super().__init__(daemon=True)
        self.closed, self.live = closed, live
        self.written: list[tuple[float, int, int]] = []  # (monotonic time, channel, log time) per message

    def run(self) -> None:
        data = self.closed.read_bytes()
        start, first_ns = time.monotonic(), None
        with self.live.open("wb") as fh:
            fh.write(data[: len(MCAP_MAGIC)])
            for op, rec, nxt in mcap_walk(data, len(MCAP_MAGIC), len(data) - len(MCAP_MAGIC)):
                msgs = record_messages(op, rec, Scan({}, {}), check_crc=False)
                if msgs:
                    first_ns = msgs[0].log_ns if first_ns is None else first_ns
                    delay = start + (max(m.log_ns for m in msgs) - first_ns) / 1e9 / SPEED - time.monotonic()
                    if delay > 0:
                        time.sleep(delay)
                fh.write(data[nxt - len(rec) - 9 : nxt])
                fh.flush()
                now = time.monotonic()
                self.written += [(now, m.channel_id, m.log_ns) for m in msgs]
            fh.write(data[-len(MCAP_MAGIC) :])
        (self.live.parent / "metadata.yaml").write_bytes((self.closed.parent / "metadata.yaml").read_bytes())


@pytest.mark.parametrize("storage", ["sqlite3", "mcap"])
def test_watch_follows_a_ros2_bag_as_it_is_recorded(tmp_path: Path, storage: str) -> None:
    """sqlite3: a tube violation within 1 s of its sample's row being committed; MCAP: within 1 s of the chunk
    holding it being written (the latency of one chunk is the recorder's, docs/online.md)."""
    plugin = StoragePlugin.SQLITE3 if storage == "sqlite3" else StoragePlugin.MCAP
    closed = _ros2(tmp_path / "closed", plugin)
    live = tmp_path / "live"
    live.mkdir()
    rec: SqliteRecord | McapRecord
    if storage == "sqlite3":
        (db,) = closed.glob("*.db3")
        shutil.copyfile(db, live / db.name)
        with sqlite3.connect(live / db.name) as con:
            con.execute("DELETE FROM messages")
        con.close()
        rec = SqliteRecord(closed, live)
    else:
        (mcap,) = closed.glob("*.mcap")
        rec = McapRecord(mcap, live / mcap.name)
    with Reader2(closed) as r:
        pose_topic = next(c for c in r.connections if c.topic == POSE)
    seen: list[tuple[float, Decision]] = []
    rec.start()
    res = watch_log(live, OnlineMonitor(builtin_scenario()), follow=True, idle_timeout_s=2.0,
                    on_decision=lambda d: seen.append((time.monotonic(), d)))
    rec.join()
    assert res.finished and res.stop_reason == "the recorder closed the log", res.stop_reason
    when, decision = next((w, d) for w, d in seen if d.name == "tube")
    assert decision.verdict == "fail" and decision.first_violation_s is not None
    pose_id = pose_topic.id if storage == "mcap" else _sqlite_topic_id(live, POSE)
    pose_writes = [(w, t) for w, c, t in rec.written if c == pose_id]
    t0 = pose_writes[0][1]
    written = next(w for w, t in pose_writes if (t - t0) / 1e9 >= decision.first_violation_s - 0.011)
    assert when - written < 1.0, f"reported {when - written:.2f} s after the sample reached the file"
    assert when < rec.written[-1][0] - 1.0  # reported while the recording was under way


def _sqlite_topic_id(folder: Path, topic: str) -> int:
    (db,) = folder.glob("*.db3")
    with sqlite3.connect(db) as con:
        (tid,) = con.execute("SELECT id FROM topics WHERE name = ?", (topic,)).fetchone()
    con.close()
    return int(tid)
