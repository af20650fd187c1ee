"""Regression suite files and the baseline comparison (no controller needed: metrics are given)."""

from __future__ import annotations

import json
import xml.etree.ElementTree as ET
from pathlib import Path

import pytest

from tubempc.regress import (
    BaselineError,
    RunOutcome,
    SuiteError,
    Tolerances,
    compare,
    comparison_junit,
    expand_suite,
    format_diff,
    load_suite,
    read_baseline,
    write_baseline,
)
from verify.junit import suite_element

BASE = {
    "verdict": "pass", "check.tube.verdict": "pass", "check.tube.margin": 0.004, "arrived": True,
    "t_ij_s.0.R3": 16.7, "tube_ratio": 0.95, "max_tube_error_m": 0.0095, "min_clearance_m": 0.08,
    "input_margin": 0.02, "workspace_margin_m": 0.3, "solver_failures": 0, "solver_backups": 0,
    "solve_time_p50_ms": 0.5, "solve_time_p95_ms": 0.9,
}


def _outcome(run_id: str, **changes: object) -> RunOutcome:
    return RunOutcome(run_id, {**BASE, **changes}, None, 1.0, None)


def test_default_suite_expands() -> None:
    loaded = load_suite()
    cases = expand_suite(loaded)
    assert len(cases) == len({c.run_id for c in cases}) == 10
    mission = next(c for c in cases if c.run_id == "nexus-sml.mission.worst.s0")
    assert mission.spec == loaded.scenarios["nexus-sml"].spec
    assert mission.targets == (("R1", 16.0), ("R3", 66.0), ("R1", None))
    leg = next(c for c in cases if c.run_id == "nexus-sml.R1-R3.random.s0")
    assert leg.spec == "G[0,inf) !(obs_1 | obs_2 | obs_3 | obs_4) & F[0,inf) mission_2"
    assert loaded.suite.tolerances.solve_time_p50_ms.allowed(1.0) == pytest.approx(9.0)  # 5 ms + 4 x 1 ms


@pytest.mark.parametrize(("patch", "field", "words"), [
    ("disturbances: [random, hurricane]", "disturbances", "unknown disturbance"),
    ("tolerances: {t_ij: 0.3}", "tolerances.t_ij", "unknown field"),
    ("tolerances: {t_ij_s: -1}", "tolerances.t_ij_s.abs", "greater than or equal"),
])
def test_malformed_suite_names_the_field(tmp_path: Path, patch: str, field: str, words: str) -> None:
    text = ("name: s\nscenarios:\n  - {name: a, scenario: nexus-sml, runs: [{name: r, start: R1, targets: [R3]}]}\n"
            "seeds: [0]\ndisturbances: [random]\n")
    key = patch.split(":", maxsplit=1)[0]
    lines = [ln for ln in text.splitlines() if not ln.startswith(key + ":")] + [patch]
    path = tmp_path / "suite.yaml"
    path.write_text("\n".join(lines) + "\n")
    with pytest.raises(SuiteError) as info:
        load_suite(path)
    assert str(path) in str(info.value) and field in str(info.value) and words in str(info.value)


def test_unknown_region_in_a_run(tmp_path: Path) -> None:
    path = tmp_path / "suite.yaml"
    path.write_text("name: s\nscenarios:\n  - {name: a, scenario: nexus-sml, runs: [{name: r, start: R1, "
                    "targets: [R42]}]}\nseeds: [0]\ndisturbances: [none]\n")
    with pytest.raises(SuiteError, match=r"scenarios\[0\]\.runs\[0\]\.targets\[0\]: region 'R42'"):
        load_suite(path)


