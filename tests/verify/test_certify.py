"""certify_log on generated logs: every format and pose type, each verdict, each data-quality fault, the CLI."""

from __future__ import annotations

import dataclasses
import hashlib
import json
import pickle
import re
import subprocess
import sys
from collections.abc import Callable
from pathlib import Path
from typing import Any

import blake3
import jsonschema
import numpy as np
import pytest

from tubempc.scenario import Scenario
from verify import (
    LogReadError,
    MissingTopicError,
    SpecError,
    TruncatedLogError,
    UnusableInputError,
    certify_log,
    write_certificate,
)
from verify.certificate import certify_json_schema
from verify.ingest.log import log_digest

MakeLog = Callable[..., Path]
TIME0_NS = 1_767_225_600 * 10**9  # the log contract's time 0 of simulated runs (conftest writes it)


def _check(cert: dict, name: str) -> dict:
    return next(c for c in cert["checks"] if c["name"] == name)


@pytest.fixture
def good(scenario: Scenario, paper_traj: Callable[..., Any]) -> Any:
    return paper_traj(scenario, rate_hz=10.0)


@pytest.mark.parametrize("fmt", ["bag", "mcap", "db3", "dir-mcap", "dir-sqlite3"])
@pytest.mark.parametrize("pose_type", ["PoseStamped", "Odometry", "TF"])
def test_every_format_and_pose_type_passes(make_log: MakeLog, scenario: Scenario, good: Any, fmt: str,
                                           pose_type: str) -> None:
    sc = scenario.model_copy(update={"topics": scenario.topics.model_copy(update={"tf_child_frame": "nexus"})})
    log = make_log(fmt, good, pose_type=pose_type, scenario=sc)
    res = certify_log(log, sc)
    cert = res.certificate
    assert cert["verdict"] == "pass", cert["checks"]
    assert res.exit_code == 0
    assert [e["region"] for e in cert["timed_run"]] == ["R1", "R3", "R1"]
    assert cert["data_quality"]["pose"]["fast_decode"] is (pose_type != "TF")
    assert list(res.trajectory.columns) == ["t_s", "x_m", "y_m", "theta_rad"]
    assert res.trajectory["x_m"].to_numpy() == pytest.approx(good.x, abs=1e-12)
    assert cert["log_digest_algorithm"] == "blake3-messages" and "log_sha256" not in cert
    assert cert["log_digest"] == log_digest(log, sc).hex and cert["scenario_sha256"] == sc.sha256()


@pytest.mark.parametrize("fmt", ["bag", "dir-mcap"])
def test_log_digest_of_the_file_on_request(make_log: MakeLog, scenario: Scenario, good: Any, fmt: str) -> None:
    """``digest="blake3"`` / ``"sha256"``: the hash of the log's bytes, named (``b3sum``'s / ``sha256sum``'s value
    for a file; SHA-256 also kept as ``log_sha256``); a bag directory hashes every file's name and bytes."""
    log = Path(make_log(fmt, good))
    files = sorted(f for f in log.rglob("*") if f.is_file()) if log.is_dir() else [log]
    b3, sha = blake3.blake3(), hashlib.sha256()
    for f in files:
        if log.is_dir():
            b3.update(str(f.relative_to(log)).encode() + b"\0")
            sha.update(str(f.relative_to(log)).encode() + b"\0")
        b3.update(f.read_bytes())
        sha.update(f.read_bytes())
    cert = certify_log(log, scenario, digest="blake3").certificate
    assert (cert["log_digest_algorithm"], cert["log_digest"]) == ("blake3", b3.hexdigest())
    cert256 = certify_log(log, scenario, digest="sha256").certificate
    assert (cert256["log_digest_algorithm"], cert256["log_digest"]) == ("sha256", sha.hexdigest())
    assert cert256["log_sha256"] == sha.hexdigest()
    default = certify_log(log, scenario).certificate
    for other in (cert, cert256):
        assert {k: v for k, v in other.items() if not k.startswith("log_")} == \
            {k: v for k, v in default.items() if not k.startswith("log_")}
    with pytest.raises(UnusableInputError, match="digest"):
        certify_log(log, scenario, digest="md5")


