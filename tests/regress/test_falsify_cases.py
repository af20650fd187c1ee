"""Falsification cases in a regression suite: a counterexample where the baseline had none is a regression."""

from __future__ import annotations

from collections.abc import Callable
from pathlib import Path

import pytest

from tubempc.regress import SuiteError, compare, expand_falsify, expand_suite, format_diff, load_suite, run_cases
from tubempc.scenario import builtin_scenario_text

SUITE = """\
name: small
scenarios:
  - name: nexus
    scenario: lab.yaml
    runs:
      - {name: R4-R5, start: R4, targets: [R5]}
seeds: [0]
disturbances: [none]
falsify:
  - {name: R4-R5, scenario: nexus, start: R4, target: R5, method: random, budget: 3, seed: 1}
"""


@pytest.fixture
def suite(tmp_path: Path) -> Path:
    (tmp_path / "lab.yaml").write_text(builtin_scenario_text())
    (tmp_path / "suite.yaml").write_text(SUITE)
    return tmp_path / "suite.yaml"


def test_falsification_cases_expand_beside_the_runs(suite: Path) -> None:
    loaded = load_suite(suite)
    (case,) = expand_falsify(loaded)
    assert case.run_id == "nexus.falsify.R4-R5"
    assert case.scenario_ref == str(suite.parent / "lab.yaml")
    assert [c.run_id for c in expand_suite(loaded)] == ["nexus.R4-R5.none.s0"]


def test_a_new_counterexample_regresses(suite: Path, tmp_path: Path, quarter_gain: Callable[[], None]) -> None:
    loaded = load_suite(suite)
    cases = expand_falsify(loaded)
    (good,) = run_cases(cases, workers=1, progress=False, out_dir=tmp_path / "good")
    assert good.error is None, good.error
    assert good.metrics["falsify.violation"] is False and good.metrics["falsify.simulations"] == 3
    assert (tmp_path / "good" / "nexus.falsify.R4-R5" / "falsify.json").is_file()
    baseline = {"runs": {good.run_id: {"metrics": good.metrics}}}

    quarter_gain()  # the bug: a quarter of the designed gain
    (bad,) = run_cases(cases, workers=1, progress=False)  # in this process, so the patch applies
    assert bad.metrics["falsify.violation"] is True
    comparison = compare(baseline, [bad], loaded.suite.tolerances)
    assert comparison.regressed
    assert {r.metric for r in comparison.by_status("regressed")} == {"falsify.violation"}, format_diff(comparison)


def test_the_same_search_on_the_same_controller_does_not_regress(suite: Path) -> None:
    loaded = load_suite(suite)
    cases = expand_falsify(loaded)
    (a,) = run_cases(cases, workers=1, progress=False)
    comparison = compare({"runs": {a.run_id: {"metrics": {**a.metrics, "falsify.violation": True}}}}, [a],
                         loaded.suite.tolerances)
    assert not comparison.regressed and [r.status for r in comparison.rows] == ["improved"]


def test_a_falsification_case_names_a_missing_region(tmp_path: Path) -> None:
    (tmp_path / "lab.yaml").write_text(builtin_scenario_text())
    (tmp_path / "suite.yaml").write_text(SUITE.replace("target: R5, method", "target: R55, method"))
    with pytest.raises(SuiteError, match=r"falsify\[0\]\.target"):
        load_suite(tmp_path / "suite.yaml")
