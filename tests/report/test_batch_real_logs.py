"""Batch certification end to end: simulated logs (pass / fail / inconclusive / unusable) through the real
certifier, in worker processes and on a real Dask LocalCluster on loopback; summaries and the worst exit code."""

from __future__ import annotations

import csv
import shutil
import xml.etree.ElementTree as ET
from pathlib import Path

import pytest

from tubempc.control.closed_loop import Target, run_closed_loop
from tubempc.rosio import write_log
from tubempc.scenario import Scenario, builtin_scenario
from verify.batch import certify_many, summary_lines, write_batch

# R1 -> R3 reaches mission_2 at about 17 s: pass. R1 -> R2 never does: the log of about 20 s ends inside the
# [0, 60] window (inconclusive); held in R2 until 70 s the window closes unmet (fail).
SPEC = "G[0,inf) !(obs_1 | obs_2 | obs_3 | obs_4) & F[0,60] mission_2"


@pytest.fixture(scope="module")
def logs(tmp_path_factory: pytest.TempPathFactory) -> dict[str, Path]:
    scenario = builtin_scenario()
    root = tmp_path_factory.mktemp("logs")
    out: dict[str, Path] = {}
    runs = {"pass.mcap": ("R1", "R3", None), "inconclusive.bag": ("R1", "R2", None), "fail.mcap": ("R1", "R2", 70.0)}
    for name, (start, goal, t_end_s) in runs.items():
        result = run_closed_loop(scenario, [Target(goal)], start_region=start, disturbance="random", seed=1,
                                 t_end_s=t_end_s)
        out[name] = write_log(result, scenario, root / name)
    truncated = root / "truncated.mcap"
    data = out["pass.mcap"].read_bytes()
    truncated.write_bytes(data[: len(data) // 2])
    out["truncated.mcap"] = truncated
    (root / "junk.bag").write_bytes(b"this is not a bag")
    out["junk.bag"] = root / "junk.bag"
    return out


def _codes(batch: object) -> dict[str, int]:
    return {Path(i.path).name: i.exit_code for i in batch.items}  # type: ignore[attr-defined]


def test_mixed_batch_in_processes(logs: dict[str, Path], tmp_path: Path) -> None:
    scenario: Scenario = builtin_scenario()
    folder = logs["pass.mcap"].parent
    batch = certify_many([folder], scenario, spec=SPEC, workers=2, progress=False)
    assert _codes(batch) == {"fail.mcap": 1, "inconclusive.bag": 2, "junk.bag": 3, "pass.mcap": 0,
                             "truncated.mcap": 3}
    assert batch.exit_code == 3
    lines = summary_lines(batch)
    assert lines[-1] == "5 log(s): 1 pass, 1 fail, 1 inconclusive, 2 unusable; exit code 3"
    assert any(ln.startswith(f"{logs['fail.mcap']}: fail (") for ln in lines)
    junk = next(i for i in batch.items if i.path.endswith("junk.bag"))
    assert junk.result is None and "junk.bag" in (junk.error or "")

    written = write_batch(batch, tmp_path / "out")
    with written["summary.csv"].open() as fh:
        rows = {r["folder"]: r for r in csv.DictReader(fh)}
    assert {k: r["verdict"] for k, r in rows.items()} == {
        "fail.mcap": "fail", "inconclusive.bag": "inconclusive", "junk.bag": "unusable", "pass.mcap": "pass",
        "truncated.mcap": "unusable"}
    assert rows["fail.mcap"]["failed_checks"]
    for name in ("pass.mcap", "fail.mcap", "inconclusive.bag"):
        for f in ("certificate.json", "report.md", "report.html", "junit.xml"):
            assert (tmp_path / "out" / name / f).is_file()
    assert (tmp_path / "out" / "junk.bag" / "error.txt").is_file()
    assert written["summary.md"].read_text().startswith("# Batch certification: exit code 3")
    root = ET.parse(written["junit.xml"]).getroot()
    assert len(root.findall("testsuite")) == 5 and root.get("errors") == "2"


def test_worst_code_without_unusable_logs(logs: dict[str, Path]) -> None:
    batch = certify_many([logs["pass.mcap"], logs["inconclusive.bag"], logs["fail.mcap"]], builtin_scenario(),
                         spec=SPEC, workers=2, progress=False)
    assert [i.exit_code for i in batch.items] == [0, 2, 1] and batch.exit_code == 1
    batch = certify_many([logs["pass.mcap"], logs["inconclusive.bag"]], builtin_scenario(), spec=SPEC, workers=1,
                         progress=False)
    assert batch.exit_code == 2


def test_dask_local_cluster(logs: dict[str, Path], tmp_path: Path) -> None:
    folder = tmp_path / "dask-logs"
    folder.mkdir()
    for name in ("pass.mcap", "fail.mcap", "inconclusive.bag", "junk.bag"):
        shutil.copy(logs[name], folder / name)
    batch = certify_many([folder], builtin_scenario(), spec=SPEC, workers=2, dask="local", progress=False)
    assert _codes(batch) == {"fail.mcap": 1, "inconclusive.bag": 2, "junk.bag": 3, "pass.mcap": 0}
    local = certify_many([folder], builtin_scenario(), spec=SPEC, workers=1, progress=False)
    # the same certificates whichever executor produced them
    assert [i.result.certificate for i in batch.items if i.result is not None] == \
        [i.result.certificate for i in local.items if i.result is not None]
