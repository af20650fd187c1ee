"""``TUBEMPC_FAST_INGEST``: our own readers and bulk decoders (the default) and plain rosbags (``=0``) give the same
log data, the same certificates and the same errors, in every format; with ``=0`` none of our fast readers runs.
And ``detect_format`` decides a log's format as rosbags' own dispatch does."""

from __future__ import annotations

import dataclasses
import math
import shutil
from collections.abc import Callable
from pathlib import Path
from types import ModuleType
from typing import Any

import numpy as np
import pytest

from scripts import make_any_robot_logs
from tubempc.scenario import Scenario, scenario_from_dict
from verify import certify_log
from verify.errors import LogReadError, TruncatedLogError
from verify.ingest import decode as decode_mod
from verify.ingest import fields as fields_mod
from verify.ingest import raw as raw_mod
from verify.ingest.log import read_log
from verify.ingest.raw import FAST_INGEST_ENV, detect_format, fast_ingest

ROOT = Path(__file__).resolve().parents[2]
#: every entry point of our own reading: the ROS1 chunk reader, the sqlite3 open + reader, the MCAP/sqlite3 message
#: loops (which hold the message-level reads), the bulk pose / twist / field decoders
FAST_PIECES: list[tuple[ModuleType, str]] = [
    (raw_mod, "read_ros1_fast"), (raw_mod, "_read_sqlite_quick"), (raw_mod, "_read_rosbag2_fast"),
    (decode_mod, "_pose_fast"), (decode_mod, "_twist_stamped_fast"), (decode_mod, "_joined"),
    (decode_mod, "_strings_fast"),
    (fields_mod, "_bulk_field"),
]


@pytest.fixture
def fast_calls(monkeypatch: pytest.MonkeyPatch) -> list[str]:
    """Every call of a fast piece is recorded (and still runs)."""
    calls: list[str] = []
    for mod, name in FAST_PIECES:
        real = getattr(mod, name)

        def spy(*args: Any, _real: Callable[..., Any] = real, _name: str = name, **kwargs: Any) -> Any:
            calls.append(_name)
            return _real(*args, **kwargs)

        monkeypatch.setattr(mod, name, spy)
    return calls


def _norm(obj: Any) -> Any:
    """A comparable form: arrays with their dtype, NaN as a string, dataclasses as dicts."""
    if dataclasses.is_dataclass(obj) and not isinstance(obj, type):
        return {f.name: _norm(getattr(obj, f.name)) for f in dataclasses.fields(obj)}
    if isinstance(obj, np.ndarray):
        return ("array", str(obj.dtype), obj.shape, _norm(obj.tolist()))
    if isinstance(obj, dict):
        return {k: _norm(v) for k, v in obj.items()}
    if isinstance(obj, list | tuple):
        return [_norm(v) for v in obj]
    if isinstance(obj, float | np.floating) and math.isnan(obj):
        return "nan"
    if isinstance(obj, np.generic):
        return obj.item()
    return obj


def _without_path_flag(data: Any) -> Any:
    """``data_quality.pose.fast_decode`` says which decoder ran: the one field that differs by design."""
    out = _norm(data)
    quality = out["data_quality"]
    assert isinstance(quality["pose"].pop("fast_decode"), bool)
    return out


def both_ways(monkeypatch: pytest.MonkeyPatch, calls: list[str], read: Callable[[], Any]) -> tuple[Any, Any]:
    """(result with our readers, result through plain rosbags); checks which path each one took."""
    monkeypatch.delenv(FAST_INGEST_ENV, raising=False)
    assert fast_ingest()
    calls.clear()
    fast = read()
    assert calls, "the default must use our own readers"
    monkeypatch.setenv(FAST_INGEST_ENV, "0")
    assert not fast_ingest()
    calls.clear()
    plain = read()
    assert calls == [], f"TUBEMPC_FAST_INGEST=0 still ran {sorted(set(calls))}"
    return fast, plain


