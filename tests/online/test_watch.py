"""``tubempc watch`` on logs that grow while it reads: a writer thread appends a recorded log's bytes in pieces
(as a recorder flushes), for an MCAP file, a ROS2 bag folder and a ROS1 bag; the result equals ``certify_log`` on
the file as it ends, and a recorder killed mid-chunk is judged as ``--salvage`` judges the cut file."""

from __future__ import annotations

import shutil
import sqlite3
import struct
import subprocess
import sys
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

from tubempc.scenario import builtin_scenario, load_scenario
from verify import certify_log
from verify.errors import LogReadError
from verify.ingest import read_log
from verify.ingest.salvage import walk_mcap, walk_ros1
from verify.online import Decision, OnlineMonitor
from verify.online.watch import watch_log

LOGS = Path(__file__).resolve().parents[2] / "logs"
ROS1_HEADER_AT = len(b"#ROSBAG V2.0\n")


def _ros1_small_chunks(src: Path, dst: Path, chunk_bytes: int = 16 * 1024) -> Path:
    """The same messages as ``src`` in a bag of many small chunks (a recorder's default is far larger)."""
    with Reader1(src) as r, Writer1(dst) as w:
        w.chunk_threshold = chunk_bytes
        conns = {c.id: w.add_connection(c.topic, c.msgtype, msgdef=c.msgdef.data, md5sum=c.digest)
                 for c in r.connections}
        for c, t, data in r.messages():
            w.write(conns[c.id], t, data)
    return dst


def _ros2_folder(src: Path, dst: Path) -> Path:
    """An MCAP file rewritten as a ROS2 bag folder (metadata.yaml + storage file), message bytes unchanged."""
    with Reader2(src) as r, Writer2(dst, version=9, storage_plugin=StoragePlugin.MCAP) as w:
        store = get_typestore(Stores.ROS2_HUMBLE)
        conns = {c.id: w.add_connection(c.topic, c.msgtype, typestore=store) for c in r.connections}
        for c, t, data in r.messages():
            w.write(conns[c.id], t, data)
    return dst


def _zero_index_pos(data: bytes) -> bytes:
    """The bag header as rosbag writes it while recording: index_pos 0 (set when the bag is closed)."""
    out = bytearray(data)
    key = out.find(b"index_pos=", ROS1_HEADER_AT)
    out[key + 10 : key + 18] = struct.pack("<Q", 0)
    return bytes(out)


class Recorder(threading.Thread):
    """Appends ``data`` to ``target`` in pieces of random size with short pauses; ``cut``: stop there and never
    close the log (killed); otherwise finish as a recorder does (ROS1: rewrite the header; folder: metadata.yaml)."""

    def __init__(self, data: bytes, target: Path, *, cut: int | None = None, final_header: bytes | None = None,
                 metadata: bytes | None = None, seed: int = 0, pause_at: float | None = None) -> None:
        super().__init__(daemon=True)
        self.data, self.target, self.cut = data, target, cut
        self.final_header, self.metadata = final_header, metadata
        self.rng = np.random.default_rng(seed)
        self.sizes: list[int] = []
        self.pause_at = pause_at  # a fraction of the bytes where the recorder waits (up to 30 s) for ``resume``
        self.resume = threading.Event()

    def run(self) -> None:
        end = len(self.data) if self.cut is None else self.cut
        pos = 0
        with self.target.open("ab") as fh:
            while pos < end:
                n = int(self.rng.integers(4_000, 120_000))
                if self.pause_at is not None and pos < self.pause_at * len(self.data) <= pos + n:
                    self.resume.wait(30.0)  # the reader's speed on a loaded machine must not decide the test
                fh.write(self.data[pos : min(end, pos + n)])
                fh.flush()
                pos = min(end, pos + n)
                self.sizes.append(pos)
                time.sleep(0.004)
        if self.cut is not None:
            return
        if self.final_header is not None:
            with self.target.open("r+b") as fh:
                fh.write(self.final_header)
        if self.metadata is not None:
            (self.target.parent / "metadata.yaml").write_bytes(self.metadata)


