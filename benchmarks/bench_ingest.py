"""Benchmark: reading 1e6 PoseStamped messages per format, our bulk numpy decode vs plain rosbags.

    python3 benchmarks/bench_ingest.py [--messages 1000000] [--formats bag,mcap,db3] [--dir /tmp/bench_ingest]

For each format one log is written (once; reused if present), then timed in the same run:
* raw: ``AnyReader.messages()`` iterated without decoding (rosbags' raw iteration speed);
* deserialize: ``AnyReader.messages()`` + ``reader.deserialize`` per message, collecting stamp, x, y;
* ours: ``verify.ingest.read_raw`` + ``verify.ingest.decode.decode_pose`` (numpy over the joined payloads).
Prints deserialize/ours (target >= 3x) and raw/ours (target >= 0.7, i.e. ours reaches 70 % of raw speed).
"""

from __future__ import annotations

import argparse
import os
import time
from pathlib import Path

import numpy as np
from rosbags.highlevel import AnyReader
from rosbags.rosbag1 import Writer as Writer1
from rosbags.rosbag2 import StoragePlugin
from rosbags.rosbag2 import Writer as Writer2
from rosbags.typesys import Stores, get_typestore

from verify.ingest import read_raw
from verify.ingest.decode import decode_pose

TOPIC = "/qualisys/nexus/pose"
TYPE = "geometry_msgs/msg/PoseStamped"
T0_NS = 1_767_225_600 * 10**9


def payloads(n: int, ros1: bool) -> tuple[np.ndarray, list[bytes]]:
    """n serialized PoseStamped messages built from one template with numpy (stamps every 10 ms, a circle)."""
    store = get_typestore(Stores.ROS1_NOETIC if ros1 else Stores.ROS2_HUMBLE)
    T = store.types
    hdr = T["std_msgs/msg/Header"](**({"seq": 0} if ros1 else {}),
                                   stamp=T["builtin_interfaces/msg/Time"](sec=0, nanosec=0), frame_id="world")
    msg = T[TYPE](header=hdr, pose=T["geometry_msgs/msg/Pose"](
        position=T["geometry_msgs/msg/Point"](x=0.0, y=0.0, z=0.0),
        orientation=T["geometry_msgs/msg/Quaternion"](x=0.0, y=0.0, z=0.0, w=1.0)))
    tmpl = np.frombuffer(bytes(store.serialize_ros1(msg, TYPE) if ros1 else store.serialize_cdr(msg, TYPE)),
                         dtype=np.uint8)
    size = tmpl.size
    mat = np.tile(tmpl, (n, 1))
    t_ns = T0_NS + np.arange(n, dtype=np.int64) * 10_000_000
    mat[:, 4:8] = (t_ns // 10**9).astype("<u4").view(np.uint8).reshape(n, 4)
    mat[:, 8:12] = (t_ns % 10**9).astype("<u4").view(np.uint8).reshape(n, 4)
    fstart = size - 56
    th = np.arange(n) * 1e-3
    mat[:, fstart : fstart + 8] = np.cos(th).astype("<f8").view(np.uint8).reshape(n, 8)
    mat[:, fstart + 8 : fstart + 16] = np.sin(th).astype("<f8").view(np.uint8).reshape(n, 8)
    return t_ns, [row.tobytes() for row in mat]


def write(path: Path, fmt: str, n: int) -> Path:
    ros1 = fmt == "bag"
    t_ns, raws = payloads(n, ros1)
    store = get_typestore(Stores.ROS1_NOETIC if ros1 else Stores.ROS2_HUMBLE)
    if ros1:
        with Writer1(path) as w:
            c = w.add_connection(TOPIC, TYPE, typestore=store)
            for t, r in zip(t_ns.tolist(), raws, strict=True):
                w.write(c, t, r)
        return path
    plugin = StoragePlugin.MCAP if fmt == "mcap" else StoragePlugin.SQLITE3
    with Writer2(path, version=9, storage_plugin=plugin) as w:
        c = w.add_connection(TOPIC, TYPE, typestore=store)
        for t, r in zip(t_ns.tolist(), raws, strict=True):
            w.write(c, t, r)
    return path


def timed(fn: object) -> tuple[float, object]:
    t0 = time.perf_counter()
    out = fn()  # type: ignore[operator]
    return time.perf_counter() - t0, out


def bench(path: Path) -> None:
    def raw() -> int:
        k = 0
        with AnyReader([path]) as r:
            for _ in r.messages(connections=[c for c in r.connections if c.topic == TOPIC]):
                k += 1
        return k

    def deser() -> int:
        xs: list[float] = []
        with AnyReader([path]) as r:
            for conn, _t, data in r.messages(connections=[c for c in r.connections if c.topic == TOPIC]):
                m = r.deserialize(data, conn.msgtype)
                xs.append(m.header.stamp.sec * 10**9 + m.header.stamp.nanosec)  # type: ignore[attr-defined]
                xs.append(m.pose.position.x)  # type: ignore[attr-defined]
                xs.append(m.pose.position.y)  # type: ignore[attr-defined]
        return len(xs) // 3

    def ours() -> int:
        rl = read_raw(path, [TOPIC])
        cols = decode_pose(rl.topics[TOPIC], rl.ros1)
        return int(cols.x_m.size)

    print(f"load average (2 cores here): {' '.join(f'{v:.2f}' for v in os.getloadavg())}")
    t_raw, n_raw = timed(raw)
    t_des, n_des = timed(deser)
    t_ours, n_ours = timed(ours)
    print(f"{path.name}: {n_ours} msgs | raw iteration {t_raw:.2f} s | AnyReader+deserialize {t_des:.2f} s | "
          f"ours {t_ours:.2f} s | deserialize/ours = {t_des / t_ours:.1f}x (target >= 3) | "
          f"raw/ours = {t_raw / t_ours:.2f} (target >= 0.7)")
    if not n_raw == n_des == n_ours:
        print(f"  count mismatch: raw {n_raw}, deserialize {n_des}, ours {n_ours}")


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--messages", type=int, default=1_000_000)
    ap.add_argument("--formats", default="bag,mcap,db3")
    ap.add_argument("--dir", type=Path, default=Path("/tmp/bench_ingest"))
    args = ap.parse_args()
    args.dir.mkdir(parents=True, exist_ok=True)
    for fmt in args.formats.split(","):
        name = {"bag": f"pose_{args.messages}.bag", "mcap": f"pose_{args.messages}_mcap",
                "db3": f"pose_{args.messages}_sqlite"}[fmt]
        path = args.dir / name
        if not path.exists():
            t_w, _ = timed(lambda path=path, fmt=fmt: write(path, fmt, args.messages))
            print(f"wrote {path} in {t_w:.1f} s")
        bench(path)


if __name__ == "__main__":
    main()
