"""Fault campaign for ``tubempc certify``: damaged logs, faulty messages, formulas, scenarios and output paths.

    python3 benchmarks/fuzz_certify.py [--cases 3000] [--seed 1] [--timeout 30] [--dir /tmp/fuzz_certify] [-v]

Seed logs are written here (ROS1 ``.bag``, bare ``.mcap``, bare sqlite3 ``.db3`` and a ROS2 bag folder; and, as a
lab recording is, small chunks shared with a camera-like topic certification does not read: ROS1 uncompressed and
lz4, MCAP uncompressed and zstd -- the message-level, one-pass and decompressing readers), each as a
clean run (stays in R1: it passes ``G !(obs_1 | ... | obs_4)``) and a violating run (three separate visits to an
obstacle's centre, so no single damage can hide all of them). Every case runs the real command line in this process
(``tubempc.cli.main`` with stdout/stderr captured, a per-case alarm to detect hangs) and is classified:

* crash: exit 70, an exception escaping ``main``, an exit code outside 0-3, a traceback or more than one stderr
  line for exit 3, a warning on stderr, an input file modified, or a required outcome missed (e.g. an optional
  topic's bad message making the log unusable);
* hang: the case exceeded ``--timeout`` seconds;
* false pass: exit 0 for a run whose ground truth violates the formula (the violating seed, whatever the damage:
  a byte-level fault touches at most one of its three visits), or for a log the fault leaves undecidable.

Case families (drawn with one ``random.Random(seed)``): byte flips, truncations and zeroed ranges of every seed
format; message-content faults (header stamps: a repeated stamp hiding an obstacle visit, stamps never set,
negative / 1970 / reordered stamps; NaN positions, zero quaternions, invalid UTF-8 frame ids, bad bytes in an
optional topic, a wrong type on the pose topic, a missing topic); formula mutations (edits, deep nesting, long
chains, huge bounds); scenario YAML mutations (edits, many regions, alias bombs, bad bytes); output paths and
non-regular log paths (also inside a bag folder), huge windows; stamp faults on every stream (a signal topic, the
nominal, ``TwistStamped`` commands), two types on one topic, option values at and past their limits,
symlinks in output folders, signal data outside the pose's span; constant and degenerate formulas (``true``,
``false``, ``G !true``, windows past the log's end: the exact verdict is required), all-infinite and NaN-only
streams (poses, a signal, commands), scenario values at and past the validator's limits, log times moved out of
file order (any stream, any format: every indexed reader yields a closed log by log time), a second publisher on a
stream at the first's log times (same or violating content). Every certify case is run
again on the other ingest path and under ``tubempc watch`` (same formula, checks, time base, clock offsets). The
last line is ``cases=N crashes=N hangs=N false_pass=N path_disagreements=N watch_disagreements=N``.
"""

from __future__ import annotations

import argparse
import contextlib
import io
import json
import math
import os
import random
import shutil
import signal
import stat
import struct
import sys
import tempfile
import time
from collections import Counter
from collections.abc import Callable, Iterator
from dataclasses import dataclass, field
from pathlib import Path
from types import FrameType
from typing import Any

import numpy as np
from rosbags.interfaces import Qos, QosDurability, QosHistory, QosLiveliness, QosReliability, QosTime
from rosbags.rosbag1 import Writer as Writer1
from rosbags.rosbag2 import CompressionFormat, CompressionMode, StoragePlugin
from rosbags.rosbag2 import Writer as Writer2
from rosbags.typesys import Stores, get_typestore

from tubempc.scenario import builtin_scenario, builtin_scenario_text

SCENARIO = builtin_scenario()
SPEC = "G[0,inf) !(obs_1 | obs_2 | obs_3 | obs_4)"
TIME0_NS = 1_767_225_600 * 10**9
RATE_HZ = 10.0
END_S = 30.0
FORMATS = ("bag", "mcap", "db3", "dir", "bag-cam", "bag-lz4", "mcap-cam", "mcap-zstd")
CAMERA = "/camera/image_raw"  # the unread topic of the "-cam" and compressed formats
POSE = "geometry_msgs/msg/PoseStamped"
TWIST = "geometry_msgs/msg/Twist"
STRING = "std_msgs/msg/String"
ODOMETRY = "nav_msgs/msg/Odometry"
TWIST_STAMPED = "geometry_msgs/msg/TwistStamped"


class Hang(BaseException):
    """Raised by the per-case alarm (a BaseException: no ``except Exception`` in the code under test catches it)."""


# ------------------------------------------------------------------------------------------------ seed logs
@dataclass
class Run:
    """Samples of one run (all arrays in reading order) and the message-level edits applied when writing it."""

    t_ns: np.ndarray
    stamp_ns: np.ndarray
    xy: np.ndarray
    quat: np.ndarray
    cmd: np.ndarray
    violating: bool
    frame_ids: dict[int, bytes] = field(default_factory=dict)  # pose index -> raw frame_id bytes
    status_patch: bytes | None = None  # raw bytes replacing one solver status payload
    pose_type: str = POSE
    topics: tuple[str, ...] = ("pose", "nominal", "cmd_vel", "solver", "metadata")
    # more messages: (log time ns, topic, type, builder(typestore types, ros1) -> message)
    extra: list[tuple[int, str, str, Callable[[Any, bool], Any]]] = field(default_factory=list)
    # the nominal's own header stamps and positions (None: the pose's); commands as TwistStamped with these stamps
    nominal_stamp_ns: np.ndarray | None = None
    nominal_xy: np.ndarray | None = None
    cmd_stamp_ns: np.ndarray | None = None
    # log times moved after the messages are placed in the file: (topic, k-th message of the topic, new log time
    # ns); the message keeps its file place and its header stamp (a tool that rewrote the log, a clock that jumped)
    log_moves: list[tuple[str, int, int]] = field(default_factory=list)
    # messages of a second publisher on their topic (a connection of its own: another caller id in ROS1, another
    # QoS profile in ROS2): (log time ns, topic, type, builder)
    second: list[tuple[int, str, str, Callable[[Any, bool], Any]]] = field(default_factory=list)


#: the signal topic of the campaign's signal families: a motor temperature (sensor_msgs/Temperature, in ROS1 and 2)
TEMP_TOPIC = "/motor/temperature"
TEMPERATURE = "sensor_msgs/msg/Temperature"
TEMP_LIMIT_C = 70.0


def temperature(stamp_ns: int, celsius: float) -> Callable[[Any, bool], Any]:
    """A builder of one ``sensor_msgs/Temperature`` message stamped ``stamp_ns``."""
    def build(ty: Any, ros1: bool) -> Any:
        sec, nsec = divmod(int(stamp_ns), 10**9)
        header = ty["std_msgs/msg/Header"](**({"seq": 0} if ros1 else {}),
                                           stamp=ty["builtin_interfaces/msg/Time"](sec=sec, nanosec=nsec),
                                           frame_id="motor")
        return ty[TEMPERATURE](header=header, temperature=float(celsius), variance=0.0)
    return build


def temperature_stream(run: Run, celsius: float = 40.0) -> list[tuple[int, str, str, Callable[[Any, bool], Any]]]:
    """A well-stamped temperature message beside every pose sample (5 ms before it)."""
    return [(int(t) - 5_000_000, TEMP_TOPIC, TEMPERATURE, temperature(int(t) - 5_000_000, celsius))
            for t in run.t_ns]


def signal_scenario_text(rate_hz: float | None = None) -> str:
    """The campaign's scenario with the signal atom ``motor_ok`` (temperature <= TEMP_LIMIT_C)."""
    rate = "" if rate_hz is None else f", rate_hz: {rate_hz!r}"
    return (builtin_scenario_text("nexus-sml").rstrip("\n") + "\nsignals:\n  motor_ok: {topic: " + TEMP_TOPIC
            + ", field: temperature, op: '<=', value: " + f"{TEMP_LIMIT_C}, unit: degC{rate}" + "}\n")


def base_run(*, violating: bool) -> Run:
    t = np.arange(0.0, END_S + 1e-9, 1.0 / RATE_HZ)
    r1 = SCENARIO.region("R1").center
    x = r1[0] + 0.05 * np.sin(t / 5.0)
    y = r1[1] + 0.05 * np.cos(t / 5.0) - 0.05
    if violating:
        obs = SCENARIO.unsafe_regions[0].center
        for visit_s in (5.0, 15.0, 25.0):
            k = round(visit_s * RATE_HZ)
            x[k : k + 3], y[k : k + 3] = obs[0], obs[1]
    t_ns = TIME0_NS + np.rint(t * 1e9).astype(np.int64)
    quat = np.tile([0.0, 0.0, 0.0, 1.0], (t.size, 1))
    return Run(t_ns, t_ns.copy(), np.column_stack([x, y]), quat, np.zeros((t.size, 3)), violating)


