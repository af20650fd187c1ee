"""Damaged input never crashes the command line: exit 3 with one line naming the file and the problem in words.

Reproducers of the classes a fault campaign found (``benchmarks/fuzz_certify.py``): library exceptions escaping the
read boundary, a bad byte in an optional topic, the fast decoder and rosbags disagreeing on invalid UTF-8, formulas
nested too deeply or with huge bounds, output paths, FIFOs, ``--debug`` changing exit codes, unclear messages,
huge scenarios, and warnings on stderr. Runs the real ``tubempc.cli.main`` in this process.
"""

from __future__ import annotations

import os
import struct
import threading
import time
from pathlib import Path
from typing import Any

import numpy as np
import pytest
from rosbags.serde import SerdeError

from tubempc.scenario import builtin_scenario, builtin_scenario_text
from verify.errors import LogReadError
from verify.ingest import decode as decode_module
from verify.ingest import log as log_module
from verify.ingest.decode import decode_pose
from verify.ingest.raw import RawTopic
from verify.ingest.readerrors import LibraryError

from .support import FUZZ, one_line_error, run

ROOT = Path(__file__).resolve().parents[2]
#: every case holds with our own readers and with plain rosbags (TUBEMPC_FAST_INGEST=0): the same exit and message
pytestmark = pytest.mark.usefixtures("ingest_path")

SPEC = "G[0,inf) !(obs_1 | obs_2 | obs_3 | obs_4)"


@pytest.fixture(scope="module")
def seed_logs(tmp_path_factory: pytest.TempPathFactory) -> dict[tuple[str, bool], Path]:
    out: dict[tuple[str, bool], Path] = FUZZ.write_seeds(tmp_path_factory.mktemp("seeds"))
    return out


def test_seed_logs_pass_and_fail_as_built(seed_logs: dict[tuple[str, bool], Path],
                                          capsys: pytest.CaptureFixture[str]) -> None:
    for (_fmt, violating), path in seed_logs.items():
        code, _, err = run(["certify", str(path), "--scenario", "nexus-sml", "--spec", SPEC], capsys)
        assert code == (1 if violating else 0), (path, err)
        assert err == ""


@pytest.mark.parametrize(("exc", "words"), [
    (AssertionError(), "index disagrees with its data"),
    (SerdeError("Invalid string length 2949534278 at offset 0."), "a message cannot be decoded"),
    (OverflowError("Python int too large to convert to C ssize_t"), "out of range"),
    (UnicodeDecodeError("utf-8", b"\xff", 0, 1, "invalid start byte"), "not"),
    (KeyError(23), "does not exist"),
    (TypeError("'NoneType' object is not subscriptable"), "malformed"),
    (MemoryError(), "more memory"),
])
def test_library_errors_become_one_line_exit_3(seed_logs: dict[tuple[str, bool], Path], monkeypatch: Any,
                                               capsys: pytest.CaptureFixture[str], exc: Exception,
                                               words: str) -> None:
    """Library errors are translated where the library is called (``LibraryError``) and keep their words; the same
    exception raised bare by our code is a bug (exit 70) when it is one a library raises only on bad bytes."""
    def boom(*args: Any, **kwargs: Any) -> Any:
        raise LibraryError(exc) if isinstance(exc, AssertionError | KeyError | TypeError) else exc

    monkeypatch.setattr(log_module, "read_raw", boom)
    path = seed_logs["bag", False]
    code, _, err = run(["certify", str(path), "--scenario", "nexus-sml"], capsys)
    assert code == 3
    one_line_error(err, str(path), words)
    # --debug adds the traceback before the same line and never changes the exit code
    code, _, err = run(["--debug", "certify", str(path), "--scenario", "nexus-sml"], capsys)
    assert code == 3 and "Traceback" in err and err.strip().splitlines()[-1].startswith("tubempc: error: ")
    if isinstance(exc, AssertionError | KeyError | TypeError):

        def bug(*args: Any, **kwargs: Any) -> Any:
            raise exc

        monkeypatch.setattr(log_module, "read_raw", bug)
        assert run(["certify", str(path), "--scenario", "nexus-sml"], capsys)[0] == 70