@pytest.mark.parametrize("fmt", ["bag", "mcap", "db3", "dir-mcap", "dir-sqlite3"])
@pytest.mark.parametrize("pose_type", ["PoseStamped", "Odometry", "TF"])
def test_log_data_is_identical_both_ways(make_log: Callable[..., Path], paper_traj: Callable[..., Any], *,
                                         scenario: Scenario, monkeypatch: pytest.MonkeyPatch,
                                         fast_calls: list[str], fmt: str, pose_type: str) -> None:
    traj = paper_traj(scenario, end_s=30.0)
    scenario = scenario.model_copy(update={"topics": scenario.topics.model_copy(update={"tf_child_frame": "nexus"})})
    path = make_log(fmt, traj, pose_type=pose_type, scenario=scenario)
    fast, plain = both_ways(monkeypatch, fast_calls, lambda: read_log(path, scenario))
    assert fast.pose.t_ns.size == traj.t_s.size
    assert _without_path_flag(fast) == _without_path_flag(plain)


def _lab() -> Scenario:
    return scenario_from_dict({
        "name": "lab", "workspace": {"x": [0.0, 5.0], "y": [0.0, 4.0]}, "robot": {"radius": 0.25},
        "inputs": {"model": "unicycle", "max_abs": [0.5, 1.0]},
        "regions": [{"name": "dock", "center": [4.4, 3.3], "radius": 0.45, "labels": ["dock"]}],
        "signals": {"slow": {"topic": "/odom", "field": "twist.twist.linear.x", "op": "<=", "value": 0.5},
                    "charged": {"topic": "/battery_state", "field": "percentage", "op": ">=", "value": 0.2}},
        "spec": "G[0,inf) (slow & charged) & F[0,40] dock",
        "topics": {"pose": "/odom", "cmd_vel": "/cmd_vel"},
    }, source="lab.yaml")


@pytest.mark.parametrize("suffix", [".bag", ".mcap"])
def test_stamped_commands_and_signal_atoms_identical_both_ways(tmp_path: Path, monkeypatch: pytest.MonkeyPatch,
                                                               fast_calls: list[str], suffix: str) -> None:
    kit = make_any_robot_logs
    ros1 = suffix == ".bag"
    run = kit.unicycle_run([(0.5, 0.5), (3.4, 0.5), (3.4, 2.5), (4.4, 3.3)], v_mps=0.4, w_radps=0.8, rate_hz=50.0)
    msgs = (kit.odometry_messages(run, "/odom", ros1=ros1)
            + kit.command_messages(run, "/cmd_vel", ros1=ros1, stamped=True)
            + kit.battery_messages([0.0, 10.0, 20.0, 30.0], [0.9, 0.8, 0.7, 0.6], "/battery_state", ros1=ros1))
    path = kit.write_messages(tmp_path / f"cmd{suffix}", msgs)
    lab = _lab()
    fast, plain = both_ways(monkeypatch, fast_calls, lambda: read_log(path, lab))
    assert fast.cmd_u is not None and set(fast.signals) == {"slow", "charged"}
    assert _without_path_flag(fast) == _without_path_flag(plain)
    fast_cert, plain_cert = both_ways(monkeypatch, fast_calls, lambda: certify_log(path, lab).certificate)
    assert fast_cert["verdict"] == "pass"
    assert _without_path_flag(fast_cert) == _without_path_flag(plain_cert)


@pytest.mark.parametrize(("name", "scenario_file"), [("late_mission.mcap", None), ("obstacle_touch.bag", None),
                                                     ("diffdrive_odom.bag", "docs/examples/diffdrive-room.yaml")])
def test_example_certificates_identical_both_ways(monkeypatch: pytest.MonkeyPatch, fast_calls: list[str], name: str,
                                                  scenario_file: str | None) -> None:
    scenario = str(ROOT / scenario_file) if scenario_file else "nexus-sml"
    fast, plain = both_ways(monkeypatch, fast_calls, lambda: certify_log(ROOT / "logs" / name, scenario).certificate)
    assert fast["verdict"] in ("pass", "fail")
    assert _without_path_flag(fast) == _without_path_flag(plain)