def _cdr_string_patch(payload: bytes, ros1: bool, new: bytes) -> bytes:
    """Replace a PoseStamped's frame_id (after seq/stamp, or CDR header + stamp) by raw ``new`` bytes."""
    at = 12  # ROS1: seq(4) sec(4) nsec(4); CDR: encapsulation(4) sec(4) nsec(4)
    (old_len,) = struct.unpack_from("<I", payload, at)
    rest = payload[at + 4 + old_len :]
    body = new if ros1 else new + b"\0"
    if not ros1:
        pad = (-(at + 4 + len(body) - 4)) % 8  # the pose (float64) is 8-aligned relative to the CDR body
        old_pad = (-(at + 4 + old_len - 4)) % 8
        rest = rest[old_pad:]
        body += b"\0" * pad
        return payload[:at] + struct.pack("<I", len(new) + 1) + body + rest
    return payload[:at] + struct.pack("<I", len(new)) + body + rest


def write_run(run: Run, path: Path, fmt: str) -> Path:
    """Write ``run`` with rosbags writers; ``fmt``: bag, mcap (bare file), db3 (bare file), dir (sqlite3 folder);
    bag-cam / bag-lz4 / mcap-cam / mcap-zstd: with a 2 KB camera message per sample and chunks of a few samples."""
    ros1 = fmt.startswith("bag")
    camera = "-" in fmt
    store = get_typestore(Stores.ROS1_NOETIC if ros1 else Stores.ROS2_HUMBLE)
    ser = store.serialize_ros1 if ros1 else store.serialize_cdr
    ty = store.types
    topics = SCENARIO.topics
    msgs: list[tuple[int, str, str, bytes]] = []
    def header(i: int, stamp_ns: int) -> Any:
        sec, nsec = divmod(int(stamp_ns), 10**9)
        stamp = ty["builtin_interfaces/msg/Time"](sec=sec, nanosec=nsec)
        return ty["std_msgs/msg/Header"](**({"seq": i} if ros1 else {}), stamp=stamp, frame_id="world")

    def pose_msg(i: int, stamp_ns: int, xy: np.ndarray) -> Any:
        return ty[POSE](header=header(i, stamp_ns), pose=ty["geometry_msgs/msg/Pose"](
            position=ty["geometry_msgs/msg/Point"](x=float(xy[i, 0]), y=float(xy[i, 1]), z=0.0),
            orientation=ty["geometry_msgs/msg/Quaternion"](*(float(q) for q in run.quat[i]))))

    for i in range(run.t_ns.size):
        pose = pose_msg(i, int(run.stamp_ns[i]), run.xy)
        raw = bytes(ser(pose, POSE))
        if i in run.frame_ids:
            raw = _cdr_string_patch(raw, ros1, run.frame_ids[i])
        if "pose" in run.topics:
            if run.pose_type == POSE:
                msgs.append((int(run.t_ns[i]), topics.pose, POSE, raw))
            else:
                msgs.append((int(run.t_ns[i]), topics.pose, STRING,
                             bytes(ser(ty[STRING](data="not a pose"), STRING))))
        if "nominal" in run.topics:
            nominal = pose if run.nominal_stamp_ns is None and run.nominal_xy is None else pose_msg(
                i, int((run.stamp_ns if run.nominal_stamp_ns is None else run.nominal_stamp_ns)[i]),
                run.xy if run.nominal_xy is None else run.nominal_xy)
            msgs.append((int(run.t_ns[i]), topics.nominal, POSE, bytes(ser(nominal, POSE))))
        if "cmd_vel" in run.topics:
            v3 = ty["geometry_msgs/msg/Vector3"]
            tw = ty[TWIST](linear=v3(x=float(run.cmd[i, 0]), y=float(run.cmd[i, 1]), z=0.0),
                           angular=v3(x=0.0, y=0.0, z=float(run.cmd[i, 2])))
            if run.cmd_stamp_ns is None:
                msgs.append((int(run.t_ns[i]), topics.cmd_vel, TWIST, bytes(ser(tw, TWIST))))
            else:
                stamped = ty[TWIST_STAMPED](header=header(i, int(run.cmd_stamp_ns[i])), twist=tw)
                msgs.append((int(run.t_ns[i]), topics.cmd_vel, TWIST_STAMPED, bytes(ser(stamped, TWIST_STAMPED))))
        if camera:
            msgs.append((int(run.t_ns[i]) + 1, CAMERA, STRING, bytes(ser(ty[STRING](data="c" * 2000), STRING))))
        if "solver" in run.topics and i % 10 == 0:
            status = {"t_s": i / RATE_HZ, "status": "Solve_Succeeded", "success": True, "iterations": 4}
            data = bytes(ser(ty[STRING](data=json.dumps(status)), STRING))
            if run.status_patch is not None and i == 100:
                data = run.status_patch
            msgs.append((int(run.t_ns[i]), topics.solver, STRING, data))
    for t_ns, topic, msgtype, build in run.extra:
        msgs.append((t_ns, topic, msgtype, bytes(ser(build(ty, ros1), msgtype))))
    for t_ns, topic, msgtype, build in run.second:
        msgs.append((t_ns, topic, msgtype + SECOND, bytes(ser(build(ty, ros1), msgtype))))
    if "metadata" in run.topics:
        meta = {"generator": "fuzz_certify", "scenario_sha256": SCENARIO.sha256(), "time0_ns": TIME0_NS}
        msgs.append((TIME0_NS, topics.metadata, STRING, bytes(ser(ty[STRING](data=json.dumps(meta)), STRING))))
    msgs.sort(key=lambda m: m[0])
    for topic, k, new_ns in run.log_moves:
        at = [i for i, m in enumerate(msgs) if m[1] == topic][k]
        msgs[at] = (new_ns, *msgs[at][1:])

    def write_all(writer: Any, close_chunk: Callable[[], None] | None = None) -> None:
        conns: dict[tuple[str, str], Any] = {}
        for k, (t, topic, msgtype, data) in enumerate(msgs):
            if (topic, msgtype) not in conns:  # a topic written with two types gets two connections
                real = msgtype.removesuffix(SECOND)
                kw: dict[str, Any] = {}
                if real != msgtype:  # a second publisher of the topic: a connection of its own
                    kw = {"callerid": "/second"} if ros1 else {"offered_qos_profiles": [SECOND_QOS]}
                conns[topic, msgtype] = writer.add_connection(topic, real, typestore=store, **kw)
            writer.write(conns[topic, msgtype], t, data)
            if close_chunk is not None and k % 40 == 39:
                close_chunk()

    if ros1:
        w1 = Writer1(path)
        if camera:
            w1.chunk_threshold = 16 << 10
        if fmt == "bag-lz4":
            w1.set_compression(Writer1.CompressionFormat.LZ4)
        with w1:
            write_all(w1)
        return path
    storage = StoragePlugin.MCAP if fmt.startswith("mcap") else StoragePlugin.SQLITE3
    bag_dir = path if fmt == "dir" else path.parent / (path.name + ".d")
    w2 = Writer2(bag_dir, version=9, storage_plugin=storage)
    if fmt == "mcap-zstd":
        w2.set_compression(CompressionMode.STORAGE, CompressionFormat.ZSTD)
    with w2:
        write_all(w2, w2.storage.close_chunk if camera else None)  # type: ignore[union-attr]
    if fmt == "dir":
        return path
    (inner,) = [p for p in bag_dir.iterdir() if p.suffix in (".mcap", ".db3")]
    shutil.move(inner, path)
    shutil.rmtree(bag_dir)
    return path


SUFFIX = {"bag": ".bag", "mcap": ".mcap", "db3": ".db3", "dir": "", "bag-cam": ".bag", "bag-lz4": ".bag",
          "mcap-cam": ".mcap", "mcap-zstd": ".mcap"}


def seed_path(root: Path, fmt: str, violating: bool) -> Path:
    return root / f"seed_{'bad' if violating else 'good'}_{fmt}{SUFFIX[fmt]}"


def write_seeds(root: Path) -> dict[tuple[str, bool], Path]:
    root.mkdir(parents=True, exist_ok=True)
    out = {}
    for fmt in FORMATS:
        for violating in (False, True):
            p = seed_path(root, fmt, violating)
            if p.exists():
                shutil.rmtree(p) if p.is_dir() else p.unlink()
            out[fmt, violating] = write_run(base_run(violating=violating), p, fmt)
    return out


# ------------------------------------------------------------------------------------------------ running a case
@dataclass
class Outcome:
    code: int | None
    stdout: str
    stderr: str
    error: str | None  # an exception that escaped main
    seconds: float


