"""Certifying a robot that is not the Nexus: a differential-drive base that logs only nav_msgs/Odometry.

The scenario names only the pose topic: the tube and input checks are *not selected* (listed under ``not_checked``
with the reason) and the verdict is over the selected checks, so such a log can pass. Check selection from the
scenario and the command line; unknown or unsupported selections are exit 3.
"""

from __future__ import annotations

import json
import subprocess
import sys
from pathlib import Path
from typing import Any

import numpy as np
import pytest

from scripts import make_any_robot_logs
from tubempc.scenario import Scenario, scenario_from_dict
from verify import certify_log
from verify.errors import ScenarioInputError

ROOT = Path(__file__).resolve().parents[2]


KIT = make_any_robot_logs
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
        assert ("disturbance: cannot plan or simulate on this scenario: required for planning and simulation"
                in lines[0])
    full = lab(disturbance={"bound": 0.02}, tube={"sigma_low": 2.0}, initial_region="start",
               mpc={"h": 0.1, "horizon": 1.2, "Q": [1, 1, 1], "R": [1, 1, 1], "P": [1, 1, 1]})
    yaml_path.write_text(json.dumps(full.to_dict()))
    for args in (("plan", "--scenario", yaml_path), ("simulate", "--scenario", yaml_path, "--to", "dock",
                                                      "--out", tmp_path / "x.mcap")):
        out = _cli(*args)
        assert out.returncode == 3
        assert out.stderr.strip() == ("tubempc: error: diffdrive-lab: inputs.model: cannot plan or simulate on this "
                                      "scenario: unicycle: the paper's tube MPC needs a fully actuated (holonomic) "
                                      "input model")
    assert not (tmp_path / "x.mcap").exists()


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


# ---- polygon regions and workspaces ----------------------------------------------------------------------------------
ROOM = [[0.0, 0.0], [3.0, 0.0], [3.0, 2.2], [0.0, 2.2]]
TABLE_SQ = [[2.2, 1.2], [2.8, 1.2], [2.8, 1.8], [2.2, 1.8]]  # inside the room: regions nest


def poly_lab(**extra: Any) -> Scenario:
    data = lab().to_dict()
    data["regions"] = [
        {"name": "start", "center": [0.5, 0.5], "radius": 0.45, "labels": ["home"]},
        {"name": "dock", "center": [4.4, 3.3], "radius": 0.45, "labels": ["dock"]},
        {"name": "room", "polygon": ROOM, "labels": ["in_room"]},
        {"name": "table", "polygon": TABLE_SQ, "labels": ["table"], "unsafe": True},
    ]
    data["workspace"] = {"polygon": [[0.0, 0.0], [5.0, 0.0], [5.0, 4.0], [0.0, 4.0]]}
    data["spec"] = "G[0,inf) !table & F[0,40] dock & F[0,1] (in_room & home)"
    data.update(extra)
    return scenario_from_dict(data, source="lab.yaml")


def _table_distance(x: np.ndarray, y: np.ndarray) -> np.ndarray:
    """Distance from outside points to the table square (the nearest point of an axis-aligned box)."""
    dx = np.maximum.reduce([2.2 - x, np.zeros_like(x), x - 2.8])
    dy = np.maximum.reduce([1.2 - y, np.zeros_like(y), y - 1.8])
    return np.hypot(dx, dy)


def test_polygon_room_table_and_workspace_pass(tmp_path: Path) -> None:
    run = _run(3.4)
    sc = poly_lab()
    assert any("(room) and regions[3] (table) may overlap" in w for w in sc.certification_warnings())
    cert = certify_log(_log(tmp_path, run), sc).certificate
    assert cert["verdict"] == "pass", cert["checks"]
    # nested regions: the start disc and the room both contain the robot at t = 0, so both labels hold
    assert [e["region"] for e in cert["timed_run"]] == ["start+room", "room", "dock"]
    clear = _check(cert, "obstacle_clearance")
    want = float((_table_distance(run.x, run.y) - 0.25).min())  # the x = 3.4 leg: 0.6 m from the table's edge
    assert clear["sample_margin_m"] == pytest.approx(want, abs=1e-12) and want == pytest.approx(0.35)
    ws = _check(cert, "workspace")
    assert ws["sample_margin_m"] == pytest.approx(0.5 - 0.25, abs=1e-12)  # the start, 0.5 m from two walls
    assert cert["scenario_warnings"] == sc.certification_warnings()


