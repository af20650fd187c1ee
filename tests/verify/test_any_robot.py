"""Certifying a robot that is not the Nexus: a differential-drive base that logs only nav_msgs/Odometry.

The scenario names only the pose topic: the tube and input checks are *not selected* (listed under ``not_checked``
with the reason) and the verdict is over the selected checks, so such a log can pass. Check selection from the
scenario and the command line; unknown or unsupported selections are exit 3.
"""

from __future__ import annotations

import importlib.util
import json
import subprocess
import sys
from pathlib import Path
from types import ModuleType
from typing import Any

import numpy as np
import pytest

from tubempc.scenario import Scenario, scenario_from_dict
from verify import certify_log
from verify.errors import ScenarioInputError

ROOT = Path(__file__).resolve().parents[2]


def _kit() -> ModuleType:
    spec = importlib.util.spec_from_file_location("any_robot_logs", ROOT / "scripts" / "make_any_robot_logs.py")
    assert spec is not None and spec.loader is not None
    mod = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(mod)
    return mod


KIT = _kit()
TABLE = (2.5, 1.5)  # centre of the obstacle (a disc of radius 0.4)


def lab(**extra: Any) -> Scenario:
    data: dict[str, Any] = {
        "name": "diffdrive-lab",
        "workspace": {"x": [0.0, 5.0], "y": [0.0, 4.0]},
        "robot": {"radius": 0.25},
        "inputs": {"model": "unicycle", "max_abs": [0.5, 1.0]},
        "regions": [
            {"name": "start", "center": [0.5, 0.5], "radius": 0.45, "labels": ["home"]},
            {"name": "dock", "center": [4.4, 3.3], "radius": 0.45, "labels": ["dock"]},
            {"name": "table", "center": list(TABLE), "radius": 0.4, "labels": ["table"], "unsafe": True},
        ],
        "spec": "G[0,inf) !table & F[0,40] dock",
        "topics": {"pose": "/odom"},
        **extra,
    }
    return scenario_from_dict(data, source="lab.yaml")


def _run(x_leg: float) -> Any:
    return KIT.unicycle_run([(0.5, 0.5), (x_leg, 0.5), (x_leg, 2.5), (4.4, 3.3)], v_mps=0.4, w_radps=0.8,
                            rate_hz=50.0, pauses={3: 3.0})


def _log(tmp_path: Path, run: Any, suffix: str = ".bag") -> Path:
    path = tmp_path / f"odom{suffix}"
    return KIT.write_messages(path, KIT.odometry_messages(run, "/odom", ros1=suffix == ".bag"))


def _check(cert: dict[str, Any], name: str) -> dict[str, Any]:
    return next(c for c in cert["checks"] if c["name"] == name)


@pytest.mark.parametrize("suffix", [".bag", ".mcap"])
def test_odometry_only_log_passes_over_the_selected_checks(tmp_path: Path, suffix: str) -> None:
    res = certify_log(_log(tmp_path, _run(3.4), suffix), lab())
    cert = res.certificate
    assert cert["verdict"] == "pass", cert["checks"]
    assert res.exit_code == 0
    assert cert["checks_selected"] == ["spec", "obstacle_clearance", "workspace"]
    assert {c["name"]: c["reason"] for c in cert["not_checked"]} == {
        "tube": "not selected: the scenario names no nominal-state topic (topics.nominal)",
        "input_box": "not selected: the scenario names no command topic (topics.cmd_vel)"}
    assert [c["name"] for c in cert["checks"]] == ["spec_trajectory", "spec_timed_run", "workspace",
                                                    "obstacle_clearance"]
    assert [e["region"] for e in cert["timed_run"]] == ["start", "dock"]
    # the leg along x = 3.4 passes the table (radius 0.4) at 0.9 m: clearance 0.9 - 0.4 - 0.25 = 0.25 m
    clear = _check(cert, "obstacle_clearance")
    assert clear["sample_margin_m"] == pytest.approx(0.25, abs=1e-9)
    # guaranteed between samples: the robot moves at most v_max * dt = 0.5 * 0.02 = 0.01 m, so >= 0.25 - 0.005
    assert 0.245 - 1e-9 <= clear["margin"] < 0.25
    assert cert["pose_source"]["type"] == "nav_msgs/msg/Odometry"
    assert cert["speed_bound_mps"] == 0.5  # the unicycle's v bound, not hypot(v, w)


