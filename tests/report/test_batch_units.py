"""Batch certification with a test double for the certifier (inline): discovery, mixed codes, summaries."""

from __future__ import annotations

import csv
import json
import xml.etree.ElementTree as ET
from collections.abc import Callable
from pathlib import Path
from typing import Any

import pytest

import verify.batch.output as batch_output
import verify.batch.run as batch_run
from tubempc.scenario import Scenario
from verify.batch import certify_many, discover_logs, worst_exit_code, write_batch
from verify.errors import TruncatedLogError


def test_worst_exit_code_orders_by_severity() -> None:
    assert worst_exit_code([]) == 0
    assert worst_exit_code([0, 2, 0]) == 2
    assert worst_exit_code([2, 1, 0]) == 1  # a violation outranks an inconclusive log
    assert worst_exit_code([1, 3, 2]) == 3
    assert worst_exit_code([3, 70]) == 70


def test_discover_logs(tmp_path: Path) -> None:
    (tmp_path / "a.bag").write_bytes(b"")
    (tmp_path / "sub").mkdir()
    (tmp_path / "sub" / "b.mcap").write_bytes(b"")
    (tmp_path / "sub" / "notes.txt").write_text("x")
    bag2 = tmp_path / "sub" / "ros2bag"
    bag2.mkdir()
    (bag2 / "metadata.yaml").write_text("rosbag2_bagfile_information: {}")
    (bag2 / "ros2bag_0.db3").write_bytes(b"")  # inside a bag folder: part of that bag, not a log of its own
    (tmp_path / "empty").mkdir()
    logs, problems = discover_logs([tmp_path, tmp_path / "a.bag", tmp_path / "missing.mcap", tmp_path / "empty"])
    assert logs == [tmp_path / "a.bag", tmp_path / "sub" / "b.mcap", bag2]
    assert [p for p, _ in problems] == [str(tmp_path / "missing.mcap"), str(tmp_path / "empty")]
    assert "not found" in problems[0][1] and "no .bag" in problems[1][1]
    assert discover_logs([bag2]) == ([bag2], [])


def _fake_certifier(make_result: Callable[..., Any]) -> Callable[..., Any]:
    def certify(path: str, scenario: Scenario, **kwargs: Any) -> Any:
        name = Path(path).stem
        if name.startswith("broken"):
            raise TruncatedLogError("the file ends inside a chunk", path=path)
        if name.startswith("crash"):
            raise RuntimeError("boom")
        return make_result(verdict=name.split("_")[0])

    return certify