def run_cli(argv: list[str], timeout_s: float) -> Outcome:
    """``tubempc.cli.main(argv)`` in this process; a Hang after ``timeout_s``; output captured."""
    from tubempc.cli import main

    out, err = io.StringIO(), io.StringIO()

    def on_alarm(signum: int, frame: FrameType | None) -> None:
        raise Hang

    # CPU time (ITIMER_PROF) detects a busy loop whatever the machine's load; wall time (ITIMER_REAL, 4x longer)
    # detects a blocked read (a FIFO, a lock)
    previous = signal.signal(signal.SIGALRM, on_alarm)
    previous_prof = signal.signal(signal.SIGPROF, on_alarm)
    signal.setitimer(signal.ITIMER_PROF, timeout_s)
    signal.setitimer(signal.ITIMER_REAL, 4 * timeout_s)
    start = time.perf_counter()
    code: int | None = None
    error = None
    try:
        with contextlib.redirect_stdout(out), contextlib.redirect_stderr(err):
            try:
                main(argv)
            except SystemExit as exc:
                code = exc.code if isinstance(exc.code, int) else (0 if exc.code is None else 1)
    except Hang:
        code, error = None, "hang"
    except Exception as exc:  # anything escaping main is a crash of the command line
        error = f"{exc.__class__.__name__}: {exc}"
    finally:
        signal.setitimer(signal.ITIMER_REAL, 0)
        signal.setitimer(signal.ITIMER_PROF, 0)
        signal.signal(signal.SIGALRM, previous)
        signal.signal(signal.SIGPROF, previous_prof)
    return Outcome(code, out.getvalue(), err.getvalue(), error, time.perf_counter() - start)


@dataclass
class Case:
    family: str
    kind: str
    argv: list[str]
    truth: str  # "violating": must not pass; "undecidable": must not pass; "any": no requirement on the verdict
    inputs: list[Path] = field(default_factory=list)  # must be byte-identical after the run
    require: Callable[[Outcome], str | None] | None = None  # an extra requirement (message when it fails)


def _snapshot(paths: list[Path]) -> dict[str, bytes]:
    snap: dict[str, bytes] = {}
    for p in paths:
        if p.is_dir():
            for f in sorted(p.rglob("*")):
                if f.is_file():
                    snap[str(f)] = f.read_bytes()
        elif p.is_file():
            snap[str(p)] = p.read_bytes()
    return snap


def classify(case: Case, res: Outcome, before: dict[str, bytes], after: dict[str, bytes]) -> tuple[str, str]:
    """(class, detail): class is ok, crash, hang or false_pass."""
    if res.error == "hang":
        return "hang", f"> timeout ({res.seconds:.1f} s)"
    if res.error is not None:
        return "crash", res.error
    if res.code not in (0, 1, 2, 3):
        return "crash", f"exit {res.code}: {res.stderr.strip()[-300:]}"
    err_lines = [ln for ln in res.stderr.splitlines() if ln.strip()]
    debug = "--debug" in case.argv
    if debug and "Traceback" in res.stderr:  # --debug adds the traceback before the one line
        err_lines = err_lines[-1:]
    if "Traceback" in res.stderr and not debug:
        return "crash", "traceback on stderr"
    if res.code == 3 and (len(err_lines) != 1 or not err_lines[0].startswith("tubempc: error: ")):
        return "crash", f"exit 3 with {len(err_lines)} stderr lines: {res.stderr.strip()[:300]!r}"
    if res.code in (0, 1, 2) and err_lines:
        return "crash", f"stderr on a normal run: {res.stderr.strip()[:300]!r}"
    if before != after:
        return "crash", "an input file was modified"
    if case.require is not None and (why := case.require(res)) is not None:
        return "crash", why
    if res.code == 0 and case.truth in ("violating", "undecidable"):
        return "false_pass", f"pass for a {case.truth} log"
    return "ok", ""


# ------------------------------------------------------------------------------------------------ case families
def _copy(src: Path, dst: Path) -> Path:
    if src.is_dir():
        shutil.copytree(src, dst)
    else:
        shutil.copyfile(src, dst)
    return dst


def _storage(p: Path) -> Path:
    return next(f for f in p.iterdir() if f.suffix == ".db3") if p.is_dir() else p


def byte_case(rng: random.Random, seeds: dict[tuple[str, bool], Path], work: Path) -> Case:
    fmt = rng.choice(FORMATS)
    violating = rng.random() < 0.5
    path = _copy(seeds[fmt, violating], work / seeds[fmt, violating].name)
    target = _storage(path)
    if fmt == "dir" and rng.random() < 0.2:
        target = path / "metadata.yaml"
    data = bytearray(target.read_bytes())
    kind = rng.choice(["flip", "flip", "truncate", "zero"])
    if kind == "flip":
        for _ in range(rng.choice([1, 1, 2, 4, 8])):
            k = rng.randrange(len(data))
            data[k] ^= 1 << rng.randrange(8) if rng.random() < 0.7 else rng.randrange(1, 256)
    elif kind == "truncate":
        data = data[: rng.randrange(len(data))]
    else:
        a = rng.randrange(len(data))
        data[a : a + rng.choice([1, 4, 16, 256, 4096])] = bytes(min(len(data) - a,
                                                                     rng.choice([1, 4, 16, 256, 4096])))
    target.write_bytes(bytes(data))
    argv = ["certify", str(path), "--scenario", "nexus-sml", "--spec", SPEC]
    if rng.random() < 0.3:
        argv.append("--salvage")
    if rng.random() < 0.2:
        argv += ["--time-base", rng.choice(["auto", "header", "log"])]
    if rng.random() < 0.1:
        argv.insert(0, "--debug")
    return Case("bytes", f"{fmt}:{kind}", argv, "violating" if violating else "any", [path])


def _not_unusable(res: Outcome) -> str | None:
    return "a bad message in an optional topic made the log unusable" if res.code == 3 else None


def content_case(rng: random.Random, seeds: dict[tuple[str, bool], Path], work: Path) -> Case:
    fmt = rng.choice(FORMATS)
    kinds = ["dup_hides_obstacle", "zero_stamps", "zero_stamps_violating", "outlier_stamp", "reorder",
             "nan_position", "zero_quaternion", "bad_utf8_frame", "bad_status_bytes", "bad_status_utf8",
             "wrong_pose_type", "missing_nominal", "missing_cmd", "huge_frame_len"]
    kind = rng.choice(kinds)
    run = base_run(violating=kind == "zero_stamps_violating")
    n = run.t_ns.size
    truth = "any"
    require: Callable[[Outcome], str | None] | None = None
    time_base = "auto"
    if kind == "dup_hides_obstacle":
        k = rng.randrange(1, n - 2)
        run.stamp_ns[k + 1] = run.stamp_ns[k]
        run.xy[rng.choice([k, k + 1])] = SCENARIO.unsafe_regions[rng.randrange(4)].center
        truth = "violating"
    elif kind in ("zero_stamps", "zero_stamps_violating"):
        run.stamp_ns[:] = 0
        truth = "violating" if run.violating else "any"
        time_base = rng.choice(["auto", "header"])
        if time_base == "header" and not run.violating:
            truth = "undecidable"
    elif kind == "outlier_stamp":
        k = rng.randrange(n)
        run.stamp_ns[k] = rng.choice([-5 * 10**9, 0, 10**9, 86_400 * 10**9]) if not fmt.startswith("bag") else \
            rng.choice([0, 10**9, 86_400 * 10**9])

        def must_pass(res: Outcome) -> str | None:
            return None if res.code == 0 else f"a good run with one outlier stamp gave exit {res.code}"

        require = must_pass
    elif kind == "reorder":
        for _ in range(rng.randrange(1, 30)):
            k = rng.randrange(n - 1)
            run.stamp_ns[[k, k + 1]] = run.stamp_ns[[k + 1, k]]
    elif kind == "nan_position":
        run.xy[rng.randrange(n), rng.randrange(2)] = math.nan
        truth = "undecidable"
    elif kind == "zero_quaternion":
        run.quat[rng.randrange(n)] = 0.0
    elif kind == "bad_utf8_frame":
        run.frame_ids[rng.randrange(n)] = b"w\xff\xfeorld"
    elif kind == "huge_frame_len":
        run.frame_ids[rng.randrange(n)] = b"x" * rng.choice([1, 7, 300])
    elif kind == "bad_status_bytes":
        run.status_patch = bytes(rng.randrange(256) for _ in range(rng.choice([0, 3, 9, 40])))
        require = _not_unusable
    elif kind == "bad_status_utf8":
        body = b'{"success": \xff\xfe}'
        run.status_patch = (struct.pack("<I", len(body)) + body if fmt.startswith("bag")
                            else b"\0\x01\0\0" + struct.pack("<I", len(body) + 1) + body + b"\0")
        require = _not_unusable
    elif kind == "wrong_pose_type":
        run.pose_type = STRING
    elif kind == "missing_nominal":
        run.topics = ("pose", "cmd_vel", "solver", "metadata")
        truth = "undecidable"
    elif kind == "missing_cmd":
        run.topics = ("pose", "nominal", "solver", "metadata")
        truth = "undecidable"
    path = write_run(run, work / f"run_{kind}{SUFFIX[fmt]}", fmt)
    argv = ["certify", str(path), "--scenario", "nexus-sml", "--spec", SPEC, "--time-base", time_base]
    return Case("content", f"{fmt}:{kind}", argv, truth, [path], require)


VALID_FORMULAS = [SPEC, "F[0,10] mission_1", "G[0,20] (mission_1 -> F[0,5] mission_1)",
                  "!obs_1 U[0,30] mission_1", "X[0,1] mission_1", "G[0,inf) (obs_1 -> F[0,1] !obs_1)"]