def test_odometry_only_log_fails_with_the_right_time_and_margin(tmp_path: Path) -> None:
    run = _run(3.0)  # the leg along x = 3.0 cuts the table's corner: 0.5 m from its centre
    res = certify_log(_log(tmp_path, run), lab())
    cert = res.certificate
    assert cert["verdict"] == "fail" and res.exit_code == 1
    clear = _check(cert, "obstacle_clearance")
    # oracle: the first sample whose disc (radius 0.25) intersects the table disc (radius 0.4)
    d = np.hypot(run.x - TABLE[0], run.y - TABLE[1]) - 0.65
    k = int(np.argmax(d < 0))
    assert clear["first_violation_time"] == pytest.approx(run.t_s[k], abs=1e-9)
    assert clear["margin"] == pytest.approx(float(d.min()), abs=1e-9)
    assert clear["margin"] == pytest.approx(-0.15, abs=1e-6)
    assert clear["region"] == "table"
    spec = _check(cert, "spec_trajectory")
    assert spec["verdict"] == "fail" and spec["first_violation_time"] <= clear["first_violation_time"] + 1e-9


def test_checks_from_the_scenario_and_the_command_line(tmp_path: Path) -> None:
    log = _log(tmp_path, _run(3.0))
    only_ws = certify_log(log, lab(checks=["workspace"]))
    assert only_ws.certificate["verdict"] == "pass"  # the table is hit, but only the workspace was asked for
    assert only_ws.certificate["checks_source"] == "scenario checks"
    assert [c["name"] for c in only_ws.certificate["checks"]] == ["workspace"]
    assert {c["name"] for c in only_ws.certificate["not_checked"]} == {"spec", "obstacle_clearance", "tube",
                                                                        "input_box"}
    cli = certify_log(log, lab(checks=["workspace"]), checks=["obstacle_clearance"])
    assert cli.certificate["verdict"] == "fail" and cli.certificate["checks_source"] == "--checks"
    with pytest.raises(ScenarioInputError, match=r"check tube was asked for .* \(topics.nominal\)"):
        certify_log(log, lab(), checks=["tube"])
    with pytest.raises(ScenarioInputError, match="unknown check"):
        certify_log(log, lab(), checks=["speed"])


def _cli(*args: str | Path) -> subprocess.CompletedProcess[str]:
    return subprocess.run([sys.executable, "-m", "tubempc", *map(str, args)], capture_output=True, text=True,
                          timeout=120, check=False)


def test_cli_checks_option(tmp_path: Path) -> None:
    log = _log(tmp_path, _run(3.0))
    yaml_path = tmp_path / "lab.yaml"
    yaml_path.write_text(json.dumps(lab().to_dict()))
    bad = _cli("certify", log, "--scenario", yaml_path, "--checks", "workspace,speed")
    assert bad.returncode == 3
    assert bad.stderr.strip().splitlines() == [
        "tubempc: error: --checks: unknown check(s) speed (choose from spec, obstacle_clearance, workspace, tube, "
        "input_box)"]
    ok = _cli("certify", log, "--scenario", yaml_path, "--checks", "workspace")
    assert ok.returncode == 0, ok.stderr
    assert "[checks: workspace; not checked: spec, obstacle_clearance, tube, input_box]" in ok.stdout
    fail = _cli("certify", log, "--scenario", yaml_path)
    assert fail.returncode == 1
    assert "obstacle_clearance: fail at t=" in fail.stdout


def test_plan_and_simulate_name_what_the_planner_lacks(tmp_path: Path) -> None:
    yaml_path = tmp_path / "lab.yaml"
    yaml_path.write_text(json.dumps(lab().to_dict()))
    for args in (("plan", "--scenario", yaml_path), ("simulate", "--scenario", yaml_path, "--to", "dock",
                                                      "--out", tmp_path / "x.mcap")):
        out = _cli(*args)
        assert out.returncode == 3, out
        lines = out.stderr.strip().splitlines()
        assert len(lines) == 1, out.stderr
        assert "disturbance: cannot plan on this scenario: required for planning and simulation" in lines[0]
    full = lab(disturbance={"bound": 0.02}, tube={"sigma_low": 2.0}, initial_region="start",
               mpc={"h": 0.1, "horizon": 1.2, "Q": [1, 1, 1], "R": [1, 1, 1], "P": [1, 1, 1]})
    yaml_path.write_text(json.dumps(full.to_dict()))
    out = _cli("plan", "--scenario", yaml_path)
    assert out.returncode == 3
    assert out.stderr.strip() == ("tubempc: error: diffdrive-lab: inputs.model: cannot plan on this scenario: "
                                  "unicycle: the paper's tube MPC needs a fully actuated (holonomic) input model")


