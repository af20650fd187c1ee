"""One judgement, told the same everywhere (issue 22) and no exit 70 on constant or degenerate formulas and values
(issue 29, items 11 and 14): regression tests from the reproducers.

The certificate states, per obligation (the whole formula and each top-level conjunct), its verdict, its margin with
the atom (and so the unit) it is the value of, its first violation, when it was decided, and for an undecided one
what was unknown; the reports, JUnit, ``certify -v`` and ``watch`` read those values and never judge again.
"""

from __future__ import annotations

import json
import math
import re
import subprocess
import sys
import xml.etree.ElementTree as ET
from collections.abc import Callable
from pathlib import Path
from typing import Any

import numpy as np
import pytest
import yaml

from tubempc.scenario import Scenario, load_scenario
from verify import certify_data, certify_log
from verify.certificate import Certificate
from verify.ingest import LogData, PoseStream
from verify.ingest.fields import SignalStream
from verify.online import OnlineMonitor
from verify.online.monitor import feed_log_data
from verify.semantics.timed_run import check_timed_run

ROOT = Path(__file__).resolve().parents[2]
T0 = 1_700_000_000 * 10**9


def _parked(scenario: Scenario, where: str = "R1", *, n: int = 31, dt_s: float = 0.1,
            x: float | None = None, y: float | None = None) -> LogData:
    """A robot parked in ``where`` (3 s at 10 Hz by default), as an in-memory log."""
    cx, cy = scenario.region(where).center
    t = T0 + np.round(np.arange(n) * dt_s * 1e9).astype(np.int64)
    pose = PoseStream(t, np.full(n, cx if x is None else x), np.full(n, cy if y is None else y), np.zeros(n))
    counts = {"read": n, "judged": n, "merged_duplicates": 0, "conflicting_duplicates": 0}
    return LogData("<parked>", "in-memory", "0" * 64, "sha256", "header", T0, pose,
                   {"topic": "/pose", "type": "geometry_msgs/msg/PoseStamped"}, None, None, None, (), None,
                   {"notes": [], "missing_definitions": []}, False, pose_samples=pose,
                   time_base_requested="header", samples={"pose": {**counts, "retimed": 0}}, signals={})


CONSTANT_OR_DEGENERATE = ["X(2,2.5] mission_1", "F[5,inf) mission_2", "G[0,inf) !obs_1 & false", "false",
                          "G !true", "F[0,5] false", "X (F (false))", "mission_1 U[5,inf) mission_2", "true",
                          "!(F[0,1] true)", "G[0,99999] mission_1"]


@pytest.mark.parametrize("spec", CONSTANT_OR_DEGENERATE)
def test_constant_and_degenerate_formulas_give_a_valid_certificate(scenario: Scenario, spec: str) -> None:
    """Exit 70 before: 'spec_trajectory failed without a first violation time and a margin'."""
    result = certify_data(_parked(scenario), scenario, spec=spec, checks=["spec"])
    cert = Certificate.model_validate(result.certificate)
    assert result.exit_code in (0, 1, 2)
    for entry in (*cert.checks, *cert.obligations):
        if entry.verdict.value == "fail":
            assert entry.first_violation_time is not None
            assert entry.margin is not None or entry.margin_reason, entry
            assert entry.explanation
    spec_traj = cert.check("spec_trajectory")
    assert spec_traj is not None
    if spec in ("false", "G !true", "G[0,inf) !obs_1 & false", "X(2,2.5] mission_1"):
        assert spec_traj.verdict.value == "fail" and spec_traj.margin is None
        assert spec_traj.margin_reason is not None and "constants or timing" in spec_traj.margin_reason
    if spec == "true":
        assert spec_traj.verdict.value == "pass" and spec_traj.margin is None and spec_traj.margin_reason


def test_constant_false_formulas_on_the_command_line_are_not_exit_70(tmp_path: Path, scenario: Scenario,
                                                                     make_log: Callable[..., Path],
                                                                     traj_cls: type[Any]) -> None:
    t = np.arange(0.0, 3.0 + 1e-9, 0.1)
    cx, cy = scenario.region("R1").center
    log = make_log("mcap", traj_cls(t, np.full(t.size, cx), np.full(t.size, cy), np.zeros(t.size)))
    for k, spec in enumerate(["false", "X (F (false))", "F[0,5] false", "G[0,inf) !obs_1 & false"]):
        out = tmp_path / f"out{k}"
        run = subprocess.run([sys.executable, "-m", "tubempc", "-v", "certify", str(log), "--scenario", "nexus-sml",
                              "--spec", spec, "--out", str(out), "--checks", "spec"],
                             capture_output=True, text=True, timeout=600, check=False)
        assert run.returncode in (1, 2), (spec, run.stderr)
        cert = json.loads((out / "certificate.json").read_text())
        Certificate.model_validate(cert)
        assert "why:" in run.stderr  # -v: the explanation of a result that is not a pass