def test_internal_error_keeps_exit_70_with_debug(seed_logs: dict[tuple[str, bool], Path], monkeypatch: Any,
                                                 capsys: pytest.CaptureFixture[str]) -> None:
    from verify import certify as certify_module

    def boom(*args: Any, **kwargs: Any) -> Any:
        raise ZeroDivisionError("a bug")

    monkeypatch.setattr(certify_module, "_judge", boom)
    path = str(seed_logs["mcap", False])
    assert run(["certify", path, "--scenario", "nexus-sml"], capsys)[0] == 70
    code, _, err = run(["--debug", "certify", path, "--scenario", "nexus-sml"], capsys)
    assert code == 70 and "Traceback" in err


@pytest.mark.parametrize("fmt", ["bag", "mcap", "db3"])
@pytest.mark.parametrize("patch", ["bytes", "utf8"])
def test_bad_optional_topic_is_a_finding(tmp_path: Path, capsys: pytest.CaptureFixture[str], fmt: str,
                                         patch: str) -> None:
    run_ = FUZZ.base_run(violating=False)
    body = b'{"success": \xff\xfe}'
    run_.status_patch = (b"\x05\x00" if patch == "bytes" else
                         struct.pack("<I", len(body)) + body if fmt == "bag" else
                         b"\0\x01\0\0" + struct.pack("<I", len(body) + 1) + body + b"\0")
    path = FUZZ.write_run(run_, tmp_path / f"run.{fmt}", fmt)
    code, _, err = run(["certify", str(path), "--scenario", "nexus-sml", "--spec", SPEC, "--out",
                        str(tmp_path / "out"), "--no-report"], capsys)
    assert code == 0, err
    import json

    cert = json.loads((tmp_path / "out" / "certificate.json").read_text())
    assert cert["data_quality"]["solver"]["undecodable"] == 1


def _pose_topic(ros1: bool, frame: bytes) -> RawTopic:
    payload = FUZZ._cdr_string_patch(_pose_payload(ros1), ros1, frame)
    return RawTopic("/pose", "geometry_msgs/msg/PoseStamped", True, [1, 2], [payload, payload])


def _pose_payload(ros1: bool) -> bytes:
    from rosbags.typesys import Stores, get_typestore

    store = get_typestore(Stores.ROS1_NOETIC if ros1 else Stores.ROS2_HUMBLE)
    ty = store.types
    hdr = ty["std_msgs/msg/Header"](**({"seq": 0} if ros1 else {}),
                                   stamp=ty["builtin_interfaces/msg/Time"](sec=5, nanosec=0), frame_id="world")
    msg = ty["geometry_msgs/msg/PoseStamped"](header=hdr, pose=ty["geometry_msgs/msg/Pose"](
        position=ty["geometry_msgs/msg/Point"](x=1.0, y=2.0, z=0.0),
        orientation=ty["geometry_msgs/msg/Quaternion"](x=0.0, y=0.0, z=0.0, w=1.0)))
    ser = store.serialize_ros1 if ros1 else store.serialize_cdr
    return bytes(ser(msg, "geometry_msgs/msg/PoseStamped"))


@pytest.mark.parametrize("ros1", [True, False])
def test_fast_and_rosbags_decoders_agree_on_invalid_utf8(ros1: bool) -> None:
    good = _pose_topic(ros1, "wörld".encode())
    fast, slow = decode_pose(good, ros1, fast=True), decode_pose(good, ros1, fast=False)
    assert fast.fast and not slow.fast
    assert np.array_equal(fast.x_m, slow.x_m) and np.array_equal(fast.stamp_ns, slow.stamp_ns)
    bad = _pose_topic(ros1, b"w\xff\xfeorld")
    for use_fast in (True, False):
        with pytest.raises(LogReadError, match="a message cannot be decoded"):  # rosbags' SerdeError, in words
            decode_pose(bad, ros1, fast=use_fast)
    assert decode_module._utf8_strings(np.frombuffer(b"ab\xc3\xa9", dtype=np.uint8), np.array([0]),
                                       np.array([4]))