def test_polygon_obstacle_hit_has_the_right_time_and_margin(tmp_path: Path) -> None:
    run = _run(3.0)  # 0.2 m from the table's right edge, less than the robot radius
    cert = certify_log(_log(tmp_path, run), poly_lab()).certificate
    clear = _check(cert, "obstacle_clearance")
    margin = _table_distance(run.x, run.y) - 0.25
    k = int(np.argmax(margin < 0))
    assert clear["verdict"] == "fail" and clear["region"] == "table"
    assert clear["first_violation_time"] == pytest.approx(run.t_s[k], abs=1e-9)
    assert clear["margin"] == pytest.approx(-0.05, abs=1e-12)
    assert _check(cert, "spec_trajectory")["verdict"] == "fail"


def test_polygon_workspace_violation(tmp_path: Path) -> None:
    """An L-shaped workspace whose upper right part (x > 3, y > 2.8) is outside: the last leg leaves it."""
    run = _run(3.4)
    ell = [[0.0, 0.0], [5.0, 0.0], [5.0, 2.8], [3.0, 2.8], [3.0, 4.0], [0.0, 4.0]]
    cert = certify_log(_log(tmp_path, run), poly_lab(workspace={"polygon": ell})).certificate
    ws = _check(cert, "workspace")
    k = int(np.argmax((run.x > 3.0) & (2.8 - run.y - 0.25 < 0)))
    assert ws["verdict"] == "fail"
    assert ws["first_violation_time"] == pytest.approx(run.t_s[k], abs=1e-9)
    assert ws["margin"] == pytest.approx(-(3.3 - 2.8) - 0.25, abs=1e-9)  # the dock lies 0.5 m past the wall


def test_between_samples_a_polygon_corner_makes_the_check_inconclusive(tmp_path: Path) -> None:
    """Two samples 1 s apart on either side of the table's corner, each clear of it: the straight path between
    them passes 0.14 m from the corner; the robot (radius 0.25) may have touched it: inconclusive, never a pass."""
    run = KIT.UnicycleRun(np.array([0.0, 1.0, 2.0]), np.array([2.6, 3.2, 3.2]), np.array([0.8, 1.4, 2.0]),
                          np.zeros(3), np.zeros(3), np.zeros(3))
    sc = poly_lab(spec="G[0,inf) !table", robot={"radius": 0.25, "max_speed": 0.9})
    cert = certify_log(_log(tmp_path, run), sc, checks=["obstacle_clearance"]).certificate
    clear = _check(cert, "obstacle_clearance")
    assert clear["verdict"] == "inconclusive", clear
    assert "between samples" in clear["reason"]


@pytest.mark.parametrize("x_leg", [3.4, 3.0])
def test_fast_monitor_and_general_engine_agree_on_polygons(monkeypatch: pytest.MonkeyPatch, x_leg: float) -> None:
    """The regular-grid path (verify.monitor.grid) and the interleaved engine (verify.monitor.engine) give the same
    verdict and margin on a formula over polygon and disc atoms."""
    from verify.semantics import trajectory

    run = _run(x_leg)
    sc = poly_lab(spec="G[0,inf) !table & F[0,40] dock & G[0,3] in_room")
    t_ns = np.round(run.t_s * 1e9).astype(np.int64)
    fast = trajectory.check_trajectory(sc.formula, t_ns, run.x, run.y, sc, max_speed_mps=0.5)
    assert trajectory.regular_grid(t_ns) is not None
    monkeypatch.setattr(trajectory, "regular_grid", lambda _t: None)
    general = trajectory.check_trajectory(sc.formula, t_ns, run.x, run.y, sc, max_speed_mps=0.5)
    assert fast.verdict == general.verdict == ("pass" if x_leg == 3.4 else "fail")
    assert fast.margin_m == pytest.approx(general.margin_m, abs=1e-12)
    assert fast.margin_hi_m == pytest.approx(general.margin_hi_m, abs=1e-12)
    assert fast.time_ns == general.time_ns


# ---- signal atoms ----------------------------------------------------------------------------------------------------
SLOW = {"topic": "/odom", "field": "twist.twist.linear.x", "op": "<=", "value": 0.5, "unit": "m/s"}