def _watch_while_recording(source: Path, kind: str, tmp_path: Path, *, cut_fraction: float | None,
                           pause: tuple[float, str] | None = None) -> tuple[Path, Path, object, list[tuple[str, int]]]:
    """Start the recorder thread, watch with --follow semantics; returns (certify path, watched path, result,
    decisions with the file size when each was reported). ``pause``: the recorder waits at that fraction of its
    bytes until the named decision is reported."""
    data = b"" if source.is_dir() else source.read_bytes()
    final_header = None
    metadata = None
    if kind == "ros1":
        final_header = data[:4096 + ROS1_HEADER_AT]
        data = _zero_index_pos(data)
        target = tmp_path / "live.bag"
        watched = certified = target
    elif kind == "folder":
        folder = tmp_path / "live_bag"
        folder.mkdir()
        (inner,) = [p for p in source.iterdir() if p.suffix == ".mcap"]
        data = inner.read_bytes()
        metadata = (source / "metadata.yaml").read_bytes()
        target = folder / inner.name
        watched, certified = folder, (folder if cut_fraction is None else target)
    else:
        target = tmp_path / "live.mcap"
        watched = certified = target
    target.write_bytes(b"")
    cut = None if cut_fraction is None else int(len(data) * cut_fraction)
    rec = Recorder(data, target, cut=cut, final_header=final_header, metadata=metadata,
                   pause_at=None if pause is None else pause[0])
    sizes: list[tuple[str, int]] = []
    mon = OnlineMonitor(builtin_scenario())

    def on_decision(d: Decision) -> None:
        sizes.append((d.name, target.stat().st_size))
        if pause is not None and d.name == pause[1]:
            rec.resume.set()

    rec.start()
    res = watch_log(watched, mon, follow=True, idle_timeout_s=1.0 if pause is None else 40.0, poll_s=0.02,
                    on_decision=on_decision)
    rec.join()
    return certified, watched, res, sizes


def _assert_same_as_certify(path: Path, res: object, *, salvage: bool) -> None:
    from verify.online.watch import WatchResult

    assert isinstance(res, WatchResult)
    cert = certify_log(path, builtin_scenario(), salvage=salvage).certificate
    assert res.result.verdict == cert["verdict"]
    assert [c.verdict for c in res.result.checks] == [c["verdict"] for c in cert["checks"]]
    assert res.partial == salvage


@pytest.mark.parametrize(("kind", "name"), [("mcap", "demo.mcap"), ("ros1", "obstacle_touch.bag"),
                                            ("folder", "late_mission.mcap")])
def test_watch_a_growing_log_equals_certify(kind: str, name: str, tmp_path: Path) -> None:
    src = LOGS / name
    if kind == "ros1":
        src = _ros1_small_chunks(src, tmp_path / "src.bag")
    elif kind == "folder":
        src = _ros2_folder(src, tmp_path / "src_bag")
    pause = (0.59, "obstacle_clearance") if kind == "ros1" else None
    certified, _watched, res, sizes = _watch_while_recording(src, kind, tmp_path, cut_fraction=None, pause=pause)
    _assert_same_as_certify(certified, res, salvage=False)
    final = certified.stat().st_size if certified.is_file() else None
    if kind == "ros1":  # the obstacle is touched at 6.7 s of 26 s: reported long before the recorder stops
        when = dict(sizes)["obstacle_clearance"]
        assert final is not None and when < 0.6 * final
    if kind == "folder":  # F[30,50] mission_2 fails at 50 s of 60 s, while the folder has no metadata.yaml yet
        assert "F[30,50] mission_2" in dict(sizes)


@pytest.mark.parametrize(("kind", "name"), [("mcap", "demo.mcap"), ("ros1", "obstacle_touch.bag"),
                                            ("folder", "demo.mcap")])
def test_recorder_killed_mid_chunk_is_judged_as_salvage(kind: str, name: str, tmp_path: Path) -> None:
    src = LOGS / name
    if kind == "ros1":
        src = _ros1_small_chunks(src, tmp_path / "src.bag")
    elif kind == "folder":
        src = _ros2_folder(src, tmp_path / "src_bag")
    certified, _watched, res, _ = _watch_while_recording(src, kind, tmp_path, cut_fraction=0.55)
    walk = walk_ros1(certified) if kind == "ros1" else walk_mcap(certified)
    for _ in walk.messages:
        pass
    assert "incomplete" in walk.stop_reason()  # really cut inside a record
    _assert_same_as_certify(certified, res, salvage=True)
    from verify.online.watch import WatchResult

    assert isinstance(res, WatchResult)
    offline = read_log(certified, builtin_scenario(), salvage=True)
    assert res.result.state.samples["pose"] == offline.pose.t_ns.size
    assert res.result.verdict != "pass"