def formula_case(rng: random.Random, seeds: dict[tuple[str, bool], Path], work: Path) -> Case:
    truth = "any"
    kind = rng.choice(["edit", "edit", "nest_not", "nest_paren", "nest_temporal", "and_chain", "or_chain",
                       "big_bound", "garbage", "empty"])
    text = rng.choice(VALID_FORMULAS)
    if kind == "edit":
        chars = list(text)
        alphabet = "()[]{},.;:!&|-><=~UFGX0123456789 abcinfmission_obs_∧∨¬◇□→\x00\n\t\\\"'"
        for _ in range(rng.randrange(1, 5)):
            op = rng.randrange(3)
            k = rng.randrange(len(chars) + 1)
            if op == 0:
                chars.insert(k, rng.choice(alphabet))
            elif chars and op == 1:
                del chars[min(k, len(chars) - 1)]
            elif chars:
                chars[min(k, len(chars) - 1)] = rng.choice(alphabet)
        text = "".join(chars)
    elif kind == "nest_not":
        depth = rng.choice([100, 500, 2000, 20000])
        text = "!" * depth + "obs_1"
    elif kind == "nest_paren":
        depth = rng.choice([100, 500, 2000, 20000])
        text = "(" * depth + "obs_1" + ")" * depth
    elif kind == "nest_temporal":
        depth = rng.choice([50, 500, 3000])
        text = "F[0,1] (" * depth + "mission_1" + ")" * depth
    elif kind in ("and_chain", "or_chain"):
        count = rng.choice([1000, 10_000, 100_000])
        op = " & " if kind == "and_chain" else " | "
        text = op.join(f"!obs_{1 + k % 4}" for k in range(count))
    elif kind == "big_bound":
        digits = rng.choice([20, 400, 5000])
        text = f"F[0,{'9' * digits}] mission_1" if rng.random() < 0.5 else f"G[{'1' * digits}.5,inf) !obs_1"
        derived = random.Random(hash(rng.getstate()[1]))  # a variant that consumes no draw (see path_case)
        if derived.random() < 0.5:  # a huge window the parser accepts: memory bounded by the log, never a pass
            text = f"G[0,{derived.choice(['1e7', '10000000', '99999999999', '1e15'])}] !obs_1"
            kind, truth = "huge_window", "undecidable"
    elif kind == "garbage":
        text = "".join(chr(rng.randrange(1, 0x3000)) for _ in range(rng.randrange(1, 80)))
    else:
        text = rng.choice(["", " ", "\n"])
    seed = seeds["mcap", False]
    argv = ["certify", str(seed), "--scenario", "nexus-sml", "--spec", text]
    return Case("formula", kind, argv, truth, [seed])


def scenario_case(rng: random.Random, seeds: dict[tuple[str, bool], Path], work: Path) -> Case:
    base = builtin_scenario_text("nexus-sml")
    lines = base.splitlines()
    kind = rng.choice(["delete_line", "duplicate_line", "number", "chars", "many_regions", "alias_bomb",
                       "bad_bytes", "empty", "not_a_mapping", "deep_yaml"])
    data: bytes
    if kind == "delete_line":
        del lines[rng.randrange(len(lines))]
        data = "\n".join(lines).encode()
    elif kind == "duplicate_line":
        k = rng.randrange(len(lines))
        lines.insert(k, lines[k])
        data = "\n".join(lines).encode()
    elif kind == "number":
        import re

        nums = list(re.finditer(r"-?\d+\.?\d*", base))
        m = rng.choice(nums)
        new = rng.choice(["-1", "0", "1e308", "nan", ".inf", "-.inf", "1e400", "9" * 400, "''", "[]", "{}"])
        data = (base[: m.start()] + new + base[m.end():]).encode()
    elif kind == "chars":
        chars = list(base)
        for _ in range(rng.randrange(1, 6)):
            chars[rng.randrange(len(chars))] = rng.choice("[]{}:,-&*!|>'\"\t#@`%")
        data = "".join(chars).encode()
    elif kind == "many_regions":
        count = rng.choice([500, 5000, 40_000])
        head = base[: base.index("regions:")]
        tail = base[base.index("initial_region:"):]
        regs = "".join(f"  - {{name: Q{k}, center: [{-2.4 + (k % 200) * 0.024:.3f}, {-2.4 + (k // 200) * 0.024:.3f}], "
                       f"radius: 0.01, labels: [obs_1], unsafe: true}}\n" for k in range(count))
        data = (head + "regions:\n  - {name: R1, center: [-1.99, -1.78], radius: 0.45, labels: [mission_1]}\n"
                + regs + tail.replace("initial_region: R1", "initial_region: R1")).encode()
    elif kind == "alias_bomb":
        bomb = 'a: &a ["x","x","x","x","x","x","x","x","x"]\n'
        for k in range(1, 9):
            bomb += f"{chr(97 + k)}: &{chr(97 + k)} [" + ",".join([f"*{chr(96 + k)}"] * 9) + "]\n"
        data = (bomb + base).encode()
    elif kind == "bad_bytes":
        raw = bytearray(base.encode())
        raw[rng.randrange(len(raw))] = rng.choice([0xFF, 0xC3, 0x00, 0x80])
        data = bytes(raw)
    elif kind == "empty":
        data = b""
    elif kind == "not_a_mapping":
        data = rng.choice([b"- 1\n- 2\n", b"42\n", b"just text\n", b"null\n"])
    else:
        depth = rng.choice([100, 1000, 10000])
        data = ("x: " + "[" * depth + "]" * depth + "\n").encode() + base.encode()
    scen = work / "scenario.yaml"
    scen.write_bytes(data)
    seed = seeds["mcap", False]
    argv = ["certify", str(seed), "--scenario", str(scen), "--spec", SPEC]
    return Case("scenario", kind, argv, "any", [seed, scen])


def path_case(rng: random.Random, seeds: dict[tuple[str, bool], Path], work: Path) -> Case:
    """Output paths that cannot be written and log paths that are not logs (a FIFO, also as the storage file of a bag
    folder, a device, a symlink loop there, empty files and folders): exit 3, nothing overwritten. Variants added
    to a kind are drawn by a generator seeded from the case generator's state (``hash(rng.getstate()[1])``, which
    consumes no draw: the case's other draws keep their values)."""
    seed = seeds["bag", False]
    kind = rng.choice(["out_existing_file", "out_below_file", "out_dev_null", "out_readonly_fs", "out_existing_dir",
                       "log_fifo", "log_dev_zero", "log_empty_dir", "log_empty_file", "log_no_ext", "log_missing",
                       "simulate_out_existing"])
    truth = "any"
    require: Callable[[Outcome], str | None] | None = None
    inputs = [seed]

    def exit3(res: Outcome) -> str | None:
        return None if res.code == 3 else f"expected exit 3, got {res.code}"

    argv = ["certify", str(seed), "--scenario", "nexus-sml", "--spec", SPEC]
    if kind == "out_existing_file":
        f = work / "taken.txt"
        f.write_text("keep me\n")
        argv += ["--out", str(f)]
        inputs.append(f)
        require = exit3
    elif kind == "out_below_file":
        f = work / "file.txt"
        f.write_text("x\n")
        argv += ["--out", str(f / "report")]
        inputs.append(f)
        require = exit3
    elif kind == "out_dev_null":
        argv += ["--out", "/dev/null"]
        require = exit3
    elif kind == "out_readonly_fs":
        argv += ["--out", "/proc/tubempc-report"]
        require = exit3
    elif kind == "out_existing_dir":  # refused without --force (nothing overwritten), replaced with it
        d = work / "previous"
        d.mkdir()
        (d / "certificate.json").write_text("{}\n")
        argv += ["--out", str(d)]
        if rng.random() < 0.5:
            argv.append("--force")

            def replaced(res: Outcome) -> str | None:
                written = json.loads((d / "certificate.json").read_text())
                return None if res.code == 0 and written.get("verdict") == "pass" else "--force did not replace"

            require = replaced
        else:
            inputs.append(d)
            require = exit3
    elif kind == "log_fifo":  # the log path itself, or the storage file of a bag folder (derived draw: see below)
        where = random.Random(hash(rng.getstate()[1])).choice(["path", "folder_fifo", "folder_dev_zero",
                                                            "folder_loop"])
        if where == "path":
            fifo = work / "pipe.bag"
            os.mkfifo(fifo)
            argv[1] = str(fifo)
        else:
            bag = work / "bag"
            shutil.copytree(seeds["dir", False], bag)
            (storage,) = [f for f in bag.iterdir() if f.suffix == ".db3"]
            storage.unlink()
            if where == "folder_fifo":
                os.mkfifo(storage)
            elif where == "folder_dev_zero":
                storage.symlink_to("/dev/zero")
            else:
                storage.symlink_to(storage)
            argv[1] = str(bag)
        kind = f"log_fifo:{where}"
        require = exit3
        inputs = []
    elif kind == "log_dev_zero":
        argv[1] = "/dev/zero"
        require = exit3
        inputs = []
    elif kind == "log_empty_dir":
        d = work / "empty"
        d.mkdir()
        argv[1] = str(d)
        require = exit3
    elif kind == "log_empty_file":
        f = work / f"empty{rng.choice(['.bag', '.mcap', '.db3'])}"
        f.write_bytes(b"")
        argv[1] = str(f)
        require = exit3
    elif kind == "log_no_ext":
        f = work / "runlog"
        shutil.copyfile(seed, f)
        argv[1] = str(f)
        require = exit3
    elif kind == "log_missing":
        argv[1] = str(work / "nope.mcap")
        require = exit3
    else:
        existing = work / rng.choice(["sim.mcap", "notes.txt"])
        existing.write_bytes(b"keep")
        argv = ["simulate", "--out", str(existing), "--from", "R1", "--to", "R1"]
        inputs = [existing]
        require = exit3
    if rng.random() < 0.2:
        argv.insert(0, "--debug")
    return Case("paths", kind, argv, truth, inputs, require)