def _battery_log(tmp_path: Path, run: Any, times: list[float], pct: list[float],
                 cells: list[list[float]] | None = None) -> Path:
    msgs = KIT.odometry_messages(run, "/odom", ros1=False) + KIT.battery_messages(times, pct, "/battery_state",
                                                                                 ros1=False, cells=cells)
    return KIT.write_messages(tmp_path / "bat.mcap", msgs)


def test_signal_atom_on_a_nested_field_passes_and_fails(tmp_path: Path) -> None:
    run = _run(3.4)
    log = _log(tmp_path, run)
    ok = certify_log(log, lab(signals={"slow": SLOW}, spec="G[0,inf) slow & F[0,40] dock")).certificate
    assert ok["verdict"] == "pass", ok["checks"]
    s = ok["signals"]["slow"]
    assert s["worst_margin"] == pytest.approx(0.1) and s["relative_worst_margin"] == pytest.approx(0.2)
    assert s["unit"] == "m/s" and s["time_base"] == "header" and s["unknown_stretches"] == []
    atom = _check(ok, "spec_trajectory")["atom_margins"]
    assert atom["slow"]["min"] == pytest.approx(0.1) and atom["slow"]["relative_min"] == pytest.approx(0.2)
    assert atom["slow"]["max"] == pytest.approx(0.5) and atom["slow"]["unit"] == "m/s"
    assert atom["dock"]["unit"] == "m" and atom["dock"]["max"] == pytest.approx(0.45 - 0.25)  # at its centre
    strict = dict(SLOW, value=0.3)
    bad = certify_log(log, lab(signals={"slow": strict}, spec="G[0,inf) slow")).certificate
    spec = _check(bad, "spec_trajectory")
    k = int(np.argmax(run.v > 0.3))  # the first sample driving faster than 0.3 m/s
    assert spec["verdict"] == "fail"
    assert spec["first_violation_time"] == pytest.approx(run.t_s[k], abs=1e-9)
    assert spec["guaranteed_margin_m"] == pytest.approx(0.3 - 0.4, abs=1e-9)  # in the field's unit (m/s)
    assert _check(bad, "spec_timed_run")["verdict"] in ("pass", "fail")  # judged at the run's entries only


def test_signal_atom_with_a_gap_is_unknown_there(tmp_path: Path) -> None:
    """A battery at 1 Hz that stops reporting from 5 s to 11 s: G battery_ok cannot pass; a later value below the
    threshold is still a fail (Kleene: false & unknown = false), at that message's time."""
    run = _run(3.4)
    times = [float(t) for t in range(22) if not 5 < t < 11]
    sig = {"battery_ok": {"topic": "/battery_state", "field": "percentage", "op": ">=", "value": 0.2,
                          "rate_hz": 1.0}}
    log = _battery_log(tmp_path, run, times, [0.9] * len(times))
    cert = certify_log(log, lab(signals=sig, spec="G[0,inf) battery_ok")).certificate
    spec = _check(cert, "spec_trajectory")
    assert cert["verdict"] == "inconclusive" and spec["verdict"] == "inconclusive", spec
    assert cert["signals"]["battery_ok"]["unknown_stretches"][0] == {"from_s": 6.5, "to_s": 11.0}
    low = [0.9 if t < 15 else 0.1 for t in times]
    (tmp_path / "low").mkdir()
    cert = certify_log(_battery_log(tmp_path / "low", run, times, low), lab(signals=sig, spec="G[0,inf) battery_ok")
                       ).certificate
    spec = _check(cert, "spec_trajectory")
    assert spec["verdict"] == "fail" and spec["first_violation_time"] == pytest.approx(15.0, abs=1e-9)
    assert cert["signals"]["battery_ok"]["worst_margin"] == pytest.approx(0.1 - 0.2, abs=1e-6)  # float32 field


def test_signal_atom_on_an_array_element(tmp_path: Path) -> None:
    run = _run(3.4)
    times = [float(t) for t in range(22)]
    cells = [[3.9, 3.8 if t < 12 else 3.4, 3.9] for t in times]
    sig = {"cell_ok": {"topic": "/battery_state", "field": "cell_voltage[1]", "op": ">", "value": 3.5, "unit": "V"}}
    cert = certify_log(_battery_log(tmp_path, run, times, [0.9] * len(times), cells),
                       lab(signals=sig, spec="G[0,inf) cell_ok")).certificate
    spec = _check(cert, "spec_trajectory")
    assert spec["verdict"] == "fail" and spec["first_violation_time"] == pytest.approx(12.0, abs=1e-9)
    assert spec["guaranteed_margin_m"] == pytest.approx(3.4 - 3.5, abs=1e-6)