def test_messages_digest_is_of_the_judged_messages(make_log: MakeLog, scenario: Scenario, good: Any,
                                                   monkeypatch: pytest.MonkeyPatch) -> None:
    """The default digest hashes the messages read, not the container: the same run stored as MCAP or sqlite3 has
    one digest, read by our readers or by plain rosbags; a ROS1 bag (other serialization) and another run differ;
    ``tubempc digest`` prints the certificate's value."""
    logs = {fmt: Path(make_log(fmt, good)) for fmt in ("dir-mcap", "dir-sqlite3", "mcap", "bag")}
    certs = {fmt: certify_log(log, scenario).certificate for fmt, log in logs.items()}
    assert {c["log_digest_algorithm"] for c in certs.values()} == {"blake3-messages"}
    assert certs["dir-mcap"]["log_digest"] == certs["dir-sqlite3"]["log_digest"] == certs["mcap"]["log_digest"]
    assert certs["bag"]["log_digest"] != certs["mcap"]["log_digest"]
    monkeypatch.setenv("TUBEMPC_FAST_INGEST", "0")
    for fmt, log in logs.items():
        assert log_digest(log, scenario).hex == certs[fmt]["log_digest"], fmt
    monkeypatch.delenv("TUBEMPC_FAST_INGEST")
    moved = dataclasses.replace(good, x=good.x + 1e-6)
    assert certify_log(make_log("mcap", moved), scenario).certificate["log_digest"] != certs["mcap"]["log_digest"]
    def run(*args: str) -> subprocess.CompletedProcess[str]:
        return subprocess.run([sys.executable, "-m", "tubempc", "digest", *args], capture_output=True, text=True,
                              check=False, timeout=120)

    out = run(str(logs["mcap"]), "--scenario", "nexus-sml")
    assert out.returncode == 0 and out.stdout.split() == [certs["mcap"]["log_digest"], "blake3-messages",
                                                          str(logs["mcap"])]
    cut = logs["mcap"].with_name("cut.mcap")
    cut.write_bytes(logs["mcap"].read_bytes()[:-200])
    bad = run(str(cut), "--scenario", "nexus-sml")
    assert bad.returncode == 3 and str(cut) in bad.stderr and "Traceback" not in bad.stderr


def test_result_pickles_and_certificate_is_json(make_log: MakeLog, scenario: Scenario, good: Any,
                                                tmp_path: Path) -> None:
    res = certify_log(make_log("mcap", good), scenario)
    again = pickle.loads(pickle.dumps(res))
    assert again.certificate == res.certificate
    path = write_certificate(res, tmp_path / "out")
    assert json.loads(path.read_text())["verdict"] == "pass"
    assert set(res.robustness.columns) == {"t_s", "rho_m"}
    assert set(res.inputs.columns) == {"t_s", "u1", "u2", "u3"}


def test_obstacle_violation_fails_with_evidence(traj_cls: Any, make_log: MakeLog,
                                                scenario: Scenario, good: Any) -> None:
    r6 = scenario.region("R6")
    x, y = good.x.copy(), good.y.copy()
    k = 300  # 30 s: put one sample inside obstacle R6
    x[k], y[k] = r6.center
    bad = traj_cls(good.t_s, x, y, good.theta, nominal=good.nominal, cmd=good.cmd)
    res = certify_log(make_log("bag", bad), scenario)
    cert = res.certificate
    assert cert["verdict"] == "fail" and res.exit_code == 1
    spec = _check(cert, "spec_trajectory")
    assert spec["verdict"] == "fail" and spec["first_violation_time"] == pytest.approx(30.0)
    assert "obs" in spec["subformula"]
    assert _check(cert, "obstacle_clearance")["region"] == "R6"
    assert _check(cert, "tube")["verdict"] == "fail"  # the nominal stayed on the planned path


