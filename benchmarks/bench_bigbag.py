"""Benchmark: certifying a lab-sized recording (camera + lidar + the robot's topics) vs a plain rosbags loop.

    python3 benchmarks/bench_bigbag.py [--size-gb 1] [--dir $TMPDIR/bench_bigbag] [--formats ros1-none,...]

Writes (once; reused when present) one log per format under ``--dir``: ~36.7 s per GB of the demo's topics (MoCap
pose, nominal pose and command at 100 Hz, solver status at 10 Hz, the run's metadata) interleaved in time, as a
recorder writes them, with ``/camera/image_raw`` (sensor_msgs/Image 640x480 rgb8, 30 Hz) and ``/scan``
(sensor_msgs/LaserScan, 1081 beams, 40 Hz): ROS1 (uncompressed, lz4 chunks), ROS2 MCAP (uncompressed, zstd chunks)
and ROS2 sqlite3, written by rosbags' writers. Then, per format, in one run on a warm page cache:

* rosbags: ``AnyReader`` over the pose, nominal pose and command topics + ``deserialize`` per message, keeping
  stamp, x, y (pose topics) and the three velocities (command): the plain loop a user writes first;
* ours: ``verify.certify.certify_log`` on the built-in scenario (every check, the certificate and its default
  digest, ``blake3-messages``: of the messages read);
* ours + file digest: the same with ``digest="blake3"``, the whole file's BLAKE3 computed beside the reading (every
  byte read once more: shown for what it costs; ``--no-file-digest`` skips it);
* the floor: what any reader of the topics certification reads must do, and nothing else: ROS1 and MCAP, the
  index (bag index; MCAP summary), then every chunk that holds a wanted topic read and decompressed (lz4 / zstd a
  few chunks ahead in the same threads as our reader, ``verify.ingest.records.in_order``); sqlite3, the bag
  folder's metadata.yaml (libyaml) and one query fetching the wanted topics' rows in log-time order. No record
  parsing, no decoding, no judging.

Library imports are outside every side's clock: each child imports rosbags' readers (``rosbags.highlevel``, ROS1
and ROS2) before its clock starts, as the rosbags loop always did; ours would otherwise pay ``rosbags.rosbag2``'s
import (~35 ms, mostly ``ruamel.yaml``) inside its first ROS2 log. Its cost is printed (ours' column). What ours
still pays on its first call is kept in "first call": its own modules for the format (imported on the first log
of that format), the certificate model's pydantic schema (built on first use), ruamel's regular expressions
(compiled on rosbags' first metadata.yaml). The project's modules are byte-compiled before any child runs
(``_compile_project``), as an installed copy's are. Ours' child then certifies the same log a second time: "second call"
is the per-log cost of a process that has certified a log before (a batch worker, a user's script); both are
printed, with ours/floor for each. Last, the child times ours' reading alone (``verify.ingest.raw.read_raw`` of the
wanted topics, warm: everything ours does before decoding), the part of ours that does the floor's work: what is left
between it and the second call is decoding, judging and the certificate, a per-log cost the floor does not have.

Each side runs ``--repeat`` times (default 3), the two sides alternating, and its fastest run is kept (the machine
is shared: the fastest run is the least disturbed one); the CPU time (user + system, every thread, from the start
to the end of the measured work, as the child process measures it) is reported too.
Each measurement runs in its own child process; its wall time is measured inside the child (imports excluded) and
its peak RSS is the child's ``ru_maxrss`` as the parent reaps it (``os.wait4``: the per-child form of
``getrusage(RUSAGE_CHILDREN)``), never the benchmark's own. (Linux carries a parent's peak RSS into a forked child,
so the logs are written by children too and this process stays at ~30 MB.) Prints one row per format (rosbags
s / MB, ours s / MB, ratio = rosbags time / ours, and the same for ours + file digest), and last
``worst_ratio_vs_rosbags=<min ratio of ours> max_rss_mb=<max over ours> formats=<n>
worst_ratio_file_digest=<min ratio of ours + file digest> worst_cpu_per_wall_uncompressed=<max CPU / wall of ours
on ros1-none, mcap-none, sqlite3> worst_ratio_vs_floor=<max of ours' wall / the floor's>
worst_ratio_vs_floor_second_call=<the same for ours' second call> worst_read_vs_floor=<the same for ours' reading
alone>``, after a second table (floor wall / CPU, ours wall / CPU and ours/floor for the first and the second call,
ours' reading alone and its ratio to the floor, ours' CPU per wall, ours' library import time).
Targets: ratio >= 2 everywhere, ours' RSS <= 250 MB and within 10 % between --size-gb 1 and 3; ours <= 1.25x the
floor; CPU <= 1.2x wall uncompressed.
"""