def test_a_region_whose_margins_overflow_and_infinite_values_give_a_valid_certificate(
        tmp_path: Path, scenario: Scenario) -> None:
    """Issue 29, items 11 and 14: a region radius of 1e308 makes margins -inf; every pose +-inf; a signal value
    -inf; every command +inf. Each is a certificate, its failed checks without a finite margin saying why."""
    data = yaml.safe_load((ROOT / "tubempc" / "scenario" / "builtin" / "nexus-sml.yaml").read_text())
    for region in data["regions"]:
        if region["name"] == "R6":
            region["radius"] = 1e308
    path = tmp_path / "big.yaml"
    path.write_text(yaml.safe_dump(data))
    big = load_scenario(path)
    for spec in (None, "G !obs_1", "F[0,2] !obs_1"):
        res = certify_data(_parked(big), big, spec=spec)
        cert = Certificate.model_validate(res.certificate)
        clearance = cert.check("obstacle_clearance")
        assert clearance is not None and clearance.verdict.value == "fail"
        assert clearance.margin is not None or clearance.margin_reason
    for x, y in ((math.inf, math.inf), (-math.inf, 0.0)):
        res = certify_data(_parked(scenario, x=x, y=y), scenario)
        cert = Certificate.model_validate(res.certificate)
        ws = cert.check("workspace")
        assert ws is not None and ws.verdict.value == "fail" and ws.margin is None
        assert ws.margin_reason is not None and "-inf" in ws.margin_reason
    log = _parked(scenario)
    n = log.pose.t_ns.size
    commands = LogData(**{**{k: getattr(log, k) for k in log.__dataclass_fields__},
                          "cmd_t_ns": log.pose.t_ns.copy(), "cmd_u": np.full((n, 3), math.inf)})
    res = certify_data(commands, scenario, checks=["input_box"])
    box = Certificate.model_validate(res.certificate).check("input_box")
    assert box is not None and box.verdict.value == "fail" and box.margin is None and box.margin_reason
    room = load_scenario(ROOT / "docs" / "examples" / "diffdrive-room.yaml")
    pose = _parked(room, "dock")
    sig = SignalStream("slow", room.signals["slow"], pose.pose.t_ns.copy(), np.full(n, -math.inf), 100_000_000,
                       "header")
    with_signal = LogData(**{**{k: getattr(pose, k) for k in pose.__dataclass_fields__}, "signals": {"slow": sig}})
    res = certify_data(with_signal, room, spec="G[0,inf) !slow")
    cert = Certificate.model_validate(res.certificate)
    assert cert.obligations[0].verdict.value == "fail"
    assert cert.obligations[0].margin is None and "slow" in (cert.obligations[0].margin_reason or "")


def test_the_timed_run_pending_next_is_a_fail_at_its_window_end() -> None:
    """The mutant named in issue 22 (``>=`` for ``>`` in the pending test of ``_next``) turned this fail into
    inconclusive: the window (0, 2] closes exactly at the end of observation, with no next entry in it."""
    res = check_timed_run("X[0,2] p", [("A", 0.0)], {"A": []}, end=2.0)
    assert res.verdict == "fail"
    assert check_timed_run("X[0,2] p", [("A", 0.0)], {"A": []}, end=1.999999999).verdict == "inconclusive"
    assert check_timed_run("X[0,2] p", [("A", 0.0), ("B", 2.0)], {"A": [], "B": ["p"]}, end=2.0).verdict == "pass"


def test_next_measures_the_time_from_each_entry_not_from_time_0() -> None:
    """A mutant of ``_next`` that adds the entry's time to the next one's instead of subtracting it survived the
    fast suite (every X was evaluated at time 0 only)."""
    run = [("A", 0.0), ("P", 5.0), ("Q", 5.5)]
    labels = {"A": [], "P": ["p"], "Q": ["q"]}
    assert check_timed_run("G[0,inf) (p -> X[0,1] q)", run, labels, end=6.0).verdict == "pass"
    assert check_timed_run("G[0,inf) (p -> X[0,0.4] q)", run, labels, end=6.0).verdict == "fail"
    assert check_timed_run("G[0,inf) (p -> X[0.6,1] q)", run, labels, end=6.0).verdict == "fail"


