"""watch times every stream (pose, nominal, commands, each signal topic) as certify does: the time rule applied to the
whole stream in certify's reading order (by log time for a closed log). Read once, watch gives the same times by
construction; following, each poll is timed with the samples before it and the whole streams are checked at the end
(a difference: never a verdict)."""

from __future__ import annotations

import struct
from collections.abc import Callable
from pathlib import Path
from typing import Any

import numpy as np
import pytest
from mcap.reader import make_reader

from tubempc.scenario import builtin_scenario, dump_scenario, load_scenario
from verify import certify_log
from verify.ingest.ros1records import MAGIC, Op, record_at
from verify.ingest.rules import ReadingRules
from verify.online import OnlineMonitor
from verify.online.follow import open_follower
from verify.online.streamtimes import StreamTimes, reading_order
from verify.online.watch import AUTO_PROBE, _Feeder, watch_log

from ..verify.support import FUZZ, run, tied_publishers_bag  # noqa: TID252  (the shared helpers; tests is not a package)

SPEC = "G[0,inf) !(obs_1 | obs_2 | obs_3 | obs_4)"


def _certify_and_watch(log: Path, capsys: pytest.CaptureFixture[str], *more: str) -> list[tuple[int, str, str]]:
    """``tubempc certify`` and ``tubempc watch`` on ``log`` (built-in scenario, SPEC, then ``more``): (exit code,
    stdout, stderr) of each."""
    args = [str(log), "--scenario", "nexus-sml", "--spec", SPEC, *more]
    return [run([cmd, *args], capsys) for cmd in ("certify", "watch")]


def _same_refusal(log: Path, capsys: pytest.CaptureFixture[str], text: str) -> None:
    """certify and watch on ``log`` both refuse it (exit 3) with the same line, which holds ``text``."""
    got = _certify_and_watch(log, capsys)
    assert [g[0] for g in got] == [3, 3], got
    assert got[0][2].strip().splitlines()[-1] == got[1][2].strip().splitlines()[-1], got
    assert text in got[1][2], got


def _assert_malformed(db: Path, query: str) -> None:
    """``query`` on the sqlite3 file ``db`` meets its damage ("database disk image is malformed")."""
    import sqlite3

    con = sqlite3.connect(f"file:{db}?mode=ro", uri=True)
    try:
        with pytest.raises(sqlite3.DatabaseError, match="malformed"):
            con.execute(query).fetchall()
    finally:
        con.close()


def _edit_topic_metadata(folder: Path, topic: str, edit: Callable[[dict[str, Any]], None]) -> None:
    """A bag folder's metadata.yaml with ``edit`` applied to ``topic``'s topics_with_message_count entry."""
    import yaml

    meta_path = folder / "metadata.yaml"
    meta = yaml.safe_load(meta_path.read_text())
    for entry in meta["rosbag2_bagfile_information"]["topics_with_message_count"]:
        if entry["topic_metadata"]["name"] == topic:
            edit(entry)
    meta_path.write_text(yaml.safe_dump(meta, sort_keys=False))
LATE_S = 527.5  # the log time one nominal message is moved by (its header stamp and file position unchanged)


def _late_nominal_log(tmp_path: Path) -> Path:
    """The clean run as a bare MCAP whose nominal message at 7.8 s has a log time 527.5 s later in its record (a
    flipped byte of the log time field): in file order its stamp fits its neighbours, in log-time order (certify's
    reading order) it comes last, an outlier, re-timed from that log time."""
    log = FUZZ.write_run(FUZZ.base_run(violating=False), tmp_path / "run.mcap", "mcap")
    sc = builtin_scenario()
    with log.open("rb") as fh:
        channels = make_reader(fh).get_summary().channels  # type: ignore[union-attr]
    (nominal,) = [cid for cid, ch in channels.items() if ch.topic == sc.topics.nominal]
    data = bytearray(log.read_bytes())
    t_ns = FUZZ.TIME0_NS + 7_800_000_000
    # a message record: opcode 5, length u64, channel u16, sequence u32, log time u64, publish time u64, payload
    at = data.find(b"\x05")
    found = 0
    while at >= 0:
        if (data[at] == 5 and struct.unpack_from("<H", data, at + 9)[0] == nominal
                and struct.unpack_from("<Q", data, at + 15)[0] == t_ns):
            struct.pack_into("<Q", data, at + 15, t_ns + round(LATE_S * 1e9))
            found += 1
        at = data.find(b"\x05", at + 1)
    assert found == 1
    log.write_bytes(bytes(data))
    return log