from __future__ import annotations

import argparse
import json
import math
import os
import subprocess
import sys
import tempfile
import time
from pathlib import Path
from typing import Any

import numpy as np

FORMATS = ("ros1-none", "ros1-lz4", "mcap-none", "mcap-zstd", "sqlite3")
UNCOMPRESSED = ("ros1-none", "mcap-none", "sqlite3")
POSE, NOMINAL, CMD = "/qualisys/nexus/pose", "/nexus/nominal_pose", "/nexus/cmd_vel"
STATUS, META = "/nexus/mpc_status", "/tubempc/metadata"
CAMERA, SCAN = "/camera/image_raw", "/scan"
T0_NS = 1_767_225_600 * 10**9
SECONDS_PER_GB = 110.0 / 3.0  # 30 Hz of 640x480 rgb8 is 27.6 MB/s
PERIOD_NS = {POSE: 10_000_000, NOMINAL: 10_000_000, CMD: 10_000_000, STATUS: 100_000_000,
             CAMERA: 33_333_333, SCAN: 25_000_000}


def _trajectory(t_s: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """The built-in scenario's mission at walking pace: R1 -> R3 -> R1 around the obstacles (as the certifier's
    tests drive it), truncated at the log's end."""
    from tubempc.scenario import builtin_scenario

    sc = builtin_scenario()
    r1, r3 = sc.region("R1").center, sc.region("R3").center
    legs = [r1, (-0.6, -0.5), r3, r3, (-0.6, -0.5), r1, r1]
    knots = [0.0, 18.0, 36.0, 55.0, 70.0, 88.0, 110.0]
    tt = np.minimum(t_s, 110.0)
    return np.interp(tt, knots, [p[0] for p in legs]), np.interp(tt, knots, [p[1] for p in legs])


def _messages(ros1: bool, seconds: float) -> list[tuple[int, str, str, bytes]]:
    """(log time, topic, type, payload) of the whole recording, sorted by log time (stable per topic)."""
    from rosbags.typesys import Stores, get_typestore

    store = get_typestore(Stores.ROS1_NOETIC if ros1 else Stores.ROS2_HUMBLE)
    T = store.types

    def ser(msg: Any, typ: str) -> bytes:
        return bytes(store.serialize_ros1(msg, typ) if ros1 else store.serialize_cdr(msg, typ))

    def header(t_ns: int, frame: str) -> Any:
        stamp = T["builtin_interfaces/msg/Time"](sec=t_ns // 10**9, nanosec=t_ns % 10**9)
        return T["std_msgs/msg/Header"](**({"seq": 0} if ros1 else {}), stamp=stamp, frame_id=frame)

    def with_stamp(tmpl: bytes, t_ns: int) -> bytes:  # header stamp at bytes 4..12 in both encodings
        return tmpl[:4] + int(t_ns // 10**9).to_bytes(4, "little") + int(t_ns % 10**9).to_bytes(4, "little") + \
            tmpl[12:]

    out: list[tuple[int, str, str, bytes]] = []
    n = int(seconds * 100)
    t_ns = T0_NS + np.arange(n, dtype=np.int64) * PERIOD_NS[POSE]
    x, y = _trajectory((t_ns - T0_NS) * 1e-9)
    vx, vy = np.gradient(x, 0.01), np.gradient(y, 0.01)
    pose_t, point_t = T["geometry_msgs/msg/Pose"], T["geometry_msgs/msg/Point"]
    quat_t, vec_t = T["geometry_msgs/msg/Quaternion"], T["geometry_msgs/msg/Vector3"]
    for i, t in enumerate(t_ns.tolist()):
        for topic, dx in ((POSE, 0.002 * math.sin(0.7 * i)), (NOMINAL, 0.0)):
            msg = T["geometry_msgs/msg/PoseStamped"](header=header(t, "world"), pose=pose_t(
                position=point_t(x=float(x[i]) + dx, y=float(y[i]), z=0.0),
                orientation=quat_t(x=0.0, y=0.0, z=0.0, w=1.0)))
            out.append((t, topic, "geometry_msgs/msg/PoseStamped", ser(msg, "geometry_msgs/msg/PoseStamped")))
        twist = T["geometry_msgs/msg/Twist"](linear=vec_t(x=float(vx[i]), y=float(vy[i]), z=0.0),
                                             angular=vec_t(x=0.0, y=0.0, z=0.0))
        out.append((t, CMD, "geometry_msgs/msg/Twist", ser(twist, "geometry_msgs/msg/Twist")))
        if i % 10 == 0:
            doc = {"t_s": i * 0.01, "status": "Solve_Succeeded", "success": True, "iterations": 12,
                   "solve_time_s": 0.004, "backup": False, "target": "R3"}
            out.append((t, STATUS, "std_msgs/msg/String", ser(T["std_msgs/msg/String"](data=json.dumps(doc)),
                                                             "std_msgs/msg/String")))
    meta = json.dumps({"generator": "bench_bigbag", "time0_ns": T0_NS})
    out.append((T0_NS, META, "std_msgs/msg/String", ser(T["std_msgs/msg/String"](data=meta), "std_msgs/msg/String")))
    rng = np.random.default_rng(7)
    # camera frames: runs of 4 equal bytes (a compressor finds something, not everything), a small pool
    frames = [np.repeat(rng.integers(0, 256, 640 * 480 * 3 // 4, dtype=np.uint8), 4).tobytes() for _ in range(8)]
    img = T["sensor_msgs/msg/Image"](header=header(T0_NS, "camera"), height=480, width=640, encoding="rgb8",
                                     is_bigendian=0, step=640 * 3, data=np.frombuffer(frames[0], dtype=np.uint8))
    img_t = ser(img, "sensor_msgs/msg/Image")
    head_len = len(img_t) - len(frames[0])
    for k, t in enumerate(range(T0_NS, T0_NS + int(seconds * 1e9), PERIOD_NS[CAMERA])):
        out.append((t, CAMERA, "sensor_msgs/msg/Image", with_stamp(img_t[:head_len], t) + frames[k % 8]))
    scan = T["sensor_msgs/msg/LaserScan"](
        header=header(T0_NS, "laser"), angle_min=-2.35, angle_max=2.35, angle_increment=4.7 / 1080,
        time_increment=0.0, scan_time=0.025, range_min=0.05, range_max=30.0,
        ranges=rng.uniform(0.5, 8.0, 1081).astype(np.float32), intensities=rng.uniform(0, 1, 1081).astype(np.float32))
    scan_t = ser(scan, "sensor_msgs/msg/LaserScan")
    for t in range(T0_NS, T0_NS + int(seconds * 1e9), PERIOD_NS[SCAN]):
        out.append((t, SCAN, "sensor_msgs/msg/LaserScan", with_stamp(scan_t, t)))
    out.sort(key=lambda m: m[0])
    return out


def write(path: Path, fmt: str, size_gb: float) -> None:
    """Write one recording (into a temporary name, renamed when complete)."""
    from rosbags.rosbag1 import Writer as Writer1
    from rosbags.rosbag2 import CompressionFormat, CompressionMode, StoragePlugin
    from rosbags.rosbag2 import Writer as Writer2
    from rosbags.typesys import Stores, get_typestore

    ros1 = fmt.startswith("ros1")
    msgs = _messages(ros1, size_gb * SECONDS_PER_GB)
    store = get_typestore(Stores.ROS1_NOETIC if ros1 else Stores.ROS2_HUMBLE)
    tmp = path.with_name(path.name + ".part")
    if tmp.exists():
        subprocess.run(["rm", "-rf", str(tmp)], check=True)
    w: Any
    if ros1:
        w = Writer1(tmp)
        if fmt == "ros1-lz4":
            w.set_compression(Writer1.CompressionFormat.LZ4)
    else:
        plugin = StoragePlugin.SQLITE3 if fmt == "sqlite3" else StoragePlugin.MCAP
        w = Writer2(tmp, version=9, storage_plugin=plugin)
        if fmt == "mcap-zstd":
            w.set_compression(CompressionMode.STORAGE, CompressionFormat.ZSTD)
    with w:
        conns: dict[str, Any] = {}
        for _t, topic, typ, _d in msgs:
            if topic not in conns:
                conns[topic] = w.add_connection(topic, typ, typestore=store)
        for t, topic, _typ, data in msgs:
            w.write(conns[topic], t, data)
    if not ros1:  # the bag directory was written under the temporary name: its storage file carries that name
        for f in tmp.iterdir():
            if f.name.startswith(tmp.name):
                f.rename(tmp / (path.name + f.name[len(tmp.name):]))
        meta = tmp / "metadata.yaml"
        meta.write_text(meta.read_text().replace(tmp.name, path.name))
    tmp.rename(path)


def _size_mb(path: Path) -> float:
    files = [p for p in path.rglob("*") if p.is_file()] if path.is_dir() else [path]
    return sum(f.stat().st_size for f in files) / 1e6


def _warm(path: Path) -> None:
    """Read every byte once so that both sides start on a warm page cache."""
    files = [p for p in path.rglob("*") if p.is_file()] if path.is_dir() else [path]
    for f in files:
        with f.open("rb") as fh:
            while fh.read(1 << 20):
                pass


# ---- the measured work, run in a child process ----

def _cpu_s() -> float:
    """CPU time of this process so far (imports included): subtracted from the child's total."""
    import resource

    u = resource.getrusage(resource.RUSAGE_SELF)
    return u.ru_utime + u.ru_stime


def _child_rosbags(path: Path) -> dict[str, Any]:
    from rosbags.highlevel import AnyReader

    setup_cpu_s = _cpu_s()
    t0 = time.perf_counter()
    kept: dict[str, list[tuple[float, ...]]] = {POSE: [], NOMINAL: [], CMD: []}
    with AnyReader([path]) as reader:
        conns = [c for c in reader.connections if c.topic in kept]
        for conn, _t, data in reader.messages(connections=conns):
            m: Any = reader.deserialize(data, conn.msgtype)
            if conn.topic == CMD:
                kept[CMD].append((m.linear.x, m.linear.y, m.angular.z))
            else:
                kept[conn.topic].append((m.header.stamp.sec * 1e9 + m.header.stamp.nanosec, m.pose.position.x,
                                         m.pose.position.y))
    wall = time.perf_counter() - t0
    work_cpu_s = _cpu_s() - setup_cpu_s
    return {"wall_s": wall, "counts": {k: len(v) for k, v in kept.items()}, "setup_cpu_s": setup_cpu_s,
            "work_cpu_s": work_cpu_s}


def _import_readers() -> float:
    """Import rosbags' readers (ROS1 and ROS2: ``rosbags.highlevel``, as the rosbags loop's child does before its
    clock starts) and return the seconds it took: library imports are no part of any side's measured work (ours
    imports ``rosbags.rosbag2`` on its first ROS2 log; ~35 ms here, most of it ``ruamel.yaml``, which rosbags'
    ``rosbag2`` package imports)."""
    t0 = time.perf_counter()
    import rosbags.highlevel  # noqa: F401

    return time.perf_counter() - t0


def _child_ours(path: Path, digest: str | None = None) -> dict[str, Any]:
    from tubempc.scenario import builtin_scenario
    from verify.certify import certify_log

    import_s = _import_readers()
    sc = builtin_scenario()

    def once() -> tuple[Any, float, float]:
        cpu0 = _cpu_s()
        t0 = time.perf_counter()
        result = certify_log(path, sc) if digest is None else certify_log(path, sc, digest=digest)
        return result, time.perf_counter() - t0, _cpu_s() - cpu0

    setup_cpu_s = _cpu_s()
    result, wall, work_cpu_s = once()  # the first call in the process: what one `tubempc certify` pays
    # the same log again: the per-log cost once the process has certified a log (a batch worker, a second log)
    second, wall2, cpu2 = once()
    # and the log's reading alone (``read_raw``: open, index, chunks, the wanted records; no decoding, judging or
    # certificate), warm as the second call: what of ours compares with the floor's work
    from verify.ingest.log import wanted_topics
    from verify.ingest.raw import read_raw

    cpu0, t0 = _cpu_s(), time.perf_counter()
    read_raw(path, wanted_topics(sc))
    wall3, cpu3 = time.perf_counter() - t0, _cpu_s() - cpu0
    cert = result.certificate
    dq = cert["data_quality"]
    counts = {POSE: dq["pose"].get("count"), NOMINAL: dq["nominal"].get("count"), CMD: dq["cmd_vel"].get("count")}
    digest = cert.get("log_digest") or cert.get("log_sha256")
    if second.certificate != cert:
        raise SystemExit(f"{path}: a second certify_log of the same log gave another certificate")
    return {"wall_s": wall, "counts": counts, "verdict": cert["verdict"], "digest": digest,
            "setup_cpu_s": setup_cpu_s, "work_cpu_s": work_cpu_s, "wall2_s": wall2, "work2_cpu_s": cpu2,
            "read_wall_s": wall3, "work3_cpu_s": cpu3,
            "import_s": import_s}


def _wanted() -> set[str]:
    from tubempc.scenario import builtin_scenario
    from verify.ingest.log import wanted_topics

    return wanted_topics(builtin_scenario())


def _floor_ros1(path: Path, wanted: set[str]) -> int:
    """ROS1: the bag header and index (connections, chunk infos), then every chunk that holds a wanted connection,
    read and decompressed (lz4 and bz2 a few ahead in threads, as the certifier's reader does)."""
    import struct

    from verify.ingest.records import WORKERS, in_order, read_scratch, retain_freed_memory
    from verify.ingest.ros1records import MAGIC, Op, connection_of, decompress, record_at

    retain_freed_memory()  # as our reader does before its first decompression

    with path.open("rb") as fh:
        fd = fh.fileno()
        size = os.fstat(fd).st_size
        head = os.pread(fd, 4096, len(MAGIC))
        bag = record_at(head, 0, len(head))
        index_pos = struct.unpack("<Q", bag.header["index_pos"])[0]
        index = os.pread(fd, size - index_pos, index_pos)
        pos, ids, chunks = 0, set(), []
        while pos < len(index):
            rec = record_at(index, pos, len(index))
            if rec.op == Op.CONNECTION:
                cid, topic, _typ, _d = connection_of(rec.header, index[rec.data_start : rec.end])
                if topic in wanted:
                    ids.add(cid)
            elif rec.op == Op.CHUNK_INFO:
                pairs = struct.iter_unpack("<II", index[rec.data_start : rec.end])
                if any(cid in ids for cid, _n in pairs):
                    chunks.append(struct.unpack("<Q", rec.header["chunk_pos"])[0])
            pos = rec.end

        def chunk(at: int) -> int:
            first = os.pread(fd, 4096, at)
            rec = record_at(first, 0, len(first), head_only=True)
            comp = rec.header.get("compression", b"none").decode()
            if comp == "none":
                return len(os.pread(fd, rec.data_len, at + rec.data_start))
            return len(decompress(read_scratch(fd, at + rec.data_start, rec.data_len), comp))

        comp = record_at(os.pread(fd, 4096, chunks[0]), 0, 4096, head_only=True).header.get("compression", b"none")
        workers = 1 if comp == b"none" else WORKERS
        return sum(in_order(chunk, sorted(chunks), workers=workers))


def _floor_mcap(path: Path, wanted: set[str]) -> int:
    """MCAP: the summary (chunk indexes), then every chunk that holds a wanted channel, read and decompressed (zstd
    a few ahead in threads, as the certifier's reader does)."""
    from rosbags.rosbag2.storage_mcap import McapReader  # imported before the clock (_child_floor)

    from verify.ingest.mcaprecords import decompress
    from verify.ingest.records import WORKERS, in_order, read_scratch, retain_freed_memory

    retain_freed_memory()

    (file,) = sorted(path.glob("*.mcap"))
    storage = McapReader(file)
    storage.open()
    try:
        ids = {int(cid) for cid, ch in storage.channels.items() if ch.topic in wanted}
        chunks = [c for c in storage.chunks if any(c.channel_count.get(cid, 0) for cid in ids)]
    finally:
        storage.close()
    with file.open("rb") as fh:
        fd = fh.fileno()

        def chunk(c: Any) -> int:
            at = int(c.chunk_start_offset) + 9 + 28 + 4 + len(c.compression) + 8
            if not c.compression:
                return len(os.pread(fd, int(c.compressed_size), at))
            stored = read_scratch(fd, at, int(c.compressed_size))
            return len(decompress(stored, c.compression, int(c.uncompressed_size)))

        workers = WORKERS if any(c.compression for c in chunks) else 1
        return sum(in_order(chunk, chunks, workers=workers))


def _floor_sqlite(path: Path, wanted: set[str]) -> int:
    """sqlite3: the bag folder's metadata.yaml (its storage files: what a reader of a bag folder reads first), then
    the wanted topics' rows (topic, log time, payload) in log-time order, one query."""
    import sqlite3

    import yaml

    meta = yaml.load((path / "metadata.yaml").read_text(), Loader=getattr(yaml, "CSafeLoader", yaml.SafeLoader))
    (name,) = meta["rosbag2_bagfile_information"]["relative_file_paths"]
    db = path / name
    con = sqlite3.connect(f"file:{db}?immutable=1", uri=True)
    try:
        ids = [r[0] for r in con.execute("SELECT id, name FROM topics") if r[1] in wanted]
        marks = ",".join("?" * len(ids))
        rows = con.execute(f"SELECT topic_id, timestamp, data FROM messages WHERE topic_id IN ({marks}) "
                           f"ORDER BY timestamp", ids).fetchall()
    finally:
        con.close()
    return sum(len(r[2]) for r in rows)


def _child_floor(path: Path, fmt: str) -> dict[str, Any]:
    """The floor: what any reader of the wanted topics must do (read and decompress the chunks that hold them;
    sqlite3: fetch their rows), nothing else: no parsing of records, no decoding, no judging."""
    wanted = _wanted()
    import sqlite3  # noqa: F401  # library imports before the clock, as for ours and the rosbags loop

    import yaml  # noqa: F401

    import verify.ingest.mcaprecords
    import verify.ingest.records
    import verify.ingest.ros1records  # noqa: F401

    import_s = _import_readers()
    setup_cpu_s = _cpu_s()
    t0 = time.perf_counter()
    fn = _floor_ros1 if fmt.startswith("ros1") else _floor_sqlite if fmt == "sqlite3" else _floor_mcap
    n_bytes = fn(path, wanted)
    wall = time.perf_counter() - t0
    work_cpu_s = _cpu_s() - setup_cpu_s
    return {"wall_s": wall, "bytes": n_bytes, "setup_cpu_s": setup_cpu_s, "work_cpu_s": work_cpu_s,
            "import_s": import_s}


def measure(kind: str, path: Path) -> dict[str, Any]:
    """One measurement in a fresh child process: its JSON result plus its peak RSS (MB)."""
    with tempfile.TemporaryFile() as out:
        proc = subprocess.Popen([sys.executable, __file__, "--child", kind, str(path)], stdout=out)
        _pid, status, usage = os.wait4(proc.pid, 0)
        proc.returncode = os.waitstatus_to_exitcode(status)
        out.seek(0)
        text = out.read().decode()
    if proc.returncode != 0:
        raise SystemExit(f"{kind} on {path} failed (exit {proc.returncode}): {text[-400:]}")
    got: dict[str, Any] = json.loads(text.strip().splitlines()[-1])
    got["rss_mb"] = usage.ru_maxrss / 1024.0  # Linux: KiB
    # the measured work's CPU, all threads, as the child measured it (RUSAGE_SELF: every thread of the process);
    # what the child spent after it (freeing, interpreter exit) is kept apart: it is no part of the work
    got["cpu_s"] = got.pop("work_cpu_s")
    if "work2_cpu_s" in got:  # ours: the second call of certify_log (per log, once the process has certified one)
        got["cpu2_s"] = got.pop("work2_cpu_s")
    measured = got["cpu_s"] + got.get("cpu2_s", 0.0) + got.pop("work3_cpu_s", 0.0)
    got["exit_cpu_s"] = usage.ru_utime + usage.ru_stime - got.pop("setup_cpu_s") - measured
    return got


def best_of(runs: list[dict[str, Any]]) -> dict[str, Any]:
    """The fastest run, with the largest peak RSS and the smallest CPU time seen."""
    best = min(runs, key=lambda r: r["wall_s"])
    out = {**best, "rss_mb": max(r["rss_mb"] for r in runs), "cpu_s": min(r["cpu_s"] for r in runs),
           "exit_cpu_s": min(r["exit_cpu_s"] for r in runs)}
    for key in ("wall2_s", "cpu2_s", "read_wall_s", "import_s"):
        if key in best:
            out[key] = min(r[key] for r in runs)
    return out


def _compile_project() -> None:
    """Byte-compile the project's packages into their ``__pycache__`` folders, as Python does on a first import (and
    pip at install): ours imports its modules for a format on the first log of that format, inside its clock, and an
    environment with ``PYTHONDONTWRITEBYTECODE`` set (as this workplace's) would otherwise compile them from source
    in every child (~8 ms for the ROS2 modules), a cost no installed copy pays."""
    import compileall

    root = Path(__file__).resolve().parent.parent
    for pkg in ("verify", "tubempc"):
        compileall.compile_dir(root / pkg, quiet=1)


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--size-gb", type=float, default=1.0)
    ap.add_argument("--dir", type=Path, default=Path(tempfile.gettempdir()) / "bench_bigbag")
    ap.add_argument("--formats", default=",".join(FORMATS))
    ap.add_argument("--repeat", type=int, default=3, help="runs per side and format; the fastest is kept")
    ap.add_argument("--no-file-digest", action="store_true", help="do not measure ours + the whole file's digest")
    ap.add_argument("--child", nargs=2, metavar=("KIND", "PATH"), help=argparse.SUPPRESS)
    ap.add_argument("--write", nargs=3, metavar=("FORMAT", "PATH", "SIZE_GB"), help=argparse.SUPPRESS)
    args = ap.parse_args()
    if args.write:
        write(Path(args.write[1]), args.write[0], float(args.write[2]))
        return
    if args.child:
        kind, p = args.child
        res = (_child_rosbags(Path(p)) if kind == "rosbags" else
               _child_floor(Path(p), kind.split(":", 1)[1]) if kind.startswith("floor:") else
               _child_ours(Path(p), "blake3") if kind == "ours+file" else _child_ours(Path(p)))
        print(json.dumps(res))
        return
    formats = [f for f in args.formats.split(",") if f]
    unknown = sorted(set(formats) - set(FORMATS))
    if unknown:
        raise SystemExit(f"--formats: unknown {', '.join(unknown)} (choose from {', '.join(FORMATS)})")
    args.dir.mkdir(parents=True, exist_ok=True)
    _compile_project()
    print(f"load average (shared machine): {' '.join(f'{v:.2f}' for v in os.getloadavg())}")
    rows: list[tuple[str, float, dict[str, Any], dict[str, Any], dict[str, Any] | None]] = []
    floors: dict[str, dict[str, Any]] = {}
    for fmt in formats:
        path = args.dir / f"bigbag_{args.size_gb:g}gb_{fmt.replace('-', '_')}{'.bag' if fmt.startswith('ros1') else ''}"
        if not path.exists():  # written by a child: this process stays small (a child's peak RSS starts at ours)
            t_w = time.perf_counter()
            subprocess.run([sys.executable, __file__, "--write", fmt, str(path), str(args.size_gb)], check=True)
            print(f"wrote {path} ({_size_mb(path):.0f} MB) in {time.perf_counter() - t_w:.0f} s", flush=True)
        _warm(path)
        kinds = ["rosbags", "ours", f"floor:{fmt}"] + ([] if args.no_file_digest else ["ours+file"])
        runs: dict[str, list[dict[str, Any]]] = {kind: [] for kind in kinds}
        for _ in range(args.repeat):
            for kind, got in runs.items():
                got.append(measure(kind, path))
        base, ours, floor = best_of(runs["rosbags"]), best_of(runs["ours"]), best_of(runs[f"floor:{fmt}"])
        whole = best_of(runs["ours+file"]) if "ours+file" in runs else None
        if base["counts"] != ours["counts"]:
            print(f"  {fmt}: message counts differ: rosbags {base['counts']}, ours {ours['counts']}")
        rows.append((fmt, _size_mb(path), base, ours, whole))
        floors[fmt] = floor
        more = "" if whole is None else f", ours + file digest {whole['wall_s']:.2f} s"
        print(f"  {fmt}: rosbags {base['wall_s']:.2f} s, ours {ours['wall_s']:.2f} s{more}", flush=True)
    print(f"| log ({args.size_gb:g} GB) | size MB | rosbags loop: wall s / CPU s / max RSS MB | certify_log: wall s / "
          f"CPU s / max RSS MB | ratio (wall) | ratio (CPU) | + file digest: wall s / max RSS MB / ratio | verdict |")
    print("|---|---|---|---|---|---|---|---|")
    for fmt, size, base, ours, whole in rows:
        extra = "-" if whole is None else (f"{whole['wall_s']:.2f} / {whole['rss_mb']:.0f} / "
                                           f"{base['wall_s'] / whole['wall_s']:.2f}x")
        print(f"| {fmt} | {size:.0f} | {base['wall_s']:.2f} / {base['cpu_s']:.2f} / {base['rss_mb']:.0f} | "
              f"{ours['wall_s']:.2f} / {ours['cpu_s']:.2f} / {ours['rss_mb']:.0f} | "
              f"{base['wall_s'] / ours['wall_s']:.2f}x | {base['cpu_s'] / ours['cpu_s']:.2f}x | {extra} | "
              f"{ours['verdict']} |")
    print()
    print("| log | floor: wall s / CPU s | certify_log, first call: wall s / CPU s | ours/floor (wall) | "
          "ours CPU/wall | certify_log, second call: wall s / CPU s | ours/floor (wall), second call | "
          "ours' reading alone (read_raw, warm): wall s / vs floor | "
          "library imports before the clock: ours s | ours: CPU s after the work (exit, not counted) |")
    print("|---|---|---|---|---|---|---|---|---|---|")
    for fmt, _size, _base, ours, _whole in rows:
        fl = floors[fmt]
        print(f"| {fmt} | {fl['wall_s']:.3f} / {fl['cpu_s']:.3f} | {ours['wall_s']:.3f} / {ours['cpu_s']:.3f} | "
              f"{ours['wall_s'] / fl['wall_s']:.2f}x | {ours['cpu_s'] / ours['wall_s']:.2f} | "
              f"{ours['wall2_s']:.3f} / {ours['cpu2_s']:.3f} | {ours['wall2_s'] / fl['wall_s']:.2f}x | "
              f"{ours['read_wall_s']:.3f} / {ours['read_wall_s'] / fl['wall_s']:.2f}x | "
              f"{ours['import_s']:.3f} | {ours['exit_cpu_s']:.2f} |")
    worst_floor = max(o["wall_s"] / floors[f]["wall_s"] for f, _s, _b, o, _w in rows)
    worst_floor2 = max(o["wall2_s"] / floors[f]["wall_s"] for f, _s, _b, o, _w in rows)
    worst_read = max(o["read_wall_s"] / floors[f]["wall_s"] for f, _s, _b, o, _w in rows)
    plain = [o["cpu_s"] / o["wall_s"] for f, _s, _b, o, _w in rows if f in UNCOMPRESSED]
    worst = min(b["wall_s"] / o["wall_s"] for _f, _s, b, o, _w in rows)
    wholes = [b["wall_s"] / w["wall_s"] for _f, _s, b, _o, w in rows if w is not None]
    print(f"worst_ratio_vs_rosbags={worst:.2f} max_rss_mb={max(o['rss_mb'] for _f, _s, _b, o, _w in rows):.0f} "
          f"formats={len(rows)}" + (f" worst_ratio_file_digest={min(wholes):.2f}" if wholes else "") +
          (f" worst_cpu_per_wall_uncompressed={max(plain):.2f}" if plain else "") +
          f" worst_ratio_vs_floor={worst_floor:.2f} worst_ratio_vs_floor_second_call={worst_floor2:.2f}"
          f" worst_read_vs_floor={worst_read:.2f}")


if __name__ == "__main__":
    main()