def _exit3(res: Outcome) -> str | None:
    return None if res.code == 3 else f"expected exit 3, got {res.code}"


STAMP_FAULTS = ("zero", "near_1970", "negative", "late", "duplicate_conflict")


def _stamp_fault(rng: random.Random, kind: str, log_ns: int) -> int:
    if kind == "zero":
        return 0
    if kind == "near_1970":
        return rng.choice([1, 10**9, 86_400 * 10**9])
    if kind == "negative":
        return -rng.choice([1, 5 * 10**9])
    return log_ns - rng.choice([30, 300]) * 10**9  # "late": delivered long after its stamp


def stream_case(rng: random.Random, seeds: dict[tuple[str, bool], Path], work: Path) -> Case:
    """Stamp faults on every stream (not only the pose), each hiding a violation that only a sample judged at its
    log time shows (the run must never pass, on any time base):

    - signal (half the cases): a second publisher on the signal topic (unset, 1970, negative or late stamps, or
      duplicates of good stamps with other values) reports a violating value held at the pose samples;
    - nominal: 1-20 nominal messages with such stamps (a duplicate: the stamp of the message before them) place the
      nominal 0.5 m from the pose (a tube violation where the pose is matched to them);
    - cmd_vel: the commands as ``TwistStamped``, 1-20 of them with such stamps and ``linear.x`` 5 m/s (bound 0.2).

    The stream is chosen by a generator seeded from the case's draws, which are those of the signal-only family
    before it (a signal case keeps its values; the nominal and command cases replace some of them)."""
    fmt = rng.choice(FORMATS[:4])
    kind = rng.choice(STAMP_FAULTS)
    run = base_run(violating=False)
    start = rng.randrange(20, 250)
    count = rng.choice([1, 3, 10, 20])
    faulty = range(start, min(start + count, run.t_ns.size))
    stream = random.Random(f"{fmt}:{kind}:{start}:{count}").choice(["signal", "signal", "nominal", "cmd_vel"])
    stamps = run.stamp_ns.copy()
    run.extra = temperature_stream(run) if stream == "signal" else []
    for k in faulty:
        log_ns = int(run.t_ns[k]) - 2_000_000  # after the good message, before the pose sample: held there
        if kind == "duplicate_conflict":
            stamp = int(run.t_ns[k]) - 5_000_000 if stream == "signal" else int(run.stamp_ns[start - 1])
        else:
            stamp = _stamp_fault(rng, kind, log_ns)
        if stream == "signal":
            run.extra.append((log_ns, TEMP_TOPIC, TEMPERATURE, temperature(stamp, 95.0)))
        else:
            stamps[k] = stamp
    if stream == "nominal":
        run.nominal_stamp_ns, run.nominal_xy = stamps, run.xy.copy()
        run.nominal_xy[list(faulty), 0] += 0.5
    elif stream == "cmd_vel":
        run.cmd_stamp_ns = stamps
        run.cmd[list(faulty), 0] = 5.0
    path = write_run(run, work / f"{stream}_{kind}{SUFFIX[fmt]}", fmt)
    inputs = [path]
    if stream == "signal":
        scenario = work / "signal.yaml"
        scenario.write_text(signal_scenario_text())
        inputs.append(scenario)
        argv = ["certify", str(path), "--scenario", str(scenario), "--spec", "G[0,inf) motor_ok"]
    else:
        argv = ["certify", str(path), "--scenario", "nexus-sml", "--spec", SPEC]
    argv += ["--time-base", rng.choice(["auto", "header", "log"])]
    return Case("streams", f"{fmt}:{stream}:{kind}", argv, "violating", inputs)


#: the type suffix that marks a second publisher's messages while the run is written (never a type's name)
SECOND = "#second"
#: the second publisher's QoS profile in ROS2 (rosbags tells two connections of one topic and type by it)
SECOND_QOS = Qos(QosHistory.KEEP_LAST, 7, QosReliability.BEST_EFFORT, QosDurability.VOLATILE, QosTime(0, 0),
                 QosTime(0, 0), QosLiveliness.AUTOMATIC, QosTime(0, 0), False)


def publishers_case(rng: random.Random, seeds: dict[tuple[str, bool], Path], work: Path) -> Case:
    """A second publisher on one stream (pose, nominal, commands, a signal), each of its messages at the log time of
    one of the first's (as a simulation's clock gives): 1-20 of them, the same content (duplicates certify merges)
    or a violating one (the pose at an obstacle, the nominal 0.5 m off, 5 m/s commands, 95 degC), their header
    stamps the first's or 3 ms later. Readers yield equal log times in each format's own order (ROS1: by
    connection); certify on either ingest path and watch must agree; a violating one must not pass (a nominal
    sample 3 ms after the first one may: the tube judges a pose sample against its nearest nominal sample)."""
    fmt = rng.choice(FORMATS)
    run = base_run(violating=False)
    stream = rng.choice(["pose", "nominal", "cmd_vel", "signal"])
    conflict = rng.random() < 0.6
    start, count = rng.randrange(5, 280), rng.choice([1, 3, 20])
    late_ns = rng.choice([0, 0, 3_000_000])
    run.extra = temperature_stream(run) if stream == "signal" else []
    obs = SCENARIO.unsafe_regions[0].center
    for k in range(start, min(start + count, run.t_ns.size)):
        t = int(run.t_ns[k])
        if stream == "signal":
            t -= 5_000_000
            run.second.append((t, TEMP_TOPIC, TEMPERATURE, temperature(t + late_ns, 95.0 if conflict else 40.0)))
        elif stream == "cmd_vel":
            v = 5.0 if conflict else 0.0
            run.second.append((t, SCENARIO.topics.cmd_vel, TWIST, _twist_builder(v)))
        else:
            x, y = (obs[0], obs[1]) if conflict and stream == "pose" else (float(run.xy[k, 0]), float(run.xy[k, 1]))
            if conflict and stream == "nominal":
                x += 0.5
            run.second.append((t, getattr(SCENARIO.topics, stream), POSE, _pose_builder(POSE, t + late_ns, x, y)))
    argv, inputs = _stream_certify(rng, run, stream, work / f"second_{stream}{SUFFIX[fmt]}", fmt)
    # a conflicting second sample stamped 3 ms after the first is no violation where the rule judges it (the tube:
    # a pose sample against its nearest nominal sample, the first one); at the same stamp it is a conflict that
    # must not pass
    truth = "violating" if conflict and (late_ns == 0 or stream != "nominal") else "any"
    return Case("publishers", f"{fmt}:{stream}:{'conflict' if conflict else 'same'}", argv, truth, inputs)


def _twist_builder(vx: float) -> Callable[[Any, bool], Any]:
    def build(ty: Any, ros1: bool) -> Any:
        v3 = ty["geometry_msgs/msg/Vector3"]
        return ty[TWIST](linear=v3(x=vx, y=0.0, z=0.0), angular=v3(x=0.0, y=0.0, z=0.0))
    return build


def _stream_certify(rng: random.Random, run: Run, stream: str, path: Path, fmt: str) -> tuple[list[str], list[Path]]:
    """``run`` written to ``path`` -> (the certify argv, its inputs) of a case about ``stream``: the signal scenario
    and ``G motor_ok`` beside the obstacle formula for a signal, else the built-in scenario; a random time base."""
    log = write_run(run, path, fmt)
    inputs = [log]
    if stream == "signal":
        scenario = path.parent / "signal.yaml"
        scenario.write_text(signal_scenario_text())
        inputs.append(scenario)
        argv = ["certify", str(log), "--scenario", str(scenario), "--spec", "G[0,inf) motor_ok & " + SPEC]
    else:
        argv = ["certify", str(log), "--scenario", "nexus-sml", "--spec", SPEC]
    return [*argv, "--time-base", rng.choice(["auto", "header", "log"])], inputs


#: where a message's log time is moved while it keeps its file place (s after its own log time; None: 1 s before
#: the log's first message)
LOG_MOVES = (0.004, 0.5, 3.0, 527.5, -2.0, None)