def test_missing_nominal_makes_tube_inconclusive(traj_cls: Any, make_log: MakeLog,
                                                 scenario: Scenario, good: Any) -> None:
    traj = traj_cls(good.t_s, good.x, good.y, good.theta, nominal=None, cmd=good.cmd)
    cert = certify_log(make_log("mcap", traj), scenario).certificate
    assert _check(cert, "tube")["verdict"] == "inconclusive"
    assert cert["verdict"] == "inconclusive"
    assert "tube" in cert["verdict_reason"]


def test_input_box_violation(traj_cls: Any, make_log: MakeLog, scenario: Scenario, good: Any) -> None:
    cmd = good.cmd.copy()
    cmd[50, 1] = 0.25
    traj = traj_cls(good.t_s, good.x, good.y, good.theta, nominal=good.nominal, cmd=cmd)
    cert = certify_log(make_log("db3", traj), scenario).certificate
    box = _check(cert, "input_box")
    assert box["verdict"] == "fail" and box["first_violation_time"] == pytest.approx(5.0)
    assert box["margin"] == pytest.approx(-0.05)


def test_log_ending_inside_a_window_is_inconclusive(make_log: MakeLog, scenario: Scenario,
                                                      paper_traj: Callable[..., Any]) -> None:
    short = paper_traj(scenario, rate_hz=10.0, end_s=60.0)
    cert = certify_log(make_log("mcap", short), scenario).certificate
    spec = _check(cert, "spec_trajectory")
    assert spec["verdict"] == "inconclusive" and "mission_1" in spec["subformula"]
    assert certify_log(make_log("mcap", short), scenario, spec="F[30,50] mission_2").certificate["verdict"] == \
        "pass"


def test_data_quality_faults_are_reported(traj_cls: Any, make_log: MakeLog, scenario: Scenario, good: Any) -> None:
    x, theta = good.x.copy(), good.theta.copy()
    x[400] = np.nan
    theta[10] = np.nan  # NaN quaternion
    x[700] += 0.5  # a jump faster than the robot can move
    t = good.t_s.copy()
    keep = (t < 20.0) | (t > 21.0)  # a dropout: samples 19.9 s and 21.1 s are neighbours
    traj = traj_cls(t[keep], x[keep], good.y[keep], theta[keep], nominal=None, cmd=None)
    extra = [(5.0, float(good.x[50]), float(good.y[50]), 0.0)]  # a duplicate stamp, written out of order
    log = make_log("bag", traj, extra_pose=extra, header_offset_ns=-2_000_000)
    cert = certify_log(log, scenario).certificate
    dq = cert["data_quality"]["pose"]
    assert dq["nan_positions"] == 1 and dq["first_nan_s"] == pytest.approx(40.0)
    assert dq["bad_quaternions"] == 1
    assert dq["jumps"]["count"] >= 1
    assert dq["dropouts"]["count"] == 1 and dq["dropouts"]["longest_gap_s"] == pytest.approx(1.2)
    # the late message's stamp (5 s) lies 95 s from its neighbours in reading order: an outlier, re-timed from its
    # log time, counted, and still judged (no sample is dropped)
    assert dq["retimed_stamps"] == 1 and dq["out_of_order_stamps"] == 0
    assert dq["read"] == dq["judged"] == len(traj.t_s) + 1
    # the headers run 2 ms behind the log time: header - log = -0.002 s
    assert dq["header_vs_log_offset_s"]["median"] == pytest.approx(-0.002)
    assert cert["verdict"] != "pass"


def test_stamps_near_1970_and_log_time_base(make_log: MakeLog, scenario: Scenario, good: Any) -> None:
    log = make_log("mcap", good, time0_ns=5 * 10**9)
    cert = certify_log(log, scenario, time_base="log").certificate
    assert cert["data_quality"]["pose"]["stamps_near_1970"] == len(good.t_s)
    assert cert["time_base"] == "log" and cert["time0_ns"] == 5 * 10**9
    custom = certify_log(log, scenario, time0_ns=5 * 10**9 - 10**9).certificate
    assert custom["timed_run"][0]["time"] == pytest.approx(1.0)