def _cli(*args: str) -> subprocess.CompletedProcess[str]:
    return subprocess.run([sys.executable, "-c", "from tubempc.cli import main; main()", *args],
                          capture_output=True, text=True, timeout=300, check=False)


def test_watch_cli_lines_and_exit_codes(tmp_path: Path) -> None:
    run = _cli("watch", str(LOGS / "obstacle_touch.bag"), "--scenario", "nexus-sml", "--out", str(tmp_path / "o"))
    assert run.returncode == 1, run.stderr
    lines = run.stdout.splitlines()
    assert any(line.split()[:3] == ["6.69", "s", "obstacle_clearance"] and "FAIL" in line for line in lines)
    assert (tmp_path / "o" / "certificate.json").is_file()
    bad = tmp_path / "bad.mcap"
    bad.write_bytes(b"not an mcap file at all")
    run = _cli("watch", str(bad), "--scenario", "nexus-sml")
    assert run.returncode == 3
    assert len(run.stderr.strip().splitlines()) == 1 and str(bad) in run.stderr
    run = _cli("watch", str(tmp_path / "missing.bag"), "--scenario", "nexus-sml")
    assert run.returncode == 3 and "missing.bag" in run.stderr


def test_watch_copy_of_input_is_not_modified(tmp_path: Path) -> None:
    src = tmp_path / "t.bag"
    shutil.copy(LOGS / "truncated.bag", src)
    before = src.read_bytes()
    res = watch_log(src, OnlineMonitor(builtin_scenario()))
    assert src.read_bytes() == before
    assert res.partial and res.result.verdict == "inconclusive"


def test_watch_a_sqlite3_bag_folder(tmp_path: Path) -> None:
    """sqlite3 storage is read row by row (the rows added since the last read); a closed bag equals certify."""
    src = LOGS / "late_mission.mcap"
    folder = tmp_path / "bag"
    store = get_typestore(Stores.ROS2_HUMBLE)
    with Reader2(src) as r, Writer2(folder, version=9, storage_plugin=StoragePlugin.SQLITE3) as w:
        conns = {c.id: w.add_connection(c.topic, c.msgtype, typestore=store) for c in r.connections}
        for c, t, data in r.messages():
            w.write(conns[c.id], t, data)
    res = watch_log(folder, OnlineMonitor(builtin_scenario()), follow=True, idle_timeout_s=0.5, poll_s=0.05)
    assert res.finished
    _assert_same_as_certify(folder, res, salvage=False)


def test_watch_waits_for_the_recorder_to_create_the_log(tmp_path: Path) -> None:
    """With --follow the log may appear after watch starts (within the idle timeout); without it, exit 3 at once."""
    target = tmp_path / "late.mcap"
    data = (LOGS / "tube_breach.mcap").read_bytes()

    def later() -> None:
        time.sleep(0.3)
        target.write_bytes(data)

    threading.Thread(target=later, daemon=True).start()
    res = watch_log(target, OnlineMonitor(builtin_scenario()), follow=True, idle_timeout_s=3.0, poll_s=0.05)
    assert res.finished and res.result.verdict == "fail"
    with pytest.raises(LogReadError, match="no such file"):
        watch_log(tmp_path / "never.mcap", OnlineMonitor(builtin_scenario()))


DIFFDRIVE = LOGS.parent / "docs" / "examples" / "diffdrive-room.yaml"


