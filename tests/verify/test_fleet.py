"""Several robots in one log: separation, per-robot atoms, joint deadlines, per-robot checks and data quality.

The logs are generated here (``scripts/make_fleet_logs.py``): robots on straight lines at constant speed, PoseStamped
and Odometry mixed, different rates, one robot with a dropout. The paths are known in closed form, so every expected
time and margin is computed densely (every 0.1 ms) and independently of the certifier.
"""

from __future__ import annotations

import math
from pathlib import Path
from typing import Any

import numpy as np
import pytest

from scripts import make_fleet_logs
from tubempc.scenario import Scenario, scenario_from_dict
from verify.certify import certify_log
from verify.errors import SpecError

ROOT = Path(__file__).resolve().parents[2]


KIT = make_fleet_logs
DOOR = ((4.0, 2.0), (6.0, 2.0), (6.0, 4.0), (4.0, 4.0))
RADII = {"a": 0.35, "b": 0.25, "c": 0.3}


def _scenario(spec: str, *, robots: tuple[str, ...] = ("a", "b", "c"), min_m: float = 0.3) -> Scenario:
    topics = {"a": {"pose": "/a/pose"}, "b": {"pose": "/b/odom"}, "c": {"pose": "/c/pose"}}
    rates = {"a": 10.0, "b": 7.0, "c": 30.0}
    return scenario_from_dict({
        "name": "fleet-test", "workspace": {"x": [0.0, 10.0], "y": [0.0, 6.0]},
        "regions": [{"name": "door", "polygon": [list(p) for p in DOOR], "labels": ["door"]},
                    {"name": "dock", "center": [8.5, 4.5], "radius": 0.7, "labels": ["dock"]}],
        "robots": [{"name": n, "topics": topics[n], "radius": RADII[n], "rate_hz": rates[n],
                    "inputs": {"model": "unicycle", "max_abs": [1.0, 2.0]}} for n in robots],
        "separation": {"min_m": min_m}, "spec": spec})


A_CROSS = KIT.Path(((0.0, 2.0, 3.0), (6.0, 8.0, 3.0), (10.0, 8.0, 3.0)))
B_CROSS = KIT.Path(((0.0, 5.0, 0.5), (1.2, 5.0, 0.5), (6.2, 5.0, 5.5), (10.0, 5.0, 5.5)))
C_SLOW = KIT.Path(((0.0, 7.5, 1.0), (10.0, 8.5, 1.0)))


def _three_robots(tmp_path: Path, a: Any, b: Any, c: Any = C_SLOW, *, suffix: str = ".bag") -> Path:
    return KIT.write_fleet_log(tmp_path / f"fleet{suffix}", [
        KIT.RobotLog(a, "/a/pose", "pose", 10.0),
        KIT.RobotLog(b, "/b/odom", "odom", 7.0),
        KIT.RobotLog(c, "/c/pose", "pose", 30.0, dropouts=((3.0, 5.0),))])


def _dense(a: Any, b: Any, min_m: float, radii: float) -> tuple[np.ndarray, np.ndarray]:
    t = np.arange(0.0, 10.0, 1e-4)
    (ax, ay), (bx, by) = a.at(t), b.at(t)
    return t, np.hypot(ax - bx, ay - by) - radii - min_m


def _check(cert: dict[str, Any], name: str) -> dict[str, Any]:
    return next(c for c in cert["checks"] if c["name"] == name)


def test_separation_violation_found_at_the_right_time_and_margin(tmp_path: Path) -> None:
    log = _three_robots(tmp_path, A_CROSS, B_CROSS, suffix=".mcap")
    cert = certify_log(log, _scenario("G !(a.door & c.door)")).certificate
    sep = _check(cert, "separation")
    assert cert["verdict"] == "fail" and sep["verdict"] == "fail" and sep["pair"] == "a-b"
    t, margin = _dense(A_CROSS, B_CROSS, 0.3, RADII["a"] + RADII["b"])
    first_true, least_true = float(t[np.argmax(margin < 0)]), float(margin.min())
    # the certificate's first violation is a real one, at most one sample period of the slower robot late
    at = sep["first_violation_time"]
    assert first_true <= at <= first_true + 1 / 7
    assert np.interp(at, t, margin) < 0
    # the margin is sound (a violation of at least that much happened) and tight (within the motion bounds)
    assert least_true <= sep["margin"] < 0
    assert sep["margin"] - least_true < 0.15
    pairs = {tuple(p["robots"]): p for p in sep["pairs"]}
    assert pairs[("a", "b")]["verdict"] == "fail" and pairs[("a", "c")]["verdict"] == "pass"