def _tree_scenario(tmp_path: Path) -> Scenario:
    """A field with a tree on the path (unsafe) and a far corner to reach."""
    path = tmp_path / "field.yaml"
    path.write_text(yaml.safe_dump({
        "name": "field", "workspace": {"x": [0.0, 60.0], "y": [0.0, 40.0]}, "robot": {"radius": 0.3},
        "inputs": {"model": "unicycle", "max_abs": [1.0, 1.0]}, "mocap": {"rate_hz": 10.0},
        "regions": [{"name": "start", "center": [5.0, 5.0], "radius": 2.0, "labels": ["home"]},
                    {"name": "tree", "center": [20.0, 5.0], "radius": 1.0, "labels": ["tree"], "unsafe": True},
                    {"name": "ne", "center": [55.0, 35.0], "radius": 2.0, "labels": ["ne_corner"]}],
        "spec": "G[0,inf) !tree & F[0,60] ne_corner", "topics": {"pose": "/odom"}}))
    return load_scenario(path)


def test_margins_are_attributed_to_the_atom_they_are_the_value_of(tmp_path: Path) -> None:
    """Issue 22: the Husky run clipped a tree for about a second and never reached the north-east corner. The
    whole formula's margin is the corner's (the most violated obligation), and the certificate says so; each
    obligation has its own margin; the timed run's margin for the tree is how long the robot stayed there, not the
    time to its next timed-run entry."""
    sc = _tree_scenario(tmp_path)
    t = np.arange(0.0, 70.0, 0.1)
    x = np.clip(5.0 + 0.5 * t, 5.0, 40.0)  # through the tree at x = 20 (t = 30 s), then on to x = 40
    y = np.full(t.size, 5.0)
    n = t.size
    pose = PoseStream(T0 + np.round(t * 1e9).astype(np.int64), x, y, np.zeros(n))
    counts = {"read": n, "judged": n, "merged_duplicates": 0, "conflicting_duplicates": 0}
    log = LogData("<field>", "in-memory", "0" * 64, "sha256", "header", T0, pose, {"topic": "/odom"}, None, None,
                  None, (), None, {"notes": []}, False, pose_samples=pose, samples={"pose": {**counts, "retimed": 0}})
    cert = Certificate.model_validate(certify_data(log, sc).certificate)
    whole, tree, corner = cert.obligations
    assert (tree.formula, corner.formula) == ("G[0,inf) !tree", "F[0,60] ne_corner")
    assert tree.verdict.value == corner.verdict.value == whole.verdict.value == "fail"
    assert tree.margin_atom == "tree" and tree.margin == pytest.approx(-1.3, abs=0.06)  # radius 1 + robot 0.3
    assert corner.margin_atom == "ne_corner" and corner.margin < tree.margin
    assert whole.margin == corner.margin and whole.margin_atom == "ne_corner"
    spec = cert.check("spec_trajectory")
    assert spec is not None and spec.details["margin_atom"] == "ne_corner" and spec.margin_unit == "m"
    assert whole.first_violation_time == pytest.approx(tree.first_violation_time)  # the earliest violation
    assert "ne_corner at" in (whole.explanation or "")
    run = cert.check("spec_timed_run")
    assert run is not None and run.verdict.value == "fail"


def test_timed_run_margin_is_the_stay_not_the_time_to_the_next_entry() -> None:
    """Entries: the robot in a tree region at 10 s (for 1 s), then nothing until a corner region at 90 s."""
    contains = np.zeros((2, 1000), dtype=bool)
    t = np.arange(1000) * 0.1
    contains[0, 100:110] = True  # tree, 10.0 - 11.0 s
    contains[1, 900:] = True  # corner, from 90 s
    from verify.semantics.timed_run import entry_exits, timed_run_of_sets

    run, labels = timed_run_of_sets(contains, t, ["tree", "corner"], {"tree": ["tree"], "corner": ["corner"]})
    exits = entry_exits(contains, t)
    assert exits == pytest.approx([11.0, 99.9])
    res = check_timed_run("G[0,inf) !tree", run, labels, end=99.9, exits=exits)
    assert res.verdict == "fail" and res.margin_s == pytest.approx(-1.0)
    old = check_timed_run("G[0,inf) !tree", run, labels, end=99.9)  # without exits: to the next entry
    assert old.margin_s == pytest.approx(-80.0)