@pytest.mark.parametrize("time_base", ["header", "auto"])
def test_watch_pushes_the_signal_atoms_of_a_growing_ros1_bag(time_base: str, tmp_path: Path) -> None:
    """diffdrive_odom.bag against its own scenario (polygon regions; the atom ``slow`` is /odom's linear speed),
    recorded in small chunks while watch reads: the verdicts of certify_log."""
    sc = load_scenario(DIFFDRIVE)
    src = _ros1_small_chunks(LOGS / "diffdrive_odom.bag", tmp_path / "src.bag", chunk_bytes=4 * 1024)
    data = src.read_bytes()
    target = tmp_path / "live.bag"
    target.write_bytes(b"")
    rec = Recorder(_zero_index_pos(data), target, final_header=data[:4096 + ROS1_HEADER_AT])
    mon = OnlineMonitor(sc)
    assert mon.signal_names == ("slow",)
    rec.start()
    res = watch_log(target, mon, follow=True, idle_timeout_s=1.0, poll_s=0.02, time_base=time_base)
    rec.join()
    assert res.finished
    cert = certify_log(target, sc, time_base=time_base).certificate
    assert res.result.verdict == cert["verdict"] == "pass"
    assert [(c.name, c.verdict) for c in res.result.checks] == [(c["name"], c["verdict"]) for c in cert["checks"]]
    assert mon.signal_counts["slow"]["messages"] == 362
    spec = next(c for c in res.result.checks if c.name == "spec_trajectory")
    assert spec.margin == pytest.approx(next(c for c in cert["checks"] if c["name"] == "spec_trajectory")["margin"])
    if time_base == "auto":
        assert any("auto: header time" in n for n in res.notes)
    # a formula the speed signal violates: decided at the first message above 0.3 m/s, long before the end
    res = watch_log(target, OnlineMonitor(sc, spec="G[0,inf) crawl"))
    assert res.result.verdict == "fail" and res.decisions[0].time_s < 1.0
    # the margin of a violated G is final only at the end (later samples may violate it more): the decision line
    # says when and where, the final line the margin, in the signal's unit, as the certificate states it
    assert res.decisions[0].margin is None and "margin" not in res.decisions[0].line()
    final = next(line for line in res.result.state.final_lines() if "G[0,inf) crawl" in line)
    cert = certify_log(target, sc, spec="G[0,inf) crawl").certificate
    assert f"margin {cert['checks'][0]['margin']:+.4g} m/s" in final


def _restamped(src: Path, dst: Path, topic: str) -> Path:
    """``src`` (MCAP) as a ROS2 bag folder whose ``topic`` messages all carry the same header stamp (a driver
    that never sets it): certify --time-base auto judges such a log on log time."""
    store = get_typestore(Stores.ROS2_HUMBLE)
    with Reader2(src) as r, Writer2(dst, version=9, storage_plugin=StoragePlugin.MCAP) as w:
        conns = {c.id: w.add_connection(c.topic, c.msgtype, typestore=store) for c in r.connections}
        for c, t, raw in r.messages():
            data = raw
            if c.topic == topic:
                msg = store.deserialize_cdr(raw, c.msgtype)
                msg.header.stamp.sec, msg.header.stamp.nanosec = 1_700_000_000, 0
                data = store.serialize_cdr(msg, c.msgtype)
            w.write(conns[c.id], t, data)
    return dst


def test_watch_time_base_auto_chooses_as_certify(tmp_path: Path) -> None:
    """auto: header stamps when they order the samples (demo.mcap), log time when they all repeat; the verdicts
    are certify --time-base auto's. An explicit header base on the repeated stamps cannot pass."""
    sc = builtin_scenario()
    res = watch_log(LOGS / "demo.mcap", OnlineMonitor(sc), time_base="auto")
    assert any("auto: header time" in n for n in res.notes)
    cert = certify_log(LOGS / "demo.mcap", sc, time_base="auto").certificate
    assert [c.verdict for c in res.result.checks] == [c["verdict"] for c in cert["checks"]]
    bad = _restamped(LOGS / "demo.mcap", tmp_path / "stamps_bag", sc.topics.pose)
    res = watch_log(bad, OnlineMonitor(sc), time_base="auto")
    assert any("auto: log time" in n and "repeat" in n for n in res.notes)
    cert = certify_log(bad, sc, time_base="auto").certificate
    assert cert["time_base"] == "log"
    assert res.result.verdict == cert["verdict"]
    assert [c.verdict for c in res.result.checks] == [c["verdict"] for c in cert["checks"]]
    assert watch_log(bad, OnlineMonitor(sc), time_base="header").result.verdict != "pass"
    with pytest.raises(LogReadError, match="time_base"):
        watch_log(bad, OnlineMonitor(sc), time_base="wall")


def test_watch_cli_time_base_auto(tmp_path: Path) -> None:
    run = _cli("watch", str(LOGS / "obstacle_touch.bag"), "--scenario", "nexus-sml", "--time-base", "auto")
    assert run.returncode == 1, run.stderr
    assert "auto: header time" in run.stdout


