"""Report captions say what the figures draw; the sampling figure and the data-quality table use one dropout rule;
the data-quality heading counts findings, not descriptions."""

from __future__ import annotations

import json
from pathlib import Path
from types import SimpleNamespace
from typing import Any

import pytest

from tubempc.scenario import Scenario, builtin_scenario, load_scenario
from verify.certificate import Certificate
from verify.certify import certify_log
from verify.figures import render_figures, sampling_caption, states_caption
from verify.report import write_reports
from verify.workspace_map import workspace_caption

ROOT = Path(__file__).resolve().parents[2]


@pytest.fixture(scope="module")
def lab() -> tuple[Any, Scenario]:
    """The odometry-only walkthrough log: no nominal, no tube radius, a pass."""
    scenario = load_scenario(ROOT / "docs" / "examples" / "diffdrive-room.yaml")
    return certify_log(ROOT / "logs" / "diffdrive_odom.bag", scenario), scenario


def test_captions_name_no_nominal_or_tube_when_the_log_has_none(lab: tuple[Any, Scenario]) -> None:
    result, scenario = lab
    cert = Certificate.model_validate(result.certificate)
    assert result.nominal is None or len(result.nominal) == 0
    for text in (workspace_caption(cert, scenario, result.trajectory, result.nominal),
                 states_caption(cert, scenario, result.nominal)):
        assert "nominal" not in text and "tube" not in text, text
    figures = {f.stem: f.caption for f in render_figures(cert, scenario, trajectory=result.trajectory,
                                                          nominal=result.nominal, inputs=None, robustness=None)}
    assert "nominal" not in figures["workspace"] and "tube" not in figures["states"]
    assert "the path coloured by time" in figures["workspace"] and "timed run" in figures["workspace"]
    assert "violation" not in figures["workspace"]  # a pass: no violation is drawn


def test_captions_name_the_nominal_and_its_band_when_drawn() -> None:
    scenario = builtin_scenario()
    result = certify_log(ROOT / "logs" / "tube_breach.mcap", scenario)
    cert = Certificate.model_validate(result.certificate)
    text = workspace_caption(cert, scenario, result.trajectory, result.nominal)
    assert "the nominal path with its tube band" in text and "each first violation" in text
    assert "the nominal with its tube band" in states_caption(cert, scenario, result.nominal)


def test_sampling_figure_counts_the_dropouts_of_the_data_quality_table(lab: tuple[Any, Scenario]) -> None:
    """A gap of 2 periods is a dropout for the data-quality table (> 1.5 median periods): the figure circles what
    the table counts, by the threshold the certificate states (it circled only gaps > 2 periods before)."""
    result, scenario = lab
    traj = result.trajectory.drop(index=100).reset_index(drop=True)  # one gap of 0.2 s in a 10 Hz stream
    data = json.loads(json.dumps(result.certificate))
    assert data["data_quality"]["pose"]["dropouts"]["threshold_s"] == pytest.approx(0.15)
    data["data_quality"]["pose"]["dropouts"]["count"] = 1
    cert = Certificate.model_validate(data)
    assert "the 1 dropout(s) the data-quality table counts are circled" in sampling_caption(cert)
    assert "threshold" in sampling_caption(Certificate.model_validate(result.certificate))
    assert "circled" not in sampling_caption(Certificate.model_validate(result.certificate))
    figures = render_figures(cert, scenario, trajectory=traj, nominal=None, inputs=None, robustness=None)
    assert any(f.stem == "sampling" for f in figures)


def test_data_quality_heading_counts_findings_not_descriptions(lab: tuple[Any, Scenario], tmp_path: Path) -> None:
    """Rates, thresholds, conventions and counts read describe the streams: a clean log has no finding (the old
    heading said "26 finding(s) that report something" for it); a note is one."""
    result, scenario = lab
    written = write_reports(result, scenario, tmp_path / "clean")
    html = written["report.html"].read_text()
    assert "(no finding reports a problem; the rows describe the streams)" in html
    data = json.loads(json.dumps(result.certificate))
    data["data_quality"]["notes"] = ["the log's metadata names another scenario"]
    data["data_quality"]["pose"]["jumps"]["count"] = 3
    noted = SimpleNamespace(certificate=data, exit_code=result.exit_code, trajectory=result.trajectory,
                            nominal=None, inputs=None, robustness=None)
    written = write_reports(noted, scenario, tmp_path / "noted")
    html = written["report.html"].read_text()
    assert "(2 finding(s) that report something, listed first" in html
    md = written["report.md"].read_text()
    assert "2 finding(s) that report something" in md
    rows = md[md.index("| finding | value |"):].splitlines()[2:4]
    assert {r.split(" | ")[0].lstrip("| ") for r in rows} == {"notes", "pose.jumps.count"}