def test_the_walkthroughs_report_shows_the_certificates_pass(tmp_path: Path) -> None:
    """Issue 22: docs' differential-drive walkthrough: certificate pass, but the report's panel said
    'G[0,inf) (!table & slow): FAIL violated at 0.00 s' (the panel judged again, without the signal data)."""
    out = tmp_path / "report"
    run = subprocess.run([sys.executable, "-m", "tubempc", "-v", "certify", str(ROOT / "logs" / "diffdrive_odom.bag"),
                          "--scenario", str(ROOT / "docs" / "examples" / "diffdrive-room.yaml"), "--out", str(out)],
                         capture_output=True, text=True, timeout=900, check=False)
    assert run.returncode == 0, run.stderr
    cert = json.loads((out / "certificate.json").read_text())
    assert cert["verdict"] == "pass"
    assert [(o["formula"], o["verdict"]) for o in cert["obligations"]][1:] == [
        ("G[0,10] in_room", "pass"), ("G[0,inf) (!table & slow)", "pass"), ("F[15,25] dock", "pass")]
    slow = cert["obligations"][2]
    assert slow["margin_atom"] == "slow" and slow["margin_unit"] == "m/s"
    md = (out / "report.md").read_text()
    page = re.sub(r"data:image/png;base64,[^\"]*", "", (out / "report.html").read_text())
    for text in (md, page):
        assert "violated at 0.00" not in text and "FAIL" not in text
    assert "G\\[0,inf) (!table & slow) | pass | 0.1 m/s (slow)" in md
    suite = ET.parse(out / "junit.xml").getroot().find("testsuite")
    assert suite is not None and suite.get("failures") == "0"
    assert {c.get("name") for c in suite.iter("testcase") if c.get("classname", "").endswith(".obligations")} >= {
        "G[0,inf) (!table & slow)", "F[15,25] dock"}
    assert "obligation G[0,inf) (!table & slow): pass, margin 0.1 m/s (slow)" in run.stderr
    from verify import figures

    source = Path(figures.__file__).read_text()
    assert "check_trajectory" not in source and "judge_formula" not in source  # the figures judge nothing


def test_an_inconclusive_result_says_what_is_unknown_and_what_would_decide_it(scenario: Scenario) -> None:
    res = certify_data(_parked(scenario), scenario, spec="G[0,inf) !obs_1 & F[0,10] mission_2", checks=["spec"])
    cert = Certificate.model_validate(res.certificate)
    late = cert.obligations[2]
    assert late.verdict.value == "inconclusive" and late.unknown is not None
    assert late.unknown.atom is None and late.unknown.to_s == pytest.approx(10.0)
    assert "past the end of the log at 3.00 s" in late.unknown.cause and "10.00 s" in late.unknown.decide
    spec = cert.check("spec_trajectory")
    assert spec is not None and spec.explanation == cert.obligations[0].explanation
    # a pose sample that is unknown: the atom, when, and why
    log = _parked(scenario)
    x = log.pose.x_m.copy()
    x[12] = math.nan
    nan_log = LogData(**{**{k: getattr(log, k) for k in log.__dataclass_fields__},
                         "pose": PoseStream(log.pose.t_ns, x, log.pose.y_m, log.pose.theta_rad)})
    cert = Certificate.model_validate(certify_data(nan_log, scenario, spec="G[0,inf) !obs_1",
                                                   checks=["spec"]).certificate)
    unknown = cert.obligations[0].unknown
    assert unknown is not None and unknown.atom == "obs_1" and unknown.from_s == pytest.approx(1.1)
    assert "unknown" in unknown.cause


def test_watch_margins_do_not_depend_on_the_batching(scenario: Scenario) -> None:
    """Issue 22: one log printed 'F[35] loops PASS margin +1.232' in one run and '+0.450' in another. A decision
    states its margin only once final; the final margins equal the certificate's whatever the batching."""
    from verify.ingest import read_log

    log = read_log(ROOT / "logs" / "obstacle_touch.bag", scenario)
    cert = certify_log(ROOT / "logs" / "obstacle_touch.bag", scenario).certificate
    lines = set()
    for every in (1, 37, 0):
        mon = OnlineMonitor(scenario)
        decisions = feed_log_data(mon, log, update_every=every)
        res = mon.close()
        decisions += mon.final_decisions
        lines.add(tuple(d.line() for d in decisions))
        finals = {c.name: c.margin for c in (*res.state.obligations, *res.state.checks)}
        for o in cert["obligations"][1:]:
            want = o["margin"]
            got = finals[o["formula"]]
            assert (got is None and want is None) or got == pytest.approx(want, abs=2e-9), o["formula"]
    assert len(lines) == 1  # the same lines whatever the batching