@pytest.mark.parametrize(("signal", "fragment"), [
    ({"topic": "/battery", "field": "percentage", "op": ">=", "value": 0.2},
     "signal s: topic /battery (field percentage) is absent from the log"),
    ({"topic": "/odom", "field": "twist.twist.linear.w", "op": "<=", "value": 0.5},
     "signal s: topic /odom (nav_msgs/msg/Odometry) has no field twist.twist.linear.w: twist.twist.linear has no "
     "'w' (its fields: x, y, z)"),
    ({"topic": "/odom", "field": "pose.covariance[40]", "op": "<=", "value": 0.5},
     "has no field pose.covariance[40]: pose.covariance has 36 element(s)"),
    ({"topic": "/odom", "field": "child_frame_id", "op": "<=", "value": 0.5},
     "field child_frame_id is a str, not a number"),
])
def test_missing_signal_topic_or_field_is_exit_3_naming_both(tmp_path: Path, signal: dict[str, Any],
                                                             fragment: str) -> None:
    log = _log(tmp_path, _run(3.4))
    yaml_path = tmp_path / "lab.yaml"
    yaml_path.write_text(json.dumps(lab(signals={"s": signal}, spec="G[0,inf) s").to_dict()))
    out = _cli("certify", log, "--scenario", yaml_path)
    assert out.returncode == 3, out
    lines = out.stderr.strip().splitlines()
    assert len(lines) == 1 and fragment in lines[0] and str(log) in lines[0], lines


# ---- clocks ----------------------------------------------------------------------------------------------------------
def _spiky_log(tmp_path: Path, *, pose_ahead_ns: int, cmd_header_offset_ns: int = 0, stamped: bool = False) -> Path:
    """Pose (Odometry) headers ``pose_ahead_ns`` ahead of the recorder; a command spike (w = 1.5) at 10.0 s."""
    run = _run(3.4)
    spike = run.w.copy()
    spike[500] = 1.5  # t = 10.0 s at 50 Hz
    run = KIT.UnicycleRun(run.t_s, run.x, run.y, run.theta, run.v, spike)
    msgs = KIT.odometry_messages(run, "/odom", ros1=False, header_offset_ns=pose_ahead_ns) + KIT.command_messages(
        run, "/cmd_vel", ros1=False, stamped=stamped, header_offset_ns=cmd_header_offset_ns)
    return KIT.write_messages(tmp_path / "clock.mcap", msgs)


def test_pose_clock_ahead_is_a_finding_and_a_correction_fixes_the_time(tmp_path: Path) -> None:
    log = _spiky_log(tmp_path, pose_ahead_ns=2_000_000_000)
    sc = lab(topics={"pose": "/odom", "cmd_vel": "/cmd_vel"})
    cert = certify_log(log, sc).certificate
    box = _check(cert, "input_box")
    assert box["first_violation_time"] == pytest.approx(8.0, abs=1e-9)  # misplaced: the clocks disagree by 2 s
    assert len(cert["clock_findings"]) == 1
    finding = cert["clock_findings"][0]
    assert finding.startswith("/cmd_vel: its times (log time base) run 2.000 s behind the pose topic /odom")
    assert "--clock-offset /cmd_vel=2.0" in finding
    assert cert["data_quality"]["clocks"]["streams"]["/cmd_vel"]["suggested_correction_s"] == 2.0
    fixed = certify_log(log, sc, clock_offsets={"/cmd_vel": 2.0}).certificate
    assert _check(fixed, "input_box")["first_violation_time"] == pytest.approx(10.0, abs=1e-9)
    assert fixed["clock_findings"] == []
    in_scenario = certify_log(log, lab(topics={"pose": "/odom", "cmd_vel": "/cmd_vel"},
                                       clock_offsets={"/cmd_vel": 2.0})).certificate
    assert _check(in_scenario, "input_box")["first_violation_time"] == pytest.approx(10.0, abs=1e-9)
    # the header-vs-log offset reads header - log: the pose headers are 2 s ahead of the recorder
    assert cert["data_quality"]["pose"]["header_vs_log_offset_s"]["median"] == pytest.approx(2.0)


