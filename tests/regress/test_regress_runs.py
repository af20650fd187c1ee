"""`tubempc regress` end to end with the real controller and certifier: a baseline from the default controller,
then a deliberately degraded controller (a smaller sigma_low; a scaled-down ancillary gain) must be caught."""

from __future__ import annotations

import subprocess
import sys
import xml.etree.ElementTree as ET
from collections.abc import Callable
from pathlib import Path

import pytest

from tubempc.regress import (
    compare,
    default_baseline_path,
    expand_falsify,
    expand_suite,
    format_diff,
    load_suite,
    read_baseline,
    run_cases,
)
from tubempc.scenario import builtin_scenario_text

SUITE = """\
name: small
scenarios:
  - name: nexus
    scenario: lab.yaml
    runs:
      - {name: R1-R3, start: R1, targets: [R3]}
seeds: [0]
disturbances: [worst]
"""


def _regress(*args: str) -> subprocess.CompletedProcess[str]:
    return subprocess.run([sys.executable, "-m", "tubempc", "regress", "--no-progress", *args], capture_output=True,
                          text=True, timeout=600, check=False)


@pytest.fixture
def small_suite(tmp_path: Path) -> Path:
    (tmp_path / "lab.yaml").write_text(builtin_scenario_text())
    (tmp_path / "suite.yaml").write_text(SUITE)
    return tmp_path / "suite.yaml"


def test_smaller_sigma_low_is_caught(small_suite: Path, tmp_path: Path) -> None:
    base = tmp_path / "base.json"
    made = _regress("--suite", str(small_suite), "--baseline", str(base), "--update-baseline", "--workers", "1")
    assert made.returncode == 0, made.stderr
    assert read_baseline(base)["runs"]["nexus.R1-R3.worst.s0"]["metrics"]["arrived"] is True

    (tmp_path / "same" / "nexus.R1-R3.worst.s0").mkdir(parents=True)
    (tmp_path / "same" / "nexus.R1-R3.worst.s0" / "run.mcap").write_bytes(b"stale")  # an earlier run's output
    same = _regress("--suite", str(small_suite), "--baseline", str(base), "--workers", "1", "--out",
                    str(tmp_path / "same"), "--force")
    assert same.returncode == 0, same.stdout + same.stderr
    assert same.stdout.strip().splitlines()[-1].startswith("OK: 1 runs")
    assert (tmp_path / "same" / "nexus.R1-R3.worst.s0" / "certificate.json").is_file()

    lab = tmp_path / "lab.yaml"
    lab.write_text(lab.read_text().replace("sigma_low: 2.0", "sigma_low: 0.5"))
    worse = _regress("--suite", str(small_suite), "--baseline", str(base), "--workers", "1", "--out",
                     str(tmp_path / "worse"))
    assert worse.returncode == 1, worse.stdout + worse.stderr
    assert worse.stdout.startswith("REGRESSED")
    # the tube is four times wider: under the worst-case push the robot settles near the new r_q = 0.04 m
    assert "nexus.R1-R3.worst.s0  max_tube_error_m: 0.01 -> 0.0399" in worse.stdout
    junit = ET.parse(tmp_path / "worse" / "junit.xml").getroot()
    assert [c.find("failure") is not None for c in junit.iter("testcase")] == [True]


def test_scaled_down_gain_is_caught(small_suite: Path, quarter_gain: Callable[[], None]) -> None:
    loaded = load_suite(small_suite)
    cases = expand_suite(loaded)
    (good,) = run_cases(cases, workers=1, progress=False)
    assert good.error is None, good.error
    baseline = {"runs": {good.run_id: {"metrics": good.metrics}}}

    quarter_gain()  # the bug: a quarter of the designed gain
    (bad,) = run_cases(cases, workers=1, progress=False)  # in this process, so the patch applies
    comparison = compare(baseline, [bad], loaded.suite.tolerances)
    regressed = {r.metric for r in comparison.by_status("regressed")}
    assert {"tube_ratio", "max_tube_error_m", "verdict"} <= regressed, format_diff(comparison)
    assert bad.metrics["tube_ratio"] > 3.5  # worst case: |q| -> delta_bar / (sigma / 4) = 4 r_q
    assert any(m.startswith("check.") and m.endswith(".verdict") for m in regressed)  # the certificate's tube check


@pytest.mark.slow  # 10 closed-loop runs + a 10-simulation search (about 20 s idle, 40 s on a loaded runner)
def test_default_suite_matches_the_shipped_baseline(tmp_path: Path) -> None:
    out = _regress("--workers", "2", "--out", str(tmp_path / "out"))
    assert out.returncode == 0, out.stdout + out.stderr
    assert out.stdout.strip().splitlines()[-1].startswith("OK: 11 runs")
    junit = ET.parse(tmp_path / "out" / "junit.xml").getroot()
    assert len(list(junit.iter("testcase"))) == 11 and junit.get("failures") == "0"
    runs = read_baseline(default_baseline_path())["runs"]
    loaded = load_suite()
    assert len(runs) == len(expand_suite(loaded)) + len(expand_falsify(loaded)) == 11
    assert all(r["metrics"]["verdict"] == "pass" for k, r in runs.items() if ".falsify." not in k)
    assert runs["nexus-sml.falsify.R4-R5"]["metrics"]["falsify.violation"] is False


def test_runs_on_dask_like_inline(small_suite: Path) -> None:
    cases = expand_suite(load_suite(small_suite))
    (inline,) = run_cases(cases, workers=1, progress=False)
    (remote,) = run_cases(cases, workers=1, dask="local", progress=False)
    assert remote.error is None, remote.error
    timing = {"solve_time_p50_ms", "solve_time_p95_ms"}  # wall-clock: differs between processes
    assert {k: v for k, v in remote.metrics.items() if k not in timing} == \
        {k: v for k, v in inline.metrics.items() if k not in timing}
