"""``watch --follow`` on a ROS1 bag written the way ``rosbag record`` writes it: the open chunk's header first with
sizes 0, its records appended one by one as messages arrive, the chunk closed at 768 KiB (header rewritten, index
records after it), connections, chunk infos and the final bag header at the end. A violation is reported within 1 s
of the violating sample reaching the file, and watching never stops while the file grows -- pose only at 100 Hz
(one chunk that stays open for the whole run) and a camera beside the pose (chunks closed every second or so)."""

from __future__ import annotations

import struct
import threading
import time
from pathlib import Path

import numpy as np
import pytest
from rosbags.rosbag1 import Reader as Reader1
from rosbags.rosbag1 import Writer as Writer1
from rosbags.typesys import Stores, get_typestore

from tubempc.scenario import builtin_scenario
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
    assert written - pose_writes[0][0] > 1.0  # the recording was under way, not read after the fact