def order_case(rng: random.Random, seeds: dict[tuple[str, bool], Path], work: Path) -> Case:
    """Log times out of file order: 1-3 messages of one stream (pose, nominal, commands, a signal) keep their place
    in the file and their header stamps while their log times move (a few ms, 0.5 s, 3 s or 527.5 s later, 2 s
    earlier, or before the log's first message). Every indexed reader yields a closed log's messages by log time;
    certify on either ingest path and watch must read them in that order (no requirement on the verdict: the
    disagreement checks decide; the violating seed must not pass)."""
    fmt = rng.choice(FORMATS)
    violating = rng.random() < 0.5
    run = base_run(violating=violating)
    stream = rng.choice(["pose", "nominal", "cmd_vel", "signal"])
    topic = TEMP_TOPIC if stream == "signal" else getattr(SCENARIO.topics, stream)
    run.extra = temperature_stream(run) if stream == "signal" else []
    start = rng.randrange(5, 290)
    for k in range(start, start + rng.choice([1, 2, 3])):
        move = rng.choice(LOG_MOVES)
        t_ns = int(run.t_ns[k]) - (5_000_000 if stream == "signal" else 0)
        run.log_moves.append((topic, k, TIME0_NS - 10**9 if move is None else t_ns + round(move * 1e9)))
    argv, inputs = _stream_certify(rng, run, stream, work / f"order_{stream}{SUFFIX[fmt]}", fmt)
    return Case("order", f"{fmt}:{stream}", argv, "violating" if violating else "any", inputs)


def _pose_builder(msgtype: str, stamp_ns: int, x: float, y: float) -> Callable[[Any, bool], Any]:
    def build(ty: Any, ros1: bool) -> Any:
        sec, nsec = divmod(stamp_ns, 10**9)
        header = ty["std_msgs/msg/Header"](**({"seq": 0} if ros1 else {}),
                                           stamp=ty["builtin_interfaces/msg/Time"](sec=sec, nanosec=nsec),
                                           frame_id="odom")
        pose = ty["geometry_msgs/msg/Pose"](position=ty["geometry_msgs/msg/Point"](x=x, y=y, z=0.0),
                                            orientation=ty["geometry_msgs/msg/Quaternion"](x=0.0, y=0.0, z=0.0,
                                                                                          w=1.0))
        if msgtype == POSE:
            return ty[POSE](header=header, pose=pose)
        v3 = ty["geometry_msgs/msg/Vector3"]
        twist = ty["geometry_msgs/msg/Twist"](linear=v3(x=0.0, y=0.0, z=0.0), angular=v3(x=0.0, y=0.0, z=0.0))
        return ty[ODOMETRY](header=header, child_frame_id="base_link",
                            pose=ty["geometry_msgs/msg/PoseWithCovariance"](pose=pose, covariance=np.zeros(36)),
                            twist=ty["geometry_msgs/msg/TwistWithCovariance"](twist=twist, covariance=np.zeros(36)))
    return build