def test_compare_directions_and_tolerances() -> None:
    baseline = {"runs": {rid: {"metrics": dict(BASE)} for rid in ("a", "b", "c", "gone")}}
    current = [
        # a: slower by 0.5 s (tolerance 0.3), tube check now fails, clearance a bit smaller (within 0.01)
        _outcome("a", **{"t_ij_s.0.R3": 17.2, "check.tube.verdict": "fail", "min_clearance_m": 0.075}),
        # b: faster and with a smaller tube ratio (improvements), and much slower solves (regression)
        _outcome("b", **{"t_ij_s.0.R3": 15.0, "tube_ratio": 0.5, "solve_time_p95_ms": 20.0}),
        # c: the transition is no longer reached
        _outcome("c", **{"t_ij_s.0.R3": None, "arrived": False}),
        _outcome("brand-new"),
        RunOutcome("broken", {}, "DesignError: tube too large", 0.1, None),
    ]
    comp = compare(baseline, current, Tolerances())
    regressed = {(r.run_id, r.metric) for r in comp.by_status("regressed")}
    assert regressed == {("a", "t_ij_s.0.R3"), ("a", "check.tube.verdict"), ("b", "solve_time_p95_ms"),
                         ("c", "t_ij_s.0.R3"), ("c", "arrived")}
    assert {(r.run_id, r.metric) for r in comp.by_status("improved")} == {("b", "t_ij_s.0.R3"), ("b", "tube_ratio")}
    assert [r.run_id for r in comp.by_status("new")] == ["brand-new"]
    assert [r.run_id for r in comp.by_status("error")] == ["broken"]
    assert [r.run_id for r in comp.by_status("missing")] == ["gone"]
    assert comp.regressed
    text = format_diff(comp)
    assert text.splitlines()[0] == "REGRESSED (5):"
    assert "a  t_ij_s.0.R3: 16.7 -> 17.2 (+0.5, tolerance 0.3)" in text
    assert "a  check.tube.verdict: pass -> fail" in text
    assert text.splitlines()[-1].startswith("REGRESSION: 5 runs")
    junit = suite_element(comparison_junit(comp, current, suite_name="t"))
    failed = [c.get("name") for c in junit.iter("testcase") if c.find("failure") is not None]
    errored = [c.get("name") for c in junit.iter("testcase") if c.find("error") is not None]
    assert failed == ["a", "b", "c", "brand-new"] and errored == ["broken"]
    assert ET.tostring(junit)


def test_within_tolerance_is_ok() -> None:
    baseline = {"runs": {"a": {"metrics": dict(BASE)}}}
    wiggle = _outcome("a", **{"t_ij_s.0.R3": 16.9, "tube_ratio": 0.99, "solve_time_p50_ms": 2.9})
    comp = compare(baseline, [wiggle], Tolerances())
    assert not comp.regressed and comp.rows == ()
    assert format_diff(comp).startswith("OK: 1 runs")


def test_baseline_round_trip(tmp_path: Path) -> None:
    suite = load_suite().suite
    path = write_baseline(tmp_path / "b.json", suite, [_outcome("a")])
    data = read_baseline(path)
    assert data["runs"]["a"]["metrics"] == BASE and data["suite_sha256"] == suite.sha256()
    assert not compare(data, [_outcome("a")], suite.tolerances).regressed
    with pytest.raises(BaselineError, match="failed"):
        write_baseline(tmp_path / "c.json", suite, [RunOutcome("x", {}, "boom", 0.0, None)])
    (tmp_path / "bad.json").write_text(json.dumps({"runs": {}}))
    with pytest.raises(BaselineError, match="not a regress baseline"):
        read_baseline(tmp_path / "bad.json")
    with pytest.raises(BaselineError, match="--update-baseline"):
        read_baseline(tmp_path / "none.json")


def test_cli_missing_baseline_is_one_line_exit_3(tmp_path: Path) -> None:
    import subprocess
    import sys

    out = subprocess.run([sys.executable, "-m", "tubempc", "regress", "--baseline", str(tmp_path / "none.json")],
                         capture_output=True, text=True, timeout=120, check=False)
    assert out.returncode == 3
    assert out.stderr.strip().splitlines()[-1].startswith("tubempc: error: ")
    assert "none.json: baseline not found" in out.stderr and "Traceback" not in out.stderr
