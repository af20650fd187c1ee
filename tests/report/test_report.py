"""Reports next to the certificate: files, self-contained HTML with its figures, JUnit structure, escaping."""

from __future__ import annotations

import base64
import xml.etree.ElementTree as ET
from collections.abc import Callable
from html.parser import HTMLParser
from pathlib import Path
from typing import Any

import numpy as np
import pytest

from tubempc.scenario import Scenario
from verify.certificate import Certificate
from verify.figures import workspace_figure
from verify.report import write_reports

PNG_MAGIC = b"\x89PNG\r\n\x1a\n"


class _Collector(HTMLParser):
    def __init__(self) -> None:
        super().__init__()
        self.tags: list[tuple[str, dict[str, str | None]]] = []
        self.text: list[str] = []

    def handle_starttag(self, tag: str, attrs: list[tuple[str, str | None]]) -> None:
        self.tags.append((tag, dict(attrs)))

    def handle_data(self, data: str) -> None:
        self.text.append(data)


def _parse(path: Path) -> _Collector:
    parser = _Collector()
    parser.feed(path.read_text(encoding="utf-8"))
    parser.close()
    return parser


@pytest.fixture(scope="module")
def failing_report(tmp_path_factory: pytest.TempPathFactory,
                   make_result: Callable[..., Any]) -> tuple[Path, dict[str, Path], Any]:
    """One rendering of the failing double's reports, shared by the read-only tests below."""
    from tubempc.scenario import builtin_scenario

    folder = tmp_path_factory.mktemp("report")
    result = make_result(verdict="fail")
    return folder, write_reports(result, builtin_scenario(), folder, suite_name="run.mcap"), result


def test_files_and_figures(failing_report: tuple[Path, dict[str, Path], Any]) -> None:
    tmp_path, written, _ = failing_report
    expected = {"report.md", "report.html", "junit.xml", "figures/workspace.png", "figures/obligations.png",
                "figures/clearance.png", "figures/states.png", "figures/tube.png", "figures/inputs.png",
                "figures/sampling.png"}
    assert set(written) == expected
    for rel, path in written.items():
        assert path == tmp_path / rel and path.stat().st_size > 0
        if rel.endswith(".png"):
            assert path.read_bytes().startswith(PNG_MAGIC)
    md = (tmp_path / "report.md").read_text()
    assert md.startswith("# Certificate: FAIL")
    for stem in ("workspace", "obligations", "clearance", "states", "tube", "inputs", "sampling"):
        assert f"(figures/{stem}.png)" in md
    assert "| tube | fail |" in md and "12.50 s" in md


def test_html_is_self_contained_with_embedded_figures(failing_report: tuple[Path, dict[str, Path], Any]) -> None:
    tmp_path = failing_report[0]
    page = _parse(tmp_path / "report.html")
    imgs = [attrs for tag, attrs in page.tags if tag == "img"]
    assert len(imgs) == 7
    for attrs in imgs:
        src = attrs["src"] or ""
        assert src.startswith("data:image/png;base64,")
        assert base64.b64decode(src.split(",", 1)[1]).startswith(PNG_MAGIC)
    # nothing is fetched from anywhere: no scripts, no external links or sources
    assert not [t for t, _ in page.tags if t in ("script", "link", "iframe", "object", "embed")]
    for _, attrs in page.tags:
        for key in ("src", "href"):
            assert not (attrs.get(key) or "").startswith(("http:", "https:", "//", "file:"))
    text = " ".join(page.text)
    assert "tube" in text and "R3" in text and "19.2" in text


def test_strings_from_log_and_scenario_are_escaped(tmp_path: Path, scenario: Scenario,
                                                   make_result: Callable[..., Any]) -> None:
    evil_scenario = scenario.model_copy(update={"name": '<script>alert("s")</script>'})
    write_reports(make_result(evil=True), evil_scenario, tmp_path)
    page = _parse(tmp_path / "report.html")
    tags = [t for t, _ in page.tags]
    assert "script" not in tags
    assert tags.count("img") == 7  # the injected <img> stayed text
    text = "".join(page.text)
    assert '<script>alert("x")</script>' in text and '<script>alert("s")</script>' in text
    md = (tmp_path / "report.md").read_text()
    assert "<script>" not in md and "&lt;script&gt;" in md
    junit = ET.parse(tmp_path / "junit.xml").getroot()
    names = [c.get("name") for c in junit.iter("testcase")]
    assert '<script>alert("x")</script><img src="http://evil.example/x.png">&' in names