def test_separation_that_may_have_been_broken_between_samples_is_inconclusive(tmp_path: Path) -> None:
    # B starts 0.672 s later than in the crossing above: the centres pass 0.97 m apart (|0.5 - delay| / sqrt 2),
    # 0.07 m clear of min_m, less than the robots may move between their samples
    delay = 0.5 + 0.97 * math.sqrt(2)
    b_late = KIT.Path(((0.0, 5.0, 0.5), (delay, 5.0, 0.5), (delay + 5.0, 5.0, 5.5), (10.0, 5.0, 5.5)))
    log = _three_robots(tmp_path, A_CROSS, b_late)
    _, margin = _dense(A_CROSS, b_late, 0.3, RADII["a"] + RADII["b"])
    assert 0 < margin.min() < 0.1  # never violated, but close
    cert = certify_log(log, _scenario("G !(a.door & b.door)")).certificate
    sep = _check(cert, "separation")
    assert sep["verdict"] == "inconclusive" and cert["verdict"] == "inconclusive"
    assert "a-b may have come closer than 0.3 m" in sep["reason"]
    assert sep["explanation"].endswith("samples of both robots closer together there would decide it")
    # with a smaller min_m the same run passes, and the stated margin is a lower bound of the true one
    cert = certify_log(log, _scenario("G !(a.door & b.door)", min_m=0.05)).certificate
    sep = _check(cert, "separation")
    assert sep["verdict"] == "pass"
    _, margin = _dense(A_CROSS, b_late, 0.05, RADII["a"] + RADII["b"])
    assert 0 < sep["margin"] <= margin.min()


def test_doorway_mutual_exclusion_fails_when_both_are_inside(tmp_path: Path) -> None:
    a = KIT.Path(((0.0, 2.0, 2.5), (6.0, 8.0, 2.5), (10.0, 8.0, 2.5)))
    b = KIT.Path(((0.0, 2.5, 3.5), (6.0, 8.5, 3.5), (10.0, 8.5, 3.5)))
    log = _three_robots(tmp_path, a, b)
    cert = certify_log(log, _scenario("G !(a.door & b.door)")).certificate
    spec = _check(cert, "spec_trajectory")
    assert spec["verdict"] == "fail" and cert["verdict"] == "fail"
    # dense: the discs are both inside the door from 2.35 s (a enters) to 3.25 s (b leaves)
    t = np.arange(0.0, 10.0, 1e-4)
    (ax, _), (bx, _) = a.at(t), b.at(t)
    both = (ax >= 4.0 + RADII["a"]) & (ax <= 6.0 - RADII["a"]) & (bx >= 4.0 + RADII["b"]) & (bx <= 6.0 - RADII["b"])
    first = float(t[np.argmax(both)])
    assert first == pytest.approx(2.35, abs=1e-3)
    assert first <= spec["first_violation_time"] <= first + 0.1
    assert "a.door" in spec["explanation"] or "door" in spec["subformula"]
    # one robot alone in the door is no violation: the separation holds and a.door & c.door never both hold
    ok = certify_log(log, _scenario("G !(a.door & c.door)")).certificate
    assert _check(ok, "spec_trajectory")["verdict"] == "pass"


@pytest.mark.parametrize(("deadline", "verdict"), [(24.0, "fail"), (25.0, "pass")])
def test_joint_deadline_passes_and_fails_at_the_right_times(deadline: float, verdict: str) -> None:
    # the walkthrough: the Husky is docked from 17.3 s, the Jackal from 24.59 s (0.45 m before dock_b's centre)
    jackal_docked = KIT.JACKAL.knots[4][0] - 0.45 / 0.5
    assert jackal_docked == pytest.approx(24.586, abs=1e-3)
    cert = certify_log(ROOT / "logs" / "two_robots.bag", ROOT / "docs" / "examples" / "two-robots-warehouse.yaml",
                       spec=f"F[0,{deadline:g}] (husky.dock & jackal.dock)").certificate
    spec = _check(cert, "spec_trajectory")
    assert spec["verdict"] == verdict
    if verdict == "pass":  # decided at the first joint sample with both docked: the Jackal's first inside
        assert jackal_docked <= spec["decided_at"] <= jackal_docked + 1 / 20
    else:  # decided when the window closed
        assert spec["decided_at"] == pytest.approx(deadline, abs=1 / 50)


