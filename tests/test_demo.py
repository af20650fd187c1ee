"""`tubempc demo`: the paper's experiment end to end passes certification and writes every promised file."""

from __future__ import annotations

import json
import subprocess
import sys
from pathlib import Path

import pytest

from tubempc.scenario import builtin_scenario
from verify import certify_log


def test_demo_end_to_end(tmp_path: Path) -> None:
    out = tmp_path / "demo"
    proc = subprocess.run([sys.executable, "-m", "tubempc", "demo", "--out", str(out)], capture_output=True,
                          text=True, timeout=600, check=False)
    assert proc.returncode == 0, proc.stdout + proc.stderr
    assert "certificate: pass" in proc.stdout
    for name in ("demo.mcap", "demo.bag", "plan.json", "certificate.json", "report.md", "report.html", "junit.xml"):
        assert (out / name).exists(), name
    cert = json.loads((out / "certificate.json").read_text())
    assert cert["verdict"] == "pass"
    # the ROS1 copy of the run certifies the same way
    assert certify_log(out / "demo.bag", builtin_scenario()).verdict == "pass"
    report = (out / "report.md").read_text()
    for paper_time in ("17.3", "20.1", "18.2", "18.5", "15.7"):
        assert paper_time in report
    assert "R5 -&gt; R1" in report and "cannot be reproduced" in report
    html = (out / "report.html").read_text()
    assert "Demo: transition times" in html and "data:image/png;base64," in html
    # the run-dependent rows: every planned and every executed (region, time) of this run is in the report's
    # table, in order (the paper's times above are constants; these come from plan.json and the certificate)
    plan = json.loads((out / "plan.json").read_text())
    table = report[report.index("Demo: the planned run and the executed one"):]
    rows = [line for line in table.splitlines() if line.startswith("| ") and line[2:3].isdigit()]
    planned = [(str(e["region"]), float(e["time"])) for e in plan["run"]]
    executed = [(str(e["region"]), float(e["time"])) for e in cert["timed_run"]]
    assert len(rows) == max(len(planned), len(executed))
    for k, row in enumerate(rows):
        cells = [c.strip() for c in row.strip("|").split("|")]
        if k < len(planned):
            assert cells[1] == planned[k][0] and float(cells[2]) == pytest.approx(planned[k][1], rel=1e-5)
        if k < len(executed):
            assert cells[3] == executed[k][0] and float(cells[4]) == pytest.approx(executed[k][1], rel=1e-5)
    # the plan's arrivals fall inside the formula's windows
    times = {e["region"]: e["time"] for e in plan["run"][1:]}
    assert 30 <= times["R3"] <= 50
    assert 80 <= times["R1"] <= 110


def test_demo_refuses_to_overwrite(tmp_path: Path) -> None:
    out = tmp_path / "demo"
    out.mkdir()
    (out / "demo.mcap").write_bytes(b"keep me")
    proc = subprocess.run([sys.executable, "-m", "tubempc", "demo", "--out", str(out)], capture_output=True,
                          text=True, timeout=600, check=False)
    assert proc.returncode == 3
    assert "exists already" in proc.stderr
    assert (out / "demo.mcap").read_bytes() == b"keep me"