def test_wal_file_and_missing_definition(make_log: MakeLog, scenario: Scenario, good: Any) -> None:
    log = make_log("db3", good)
    wal = log.with_name(log.name + "-wal")
    wal.write_bytes(b"\0" * 128)
    before = log.read_bytes()
    cert = certify_log(log, scenario).certificate
    assert any("-wal" in n for n in cert["data_quality"]["notes"])
    assert log.read_bytes() == before and wal.read_bytes() == b"\0" * 128  # inputs never modified
    nodef = make_log("dir-mcap", good, omit_definition=True)
    cert2 = certify_log(nodef, scenario).certificate
    assert any(scenario.topics.pose in m for m in cert2["data_quality"]["missing_definitions"])
    assert cert2["verdict"] == "pass"


@pytest.mark.parametrize("fmt", ["bag", "mcap"])
def test_truncated_log_exit3_and_salvage_partial(make_log: MakeLog, scenario: Scenario, good: Any,
                                                 fmt: str) -> None:
    log = make_log(fmt, good)
    data = log.read_bytes()
    cut = log.with_name("cut" + log.suffix)
    cut.write_bytes(data[: len(data) * 2 // 3])
    with pytest.raises(TruncatedLogError, match=str(cut.name)):
        certify_log(cut, scenario)
    res = certify_log(cut, scenario, salvage=True)
    cert = res.certificate
    assert cert["partial"] is True and cert["verdict"] != "pass"
    assert 0 < len(res.trajectory) < len(good.t_s)


def test_unusable_inputs(traj_cls: Any, make_log: MakeLog, scenario: Scenario, good: Any, tmp_path: Path) -> None:
    traj = traj_cls(good.t_s, good.x, good.y, good.theta)
    log = make_log("mcap", traj)
    with pytest.raises(MissingTopicError, match="/nope"):
        certify_log(log, scenario.model_copy(update={"topics": scenario.topics.model_copy(
            update={"pose": "/nope"})}))
    with pytest.raises(SpecError):
        certify_log(log, scenario, spec="F[0,1] unknown_label")
    junk = tmp_path / "junk.bag"
    junk.write_bytes(b"not a bag at all")
    with pytest.raises(LogReadError, match=r"junk\.bag"):
        certify_log(junk, scenario)


def test_cli_exit_codes_and_out_folders(traj_cls: Any, make_log: MakeLog, scenario: Scenario, good: Any,
                                        tmp_path: Path) -> None:
    ok = make_log("mcap", good)
    nonom = make_log("bag", traj_cls(good.t_s, good.x, good.y, good.theta, nominal=None, cmd=good.cmd))
    out = tmp_path / "out"

    def run(*args: str) -> subprocess.CompletedProcess[str]:
        return subprocess.run([sys.executable, "-m", "tubempc", "certify", *args], capture_output=True, text=True,
                              check=False)

    r = run(str(ok), "--scenario", "nexus-sml", "--out", str(out))
    assert r.returncode == 0, r.stderr
    assert json.loads((out / "certificate.json").read_text())["verdict"] == "pass"
    r = run(str(ok), str(nonom), "--scenario", "nexus-sml", "--out", str(out / "many"), "--digest", "sha256")
    assert r.returncode == 2, r.stdout + r.stderr
    many = sorted((out / "many").glob("*/certificate.json"))
    assert len(many) == 2
    assert {json.loads(c.read_text())["log_digest_algorithm"] for c in many} == {"sha256"}
    r = run(str(tmp_path / "missing.mcap"), "--scenario", "nexus-sml")
    assert r.returncode == 3 and r.stderr.count("\n") == 1 and "missing.mcap" in r.stderr
    r = run(str(ok), "--scenario", "nexus-sml", "--spec", "F[0,10] obs_1")
    assert r.returncode == 1


def test_time0_default_is_first_pose(make_log: MakeLog, scenario: Scenario, good: Any) -> None:
    cert = certify_log(make_log("dir-sqlite3", good), scenario).certificate
    assert cert["time0_ns"] == TIME0_NS


def test_cli_json_quiet_verbose_and_time_precision(make_log: MakeLog, good: Any) -> None:
    ok = make_log("mcap", good)

    def run(*args: str) -> subprocess.CompletedProcess[str]:
        return subprocess.run([sys.executable, "-m", "tubempc", *args], capture_output=True, text=True, check=False,
                              timeout=120)

    one = run("certify", str(ok), "--scenario", "nexus-sml", "--json")
    assert one.returncode == 0
    assert json.loads(one.stdout)["verdict"] == "pass"  # stdout is the certificate alone
    assert one.stderr.startswith(f"{ok}: pass")  # the summary went to stderr
    many = run("-q", "certify", str(ok), str(ok.parent / "missing.mcap"), "--scenario", "nexus-sml", "--json")
    entries = json.loads(many.stdout)
    assert [e["verdict"] for e in entries] == ["pass", "unusable"]
    # -q silences the summary, never an error line
    assert many.stderr.splitlines() == [f"tubempc: error: {ok.parent / 'missing.mcap'}: file not found"]
    jsonschema.validate(entries, certify_json_schema())
    jsonschema.validate(json.loads(one.stdout), certify_json_schema())
    assert entries[1]["exit_code"] == 3 and "missing.mcap" in entries[1]["error"]
    fail = run("certify", str(ok), "--scenario", "nexus-sml", "--spec", "F[0,10] obs_1", "-v")
    assert fail.returncode == 1
    assert re.search(r"spec_trajectory: fail at t=\d+\.\d\d s", fail.stdout), fail.stdout  # 2 decimals, not 9
    assert "obstacle_clearance: pass, margin" in fail.stderr  # -v lists every check
    assert run("certify", "-q", str(ok), "--scenario", "nexus-sml").stdout == ""


@pytest.mark.parametrize("spec", ["F[0,10] mission_2", "G[0,5] mission_2", "mission_1 U[0,5] mission_2",
                                  "G[0,inf) !obs_1 & F[2,3] obs_1"])
def test_a_failed_formula_always_states_its_margin(make_log: MakeLog, scenario: Scenario, good: Any,
                                                   spec: str) -> None:
    cert = certify_log(make_log("mcap", good), scenario, spec=spec).certificate
    check = _check(cert, "spec_trajectory")
    assert check["verdict"] == "fail"
    assert isinstance(check["margin"], float) and check["margin"] < 0


@pytest.mark.parametrize("log", ["late_mission.mcap", "obstacle_touch.bag", "tube_breach.mcap"])
def test_every_failed_check_states_time_margin_and_unit(log: str, scenario: Scenario) -> None:
    cert = certify_log(Path(__file__).resolve().parents[2] / "logs" / log, scenario).certificate
    failed = [c for c in cert["checks"] if c["verdict"] == "fail"]
    assert failed
    for check in failed:
        assert isinstance(check["first_violation_time"], float), check
        assert isinstance(check["margin"], float) and check["margin"] <= 0, check
        assert check["margin_unit"] in ("m", "s", "m/s", "rad/s"), check  # one unit: the margin's own
    for check in cert["checks"]:
        assert "margin_unit" in check


def test_missed_window_margin_is_how_late_in_seconds() -> None:
    from verify.semantics.timed_run import check_timed_run

    labels = {"R1": ["mission_1"], "R3": ["mission_2"], "R8": ["obs_3"]}
    late = check_timed_run("F[30,50] mission_2", [("R1", 0.0), ("R3", 56.0)], labels, end=60.0)
    assert (late.verdict, late.time_s, late.margin_s) == ("fail", 50.0, pytest.approx(-6.0))
    never = check_timed_run("F[30,50] mission_2", [("R1", 0.0)], labels, end=60.0)
    assert never.margin_s == pytest.approx(-10.0)  # not reached by the log's end: at least 10 s late
    touch = check_timed_run("G[0,inf) !obs_3", [("R1", 0.0), ("R8", 6.5), ("R1", 9.0)], labels, end=20.0)
    assert (touch.time_s, touch.margin_s) == (6.5, pytest.approx(-2.5))  # inside the obstacle for 2.5 s