@pytest.mark.parametrize(("spec", "words"), [
    ("!" * 500 + "obs_1", "nested 500 deep"),
    ("(" * 500 + "obs_1" + ")" * 500, "nested"),
    (" & ".join(["!obs_1"] * 100_000), "characters"),
    ("F[0," + "9" * 5000 + "] mission_1", "more than 12 digits"),
])
def test_formula_limits_are_exit_3_one_line(seed_logs: dict[tuple[str, bool], Path],
                                            capsys: pytest.CaptureFixture[str], spec: str, words: str) -> None:
    start = time.perf_counter()
    code, _, err = run(["certify", str(seed_logs["mcap", False]), "--scenario", "nexus-sml", "--spec", spec], capsys)
    assert code == 3
    one_line_error(err, words)
    assert len(err) < 800 and time.perf_counter() - start < 10


def test_formula_at_the_depth_limit_is_judged(seed_logs: dict[tuple[str, bool], Path],
                                              capsys: pytest.CaptureFixture[str]) -> None:
    from tubempc.mitl.parser import MAX_DEPTH

    spec = "F[0,1] (" * (MAX_DEPTH - 1) + "mission_1" + ")" * (MAX_DEPTH - 1)
    code, _, err = run(["certify", str(seed_logs["mcap", False]), "--scenario", "nexus-sml", "--spec", spec], capsys)
    assert code == 0, err
    chain = " & ".join(["!obs_1"] * MAX_DEPTH)
    assert run(["certify", str(seed_logs["mcap", False]), "--scenario", "nexus-sml", "--spec", chain], capsys)[0] == 0


def test_output_paths(seed_logs: dict[tuple[str, bool], Path], tmp_path: Path,
                      capsys: pytest.CaptureFixture[str]) -> None:
    log = str(seed_logs["bag", False])
    base = ["certify", log, "--scenario", "nexus-sml", "--spec", SPEC]
    taken = tmp_path / "taken.txt"
    taken.write_text("keep")
    for out, words in [(str(taken), "not a folder"), (str(taken / "report"), "which is a file"),
                       ("/dev/null", "not a folder"), ("/proc/tubempc-report", "cannot create")]:
        code, _, err = run([*base, "--out", out], capsys)
        assert code == 3, (out, err)
        one_line_error(err, words)
    assert taken.read_text() == "keep"
    previous = tmp_path / "previous"
    previous.mkdir()
    (previous / "certificate.json").write_text("{}")
    code, _, err = run([*base, "--out", str(previous)], capsys)
    assert code == 3
    one_line_error(err, "exists already", "--force")
    assert (previous / "certificate.json").read_text() == "{}"
    assert run([*base, "--out", str(previous), "--force"], capsys)[0] == 0
    assert '"verdict": "pass"' in (previous / "certificate.json").read_text()
    bag_dir = seed_logs["dir", False]
    code, _, err = run(["certify", str(bag_dir), "--scenario", "nexus-sml", "--out", str(bag_dir / "r")], capsys)
    assert code == 3
    one_line_error(err, "inside the log")


def test_simulate_refuses_an_existing_log_before_simulating(tmp_path: Path,
                                                            capsys: pytest.CaptureFixture[str]) -> None:
    existing = tmp_path / "sim.mcap"
    existing.write_bytes(b"keep")
    start = time.perf_counter()
    code, _, err = run(["simulate", "--to", "R3", "--out", str(existing)], capsys)
    assert code == 3 and time.perf_counter() - start < 5
    one_line_error(err, "exists already", "--force")
    notes = tmp_path / "notes.txt"
    notes.write_bytes(b"keep")
    code, _, err = run(["simulate", "--to", "R3", "--out", str(notes), "--force"], capsys)
    assert code == 3
    one_line_error(err, "not a log file")
    assert existing.read_bytes() == notes.read_bytes() == b"keep"