def test_walkthrough_per_robot_checks_timed_runs_and_quality() -> None:
    cert = certify_log(ROOT / "logs" / "two_robots.bag",
                       ROOT / "docs" / "examples" / "two-robots-warehouse.yaml").certificate
    assert cert["verdict"] == "pass"
    names = [c["name"] for c in cert["checks"]]
    assert names[:2] == ["spec_trajectory", "separation"]
    assert {"husky/obstacle_clearance", "husky/workspace", "jackal/obstacle_clearance",
            "jackal/workspace"} <= set(names)
    assert {e["robot"] for e in cert["timed_run"]} == {"husky", "jackal"}
    dock = [e for e in cert["timed_run"] if e["region"].startswith("dock")]
    assert [(e["robot"], e["region"]) for e in dock] == [("husky", "dock_a"), ("jackal", "dock_b")]
    robots = {r["name"]: r for r in cert["robots"]}
    assert robots["husky"]["data_quality"]["pose"]["rate_hz"] == pytest.approx(50.0)
    assert robots["jackal"]["data_quality"]["pose"]["rate_hz"] == pytest.approx(20.0)
    assert robots["jackal"]["pose_source"]["type"].endswith("Odometry")
    assert cert["fleet"]["joint_span_s"] == [0.0, 30.0]


def test_dropout_is_reported_per_robot_and_bounds_its_atoms(tmp_path: Path) -> None:
    log = _three_robots(tmp_path, A_CROSS, B_CROSS)
    cert = certify_log(log, _scenario("G !c.door")).certificate
    robots = {r["name"]: r for r in cert["robots"]}
    drop = robots["c"]["data_quality"]["pose"]["dropouts"]
    assert drop["count"] == 1 and drop["longest_gap_s"] == pytest.approx(2.0, abs=0.04)
    assert robots["a"]["data_quality"]["pose"]["dropouts"]["count"] == 0
    # c is far from the door: even over its 2 s dropout (at most 1 m travelled) c.door is false for certain
    assert _check(cert, "spec_trajectory")["verdict"] == "pass"


def test_unqualified_atom_is_refused_naming_the_robots(tmp_path: Path) -> None:
    log = _three_robots(tmp_path, A_CROSS, B_CROSS)
    with pytest.raises(SpecError, match=r"unqualified atom\(s\) door in a scenario with robots a, b, c"):
        certify_log(log, _scenario("G !a.door"), spec="G !door")


def _same(cert: dict[str, Any], result: Any) -> None:
    assert result.verdict == cert["verdict"]
    online = {c.name: c for c in result.checks}
    assert set(online) == {c["name"] for c in cert["checks"]}
    for c in cert["checks"]:
        o = online[c["name"]]
        assert o.verdict == c["verdict"], c["name"]
        if c["first_violation_time"] is not None:
            assert o.first_violation_ns is not None
            assert round((o.first_violation_ns - cert["time0_ns"]) * 1e-9, 9) == c["first_violation_time"]
        if c["margin"] is not None and o.margin is not None:
            assert o.margin == pytest.approx(c["margin"], abs=1e-9), c["name"]


@pytest.mark.parametrize("case", ["walkthrough", "crossing", "doorway"])
def test_online_close_equals_certify(case: str, tmp_path: Path) -> None:
    from verify.fleet import read_fleet
    from verify.online.fleet import FleetMonitor, feed_fleet_logs

    if case == "walkthrough":
        log = ROOT / "logs" / "two_robots.bag"
        sc = scenario_from_dict(__import__("yaml").safe_load(
            (ROOT / "docs" / "examples" / "two-robots-warehouse.yaml").read_text()))
    elif case == "crossing":
        log, sc = _three_robots(tmp_path, A_CROSS, B_CROSS), _scenario("G !(a.door & c.door)")
    else:
        log = _three_robots(tmp_path, KIT.Path(((0.0, 2.0, 2.5), (6.0, 8.0, 2.5), (10.0, 8.0, 2.5))),
                            KIT.Path(((0.0, 2.5, 3.5), (6.0, 8.5, 3.5), (10.0, 8.5, 3.5))))
        sc = _scenario("G !(a.door & b.door) & F[0,9] c.dock")
    cert = certify_log(log, sc).certificate
    monitor = FleetMonitor(sc)
    decisions = feed_fleet_logs(monitor, read_fleet(log, sc))
    _same(cert, monitor.close())
    # a robot's check decided online is told with its robot's name and a time from the fleet's time 0
    assert all("/" in d.name for d in decisions)


def test_batch_and_compare_read_a_fleet_certificate(tmp_path: Path) -> None:
    from tubempc.compare.metrics import certificate_metrics
    from verify.certificate import Certificate
    from verify.certify import write_certificate

    result = certify_log(ROOT / "logs" / "two_robots.bag", ROOT / "docs" / "examples" / "two-robots-warehouse.yaml")
    path = write_certificate(result, tmp_path)
    cert = Certificate.model_validate_json(path.read_text())
    metrics = certificate_metrics(cert)
    # each robot's timed run is its own: no transition from one robot's region to the other's
    assert metrics["entry_s.jackal/dock_b"].number == pytest.approx(24.6)
    assert "transition_s.husky/door->dock_a" in metrics
    transitions = [k for k in metrics if k.startswith("transition_s.")]
    assert transitions
    assert all(k.startswith(("transition_s.husky/", "transition_s.jackal/")) for k in transitions)
    assert metrics["check.husky/obstacle_clearance.verdict"].verdict == "pass"
    assert metrics["check.separation.margin"].number == pytest.approx(cert.check("separation").margin)