class SqliteRecorder(threading.Thread):
    """A ROS2 recorder with sqlite3 storage: creates the storage file in ``folder`` with the source's tables, then
    inserts the source's message rows in batches of random size, one transaction each, and writes metadata.yaml at
    the end. Past ``pause_at`` of the rows it waits (up to 30 s) for ``resume``: the reader's speed on a loaded
    machine does not decide whether a decision comes before the end."""

    def __init__(self, source: Path, folder: Path, seed: int = 1, pause_at: float = 1.0) -> None:
        super().__init__(daemon=True)
        self.source, self.folder = source, folder
        self.rng = np.random.default_rng(seed)
        self.rows_when: list[int] = [0]
        self.pause_at = pause_at
        self.resume = threading.Event()

    def run(self) -> None:
        (db,) = [p for p in self.source.iterdir() if p.suffix == ".db3"]
        src = sqlite3.connect(db)
        live = sqlite3.connect(self.folder / db.name)  # the name metadata.yaml gives
        try:
            for (sql,) in src.execute("SELECT sql FROM sqlite_master WHERE type = 'table' AND sql IS NOT NULL"):
                live.execute(sql)
            for (name,) in src.execute("SELECT name FROM sqlite_master WHERE type = 'table'"):
                if name != "messages":
                    rows = src.execute(f"SELECT * FROM {name}").fetchall()
                    if rows:
                        live.executemany(f"INSERT INTO {name} VALUES ({', '.join('?' * len(rows[0]))})", rows)
            live.commit()
            rows = src.execute("SELECT id, topic_id, timestamp, data FROM messages ORDER BY id").fetchall()
            pos = 0
            while pos < len(rows):
                n = int(self.rng.integers(200, 1500))
                live.executemany("INSERT INTO messages (id, topic_id, timestamp, data) VALUES (?, ?, ?, ?)",
                                 rows[pos : pos + n])
                live.commit()
                if pos < self.pause_at * len(rows) <= pos + n:
                    self.resume.wait(30.0)
                pos = min(len(rows), pos + n)
                self.rows_when.append(pos)
                time.sleep(0.02)
        finally:
            src.close()
            live.close()
        (self.folder / "metadata.yaml").write_bytes((self.source / "metadata.yaml").read_bytes())


def test_watch_a_growing_sqlite3_bag_folder(tmp_path: Path) -> None:
    """A ROS2 bag folder with sqlite3 storage written row batch by row batch while watch reads: each decision is
    reported while the recorder is still writing (F[30,50] mission_2 fails at 50 s of 60 s), and the end equals
    certify_log on the finished folder."""
    src = tmp_path / "src_bag"
    store = get_typestore(Stores.ROS2_HUMBLE)
    with Reader2(LOGS / "late_mission.mcap") as r, Writer2(src, version=9, storage_plugin=StoragePlugin.SQLITE3) as w:
        conns = {c.id: w.add_connection(c.topic, c.msgtype, typestore=store) for c in r.connections}
        for c, t, data in r.messages():
            w.write(conns[c.id], t, data)
    folder = tmp_path / "live_bag"
    folder.mkdir()
    rec = SqliteRecorder(src, folder, pause_at=0.95)
    seen: dict[str, bool] = {}

    def on_decision(d: Decision) -> None:
        seen.setdefault(d.name, (folder / "metadata.yaml").is_file())
        if d.name == "F[30,50] mission_2":
            rec.resume.set()

    rec.start()
    res = watch_log(folder, OnlineMonitor(builtin_scenario()), follow=True, idle_timeout_s=40.0, poll_s=0.02,
                    on_decision=on_decision)
    rec.join()
    assert res.finished and len(rec.rows_when) > 5  # really written in several transactions
    assert seen["F[30,50] mission_2"] is False  # decided before the recorder finished
    _assert_same_as_certify(folder, res, salvage=False)


def test_watch_applies_the_scenarios_clock_offsets_as_certify() -> None:
    """A clock offset on /odom moves the pose and the signal alike: the same verdicts and first violation as
    certify, and the decision at the same time from the first sample."""
    sc = load_scenario(DIFFDRIVE)
    sc = sc.model_copy(update={"clock_offsets": {"/odom": 0.5}})
    spec = "G[0,inf) crawl"
    res = watch_log(LOGS / "diffdrive_odom.bag", OnlineMonitor(sc, spec=spec))
    cert = certify_log(LOGS / "diffdrive_odom.bag", sc, spec=spec).certificate
    assert [(c.name, c.verdict) for c in res.result.checks] == [(c["name"], c["verdict"]) for c in cert["checks"]]
    got = next(c for c in res.result.checks if c.name == "spec_trajectory")
    want = next(c for c in cert["checks"] if c["name"] == "spec_trajectory")
    assert got.first_violation_ns is not None
    assert round((got.first_violation_ns - cert["time0_ns"]) * 1e-9, 9) == want["first_violation_time"]
    assert cert["time0_ns"] == read_log(LOGS / "diffdrive_odom.bag", load_scenario(DIFFDRIVE)).time0_ns + 500_000_000