def _error_both_ways(monkeypatch: pytest.MonkeyPatch, read: Callable[[], Any]) -> tuple[Any, Any]:
    got = []
    for value in ("1", "0"):
        monkeypatch.setenv(FAST_INGEST_ENV, value)
        with pytest.raises(LogReadError) as err:
            read()
        got.append((type(err.value), str(err.value)))
    return got[0], got[1]


@pytest.mark.parametrize("fmt", ["bag", "mcap", "db3"])
def test_damaged_logs_fail_alike_both_ways(make_log: Callable[..., Path], paper_traj: Callable[..., Any], *,
                                           scenario: Scenario, monkeypatch: pytest.MonkeyPatch,
                                           tmp_path: Path, fmt: str) -> None:
    path = make_log(fmt, paper_traj(scenario, end_s=20.0))
    cut = tmp_path / f"cut{path.suffix}"
    data = path.read_bytes()
    cut.write_bytes(data[: len(data) * 2 // 3])
    fast, plain = _error_both_ways(monkeypatch, lambda: read_log(cut, scenario))
    assert fast == plain
    assert issubclass(fast[0], LogReadError) and str(cut) in fast[1]
    if fmt != "db3":  # --salvage reads the complete records of ROS1 and MCAP logs (our stream walk, both ways)
        assert fast[0] is TruncatedLogError
        salvaged = []
        for value in ("1", "0"):
            monkeypatch.setenv(FAST_INGEST_ENV, value)
            salvaged.append(_without_path_flag(read_log(cut, scenario, salvage=True)))
        assert salvaged[0] == salvaged[1] and salvaged[0]["partial"] is True


@pytest.mark.parametrize(("value", "on"), [("0", False), ("false", False), ("Off", False), ("no", False),
                                           ("1", True), ("", True), ("yes", True)])
def test_switch_values(monkeypatch: pytest.MonkeyPatch, value: str, on: bool) -> None:
    monkeypatch.setenv(FAST_INGEST_ENV, value)
    assert fast_ingest() is on


# ---- detect_format: rosbags' dispatch ------------------------------------------------------------------------------
def _set_storage(bag: Path, storage_id: str) -> None:
    meta = bag / "metadata.yaml"
    text = meta.read_text(encoding="utf-8")
    old = next(line for line in text.splitlines() if "storage_identifier:" in line)
    meta.write_text(text.replace(old, old.split(":")[0] + f": {storage_id}"), encoding="utf-8")


def test_detect_format_follows_rosbags(make_log: Callable[..., Path], paper_traj: Callable[..., Any],
                                       scenario: Scenario, tmp_path: Path) -> None:
    traj = paper_traj(scenario, end_s=5.0)
    mcap_dir, sqlite_dir = make_log("dir-mcap", traj), make_log("dir-sqlite3", traj)
    assert (detect_format(mcap_dir), detect_format(sqlite_dir)) == ("mcap", "sqlite3")
    # the metadata's storage_identifier decides, as in rosbags' DirectoryReader, even against the files' names
    odd = shutil.copytree(mcap_dir, tmp_path / "odd")
    (odd / "notes.db3").write_bytes(b"")
    assert detect_format(odd) == "mcap"
    _set_storage(odd, "sqlite3")
    assert detect_format(odd) == "sqlite3"
    _set_storage(odd, "rosbag_v2_fancy")
    with pytest.raises(LogReadError, match=r"storage plugin 'rosbag_v2_fancy'; rosbags reads mcap and sqlite3"):
        detect_format(odd)
    # a metadata.yaml that cannot say: the storage files name the format
    (odd / "metadata.yaml").write_text("rosbag2_bagfile_information: [", encoding="utf-8")
    (odd / "notes.db3").unlink()
    assert detect_format(odd) == "mcap"
    shutil.copy(sqlite_dir / "metadata.yaml", odd / "metadata.yaml")
    for p in odd.iterdir():
        if p.suffix == ".mcap":
            p.rename(p.with_suffix(".db3"))
    (odd / "metadata.yaml").write_text("{}", encoding="utf-8")
    assert detect_format(odd) == "sqlite3"
    # bare files: rosbags' suffix table (exact), .bag in any case (rosbags' ROS1 reader opens any name)
    assert [detect_format(tmp_path / n) for n in ("a.bag", "a.BAG", "a.mcap", "a.db3")] == \
        ["ros1", "ros1", "mcap", "sqlite3"]
    with pytest.raises(LogReadError, match=r"'\.MCAP': rosbags recognizes '\.mcap' in lower case only"):
        detect_format(tmp_path / "a.MCAP")
    with pytest.raises(LogReadError, match=r"unrecognized log type '\.txt': expected \.bag, \.db3, \.mcap"):
        detect_format(tmp_path / "a.txt")
    empty = tmp_path / "empty"
    empty.mkdir()
    with pytest.raises(LogReadError, match=r"without metadata\.yaml"):
        detect_format(empty)


def test_unknown_storage_plugin_is_one_line_exit_3(make_log: Callable[..., Path], paper_traj: Callable[..., Any],
                                                   scenario: Scenario, tmp_path: Path,
                                                   capsys: pytest.CaptureFixture[str]) -> None:
    from tubempc.cli import main

    bag = make_log("dir-mcap", paper_traj(scenario, end_s=5.0))
    _set_storage(bag, "rosbag_v2_fancy")
    with pytest.raises(SystemExit) as exc:
        main(["certify", str(bag), "--scenario", "nexus-sml", "--out", str(tmp_path / "out")])
    err = capsys.readouterr().err.strip()
    assert exc.value.code == 3
    assert len(err.splitlines()) == 1 and str(bag) in err and "rosbag_v2_fancy" in err, err


@pytest.mark.parametrize("ros1", [True, False])
def test_string_decoder_agrees_with_rosbags_on_every_damage(monkeypatch: pytest.MonkeyPatch, ros1: bool) -> None:
    """The bulk std_msgs/String decoder (solver status, run metadata) gives exactly rosbags' texts, and a topic with
    one message rosbags refuses (cut, no NUL, bad UTF-8, bytes after the string) goes to the per-message path,
    which skips only that message."""
    from rosbags.typesys import Stores, get_typestore

    from verify.ingest.raw import RawTopic

    store = get_typestore(Stores.ROS1_NOETIC if ros1 else Stores.ROS2_HUMBLE)
    cls = store.types["std_msgs/msg/String"]
    ser = store.serialize_ros1 if ros1 else store.serialize_cdr
    texts = ['{"success": true, "k": 1}', "", "é ✓", '{"success": false}' * 7]
    good = [bytes(ser(cls(data=t), "std_msgs/msg/String")) for t in texts]
    whole = RawTopic("/status", "std_msgs/msg/String", True, list(range(len(good))), good)
    fast = decode_mod.decode_strings(whole, ros1, fast=True)
    assert fast == decode_mod.decode_strings(whole, ros1, fast=False) == list(enumerate(texts))
    body = 4 if ros1 else 8  # the string's first byte
    damaged = {
        "cut": good[0][:-3],
        "bad utf-8": good[2][:body] + b"\xff" + good[2][body + 1:],
        "trailing bytes": good[0] + b"\x00" * 5,
        "no nul": good[0][:-1] + b"x" if not ros1 else good[0] + b"\x01",
        "length past the end": good[0][:body - 4] + (10**6).to_bytes(4, "little") + good[0][body:],
    }
    declined: list[bool] = []
    real = decode_mod._strings_fast

    def spy(raw: Any, r1: bool) -> Any:
        got = real(raw, r1)
        declined.append(got is None)
        return got

    monkeypatch.setattr(decode_mod, "_strings_fast", spy)
    for what, payload in damaged.items():
        topic = RawTopic("/status", "std_msgs/msg/String", True, list(range(len(good) + 1)), [*good, payload])
        declined.clear()
        fast = decode_mod.decode_strings(topic, ros1, fast=True)
        assert declined == [True], what  # the bulk decoder declined the topic
        assert fast == decode_mod.decode_strings(topic, ros1, fast=False), what