def types_case(rng: random.Random, seeds: dict[tuple[str, bool], Path], work: Path) -> Case:
    """Two message types on one topic: PoseStamped message(s) among the robot's Odometry on the pose topic (the
    robot drives through an obstacle). Exit 3 naming both types, on both paths."""
    fmt = rng.choice(FORMATS[:4])
    run = base_run(violating=True)
    run.topics = ("metadata",)
    where = rng.choice(["first", "middle", "last"])
    k = {"first": 0, "middle": run.t_ns.size // 2, "last": run.t_ns.size - 1}[where]
    others = [k] if rng.random() < 0.7 else list(range(k, min(k + 5, run.t_ns.size)))
    run.extra = [(int(t), "/odom", POSE if i in others else ODOMETRY,
                  _pose_builder(POSE if i in others else ODOMETRY, int(t), float(x), float(y)))
                 for i, (t, (x, y)) in enumerate(zip(run.t_ns, run.xy, strict=True))]
    path = write_run(run, work / f"types{SUFFIX[fmt]}", fmt)
    scenario = work / "odom.yaml"
    scenario.write_text(builtin_scenario_text("nexus-sml").replace(
        "topics: {pose: /qualisys/nexus/pose, cmd_vel: /nexus/cmd_vel, nominal: /nexus/nominal_pose}",
        "topics: {pose: /odom}"))

    def names_both(res: Outcome) -> str | None:
        if res.code != 3 or POSE not in res.stderr or ODOMETRY not in res.stderr:
            return f"two types on one topic: exit {res.code} {res.stderr.strip()[:200]!r}"
        return None

    argv = ["certify", str(path), "--scenario", str(scenario), "--spec", SPEC]
    return Case("types", f"{fmt}:{where}", argv, "violating", [path, scenario], names_both)


LIMIT_VALUES = ["0", "1e-9", "-0.5", "4e9", "-4e9", "4.000001e9", "7.6e9", "9.3e9", "1e12", "1e300", "-1e300",
                "nan", "inf", "-inf", "1e-320"]


def limits_case(rng: random.Random, seeds: dict[tuple[str, bool], Path], work: Path) -> Case:
    """Option and scenario values at and past their limits: clock offsets (option and scenario), signal rates.
    A value out of range is exit 3 naming the option or field; a value in range is judged (the violation stays)."""
    fmt = rng.choice(FORMATS[:4])
    run = base_run(violating=False)
    run.extra = temperature_stream(run)
    for k in range(100, 110):  # the violation: 95 degC held at ten pose samples (good stamps)
        run.extra.append((int(run.t_ns[k]) - 2_000_000, TEMP_TOPIC, TEMPERATURE,
                          temperature(int(run.t_ns[k]) - 2_000_000, 95.0)))
    path = write_run(run, work / f"limits{SUFFIX[fmt]}", fmt)
    scenario = work / "limits.yaml"
    where = rng.choice(["option", "scenario", "rate", "unknown_topic"])
    value = rng.choice(LIMIT_VALUES)
    argv = ["certify", str(path), "--scenario", str(scenario), "--spec", "G[0,inf) motor_ok"]
    text = signal_scenario_text()
    try:
        number = float(value)
    except ValueError:
        number = math.nan
    in_range = math.isfinite(number) and abs(number) <= 4e9
    if where == "option":
        argv += ["--clock-offset", f"{TEMP_TOPIC}={value}"]
    elif where == "scenario":
        text += f"clock_offsets: {{{TEMP_TOPIC}: {value if math.isfinite(number) else '.nan'}}}\n"
    elif where == "rate":
        value = rng.choice(["1e-300", "1e-7", "1e-6", "10", "1e9", "1e10", "1e300"])
        number = float(value)
        in_range = 1e-6 <= number <= 1e9
        text = signal_scenario_text(number)
    else:
        argv += ["--clock-offset", "/motor/temperatur=0.02"]
        in_range = False
    scenario.write_text(text)

    def outcome(res: Outcome) -> str | None:
        if not in_range and res.code != 3:
            return f"{where}={value} out of range: exit {res.code}"
        if not in_range and where != "rate" and "clock" not in res.stderr:
            return f"{where}={value}: the error does not name the option or field: {res.stderr.strip()[:200]!r}"
        if in_range and res.code == 3:
            return f"{where}={value} in range: exit 3 {res.stderr.strip()[:200]!r}"
        return None

    truth = "violating" if where not in {"option", "scenario"} or abs(number) < 1 else "any"
    return Case("limits", f"{where}:{value}", argv, truth, [path, scenario], outcome)


def outputs_case(rng: random.Random, seeds: dict[tuple[str, bool], Path], work: Path) -> Case:
    """Symlinks and special files in the output folder (``--force``): never written through, never replaced."""
    fmt = rng.choice(FORMATS[:4])
    log = _copy(seeds[fmt, rng.random() < 0.5], work / seeds[fmt, False].name)
    out = work / "out"
    out.mkdir()
    name = rng.choice(["report.html", "certificate.json", "report.md", "junit.xml", "figures"])
    kind = rng.choice(["symlink_to_log", "symlink_dangling", "fifo", "folder", "hardlink_to_log"])
    target = _storage(log)
    if kind == "symlink_to_log":
        (out / name).symlink_to(target)
    elif kind == "symlink_dangling":
        (out / name).symlink_to(work / "nowhere")
    elif kind == "fifo":
        os.mkfifo(out / name)
    elif kind == "folder":
        (out / name).mkdir()
    elif name != "figures":
        os.link(target, out / name)
    else:
        (out / name).mkdir()
    argv = ["certify", str(log), "--scenario", "nexus-sml", "--spec", SPEC, "--out", str(out), "--force"]

    def outcome(res: Outcome) -> str | None:
        harmless = kind == "hardlink_to_log" or (kind == "folder" and name == "figures")
        if not harmless and res.code != 3:
            return f"{kind} {name} in the output folder: exit {res.code}"
        return None

    return Case("outputs", f"{kind}:{name}", argv, "any", [log], outcome)


def span_case(rng: random.Random, seeds: dict[tuple[str, bool], Path], work: Path) -> Case:
    """Signal data outside the pose's span: the pose stream stops early (or starts late) while the signal goes on
    and violates there. The run is the pose's span; a violation outside it is not judged, so the run cannot pass."""
    fmt = rng.choice(FORMATS[:4])
    run = base_run(violating=False)
    n = run.t_ns.size
    run.extra = temperature_stream(run)
    cut = rng.randrange(20, n - 20)
    after = rng.random() < 0.7
    run.topics = ("nominal", "cmd_vel", "solver", "metadata")
    keep = range(cut) if after else range(cut, n)
    run.extra += [(int(run.t_ns[i]), SCENARIO.topics.pose, POSE,
                   _pose_builder(POSE, int(run.stamp_ns[i]), float(run.xy[i, 0]), float(run.xy[i, 1])))
                  for i in keep]
    k = rng.randrange(cut + 2, n) if after else rng.randrange(0, cut - 2)
    run.extra.append((int(run.t_ns[k]) - 2_000_000, TEMP_TOPIC, TEMPERATURE,
                      temperature(int(run.t_ns[k]) - 2_000_000, 95.0)))
    path = write_run(run, work / f"span{SUFFIX[fmt]}", fmt)
    scenario = work / "signal.yaml"
    scenario.write_text(signal_scenario_text())
    argv = ["certify", str(path), "--scenario", str(scenario), "--spec", "G[0,inf) motor_ok"]
    return Case("span", "after" if after else "before", argv, "undecidable", [path, scenario])



#: constant and degenerate formulas: (text, the verdict certify must give on a clean run judged on spec alone)
CONSTANT_FORMULAS = [("true", 0), ("false", 1), ("G !true", 1), ("F[0,5] false", 1), ("X (F (false))", 1),
                     ("G[0,inf) !obs_1 & false", 1), ("!false", 0), ("G[0,inf) true", 0), ("F[0,5] true", 0),
                     ("true U[0,5] false", 1), ("false U[0,5] true", 0), ("G[0,inf) (false -> obs_1)", 0),
                     ("F[5,inf) false", 1), ("X(2,2.5] true", 1), ("G[0,inf) (true | obs_1)", 0),
                     ("F[100,200] mission_1", 2), ("G[100,200] false", 2), ("F[0,inf) false", 1)]


def constant_case(rng: random.Random, seeds: dict[tuple[str, bool], Path], work: Path) -> Case:
    """Constant and degenerate formulas (``true``, ``false``, ``G !true``, windows past the log's end) on a clean
    seed: the verdict is known exactly (``CONSTANT_FORMULAS``); never exit 70, never a pass for a false formula."""
    text, want = rng.choice(CONSTANT_FORMULAS)
    fmt = rng.choice(FORMATS[:4])
    seed = seeds[fmt, False]
    argv = ["certify", str(seed), "--scenario", "nexus-sml", "--spec", text, "--checks", "spec"]

    def exact(res: Outcome) -> str | None:
        return None if res.code == want else f"{text!r}: exit {res.code}, expected {want}"

    truth = "violating" if want == 1 else "undecidable" if want == 2 else "any"
    return Case("constant", f"{fmt}:{text}", argv, truth, [seed], exact)


def infinite_case(rng: random.Random, seeds: dict[tuple[str, bool], Path], work: Path) -> Case:
    """Streams whose values are all infinite or NaN (poses, a signal, commands), or infinite in one stretch:
    never exit 70; a run whose data is all NaN, or whose signal is NaN, is never a pass."""
    fmt = rng.choice(FORMATS[:4])
    run = base_run(violating=False)
    kind = rng.choice(["pose_inf", "pose_-inf", "pose_nan", "pose_mixed", "pose_inf_stretch", "signal_inf",
                       "signal_-inf", "signal_nan", "cmd_inf", "cmd_nan", "all_nan"])
    spec, truth, checks = SPEC, "any", "spec"
    argv_extra: list[str] = []
    scenario = "nexus-sml"
    inputs: list[Path] = []
    if kind.startswith("pose_"):
        value = {"pose_inf": math.inf, "pose_-inf": -math.inf, "pose_nan": math.nan}.get(kind)
        if value is not None:
            run.xy[:] = value
        elif kind == "pose_mixed":
            run.xy[:, 0], run.xy[:, 1] = math.inf, -math.inf
        else:
            k = rng.randrange(run.xy.shape[0] - 20)
            run.xy[k: k + 20] = rng.choice([math.inf, -math.inf])
        truth = "undecidable" if kind == "pose_nan" else "any"
    elif kind.startswith("signal_"):
        value = {"signal_inf": math.inf, "signal_-inf": -math.inf, "signal_nan": math.nan}[kind]
        run.extra = temperature_stream(run, value)
        path_s = work / "signal.yaml"
        path_s.write_text(signal_scenario_text())
        scenario, spec = str(path_s), "G[0,inf) motor_ok"
        truth = "violating" if kind == "signal_inf" else "undecidable" if kind == "signal_nan" else "any"
        inputs.append(path_s)
    elif kind.startswith("cmd_"):
        run.cmd[:] = math.inf if kind == "cmd_inf" else math.nan
        checks = "input_box"
        truth = "violating" if kind == "cmd_inf" else "undecidable"
    else:
        run.xy[:] = math.nan
        run.cmd[:] = math.nan
        checks = "spec,input_box,workspace,obstacle_clearance"
        truth = "undecidable"
    path = write_run(run, work / f"inf_{kind}{SUFFIX[fmt]}", fmt)
    argv = ["certify", str(path), "--scenario", scenario, "--spec", spec, "--checks", checks, *argv_extra]
    return Case("infinite", f"{fmt}:{kind}", argv, truth, [path, *inputs])


#: scenario fields at and past the limits the validator accepts: (dotted YAML path as text to replace, values)
SCENARIO_LIMITS = [("mocap: {rate_hz: 100.0}", [f"mocap: {{rate_hz: {v}}}" for v in
                                                 ("1e-300", "1e-9", "1e300", "0", "9" * 5000, ".inf")]
                    + [f"mocap: {{rate_hz: 100.0, noise_std: {v}}}" for v in ("1e308", "0", "-1", ".nan", "5e-324")]),
                   ("radius: 0.45", ["radius: 1e308", "radius: 1e-300", "radius: 0", "radius: 5e-324"]),
                   ("robot: {radius: 0.27}", ["robot: {radius: 1e308}", "robot: {radius: 0}",
                                              "robot: {radius: 1e-300}", "robot: {radius: 1e300, max_speed_mps: 0}"]),
                   ("disturbance: {bound: 0.02}", ["disturbance: {bound: 1e308}", "disturbance: {bound: 0}"]),
                   ("sigma_low: 2.0", ["sigma_low: 1e-308", "sigma_low: 1e308"]),
                   ("max_abs: [0.2, 0.2, 0.2]", ["max_abs: [1e308, 1e308, 1e308]", "max_abs: [0, 0, 0]",
                                                 "max_abs: [5e-324, 0.2, 0.2]"]),
                   ("center: [-1.99, -1.78]", ["center: [1e308, -1e308]", "center: [-1.99, " + "1" * 5000 + "]"])]


def scenario_limits_case(rng: random.Random, seeds: dict[tuple[str, bool], Path], work: Path) -> Case:
    """Scenario values at and past the limits of the validator (rates, noise, radii, speeds, centres, integers of
    thousands of digits): exit 3 naming the field, or a verdict; never exit 70. A value the field's text does not
    hold in this scenario is replaced in the first place it appears."""
    base = builtin_scenario_text("nexus-sml")
    present = [(old, new) for old, news in SCENARIO_LIMITS if old in base for new in news]
    old, new = rng.choice(present)
    scen = work / "limits.yaml"
    scen.write_text(base.replace(old, new, 1))
    fmt = rng.choice(FORMATS[:4])
    seed = seeds[fmt, True]
    argv = ["certify", str(seed), "--scenario", str(scen), "--spec", SPEC]
    return Case("scenario_limits", new[:50], argv, "any",
                [seed, scen])


FAMILIES: list[tuple[str, float, Callable[[random.Random, dict[tuple[str, bool], Path], Path], Case]]] = [
    ("bytes", 0.34, byte_case), ("content", 0.13, content_case), ("formula", 0.06, formula_case),
    ("scenario", 0.06, scenario_case), ("paths", 0.04, path_case), ("streams", 0.07, stream_case),
    ("types", 0.05, types_case), ("limits", 0.05, limits_case), ("outputs", 0.04, outputs_case),
    ("span", 0.04, span_case), ("constant", 0.06, constant_case), ("infinite", 0.06, infinite_case),
    ("scenario_limits", 0.04, scenario_limits_case), ("order", 0.05, order_case),
    ("publishers", 0.05, publishers_case)]


@contextlib.contextmanager
def _workdir(root: Path) -> Iterator[Path]:
    d = Path(tempfile.mkdtemp(dir=root))
    try:
        yield d
    finally:
        for p in d.rglob("*"):
            with contextlib.suppress(OSError):
                if p.is_dir() and not p.is_symlink():
                    p.chmod(stat.S_IRWXU)
        shutil.rmtree(d, ignore_errors=True)


def _fresh(folder: Path) -> Path:
    shutil.rmtree(folder, ignore_errors=True)
    folder.mkdir(parents=True)
    return folder


@dataclass
class Report:
    cases: int = 0
    counts: Counter[str] = field(default_factory=Counter)
    by_kind: Counter[str] = field(default_factory=Counter)
    failures: list[str] = field(default_factory=list)
    exit_codes: Counter[str] = field(default_factory=Counter)
    per_format: Counter[str] = field(default_factory=Counter)  # family:format (bytes, content) or family

    @property
    def last_line(self) -> str:
        return (f"cases={self.cases} crashes={self.counts['crash']} hangs={self.counts['hang']} "
                f"false_pass={self.counts['false_pass']} path_disagreements={self.counts['path_disagreement']} "
                f"watch_disagreements={self.counts['watch_disagreement']}")


def _certify_argv(argv: list[str]) -> list[str] | None:
    """The argv without ``--debug`` when it runs ``certify`` on one log, else None."""
    rest = [a for a in argv if a != "--debug"]
    return rest if rest and rest[0] == "certify" else None


def other_path(argv: list[str], timeout_s: float) -> Outcome:
    """The same command on the other ingest path (``TUBEMPC_FAST_INGEST`` flipped)."""
    from verify.ingest.raw import FAST_INGEST_ENV, fast_ingest

    before = os.environ.get(FAST_INGEST_ENV)
    os.environ[FAST_INGEST_ENV] = "0" if fast_ingest() else "1"
    try:
        return run_cli(argv, timeout_s)
    finally:
        if before is None:
            del os.environ[FAST_INGEST_ENV]
        else:
            os.environ[FAST_INGEST_ENV] = before


def watch_argv(argv: list[str]) -> list[str]:
    """``tubempc watch`` on the same log, scenario, formula, time base and checks as a certify argv."""
    out = ["watch", argv[1]]
    keep = {"--scenario", "--spec", "--time-base", "--checks", "--clock-offset"}
    for k, a in enumerate(argv[2:-1], start=2):
        if a in keep:
            out += [a, argv[k + 1]]
    if "--time-base" not in out:
        out += ["--time-base", "auto"]  # certify's default (watch's is header)
    return out


def disagreement(first: Outcome, second: Outcome) -> str | None:
    """Two runs that must agree: a crash of the second, two different verdicts, or a pass where the other did not."""
    if second.error is not None or second.code not in (0, 1, 2, 3):
        return f"crashed: {second.error or second.code} {second.stderr.strip()[-200:]!r}"
    if first.code in (0, 1, 2) and second.code in (0, 1, 2) and first.code != second.code:
        return f"exit {first.code} vs {second.code}"
    if (first.code == 0) != (second.code == 0) and 3 not in (first.code, second.code):
        return f"exit {first.code} vs {second.code}"
    if (first.code == 0 and second.code == 3) or (first.code == 3 and second.code == 0):
        return f"exit {first.code} vs {second.code}: {(first.stderr or second.stderr).strip()[:200]!r}"
    return None


def run_campaign(cases: int, seed: int, *, root: Path, timeout_s: float = 30.0, verbose: bool = False,
                 families: tuple[str, ...] | None = None, only: int | None = None,
                 minutes: float | None = None) -> Report:
    """Run ``cases`` cases drawn from ``random.Random(seed)``; returns the counts (see the module docstring).

    ``only``: replay case number ``only`` of that campaign alone (its files are kept under ``root/case``)."""
    import warnings

    warnings.resetwarnings()  # pytest's or the caller's filters must not hide a warning that leaks to stderr
    rng = random.Random(seed)
    seeds = write_seeds(root / "seeds")
    chosen = [f for f in FAMILIES if families is None or f[0] in families]
    weights = [w for _, w, _ in chosen]
    report = Report()
    deadline = None if minutes is None else time.monotonic() + 60.0 * minutes
    for i in range(cases):
        if deadline is not None and time.monotonic() > deadline:
            break  # the time budget is spent: the report covers the cases run
        if verbose and i and i % 100 == 0:
            print(f"progress: {report.last_line}", file=sys.stderr, flush=True)
        _, _, make = rng.choices(chosen, weights)[0]
        case_rng = random.Random(rng.getrandbits(64))
        if only is not None and i != only:
            continue
        with _workdir(root) if only is None else contextlib.nullcontext(_fresh(root / "case")) as work:
            case = make(case_rng, seeds, work)
            before = _snapshot(case.inputs)
            res = run_cli(case.argv, timeout_s)
            after = _snapshot(case.inputs)
            cls, detail = classify(case, res, before, after)
            plain = _certify_argv(case.argv)
            if cls == "ok" and plain is not None:  # fast vs plain ingest, then certify vs watch, on every case
                why = disagreement(res, other_path(case.argv, timeout_s))
                if why is not None:
                    cls, detail = "path_disagreement", f"fast vs plain: {why}"
                elif "--out" not in plain:
                    watched = watch_argv(plain)
                    seen = run_cli(watched, timeout_s)
                    if res.code == 3 and seen.code in (0, 1, 2):
                        # watch reads records as they complete, without the index certify checks the file
                        # against: a log certify refuses as damaged can still be judged (counted, not a verdict
                        # disagreement; listed with -v)
                        report.counts["watch_judged_refused"] += 1
                        if verbose:
                            print(f"#{i} info: certify exit 3, watch exit {seen.code} [{' '.join(watched)}]",
                                  file=sys.stderr)
                    elif (case.family == "bytes" and seen.code == 3 and res.code in (0, 1, 2)
                          and "malformed" in seen.stderr and "record" in seen.stderr):
                        # the reverse: certify reads the messages it needs through the index and never parses the
                        # damaged bytes (a record of a topic it does not read); watch walks every record as it
                        # completes and refuses the damage with one line naming its byte (counted, listed with -v)
                        report.counts["watch_refused_damaged"] += 1
                        if verbose:
                            print(f"#{i} info: certify exit {res.code}, watch exit 3: {seen.stderr.strip()[:160]}",
                                  file=sys.stderr)
                    elif seen.code == 2 and "not closed by its recorder" in seen.stdout + seen.stderr and res.code == 0:
                        # a bare .db3 has no metadata.yaml that says the recorder closed it: watch judges it as
                        # --salvage does (partial, never a pass); counted, not a disagreement
                        report.counts["watch_partial"] += 1
                    elif (why := disagreement(res, seen)) is not None:
                        cls, detail = "watch_disagreement", f"certify vs watch: {why} [{' '.join(watched)}]"
        report.cases += 1
        report.counts[cls] += 1
        report.exit_codes[f"{case.family}:{res.code}"] += 1
        fmt = case.kind.split(":")[0] if case.family in ("bytes", "content") else ""
        report.per_format[f"{case.family}:{fmt}" if fmt else case.family] += 1
        if cls != "ok":
            report.by_kind[f"{cls} {case.family}:{case.kind}"] += 1
            argv = " ".join(a if len(a) < 80 else a[:60] + f"...({len(a)} chars)" for a in case.argv)
            report.failures.append(f"#{i} {cls} {case.family}:{case.kind}: {detail} [{argv}]")
            if verbose:
                print(report.failures[-1], file=sys.stderr)
    return report


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--cases", type=int, default=3000)
    ap.add_argument("--seed", type=int, default=1)
    ap.add_argument("--timeout", type=float, default=30.0,
                    help="CPU seconds per case (4x as many wall seconds) before it counts as a hang")
    ap.add_argument("--dir", type=Path, default=None, help="work folder (default: a fresh temporary folder)")
    ap.add_argument("--families", default=None, help="comma-separated subset of: " +
                    ", ".join(f[0] for f in FAMILIES))
    ap.add_argument("-v", "--verbose", action="store_true", help="print each failing case as it happens")
    ap.add_argument("--only", type=int, default=None, help="replay this case number alone (files kept)")
    ap.add_argument("--minutes", type=float, default=None, help="stop drawing cases after this many minutes")
    args = ap.parse_args()
    root = args.dir or Path(tempfile.mkdtemp(prefix="fuzz_certify_"))
    root.mkdir(parents=True, exist_ok=True)
    fams = tuple(args.families.split(",")) if args.families else None
    start = time.perf_counter()
    report = run_campaign(args.cases, args.seed, root=root, timeout_s=args.timeout, verbose=args.verbose,
                          families=fams, only=args.only, minutes=args.minutes)
    for line in report.failures[:60]:
        print(line)
    for key, count in sorted(report.by_kind.items()):
        print(f"{count:6d}  {key}")
    print("cases per family and format: " + ", ".join(f"{k}={v}" for k, v in sorted(report.per_format.items())))
    print("exit codes per family: " + ", ".join(f"{k}={v}" for k, v in sorted(report.exit_codes.items())))
    print(f"watch refused damaged bytes certify did not read (exit 3): {report.counts['watch_refused_damaged']}")
    print(f"watch judged a log certify refused (exit 3): {report.counts['watch_judged_refused']}; watch judged a "
          f"log as not closed by its recorder (partial) where certify passed: {report.counts['watch_partial']}")
    print(f"seed={args.seed} seconds={time.perf_counter() - start:.0f}")
    print(report.last_line)


if __name__ == "__main__":
    main()