def test_fifo_and_devices_are_refused_without_blocking(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    fifo = tmp_path / "pipe.bag"
    os.mkfifo(fifo)
    timer = threading.Timer(20.0, lambda: open(fifo, "wb").close())  # unblocks a reader that waits (a failure)
    timer.start()
    try:
        start = time.perf_counter()
        code, _, err = run(["certify", str(fifo), "--scenario", "nexus-sml"], capsys)
        assert code == 3 and time.perf_counter() - start < 10
        one_line_error(err, "FIFO")
    finally:
        timer.cancel()
    code, _, err = run(["certify", "/dev/zero", "--scenario", "nexus-sml"], capsys)
    assert code == 3


def test_empty_folder_and_bad_metadata_name_the_problem(tmp_path: Path, seed_logs: dict[tuple[str, bool], Path],
                                                        capsys: pytest.CaptureFixture[str]) -> None:
    empty = tmp_path / "empty"
    empty.mkdir()
    code, _, err = run(["certify", str(empty), "--scenario", "nexus-sml"], capsys)
    assert code == 3
    one_line_error(err, "holds no .bag")
    import shutil

    bag = shutil.copytree(seed_logs["dir", False], tmp_path / "bag")
    meta = bag / "metadata.yaml"
    meta.write_text(meta.read_text().replace("version:", "vers:").replace("topics_with_message_count:", "x: ["))
    code, _, err = run(["certify", str(bag), "--scenario", "nexus-sml"], capsys)
    assert code == 3
    one_line_error(err, str(bag), "sqlite3")  # named by its storage files, not "mcap"
    (bag / "metadata.yaml").write_text("rosbag2_bagfile_information: {}\n")  # KeyError('version') in rosbags
    code, _, err = run(["certify", str(bag), "--scenario", "nexus-sml"], capsys)
    assert code == 3
    one_line_error(err, str(bag), "metadata.yaml is incomplete or malformed")


def test_scenario_with_40000_regions_is_refused_fast(tmp_path: Path, seed_logs: dict[tuple[str, bool], Path],
                                                     capsys: pytest.CaptureFixture[str]) -> None:
    """Stated limits: files up to 256 KiB (40,000 regions are ~2 MB) and 2,000 regions, checked before the
    pairwise region checks."""
    from tubempc.scenario.loader import MAX_REGIONS

    base = builtin_scenario_text()
    head, tail = base[: base.index("regions:")], base[base.index("initial_region:"):]
    for name, count in [("big.yaml", 40_000), ("many.yaml", MAX_REGIONS + 1)]:
        regions = "".join(f"- {{name: Q{k}, center: [0, 0], radius: 0.01}}\n" for k in range(count))
        path = tmp_path / name
        path.write_text(head + "regions:\n" + regions + tail)
        start = time.perf_counter()
        code, _, err = run(["certify", str(seed_logs["mcap", False]), "--scenario", str(path)], capsys)
        assert code == 3 and time.perf_counter() - start < 10, err
        one_line_error(err, str(path), "bytes" if count == 40_000 else f"at most {MAX_REGIONS}")


def test_huge_coordinates_print_no_warning(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    run_ = FUZZ.base_run(violating=False)
    run_.xy[100] = (1e308, -1e308)
    path = FUZZ.write_run(run_, tmp_path / "run.mcap", "mcap")
    code, _, err = run(["certify", str(path), "--scenario", "nexus-sml", "--spec", SPEC], capsys)
    assert code == 1 and err == ""


def test_declared_message_count_guards_against_silent_loss(tmp_path: Path) -> None:
    """A reader that stops early on a damaged index would drop samples: the counts the file declares catch it."""
    from verify.errors import TruncatedLogError
    from verify.ingest.raw import _check_counts

    class Conn:
        topic = "/pose"
        msgcount = 301

    out = {"/pose": RawTopic("/pose", "geometry_msgs/msg/PoseStamped", True, [1, 2], [b"", b""])}
    with pytest.raises(TruncatedLogError, match="declares 301 messages on /pose but only 2"):
        _check_counts(tmp_path / "x.mcap", "mcap", [Conn()], out)  # type: ignore[list-item]
    Conn.msgcount = 2
    _check_counts(tmp_path / "x.mcap", "mcap", [Conn()], out)  # type: ignore[list-item]
    assert builtin_scenario().name == "nexus-sml"


def test_fault_campaign_slice(tmp_path: Path) -> None:
    """A short seeded slice of the fault campaign (every family; the full run is benchmarks/fuzz_certify.py)."""
    report = FUZZ.run_campaign(40, 20261201, root=tmp_path, timeout_s=60.0)
    assert report.cases == 40
    assert sum(v for k, v in report.exit_codes.items() if k.startswith("bytes:")) > 0
    assert (report.counts["crash"], report.counts["hang"], report.counts["false_pass"]) == (0, 0, 0), \
        report.failures


@pytest.mark.parametrize("fmt", ["mcap-zstd", "bag-lz4"])
def test_a_chunk_that_does_not_decompress_is_exit_3_or_salvaged(seed_logs: dict[tuple[str, bool], Path],
                                                                tmp_path: Path, capsys: pytest.CaptureFixture[str],
                                                                fmt: str) -> None:
    """Damage inside compressed chunks (zstd, lz4) is a log that cannot be read, never an internal error (the fault
    campaign's compressed seeds found zstd's own error escaping); --salvage stops at the damaged chunk."""
    src = seed_logs[fmt, True]
    data = src.read_bytes()
    seen = set()
    for k in range(8):
        bad = bytearray(data)
        for at in range(len(data) // 4 + k * 97, len(data) * 3 // 4, len(data) // 9):
            bad[at] ^= 0x5A
        path = tmp_path / f"bad{k}{src.suffix}"
        path.write_bytes(bytes(bad))
        for salvage in ([], ["--salvage"]):
            code, _, err = run(["certify", str(path), "--scenario", "nexus-sml", "--spec", SPEC, *salvage], capsys)
            assert code in (1, 2, 3), (code, err)  # the violating run: never a pass, never exit 70
            if code == 3:
                one_line_error(err, str(path))
            seen.add(code)
    assert 3 in seen


def test_salvage_reads_the_complete_zstd_chunks_of_a_cut_mcap(seed_logs: dict[tuple[str, bool], Path],
                                                              tmp_path: Path, capsys: pytest.CaptureFixture[str]
                                                              ) -> None:
    """A zstd-compressed MCAP cut in the middle: --salvage decompresses its complete chunks (with the zstd module
    rosbags uses) and judges them: the violating run fails on the visits before the cut, partial."""
    src = seed_logs["mcap-zstd", True]
    path = tmp_path / "cut.mcap"
    path.write_bytes(src.read_bytes()[: int(src.stat().st_size * 0.8)])
    code, _, err = run(["certify", str(path), "--scenario", "nexus-sml", "--spec", SPEC], capsys)
    assert code == 3
    code, out, err = run(["certify", str(path), "--scenario", "nexus-sml", "--spec", SPEC, "--salvage"], capsys)
    assert code == 1, (out, err)


@pytest.mark.parametrize("fmt", ["db3", "dir"])
def test_a_messages_table_without_its_id_column_is_refused_on_both_paths(tmp_path: Path, fmt: str,
                                                                         capsys: pytest.CaptureFixture[str]) -> None:
    """A sqlite3 storage whose schema text names the messages table's first column otherwise (a damaged byte in
    ``sqlite_master``): rosbags' open counts ``messages.id`` and refuses the storage; our quick open skipped that
    count and certified the log (fault campaign seed 121 case 275: exit 0 fast, 3 plain). Both refuse it now, in one
    line naming the storage file (not its metadata.yaml), and so does watch."""
    import sqlite3

    log = FUZZ.write_run(FUZZ.base_run(violating=False), tmp_path / ("run.db3" if fmt == "db3" else "run"), fmt)
    db = log if fmt == "db3" else next(log.glob("*.db3"))
    con = sqlite3.connect(db)
    try:
        con.execute("PRAGMA writable_schema = ON")
        con.execute("UPDATE sqlite_master SET sql = replace(sql, '  id INTEGER PRIMARY KEY', "
                    "'  xd INTEGER PRIMARY KEY') WHERE name = 'messages'")
        con.commit()
    finally:
        con.close()
    for cmd in ("certify", "watch"):
        code, _out, err = run([cmd, str(log), "--scenario", "nexus-sml", "--spec", SPEC], capsys)
        assert code == 3, (cmd, err)
        one_line_error(err, "id")
        assert "metadata.yaml" not in err, err