# ---- input models: holonomic / unicycle, Twist / TwistStamped ------------------------------------------------------
def _cmd_log(tmp_path: Path, run: Any, suffix: str, *, stamped: bool, lateral: np.ndarray | None = None,
             header_offset_ns: int = 0) -> Path:
    ros1 = suffix == ".bag"
    msgs = KIT.odometry_messages(run, "/odom", ros1=ros1) + KIT.command_messages(
        run, "/cmd_vel", ros1=ros1, stamped=stamped, lateral=lateral, header_offset_ns=header_offset_ns)
    return KIT.write_messages(tmp_path / f"cmd{suffix}", msgs)


@pytest.mark.parametrize("suffix", [".bag", ".mcap"])
@pytest.mark.parametrize("stamped", [False, True])
def test_unicycle_commands_pass_and_fail_per_component(tmp_path: Path, suffix: str, stamped: bool) -> None:
    run = _run(3.4)
    sc = lab(topics={"pose": "/odom", "cmd_vel": "/cmd_vel"})
    ok = certify_log(_cmd_log(tmp_path, run, suffix, stamped=stamped), sc).certificate
    box = _check(ok, "input_box")
    assert box["verdict"] == "pass" and box["model"] == "unicycle"
    # v 0.4 of 0.5, w 0.8 of 1.0, lateral 0 of the 1 mm/s tolerance (the tightest: the check's margin)
    assert box["component_margins"] == pytest.approx({"linear.x": 0.1, "angular.z": 0.2, "linear.y": 0.001},
                                                     abs=1e-8)
    assert box["margin"] == pytest.approx(0.001, abs=1e-8)
    assert ok["data_quality"]["cmd_vel"]["type"].endswith("TwistStamped" if stamped else "Twist")
    assert ok["data_quality"]["cmd_vel"]["time_base"] == ("header" if stamped else "log")
    # a lateral velocity of 2 cm/s at sample 300 is a violation for a differential drive (tolerance 1 mm/s)
    lateral = np.zeros_like(run.v)
    lateral[300] = 0.02
    (tmp_path / "b").mkdir()
    bad = certify_log(_cmd_log(tmp_path / "b", run, suffix, stamped=stamped, lateral=lateral), sc).certificate
    box = _check(bad, "input_box")
    assert box["verdict"] == "fail" and box["component"] == "linear.y"
    assert box["first_violation_time"] == pytest.approx(run.t_s[300], abs=1e-9)
    assert box["margin"] == pytest.approx(0.001 - 0.02, abs=1e-8)
    # the same commands under a holonomic box [0.5, 0.5, 1.0]: the lateral 2 cm/s is allowed
    holo = lab(topics={"pose": "/odom", "cmd_vel": "/cmd_vel"}, inputs={"max_abs": [0.5, 0.5, 1.0]})
    again = certify_log(tmp_path / "b" / f"cmd{suffix}", holo).certificate
    assert _check(again, "input_box")["verdict"] == "pass"
    assert again["speed_bound_mps"] == pytest.approx(np.hypot(0.5, 0.5))


def test_twist_stamped_uses_its_header_on_the_header_time_base(tmp_path: Path) -> None:
    """The command's header runs 0.5 s behind its log time: on the header time base the spike is reported at the
    header time; the fast decode and rosbags' deserialize agree."""
    run = _run(3.4)
    spike = run.w.copy()
    spike[400] = 1.5
    run = KIT.UnicycleRun(run.t_s, run.x, run.y, run.theta, run.v, spike)
    sc = lab(topics={"pose": "/odom", "cmd_vel": "/cmd_vel"})
    log = _cmd_log(tmp_path, run, ".mcap", stamped=True, header_offset_ns=-500_000_000)
    header = _check(certify_log(log, sc).certificate, "input_box")
    assert header["component"] == "angular.z" and header["margin"] == pytest.approx(-0.5, abs=1e-8)
    assert header["first_violation_time"] == pytest.approx(run.t_s[400] - 0.5, abs=1e-9)
    logged = _check(certify_log(log, sc, time_base="log").certificate, "input_box")
    assert logged["first_violation_time"] == pytest.approx(run.t_s[400], abs=1e-9)

    from verify.ingest.decode import decode_twist
    from verify.ingest.raw import read_raw

    raw = read_raw(log, {"/cmd_vel"}).topics["/cmd_vel"]
    fast, slow = decode_twist(raw, False), decode_twist(raw, False, fast=False)
    assert fast.fast and not slow.fast
    assert np.array_equal(fast.u, slow.u) and np.array_equal(fast.stamp_ns, slow.stamp_ns)