def test_junit_one_case_per_check_and_per_obligation(failing_report: tuple[Path, dict[str, Path], Any]) -> None:
    tmp_path, _, result = failing_report
    root = ET.parse(tmp_path / "junit.xml").getroot()
    assert root.tag == "testsuites"
    (suite,) = root.findall("testsuite")
    assert suite.get("name") == "run.mcap"
    # the inconclusive check is a failure too (dashboards paint <skipped> green): 2 failures, nothing skipped
    assert (suite.get("tests"), suite.get("failures"), suite.get("skipped"), suite.get("errors")) == ("5", "2", "0",
                                                                                                      "0")
    cases = {c.get("name"): c for c in suite.findall("testcase") if c.get("classname") == "run.mcap"}
    assert list(cases) == [c["name"] for c in result.certificate["checks"]]
    obligations = [c for c in suite.findall("testcase") if c.get("classname") == "run.mcap.obligations"]
    assert [c.get("name") for c in obligations] == [f"{o['formula']} (whole formula)"
                                                    for o in result.certificate["obligations"]]
    failure = cases["tube"].find("failure")
    assert failure is not None and "12.5" in (failure.get("message") or "")
    assert failure.get("type") == "violation"
    undecided = cases["inputs"].find("failure")
    assert undecided is not None and undecided.get("type") == "inconclusive" and cases["inputs"].find("skipped") is None
    assert list(cases["mitl_timed_run"]) == []  # a passing check has no child element
    props = {p.get("name"): p.get("value") for p in suite.iter("property")}
    assert props["verdict"] == "fail" and props["log_sha256"] == "cd" * 32


def test_junit_inconclusive_can_stay_skipped(tmp_path: Path, scenario: Scenario,
                                            make_result: Callable[..., Any]) -> None:
    write_reports(make_result(verdict="inconclusive"), scenario, tmp_path, junit_inconclusive="skipped")
    suite = ET.parse(tmp_path / "junit.xml").getroot().find("testsuite")
    assert suite is not None and (suite.get("failures"), suite.get("skipped")) == ("0", "1")
    write_reports(make_result(verdict="inconclusive"), scenario, tmp_path / "default")
    suite = ET.parse(tmp_path / "default" / "junit.xml").getroot().find("testsuite")
    assert suite is not None and (suite.get("failures"), suite.get("skipped")) == ("1", "0")


def test_one_junit_writer_for_certify_batch_and_regress() -> None:
    """certify, batch and regress all build ``verify.junit`` suites; no other module writes JUnit XML."""
    import re as _re

    root = Path(__file__).resolve().parents[2]
    writers = [p for folder in ("verify", "tubempc") for p in (root / folder).rglob("*.py")
               if _re.search(r"SubElement\([^)]*\"testcase\"|Element\(\"testsuites?\"", p.read_text(encoding="utf-8"))]
    assert [p.relative_to(root).as_posix() for p in writers] == ["verify/junit.py"]


def test_passing_run_and_missing_optional_data(tmp_path: Path, scenario: Scenario,
                                               make_result: Callable[..., Any]) -> None:
    written = write_reports(make_result(verdict="pass", with_optional=False), scenario, tmp_path)
    # without nominal/inputs/robustness the figures that need them are left out rather than drawn empty
    assert {k for k in written if k.startswith("figures/")} == {
        "figures/workspace.png", "figures/obligations.png", "figures/clearance.png", "figures/states.png",
        "figures/sampling.png"}
    suite = ET.parse(tmp_path / "junit.xml").getroot().find("testsuite")
    assert suite is not None and suite.get("failures") == "0" and suite.get("skipped") == "0"
    assert (tmp_path / "report.md").read_text().startswith("# Certificate: PASS")


def test_violation_is_drawn_on_the_map(scenario: Scenario, make_result: Callable[..., Any]) -> None:
    failing = make_result(verdict="fail")
    passing_cert = {**failing.certificate, "checks": [c for c in failing.certificate["checks"]
                                                      if c["verdict"] != "fail"]}
    with_mark = workspace_figure(Certificate.model_validate(failing.certificate), scenario, failing.trajectory,
                                 failing.nominal)
    without = workspace_figure(Certificate.model_validate(passing_cert), scenario, failing.trajectory, failing.nominal)
    again = workspace_figure(Certificate.model_validate(passing_cert), scenario, failing.trajectory, failing.nominal)
    assert again == without  # deterministic
    # the difference is the violation drawn in the failure colour: more pixels of that colour on the failing map
    from matplotlib.colors import to_rgb

    from verify.workspace_map import _FAIL_COLOUR

    def fail_pixels(png: bytes) -> int:
        import io

        import matplotlib.image as mpimg

        rgb = mpimg.imread(io.BytesIO(png), format="png")[..., :3]
        return int(np.count_nonzero(np.all(np.abs(rgb - np.asarray(to_rgb(_FAIL_COLOUR))) < 0.08, axis=-1)))

    assert fail_pixels(with_mark) > fail_pixels(without) + 20


def test_reports_and_batch_import_only_the_shared_parts_of_tubempc() -> None:
    import subprocess
    import sys

    code = ("import sys, verify.report, verify.figures, verify.batch; "
            "print(' '.join(m for m in sys.modules if m.startswith('tubempc')))")
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True, timeout=120)
    allowed = ("tubempc.mitl", "tubempc.scenario", "runkit")  # the bottom layers (docs/architecture.md)
    loaded = out.stdout.split()
    assert loaded and all(m in ("tubempc", "tubempc.errors") or m.startswith(allowed) for m in loaded), loaded