def test_watch_reads_a_closed_log_in_certifys_order(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    """A nominal message whose log time is far later than its file position: certify re-times its stamp (an outlier
    in log-time order) and leaves a pose sample without a nominal sample -- the tube is undecided; watch, reading the
    file in its order, passed it."""
    log = _late_nominal_log(tmp_path)
    sc = builtin_scenario()
    for base in ("header", "auto"):
        cert = certify_log(log, sc, spec=SPEC, time_base=base).certificate
        tube = next(c for c in cert["checks"] if c["name"] == "tube")
        assert tube["verdict"] == "inconclusive" and cert["samples"]["nominal"]["retimed"] == 1
        res = watch_log(log, OnlineMonitor(sc, spec=SPEC), time_base=base)
        assert res.result.verdict == cert["verdict"] == "inconclusive", (base, res.result.verdict_reason)
        assert [(c.name, c.verdict) for c in res.result.checks] == [(c["name"], c["verdict"]) for c in cert["checks"]]
    codes = [run([cmd, str(log), "--scenario", "nexus-sml", "--spec", SPEC, "--time-base", "header"],
                 capsys)[0] for cmd in ("certify", "watch")]
    assert codes == [2, 2]


def _late_nominal_bag(tmp_path: Path) -> Path:
    """The clean run as a ROS1 bag (uncompressed chunks) whose nominal message at 7.8 s has a log time 527.5 s later,
    in its message record and its index entry alike (a bag rewritten by a tool, or a clock that jumped): rosbags'
    reader yields it last (each connection's index sorted by time), the file holds it in its place."""
    log = FUZZ.write_run(FUZZ.base_run(violating=False), tmp_path / "run.bag", "bag")
    nominal = builtin_scenario().topics.nominal
    data = bytearray(log.read_bytes())
    old = struct.pack("<II", *divmod(FUZZ.TIME0_NS + 7_800_000_000, 10**9))
    new = struct.pack("<II", *divmod(FUZZ.TIME0_NS + 7_800_000_000 + round(LATE_S * 1e9), 10**9))
    pos, cid, done = len(MAGIC), None, []
    while pos < len(data):
        rec = record_at(data, pos, len(data))
        inner = [rec]
        if rec.op == Op.CHUNK:  # uncompressed: its records in place
            inner, at = [], rec.data_start
            while at < rec.end:
                inner.append(record_at(data, at, rec.end))
                at = inner[-1].end
        for r in inner:
            if r.op == Op.CONNECTION and r.header["topic"].decode() == nominal:
                cid = r.header["conn"]
            elif r.op == Op.MESSAGE_DATA and r.header["conn"] == cid and r.header["time"] == old:
                at = data.index(b"time=" + old, r.data_start - 64, r.data_start) + 5
                data[at : at + 8] = new
                done.append("record")
            elif r.op == Op.INDEX_DATA and r.header["conn"] == cid:
                for e in range(r.data_start, r.end, 12):
                    if data[e : e + 8] == old:
                        data[e : e + 8] = new
                        done.append("index")
        pos = rec.end
    assert sorted(done) == ["index", "record"]
    log.write_bytes(bytes(data))
    return log


def _late_nominal_folder(tmp_path: Path) -> Path:
    """The clean run as a sqlite3 bag folder whose nominal row at 7.8 s has a timestamp 527.5 s later: the query of
    every reader orders the rows by timestamp, the row id keeps it in its place."""
    import sqlite3

    log = FUZZ.write_run(FUZZ.base_run(violating=False), tmp_path / "run", "dir")
    (db,) = log.glob("*.db3")
    con = sqlite3.connect(db)
    try:
        (tid,) = con.execute("SELECT id FROM topics WHERE name = ?", (builtin_scenario().topics.nominal,)).fetchone()
        t_ns = FUZZ.TIME0_NS + 7_800_000_000
        moved = con.execute("UPDATE messages SET timestamp = ? WHERE topic_id = ? AND timestamp = ?",
                            (t_ns + round(LATE_S * 1e9), tid, t_ns)).rowcount
        con.commit()
    finally:
        con.close()
    assert moved == 1
    return log


@pytest.mark.parametrize("make", [_late_nominal_log, _late_nominal_bag, _late_nominal_folder],
                         ids=["mcap", "ros1", "sqlite3-folder"])
def test_watch_reads_every_closed_log_by_log_time(tmp_path: Path, make: Callable[[Path], Path]) -> None:
    """Every indexed reader yields a closed log's messages by log time, whatever the format: certify re-times the
    late nominal stamp and leaves the tube undecided. watch read a closed ROS1 bag and a closed sqlite3 bag folder in
    file order and passed them (only MCAP was read by log time)."""
    log = make(tmp_path)
    sc = builtin_scenario()
    for base in ("header", "auto"):
        cert = certify_log(log, sc, spec=SPEC, time_base=base).certificate
        assert cert["verdict"] == "inconclusive" and cert["samples"]["nominal"]["retimed"] == 1
        res = watch_log(log, OnlineMonitor(sc, spec=SPEC), time_base=base)
        assert res.finished and res.result.verdict == "inconclusive", (base, res.result.verdict_reason)
        assert [(c.name, c.verdict) for c in res.result.checks] == [(c["name"], c["verdict"]) for c in cert["checks"]]


def test_watch_reads_a_bare_sqlite3_storage_by_timestamp(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    """A bare ``.db3`` (no bag folder: never closed for watch, which judges it as partial) of the clean run, three of
    whose pose rows (24.1-24.3 s) keep their place while their log times move 4 ms and 3 s later and to before the
    log's start: certify reads every sqlite3 storage by timestamp (there is no salvage walk of one), re-times the
    pose sample logged 3 s late and fails the tube there (28.2 s); watch read the rows by id, found the same tube
    violation, and still said inconclusive: its time rule, applied again in certify's order at the end, gave the
    moved samples other times (fault campaign seed 102 cases 157 and 442)."""
    run0 = FUZZ.base_run(violating=False)
    pose = builtin_scenario().topics.pose
    run0.log_moves = [(pose, 241, int(run0.t_ns[241]) + 4_000_000), (pose, 242, int(run0.t_ns[242]) + 3_000_000_000),
                      (pose, 243, FUZZ.TIME0_NS - 1_000_000_000)]
    log = FUZZ.write_run(run0, tmp_path / "run.db3", "db3")
    for base in ("header", "auto"):
        got = _certify_and_watch(log, capsys, "--time-base", base)
        assert [g[0] for g in got] == [1, 1], (base, got)
        assert "judged at other times than certify gives them" not in got[1][2], got


def test_a_negative_sqlite3_timestamp_is_refused_by_every_reader(tmp_path: Path,
                                                                 capsys: pytest.CaptureFixture[str]) -> None:
    """A bare ``.db3`` whose pose row at 12 s holds a negative timestamp (sqlite3 stores a signed INTEGER; a damaged
    byte makes one, 236 years before the others): on ``--time-base log`` certify stopped with an internal error (the
    run's time span overflowed), and watch, sorting the log times as the unsigned u64 of MCAP and ROS1, stopped with
    one on every base (fault campaign seed 103 case 617). The row is damage, as a NULL one is: one line, exit 3, from
    certify on either ingest path and from watch."""
    run0 = FUZZ.base_run(violating=False)
    pose = builtin_scenario().topics.pose
    run0.log_moves = [(pose, 120, -7_456_146_430_654_775_808)]
    log = FUZZ.write_run(run0, tmp_path / "run.db3", "db3")
    for base in ("header", "auto", "log"):
        got = _certify_and_watch(log, capsys, "--time-base", base)
        assert [g[0] for g in got] == [3, 3], (base, got)
        assert all("has no log time (NULL or negative)" in g[2] and "internal error" not in g[2] for g in got), got
    with pytest.MonkeyPatch.context() as mp:
        mp.setenv("TUBEMPC_FAST_INGEST", "0")
        assert _certify_and_watch(log, capsys)[0][0] == 3


def _index_entry_patched(db: Path, topic: str, at_s: float, *, to_s: float | None = None,
                         key_s: float | None = None) -> None:
    """In the sqlite3 file ``db``, the timestamp index entry of ``topic``'s row logged at ``at_s`` rewritten in place,
    as a damaged byte of the index page does: made to name the row logged at ``to_s`` (its row id field), or to hold
    the timestamp ``key_s`` (its key; the entry stays where it is in the index). An index record is (header 3,
    serial types 6 and 2: an 8-byte timestamp and a 2-byte row id, big-endian)."""
    import sqlite3

    con = sqlite3.connect(db)
    try:
        (tid,) = con.execute("SELECT id FROM topics WHERE name = ?", (topic,)).fetchone()
        ids = [con.execute("SELECT id FROM messages WHERE topic_id = ? AND timestamp = ?",
                           (tid, FUZZ.TIME0_NS + round(t * 1e9))).fetchone()[0] for t in (at_s, to_s or at_s)]
    finally:
        con.close()
    data = bytearray(db.read_bytes())
    entry = bytes([3, 6, 2]) + struct.pack(">qH", FUZZ.TIME0_NS + round(at_s * 1e9), ids[0])
    assert data.count(entry) == 1
    at = data.index(entry) + 3
    key = FUZZ.TIME0_NS + round((at_s if key_s is None else key_s) * 1e9)
    data[at : at + 10] = struct.pack(">qH", key, ids[1])
    db.write_bytes(bytes(data))


def test_an_index_entry_out_of_time_order_keeps_its_place(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    """A sqlite3 bag folder whose timestamp index entry of the nominal row at 12.3 s holds 19.95 s (a damaged key,
    changed in place): certify's query walks the index in its order and reads that nominal message in its place,
    with log time 19.95 s, where its stamp (12.3 s) fits its neighbours: the clean run passes. watch, sorting the
    closed storage's messages by log time, moved it to 19.95 s's place, where its stamp is an outlier, and left the
    tube undecided (fault campaign seed 120 cases 398, 593, 756: a fault of this round's first sorting, never on the
    round's start). The follower now delivers a sqlite3 storage's messages in the index walk's order."""
    log = FUZZ.write_run(FUZZ.base_run(violating=False), tmp_path / "run", "dir")
    (db,) = log.glob("*.db3")
    _index_entry_patched(db, builtin_scenario().topics.nominal, 12.3, key_s=19.95)
    for base in ("header", "auto"):
        got = _certify_and_watch(log, capsys, "--time-base", base)
        assert got[0][0] == got[1][0], (base, got)


def test_a_row_named_by_two_index_entries_is_read_twice(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    """A bare ``.db3`` whose timestamp index entry of the nominal row at 21.1 s names the nominal row at 24.1 s (a
    damaged row id): certify's query walks the index and reads the 24.1 s row twice -- its payload at 21.1 s, whose
    stamp is then re-timed, and the tube fails there -- and never the 21.1 s row. watch keyed the index entries by
    row id, read each row once and missed the nominal sample at 21.1 s: the tube undecided (fault campaign seed 87
    case 1224, seed 103 case 1083)."""
    log = FUZZ.write_run(FUZZ.base_run(violating=False), tmp_path / "run.db3", "db3")
    _index_entry_patched(log, builtin_scenario().topics.nominal, 21.1, to_s=24.1)
    for base in ("header", "auto"):
        got = _certify_and_watch(log, capsys, "--time-base", base)
        assert [g[0] for g in got] == [1, 1], (base, got)
        cert = certify_log(log, builtin_scenario(), spec=SPEC, time_base=base).certificate
        assert cert["samples"]["nominal"]["read"] == 301 and cert["samples"]["nominal"]["retimed"] == 1


@pytest.mark.parametrize("compression", ["none", "lz4"])
def test_a_closed_bag_is_held_in_certifys_order_among_equal_log_times(tmp_path: Path, compression: str) -> None:
    """Two connections on one topic with log times tied across them (60 messages per time, as a simulation's clock
    gives): certify's readers yield them by log time, then by connection as the bag's index lists them (rosbags merges
    its connections' lists), not in file order; watch, reading the closed bag once, holds its messages in that
    order too (the fast reader, the plain path and watch: one order)."""
    from verify.ingest.raw import read_raw
    from verify.online.watch import _in_log_order

    path = tied_publishers_bag(tmp_path / "tied.bag", None if compression == "none" else compression)
    follower = open_follower(path)
    held = [m.payload for m in _in_log_order(follower.poll()) if m.topic == "/pose"]
    assert follower.finished
    for fast in ("1", "0"):
        with pytest.MonkeyPatch.context() as mp:
            mp.setenv("TUBEMPC_FAST_INGEST", fast)
            certify_order = list(read_raw(path, {"/pose"}).topics["/pose"].payloads)
        assert held == certify_order, fast
    assert held != sorted(held, key=lambda b: struct.unpack_from("<d", b, len(b) - 56)[0])  # not the file order


def test_following_checks_every_stream_against_certifys_times(tmp_path: Path) -> None:
    """Followed poll by poll in file order, the nominal message keeps its stamp; at the end the rule applied to the
    whole nominal stream in certify's order gives it another time: a note names the topic, and the run's verdict is
    not a pass. The clean log followed the same way: no note, a pass."""
    sc = builtin_scenario()
    clean = FUZZ.write_run(FUZZ.base_run(violating=False), tmp_path / "clean.mcap", "mcap")
    for log, differs in ((_late_nominal_log(tmp_path), True), (clean, False)):
        msgs = open_follower(log).poll()
        monitor = OnlineMonitor(sc, spec=SPEC)
        feeder = _Feeder(monitor, ReadingRules.of(sc, "header"), False, log, probe=AUTO_PROBE)
        for k in range(0, len(msgs), 40):
            feeder.feed(msgs[k : k + 40], final=k + 40 >= len(msgs), by_log_time=k + 40 >= len(msgs))
            monitor.update()
        why = feeder.finish(by_log_time=True)
        assert bool(why) == differs, why
        if differs:
            assert len(why) == 1 and why[0].startswith(f"{sc.topics.nominal}: 1 of 301 sample(s)"), why
        else:
            assert monitor.close().verdict == "pass"


def test_a_signal_message_alone_in_its_poll_is_timed_as_in_the_whole_stream(tmp_path: Path) -> None:
    """A violating temperature message stamped near 1970 (a clock not set) among well-stamped ones: in the whole
    stream an outlier, re-timed from its log time (10 s into the run), so certify fails the run. Read alone in its
    poll the rule saw no neighbours and kept the 1970 stamp (never judged at 10 s); timed with the samples before it,
    it is judged where certify judges it."""
    run0 = FUZZ.base_run(violating=False)
    run0.extra = FUZZ.temperature_stream(run0)
    bad_log_ns = FUZZ.TIME0_NS + 10_000_000_000 - 2_000_000
    run0.extra.append((bad_log_ns, FUZZ.TEMP_TOPIC, FUZZ.TEMPERATURE, FUZZ.temperature(5 * 10**9, 95.0)))
    log = FUZZ.write_run(run0, tmp_path / "run.mcap", "mcap")
    scenario = tmp_path / "scenario.yaml"
    scenario.write_text(FUZZ.signal_scenario_text())
    sc = load_scenario(scenario)
    spec = "G[0,inf) motor_ok"
    cert = certify_log(log, sc, spec=spec, time_base="header").certificate
    assert cert["verdict"] == "fail"
    msgs = open_follower(log).poll()
    (k,) = [i for i, m in enumerate(msgs) if m.topic == FUZZ.TEMP_TOPIC and m.log_ns == bad_log_ns]
    monitor = OnlineMonitor(sc, spec=spec)
    feeder = _Feeder(monitor, ReadingRules.of(sc, "header"), False, log, probe=AUTO_PROBE)
    for poll in (msgs[:k], [msgs[k]], msgs[k + 1 :]):
        feeder.feed(poll, final=poll[-1] is msgs[-1], by_log_time=poll[-1] is msgs[-1])
        monitor.update()
    assert feeder.finish(by_log_time=True) == []
    res = monitor.close()
    assert res.verdict == "fail", res.verdict_reason
    spec_check = next(c for c in res.checks if c.name == "spec_trajectory")
    want = next(c for c in cert["checks"] if c["name"] == "spec_trajectory")
    assert spec_check.first_violation_ns is not None
    assert abs((spec_check.first_violation_ns - cert["time0_ns"]) * 1e-9 - want["first_violation_time"]) < 1e-6


def test_stream_times_by_single_samples_match_the_whole_stream() -> None:
    """One sample per poll (a slow topic followed live), hundreds of polls: each is timed with the samples before
    it, so the unset and the 1970 stamp are re-timed as on the whole stream and nothing differs at the end; in
    log-time order (a closed log) a sample whose log time is far from its place is an outlier there."""
    sc = builtin_scenario()
    rules = ReadingRules.of(sc, "header")
    n = 400
    logs = FUZZ.TIME0_NS + np.arange(n, dtype=np.int64) * 100_000_000
    stamps = logs.copy()
    stamps[150], stamps[300] = 0, 10**9

    def rule(s: np.ndarray | None, log: np.ndarray) -> tuple[object, np.ndarray]:
        return rules.stream_times("/x", s, log, pose_base="header")

    clock = StreamTimes("/x")
    pushed = np.concatenate([clock.times(rule, stamps[k : k + 1], logs[k : k + 1]) for k in range(n)])
    _, whole = rule(stamps, logs)
    assert np.array_equal(pushed, whole) and whole[150] == logs[150] and whole[300] == logs[300]
    tb, differ = clock.final(rule, by_log_time=True)
    assert differ == 0 and tb.retimed == 2
    late = logs.copy()
    late[78] += 527 * 10**9  # read at its place in the file, last by log time
    assert reading_order(late, by_log_time=True)[-1] == 78 and reading_order(late, by_log_time=False)[-1] == n - 1
    moved = StreamTimes("/x")
    moved.times(rule, logs.copy(), late)
    assert moved.final(rule, by_log_time=False)[1] == 0 and moved.final(rule, by_log_time=True)[1] == 1


def _damaged_db3(tmp_path: Path) -> Path:
    """The clean run as a sqlite3 bag folder whose table row of the pose message at 13.7 s holds another timestamp
    than the database's timestamp index, which the readers order by: certify reads the index's time (ordered as
    recorded), the follower the row's (in row order)."""
    folder = FUZZ.write_run(FUZZ.base_run(violating=False), tmp_path / "run", "dir")
    (log,) = folder.glob("*.db3")
    data = bytearray(log.read_bytes())
    field = struct.pack(">q", FUZZ.TIME0_NS + 13_700_000_000)
    # the table row (then the CDR payload; an index entry: then the row id) whose record header gives topic_id the
    # serial type 9 (the constant 1: the pose's topic) and the timestamp 6 (an 8-byte integer), then the blob's
    at = [k for k in range(len(data)) if data.startswith(field, k) and data[k - 4 : k - 2] == b"\x09\x06"
          and data[k + 8 : k + 12] == b"\0\x01\0\0"]
    assert len(at) == 1, at
    data[at[0] : at[0] + 8] = struct.pack(">q", -8_248_779_958_071_983_104)
    log.write_bytes(bytes(data))
    return folder


def test_watch_keeps_the_row_order_where_certify_reads_the_timestamp_index(tmp_path: Path,
                                                                         capsys: pytest.CaptureFixture[str]) -> None:
    """sqlite3 (as ROS1) is read in the order of its index, whose times are the file order of a recorded log: a row
    whose own timestamp is damaged is not moved (sorted by that time it became an outlier, re-timed, and the tube
    undecided where certify passed: seed 102, case 200)."""
    log = _damaged_db3(tmp_path)
    for base in ("header", "auto"):
        got = [run([cmd, str(log), "--scenario", "nexus-sml", "--spec", SPEC, "--time-base", base], capsys)[0]
               for cmd in ("certify", "watch")]
        assert got == [0, 0], (base, got)


class _Polls:
    """A follower that delivers a complete MCAP log's messages 40 at a time, closed with the last poll."""

    def __init__(self, path: Path, wanted: object = None) -> None:
        self.path, self.format, self.finished, self.delivered = path, "mcap", False, 0
        self.declared_topics: dict[str, str] = {}
        self._msgs = open_follower(path).poll()

    def poll(self) -> list[object]:
        out = self._msgs[self.delivered : self.delivered + 40]
        self.delivered += len(out)
        self.finished = self.delivered >= len(self._msgs)
        return list(out)

    def rest(self) -> list[object]:
        return []


def test_watch_follow_is_never_a_pass_on_times_certify_would_not_use(tmp_path: Path,
                                                                    monkeypatch: pytest.MonkeyPatch) -> None:
    """watch --follow on the log whose nominal message certify re-times: the decisions were made on the message's
    stamp, so the run's verdict is inconclusive (certify's) with a note naming the topic; on the clean log, a pass."""
    from verify.online import watch

    monkeypatch.setattr(watch, "open_follower", _Polls)
    sc = builtin_scenario()
    clean = FUZZ.write_run(FUZZ.base_run(violating=False), tmp_path / "clean.mcap", "mcap")
    for log, want in ((_late_nominal_log(tmp_path), "inconclusive"), (clean, "pass")):
        res = watch_log(log, OnlineMonitor(sc, spec=SPEC), follow=True, poll_s=0.01, time_base="header")
        assert res.finished and res.result.verdict == want, (log, res.result.verdict_reason, res.notes)
        named = [n for n in res.notes if n.startswith(f"{sc.topics.nominal}: 1 of 301 sample(s)")]
        assert len(named) == (want == "inconclusive"), res.notes


def test_a_log_time_beyond_int64_is_ordered_as_certify_orders_it() -> None:
    """A closed MCAP log whose message has a log time of 2**63 or more (a flipped top bit): watch ordered the poll by
    int64 and crashed (exit 70, fault campaign seed 66 case 0); u64, as certify's reader, puts it last."""
    from verify.ingest.salvage import SalvagedMessage
    from verify.online.watch import _in_log_order

    msgs = [SalvagedMessage("/p", "std_msgs/msg/Empty", True, t, b"") for t in (5, 2**63 + 7, 3, 2**64 - 1, 4)]
    assert [m.log_ns for m in _in_log_order(msgs)] == [3, 4, 5, 2**63 + 7, 2**64 - 1]


def _db3_with_damaged_camera(tmp_path: Path, *, damaged: bool = True) -> Path:
    """The clean run as a bare .db3 with a camera topic (10 KB images: their bytes on overflow pages) whose first
    image's overflow chain points past the end of the file: its payload cannot be read ("database disk image is
    malformed"), every other row can; and a row whose topic id no topic has, its timestamp beyond its cell."""
    import sqlite3

    log = FUZZ.write_run(FUZZ.base_run(violating=False), tmp_path / ("run.db3" if damaged else "clean.db3"), "db3")
    con = sqlite3.connect(log)
    con.execute("INSERT INTO topics (id, name, type, serialization_format, offered_qos_profiles, "
                "type_description_hash) VALUES (99, '/camera/image_raw', 'sensor_msgs/msg/Image', 'cdr', '', '')")
    t0 = con.execute("SELECT min(timestamp) FROM messages").fetchone()[0]
    con.executemany("INSERT INTO messages (topic_id, timestamp, data) VALUES (99, ?, ?)",
                    [(t0 + k * 10**8, bytes([0xA0 + k]) * 10_000) for k in range(5)])
    con.commit()
    page = con.execute("PRAGMA page_size").fetchone()[0]
    con.close()
    if not damaged:
        return log
    data = bytearray(log.read_bytes())
    # an overflow page of the first image: the page's 4-byte link to the next overflow page, then image bytes only
    first = [p for p in range(page, len(data), page) if data[p + 4 : p + page] == bytes([0xA0]) * (page - 4)]
    assert first, "no overflow page of the first image"
    data[first[0] : first[0] + 4] = (2**31 - 1).to_bytes(4, "big")
    log.write_bytes(bytes(data))
    _assert_malformed(log, "SELECT data FROM messages WHERE topic_id = 99")
    return log


def test_watch_reads_a_sqlite3_storage_as_certify_does(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    """A .db3 whose damaged pages hold only another topic's payloads: certify reads the wanted topics' rows and
    passes; watch read every row's payload and refused the log (exit 3, "database disk image is malformed": fault
    campaign seed 68 case 584, seed 71 case 1401). Now both read the same rows, and watch names the log's topics as
    certify does (its topics table), the camera's included."""
    log, clean = _db3_with_damaged_camera(tmp_path), _db3_with_damaged_camera(tmp_path, damaged=False)
    got = [g[:2] for p in (log, clean) for g in _certify_and_watch(p, capsys)]
    # certify passes both; watch says of the damaged log what it says of the clean one (a bare .db3 has no mark of
    # its recorder closing it: inconclusive, exit 2, read once), never a refusal
    assert [g[0] for g in got] == [0, 2, 0, 2], got
    assert got[1][1].replace(str(log), "LOG") == got[3][1].replace(str(clean), "LOG"), got
    res = watch_log(log, OnlineMonitor(builtin_scenario(), spec=SPEC))
    assert res.result.checks == watch_log(clean, OnlineMonitor(builtin_scenario(), spec=SPEC)).result.checks
    assert certify_log(log, builtin_scenario(), spec=SPEC).certificate["verdict"] == "pass"
    # a pose topic the log does not have: both name the log's topics, the camera's included (its topics table)
    sc = builtin_scenario()
    other = tmp_path / "other.yaml"
    other.write_text(dump_scenario(sc.model_copy(update={"topics": sc.topics.model_copy(update={"pose": "/vicon"})})))
    errs = [run([cmd, str(log), "--scenario", str(other), "--spec", SPEC], capsys) for cmd in ("certify", "watch")]
    assert [e[0] for e in errs] == [3, 3], errs
    lines = [e[2].strip().splitlines()[-1] for e in errs]
    assert lines[0] == lines[1] and "/camera/image_raw" in lines[0], lines


def test_watch_reads_a_sqlite3_message_time_where_certify_reads_it(tmp_path: Path,
                                                                   capsys: pytest.CaptureFixture[str]) -> None:
    """A bag folder whose timestamp index holds another time for one nominal message than its table row: certify's
    query (rosbags') walks the index and reads the message's time there (far beyond the run: no nominal sample for
    the pose beside it, the tube undecided, exit 2); watch read the row's own time and passed (exit 0: fault campaign
    seed 73 case 651). Both read the index's time now."""
    import sqlite3

    folder = FUZZ.write_run(FUZZ.base_run(violating=False), tmp_path / "run", "dir")
    (log,) = folder.glob("*.db3")
    t_ns = FUZZ.TIME0_NS + 13_700_000_000
    con = sqlite3.connect(f"file:{log}?mode=ro", uri=True)
    try:
        (rid,) = con.execute("SELECT messages.id FROM messages JOIN topics ON topic_id = topics.id WHERE name = ? "
                             "AND timestamp = ?", ("/nexus/nominal_pose", t_ns)).fetchone()
    finally:
        con.close()
    data = bytearray(log.read_bytes())
    # the index entry (its record header: 3 bytes, the timestamp an 8-byte integer, the row id a 2-byte one)
    entry = b"\x03\x06\x02" + struct.pack(">q", t_ns) + struct.pack(">H", rid)
    at = [k for k in range(len(data)) if data.startswith(entry, k)]
    assert len(at) == 1, at
    data[at[0] + 3 : at[0] + 11] = struct.pack(">q", 2_055_455_992_151_711_744)
    log.write_bytes(bytes(data))
    got = _certify_and_watch(folder, capsys, "--time-base", "log")
    assert [g[0] for g in got] == [2, 2], got
    cert = certify_log(folder, builtin_scenario(), spec=SPEC, time_base="log").certificate
    res = watch_log(folder, OnlineMonitor(builtin_scenario(), spec=SPEC), time_base="log")
    (tube,) = [c for c in cert["checks"] if c["name"] == "tube"]
    assert tube["reason"].startswith("1 pose sample(s) without a usable nominal sample"), tube
    (mine,) = [c for c in res.result.checks if c.name == "tube"]
    assert mine.verdict == "inconclusive" and mine.details.get("reason") == tube["reason"], mine


def test_watch_refuses_a_closed_bag_record_that_runs_past_its_index(tmp_path: Path,
                                                                    capsys: pytest.CaptureFixture[str]) -> None:
    """A closed ROS1 bag (its header names its index) whose index data record after a chunk has a damaged header
    length: rosbags reads those records at fixed offsets and never uses that length, so certify judges the bag
    (exit 0); watch walked the records, took the record for one still being written and waited, then judged the
    records before it (exit 2 where certify said fail: fault campaign seed 73 case 469). In a closed bag no record
    is still being written: watch refuses it with one line naming the record's byte, as it refuses other damage
    certify's reader does not parse."""
    from verify.ingest.ros1records import record_at

    log = FUZZ.write_run(FUZZ.base_run(violating=False), tmp_path / "run.bag", "bag-lz4")
    data = bytearray(log.read_bytes())
    pos, chunks, at = 13, 0, None
    while at is None:
        rec = record_at(data, pos, len(data), head_only=True)
        chunks += rec.op == 0x05
        if rec.op == 0x04 and chunks == 2:
            at = pos  # the first index data record after the second chunk
        pos = rec.end
    data[at + 3] ^= 0x02  # the high byte of its header length: the record now runs far past the file's end
    log.write_bytes(bytes(data))
    (c_code, _, _), (w_code, _, w_err) = _certify_and_watch(log, capsys)
    assert c_code == 0 and w_code == 3, (c_code, w_code, w_err)
    assert f"malformed ROS1 record at byte {at} (the record at byte {at} runs past the bag's index" in w_err


def test_watch_checks_a_closed_mcap_logs_declared_counts_as_certify(tmp_path: Path,
                                                                    capsys: pytest.CaptureFixture[str]) -> None:
    """An MCAP file whose Statistics record declares more pose messages than it holds: certify refuses it (exit 3,
    "declares N messages on /qualisys/nexus/pose but only M can be read"); watch read the file to its footer and
    passed (fault campaign seed 74 case 790). The closed file's counts are checked by the same rule now."""
    from verify.ingest.mcaprecords import MAGIC as MCAP_MAGIC
    from verify.ingest.mcaprecords import Op, parse_channel, walk

    log = FUZZ.write_run(FUZZ.base_run(violating=False), tmp_path / "run.mcap", "mcap")
    data = bytearray(log.read_bytes())
    pose_id, stats_at = None, None
    for op, rec, nxt in walk(data, len(MCAP_MAGIC), len(data) - len(MCAP_MAGIC)):
        start = nxt - len(rec)
        if op == Op.CHANNEL and parse_channel(rec).topic == "/qualisys/nexus/pose":
            pose_id = parse_channel(rec).id
        elif op == Op.STATISTICS:
            stats_at = start
    assert pose_id is not None and stats_at is not None
    pairs = stats_at + 46  # the (channel id u16, count u64) pairs after the fixed fields and the map's length
    (length,) = struct.unpack_from("<I", data, pairs - 4)
    for at in range(pairs, pairs + length, 10):
        cid, n = struct.unpack_from("<HQ", data, at)
        if cid == pose_id:
            struct.pack_into("<Q", data, at + 2, n + 5)
    log.write_bytes(bytes(data))
    _same_refusal(log, capsys,
                  "declares 306 messages on /qualisys/nexus/pose but only 301 can be read")


def test_watch_reads_no_column_of_a_row_certify_does_not_read(tmp_path: Path,
                                                              capsys: pytest.CaptureFixture[str]) -> None:
    """A .db3 with a row whose topic id is text that is not UTF-8 (a damaged record header): certify's query selects
    the wanted topics' rows and never reads it (exit 0); watch's follower read every row's topic id and refused the
    log ("Could not decode to UTF-8 column 'topic_id'", exit 3: fault campaign seed 80 case 850). Now it selects the
    same rows as certify, and says of the log what it says of the clean one."""
    import sqlite3

    clean = FUZZ.write_run(FUZZ.base_run(violating=False), tmp_path / "clean.db3", "db3")
    log = tmp_path / "run.db3"
    log.write_bytes(clean.read_bytes())
    con = sqlite3.connect(log)
    con.execute("INSERT INTO messages (topic_id, timestamp, data) VALUES (CAST(x'1886725536' AS TEXT), 1, x'00')")
    con.commit()
    con.close()
    got = [g[:2] for p in (log, clean) for g in _certify_and_watch(p, capsys)]
    assert [g[0] for g in got] == [0, 2, 0, 2], got
    assert got[1][1].replace(str(log), "LOG") == got[3][1].replace(str(clean), "LOG"), got


def test_watch_reads_a_closed_bags_index_by_certifys_rules(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    """A closed ROS1 bag whose index holds a chunk info record without its end time: rosbags refuses the index
    (certify exit 3; --salvage reads its chunks, partial); watch read its chunks as they complete and passed it
    (fault campaign seed 82 case 114). The chunk info rule is the record layer's (``chunk_info_of``), read by the
    fast reader and by the stream at the index: an index the indexed readers refuse does not close the bag, so
    watch judges it as --salvage does, never a pass."""
    log = FUZZ.write_run(FUZZ.base_run(violating=False), tmp_path / "run.bag", "bag-lz4")
    data = bytearray(log.read_bytes())
    at = data.rindex(b"end_time=")  # a field of the bag index's last chunk info record
    data[at : at + 8] = b"end_tima"
    log.write_bytes(bytes(data))
    args = [str(log), "--scenario", "nexus-sml", "--spec", SPEC]
    got = [run(argv, capsys) for argv in (["certify", *args], ["certify", *args, "--salvage"], ["watch", *args])]
    assert [g[0] for g in got] == [3, 2, 2], got
    assert "inconclusive" in got[2][1] and "not closed by its recorder" in got[2][1], got


def test_watch_checks_a_closed_sqlite3_folders_declared_counts(tmp_path: Path,
                                                               capsys: pytest.CaptureFixture[str]) -> None:
    """A sqlite3 bag folder whose metadata.yaml declares one command message more than its database holds: certify
    refuses it (exit 3, "declares 302 messages on /nexus/cmd_vel but only 301 can be read"); watch passed it (fault
    campaign seed 82 case 111). The same rule (``check_declared_counts``) at the folder's close now."""
    folder = FUZZ.write_run(FUZZ.base_run(violating=False), tmp_path / "run", "dir")

    def one_more(entry: dict[str, Any]) -> None:
        entry["message_count"] += 1

    _edit_topic_metadata(folder, "/nexus/cmd_vel", one_more)
    _same_refusal(folder, capsys,
                  "declares 302 messages on /nexus/cmd_vel but only 301 can be read")


def test_watch_refuses_a_closed_sqlite3_folder_certifys_query_cannot_read(tmp_path: Path,
                                                                          capsys: pytest.CaptureFixture[str]) -> None:
    """A sqlite3 bag folder whose timestamp index has a garbled leaf page: certify's query walks that index and
    the database is unreadable to it (exit 3); watch read the rows in row order and judged them (fault campaign seed
    82 case 90, where the walk met a garbled row cell). At the folder's close watch now reads the wanted rows as
    certify's query does, and refuses it too."""
    import sqlite3

    folder = FUZZ.write_run(FUZZ.base_run(violating=False), tmp_path / "run", "dir")
    (log,) = folder.glob("*.db3")
    con = sqlite3.connect(f"file:{log}?mode=ro", uri=True)
    try:
        page = con.execute("PRAGMA page_size").fetchone()[0]
    finally:
        con.close()
    data = bytearray(log.read_bytes())
    leaves = [p for p in range(page, len(data), page) if data[p] == 0x0A]  # index b-tree leaf pages (not page 1)
    assert leaves
    at = leaves[len(leaves) // 2]
    data[at + 8 : at + page] = b"\xff" * (page - 8)  # its cell pointers and cells garbled, its header kept
    log.write_bytes(bytes(data))
    got = _certify_and_watch(folder, capsys)
    assert [g[0] for g in got] == [3, 3], got
    assert "sqlite3" in got[1][2] and ("unreadable" in got[1][2] or "malformed" in got[1][2]), got


def test_watch_reads_a_closed_sqlite3_folders_topics_as_rosbags_matches_them(
        tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    """A sqlite3 bag folder whose metadata.yaml gives the pose topic another type hash than its database: rosbags'
    folder reader matches metadata.yaml's connections to the storage's by topic, type, serialization, QoS and type
    hash, reads no pose row, and certify refuses the log ("declares 301 messages ... but only 0 can be read"); watch
    read the rows by the database's topic names and passed (fault campaign seed 82 case 497). At the close watch
    counts only the rows certify's readers read (``read_topics_by_storage``, the readers' own matching)."""
    folder = FUZZ.write_run(FUZZ.base_run(violating=False), tmp_path / "run", "dir")

    def other_hash(entry: dict[str, Any]) -> None:
        tm = entry["topic_metadata"]
        assert tm.get("type_description_hash"), tm
        tm["type_description_hash"] = tm["type_description_hash"][:-1] + "0"

    _edit_topic_metadata(folder, "/qualisys/nexus/pose", other_hash)
    _same_refusal(folder, capsys,
                  "declares 301 messages on /qualisys/nexus/pose but only 0 can be read")


def test_watch_never_passes_a_folder_certifys_readers_do_not_open(tmp_path: Path,
                                                                  capsys: pytest.CaptureFixture[str]) -> None:
    """A sqlite3 bag folder whose metadata.yaml lacks a key rosbags requires (a topic's serialization_format):
    certify refuses it (exit 3); watch's own metadata reading did not need the key and passed the log (fault
    campaign seed 83 case 1140, seed 84 case 350). A folder certify's readers do not open is not closed for watch
    either: judged as --salvage judges it, never a pass."""
    folder = FUZZ.write_run(FUZZ.base_run(violating=False), tmp_path / "run", "dir")
    meta_path = folder / "metadata.yaml"
    text = meta_path.read_text()
    assert "serialization_format:" in text
    meta_path.write_text(text.replace("serialization_format:", "smrialization_format:", 1))
    got = _certify_and_watch(folder, capsys)
    assert [g[0] for g in got] == [3, 2], got
    assert "not closed by its recorder" in got[1][1], got


def test_watch_names_a_closed_bags_connections_as_its_index_does(tmp_path: Path,
                                                                 capsys: pytest.CaptureFixture[str]) -> None:
    """A ROS1 bag whose copy of the nominal pose's connection record inside a chunk names another topic: rosbags
    takes connections from the bag's index and reads the nominal stream (certify: pass); watch named the messages
    by the chunk's copy, saw no nominal stream and left the tube undecided (fault campaign seed 84 case 1196). At
    the index the stream now names its connections as the index does."""
    log = FUZZ.write_run(FUZZ.base_run(violating=False), tmp_path / "run.bag", "bag")
    data = bytearray(log.read_bytes())
    field = b"topic=/nexus/nominal_pose"
    first, last = data.find(field), data.rfind(field)
    assert 0 < first < last  # the chunk's copy first, the index's record last
    data[first + len(b"topic=/nexus/") : first + len(b"topic=/nexus/") + 1] = b"l"
    log.write_bytes(bytes(data))
    got = _certify_and_watch(log, capsys)
    assert [g[0] for g in got] == [0, 0], got


def test_watch_reads_a_sqlite3_table_its_scan_cannot_walk_as_certify_does(tmp_path: Path,
                                                                          capsys: pytest.CaptureFixture[str]) -> None:
    """A .db3 (fault campaign seed 86 case 1211, kept as it was damaged: four flipped bytes) whose table a scan in
    row order cannot walk ("database disk image is malformed") while certify's query, which walks the timestamp
    index and looks each row up, reads every row (certify: pass). watch refused it (exit 3); where its scan meets
    the damage it now reads the rows as certify's query does (and on such a table SQLite reads ``id`` as NULL through
    the index: the rows are keyed by ``rowid``), and says what it says of a bare .db3 (not closed: inconclusive)."""
    import shutil

    log = tmp_path / "damaged.db3"
    shutil.copyfile(Path(__file__).parent / "data" / "table_scan_damaged.db3", log)
    _assert_malformed(log, "SELECT id, topic_id, timestamp, data FROM messages WHERE id > 0 ORDER BY id")
    got = _certify_and_watch(log, capsys)
    assert [g[0] for g in got] == [0, 2], got
    assert "inconclusive (read once (no --follow); 301 pose samples)" in got[1][1], got


def test_watch_refuses_a_closed_mcap_message_of_a_channel_never_declared(tmp_path: Path,
                                                                         capsys: pytest.CaptureFixture[str]) -> None:
    """A closed MCAP file with a message whose channel id no channel record declares (a damaged id): the scan refuses
    it (certify exit 3, "a message refers to channel N, which the file never declares"); watch dropped the message
    and passed (fault campaign seed 86 case 1034). At the close watch applies the scan's rule
    (``check_channels_declared``)."""
    from verify.ingest.mcaprecords import MAGIC as MCAP_MAGIC
    from verify.ingest.mcaprecords import Op, walk

    log = FUZZ.write_run(FUZZ.base_run(violating=False), tmp_path / "run.mcap", "mcap")
    data = bytearray(log.read_bytes())
    chunk = next(nxt - len(rec) for op, rec, nxt in walk(data, len(MCAP_MAGIC), len(data) - len(MCAP_MAGIC))
                 if op == Op.CHUNK)
    (name_len,) = struct.unpack_from("<I", data, chunk + 28)  # start, end, size, crc; then the compression's name
    assert name_len == 0  # uncompressed: its records follow the stored size
    records = chunk + 28 + 4 + 8
    pos = records
    while data[pos] != Op.MESSAGE:
        pos += 9 + struct.unpack_from("<Q", data, pos + 1)[0]
    struct.pack_into("<H", data, pos + 9, 77)  # the first message's channel id: a channel the file never declares
    struct.pack_into("<I", data, chunk + 24, 0)  # the chunk's CRC: 0, "not computed"
    log.write_bytes(bytes(data))
    got = _certify_and_watch(log, capsys)
    assert [g[0] for g in got] == [3, 3], got
    assert "a message refers to channel 77, which the file never declares" in got[1][2], got