def test_mixed_batch_inline(tmp_path: Path, scenario: Scenario, make_result: Callable[..., Any],
                            monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.setattr(batch_run, "_certify_function", lambda: _fake_certifier(make_result))
    monkeypatch.setattr(batch_output, "_write_certificate",
                        lambda result, out: (out / "certificate.json").write_text(json.dumps(result.certificate)))
    logs = tmp_path / "logs"
    logs.mkdir()
    for name in ("pass_1.mcap", "inconclusive_1.bag", "broken.mcap"):
        (logs / name).write_bytes(b"")
    result = certify_many([logs], scenario, workers=1, progress=False)
    assert [i.verdict for i in result.items] == ["unusable", "inconclusive", "pass"]  # sorted by file name
    assert result.exit_code == 3
    assert "ends inside a chunk" in (result.items[0].error or "")
    (logs / "fail_1.mcap").write_bytes(b"")
    (logs / "broken.mcap").unlink()
    result = certify_many([logs / "pass_1.mcap", logs / "fail_1.mcap", logs / "inconclusive_1.bag"], scenario,
                          workers=1, progress=False)
    assert [i.exit_code for i in result.items] == [0, 1, 2] and result.exit_code == 1

    (logs / "crash.mcap").write_bytes(b"")
    result = certify_many([logs / "pass_1.mcap", logs / "crash.mcap", tmp_path / "nope.bag"], scenario, workers=1,
                          progress=False)
    assert [i.exit_code for i in result.items] == [0, 70, 3] and result.exit_code == 70
    assert "RuntimeError: boom" in (result.items[1].error or "")

    out = tmp_path / "out"
    files = write_batch(result, out, workers=1)  # in this process: the monkeypatched writer applies
    assert set(files) == {"summary.md", "summary.html", "summary.csv", "junit.xml"}
    page = files["summary.html"].read_text()
    assert '<a href="pass_1.mcap/report.html">' in page and "nope.bag" in page and "<script" not in page
    assert (out / "pass_1.mcap" / "certificate.json").is_file()
    assert (out / "pass_1.mcap" / "report.html").is_file()
    assert "boom" in (out / "crash.mcap" / "error.txt").read_text()
    with (out / "summary.csv").open() as fh:
        rows = list(csv.DictReader(fh))
    assert [(r["folder"], r["verdict"], r["exit_code"]) for r in rows] == [
        ("pass_1.mcap", "pass", "0"), ("crash.mcap", "error", "70"), ("nope.bag", "unusable", "3")]
    summary = (out / "summary.md").read_text()
    assert summary.startswith("# Batch certification: exit code 70")
    assert "(pass_1.mcap/report.md)" in summary
    root = ET.parse(out / "junit.xml").getroot()
    assert [s.get("name") for s in root.findall("testsuite")] == ["pass_1.mcap", "crash.mcap", "nope.bag"]
    assert root.get("errors") == "2"


def test_same_file_names_get_distinct_folders(tmp_path: Path, scenario: Scenario, make_result: Callable[..., Any],
                                              monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.setattr(batch_run, "_certify_function", lambda: _fake_certifier(make_result))
    for d in ("a", "b"):
        (tmp_path / d).mkdir()
        (tmp_path / d / "pass_run.mcap").write_bytes(b"")
    result = certify_many([tmp_path / "a", tmp_path / "b"], scenario, workers=1, progress=False)
    assert [i.name for i in result.items] == ["pass_run.mcap", "pass_run.mcap-2"]


def test_malformed_spec_stops_the_whole_batch(tmp_path: Path, scenario: Scenario) -> None:
    with pytest.raises(ValueError, match="column"):
        certify_many([tmp_path], scenario, spec="F[1,2 a")


def test_log_names_are_escaped_in_summaries(tmp_path: Path, scenario: Scenario, make_result: Callable[..., Any],
                                            monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.setattr(batch_run, "_certify_function", lambda: _fake_certifier(make_result))
    monkeypatch.setattr(batch_output, "_write_certificate",
                        lambda result, out: (out / "certificate.json").write_text(json.dumps(result.certificate)))
    evil = tmp_path / 'pass_<script>alert("x")<|>.mcap'
    evil.write_bytes(b"")
    batch = certify_many([evil], scenario, workers=1, progress=False)
    assert batch.items[0].name == "pass__script_alert_x_.mcap"  # a safe folder name
    files = write_batch(batch, tmp_path / "out", reports=False, workers=1)
    assert "<script>" not in files["summary.html"].read_text()
    assert "&lt;script&gt;" in files["summary.html"].read_text()
    md = files["summary.md"].read_text()
    assert "<script>" not in md and "\\|" in md  # the pipe cannot break the table


def test_worst_margin_of_a_failed_log_is_its_failed_checks(scenario: Scenario,
                                                            make_result: Callable[..., Any]) -> None:
    """A passing check's margin (here -0.0 < 0.3 > ...) never stands for a failed log; the most negative fail does."""
    from types import SimpleNamespace

    from verify.batch import BatchItem, BatchResult

    checks = [{"name": "workspace", "verdict": "pass", "margin": 0.3, "margin_unit": "m"},
              {"name": "spec_trajectory", "verdict": "fail", "margin": -0.2, "margin_unit": "m"},
              {"name": "obstacle_clearance", "verdict": "fail", "margin": -0.5, "margin_unit": "m"},
              {"name": "spec_timed_run", "verdict": "fail", "margin": -7.0, "margin_unit": "s"},  # seconds: not m
              {"name": "tube", "verdict": "pass", "margin": -0.9, "margin_unit": "m"}]  # a pass below the fails
    checks = [{**c, "first_violation_time": 1.0 if c["verdict"] == "fail" else None} for c in checks]
    base = make_result(verdict="fail").certificate  # a whole certificate: the batch reads the typed model

    def result(entries: list[dict[str, Any]], code: int) -> SimpleNamespace:
        return SimpleNamespace(certificate={**base, "checks": entries}, exit_code=code)

    item = BatchItem("a.bag", "a", 1, "fail", None, 0.1, result(checks, 1))  # type: ignore[arg-type]
    row = BatchResult((item,), scenario, None).rows()[0]
    assert row["worst_margin_m"] == -0.5
    ok = BatchItem("b.bag", "b", 0, "pass", None, 0.1, result(checks[:1], 0))  # type: ignore[arg-type]
    assert BatchResult((ok,), scenario, None).rows()[0]["worst_margin_m"] == 0.3


def test_a_worker_that_dies_twice_is_exit_70_and_the_batch_goes_on() -> None:
    from verify.batch.run import _Job, _worker_died

    item = _worker_died(_Job("x.bag", "x", None, None, "auto", False))  # type: ignore[arg-type]
    assert item.exit_code == 70 and item.verdict == "error" and "died twice" in (item.error or "")


def test_certificates_only_are_written_in_this_process(tmp_path: Path, scenario: Scenario,
                                                       make_result: Callable[..., Any],
                                                       monkeypatch: pytest.MonkeyPatch) -> None:
    """Without reports no pool (nor a second Dask cluster) is started: shipping every result with its frames to
    one cost more than writing its certificate here."""
    monkeypatch.setattr(batch_run, "_certify_function", lambda: _fake_certifier(make_result))
    monkeypatch.setattr(batch_output, "_write_certificate",
                        lambda result, out: (out / "certificate.json").write_text(json.dumps(result.certificate)))

    def no_pool(*args: Any, **kwargs: Any) -> Any:
        raise AssertionError("write_batch started an executor to write certificates only")

    monkeypatch.setattr(batch_output, "parallel_map", no_pool)
    for name in ("pass_a.mcap", "pass_b.mcap"):
        (tmp_path / name).write_bytes(b"")
    batch = certify_many([tmp_path / "pass_a.mcap", tmp_path / "pass_b.mcap"], scenario, workers=1, progress=False)
    files = write_batch(batch, tmp_path / "out", reports=False, workers=2, dask="local")
    assert (tmp_path / "out" / "pass_a.mcap" / "certificate.json").is_file()
    assert (tmp_path / "out" / "pass_b.mcap" / "certificate.json").is_file()
    assert files["junit.xml"].is_file()


def test_process_server_builds_the_first_call_caches() -> None:
    """The batch's process server preloads ``verify.batch.warm``: the MITL parser and both type stores are built
    before the workers fork, not in each worker's first log."""
    import subprocess
    import sys

    assert "verify.batch.warm" in batch_run._PRELOAD
    code = ("import verify.batch.warm; from tubempc.mitl.parser import _parser; "
            "from verify.ingest.decode import typestore; "
            "print(_parser.cache_info().currsize, typestore.cache_info().currsize)")
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True)
    assert out.stdout.split() == ["1", "2"]