def test_watch_judges_a_fleet_log_as_certify(tmp_path: Path) -> None:
    from verify.online.fleet import FleetMonitor
    from verify.online.watch import watch_log

    log = _three_robots(tmp_path, A_CROSS, B_CROSS)
    sc = _scenario("G !(a.door & b.door)")
    res = watch_log(log, FleetMonitor(sc))
    cert = certify_log(log, sc).certificate
    _same(cert, res.result)
    assert res.finished and res.result.verdict == "fail"
    assert {d.name for d in res.decisions} >= {"separation", "spec_trajectory", "a/workspace", "c/workspace"}
    assert any("final  separation FAIL" in line for line in res.result.state.final_lines())


def test_a_robot_whose_pose_topic_is_missing_is_named(tmp_path: Path) -> None:
    from verify.errors import MissingTopicError

    log = KIT.write_fleet_log(tmp_path / "two.bag", [KIT.RobotLog(A_CROSS, "/a/pose", "pose", 10.0),
                                                     KIT.RobotLog(B_CROSS, "/b/odom", "odom", 7.0)])
    with pytest.raises(MissingTopicError, match=r"robot c: pose topic /c/pose is absent"):
        certify_log(log, _scenario("G !(a.door & b.door)"))


def test_pair_separation_and_proximity_atoms(tmp_path: Path) -> None:
    log = _three_robots(tmp_path, A_CROSS, B_CROSS)
    data = _scenario("G !a.door").to_dict()
    data["spec"] = "G !near"
    data["separation"] = {"min_m": 0.3, "pairs": [{"robots": ["b", "a"], "min_m": 0.0}]}
    data["proximity"] = {"near": {"robots": ["a", "b"], "within_m": 1.0}}
    cert = certify_log(log, scenario_from_dict(data)).certificate
    # the pair's own min_m (0: the discs must not overlap) applies to a-b; they overlap, so it still fails
    sep = _check(cert, "separation")
    pairs = {tuple(p["robots"]): p for p in sep["pairs"]}
    assert pairs[("a", "b")]["min_m"] == 0.0 and pairs[("a", "c")]["min_m"] == 0.3
    t, margin0 = _dense(A_CROSS, B_CROSS, 0.0, RADII["a"] + RADII["b"])
    assert margin0.min() <= sep["margin"] < 0
    # near: the discs within 1 m of each other; G !near fails when they first come that close
    spec = _check(cert, "spec_trajectory")
    first_near = float(t[np.argmax(margin0 <= 1.0)])
    assert spec["verdict"] == "fail"
    assert first_near <= spec["first_violation_time"] <= first_near + 1 / 7
    assert cert["fleet"]["proximity"] == {"near": {"robots": ["a", "b"], "within_m": 1.0}}


def test_scenario_checks_select_each_robots_checks() -> None:
    data = __import__("yaml").safe_load((ROOT / "docs" / "examples" / "two-robots-warehouse.yaml").read_text())
    cert = certify_log(ROOT / "logs" / "two_robots.bag", scenario_from_dict({**data, "checks": ["workspace"]})
                       ).certificate
    assert [c["name"] for c in cert["checks"]] == ["separation", "husky/workspace", "jackal/workspace"]
    assert cert["checks_source"] == "scenario checks"


def test_a_robot_observed_alone_for_long_makes_the_run_inconclusive(tmp_path: Path) -> None:
    a = KIT.Path(((0.0, 1.0, 5.0), (10.0, 6.0, 5.0)))
    b = KIT.Path(((0.0, 1.0, 1.0), (10.0, 3.0, 1.0)))
    log = KIT.write_fleet_log(tmp_path / "late.bag", [
        KIT.RobotLog(a, "/a/pose", "pose", 10.0), KIT.RobotLog(b, "/b/odom", "odom", 7.0),
        KIT.RobotLog(C_SLOW, "/c/pose", "pose", 30.0, start_s=3.0)])
    cert = certify_log(log, _scenario("G !(a.door & b.door)")).certificate
    assert all(c["verdict"] == "pass" for c in cert["checks"] if c["name"] != "c/workspace")
    assert cert["fleet"]["joint_span_s"] == [3.0, 10.0]
    assert cert["verdict"] == "inconclusive"
    assert "robot a: observed 0.0-10.0 s, but every robot only 3.0-10.0 s" in cert["verdict_reason"]