def test_stamped_commands_from_another_computer(tmp_path: Path) -> None:
    """The commands' header clock runs 0.5 s behind the pose's: found, and corrected from the command line."""
    log = _spiky_log(tmp_path, pose_ahead_ns=0, cmd_header_offset_ns=-500_000_000, stamped=True)
    yaml_path = tmp_path / "lab.yaml"
    yaml_path.write_text(json.dumps(lab(topics={"pose": "/odom", "cmd_vel": "/cmd_vel"}).to_dict()))
    out = _cli("certify", log, "--scenario", yaml_path, "--out", tmp_path / "r")
    assert out.returncode == 1
    cert = json.loads((tmp_path / "r" / "certificate.json").read_text())
    assert _check(cert, "input_box")["first_violation_time"] == pytest.approx(9.5, abs=1e-9)
    assert "/cmd_vel: its times (header time base) run 0.500 s behind" in cert["clock_findings"][0]
    assert "Finding: /cmd_vel: its times" in (tmp_path / "r" / "report.md").read_text()
    out = _cli("certify", log, "--scenario", yaml_path, "--clock-offset", "/cmd_vel=0.5", "--out", tmp_path / "r2")
    cert = json.loads((tmp_path / "r2" / "certificate.json").read_text())
    assert _check(cert, "input_box")["first_violation_time"] == pytest.approx(10.0, abs=1e-9)
    assert cert["clock_findings"] == []
    bad = _cli("certify", log, "--scenario", yaml_path, "--clock-offset", "cmd_vel:0.5")
    assert bad.returncode == 3
    assert bad.stderr.strip() == ("tubempc: error: --clock-offset 'cmd_vel:0.5': expected TOPIC=SECONDS, "
                                  "e.g. /cmd_vel=2.0")


def test_reports_draw_polygon_scenarios_without_a_tube(tmp_path: Path) -> None:
    from verify.report import write_reports

    sc = poly_lab(topics={"pose": "/odom", "cmd_vel": "/cmd_vel"})
    res = certify_log(_cmd_log(tmp_path, _run(3.4), ".mcap", stamped=False), sc)
    written = write_reports(res, sc, tmp_path / "r")
    assert {"figures/workspace.png", "figures/inputs.png", "report.md"} <= set(written)
    md = (tmp_path / "r" / "report.md").read_text()
    assert "Verdict over the checks: spec, obstacle_clearance, workspace, input_box." in md
    assert "not checked: tube (not selected: the scenario names no nominal-state topic (topics.nominal))" in md
    assert "tube radius" not in md


@pytest.mark.parametrize("ros1", [True, False])
@pytest.mark.parametrize(("topic", "field"), [
    ("/odom", "twist.twist.linear.x"), ("/odom", "pose.covariance[35]"), ("/odom", "pose.pose.orientation.z"),
    ("/battery_state", "percentage"), ("/battery_state", "cell_voltage[1]"), ("/battery_state", "present"),
    ("/battery_state", "power_supply_status"),
])
def test_bulk_field_decode_equals_deserialize(tmp_path: Path, ros1: bool, topic: str, field: str) -> None:
    """The layout walk reads the same values and header stamps as rosbags' deserialize, in both encodings (frame ids
    of different lengths per message, so offsets differ between messages)."""
    from verify.ingest.fields import decode_field
    from verify.ingest.raw import read_raw

    run = _run(3.4)
    msgs = KIT.odometry_messages(run, "/odom", ros1=ros1)
    for k, (_, _, _, m) in enumerate(msgs):
        m.header.frame_id = "odom" + "x" * (k % 5)
    times = [float(t) for t in range(20)]
    msgs += KIT.battery_messages(times, [0.9 - 0.01 * t for t in times], "/battery_state", ros1=ros1,
                                 cells=[[3.9, 3.8 - 0.01 * t, 3.7][: 2 + int(t) % 2] for t in times])
    log = KIT.write_messages(tmp_path / ("f.bag" if ros1 else "f.mcap"), msgs)
    raw = read_raw(log, {topic}).topics[topic]
    fast, slow = decode_field(raw, ros1, field), decode_field(raw, ros1, field, fast=False)
    assert fast.fast and not slow.fast
    assert np.array_equal(fast.value, slow.value)
    assert fast.stamp_ns is not None and slow.stamp_ns is not None
    assert np.array_equal(fast.stamp_ns, slow.stamp_ns)
