"""`tubempc compare`: recorded runs before and after a change -> exit 0 / 1 / 2 / 3 with the diff, page and JUnit."""

from __future__ import annotations

import shutil
import xml.etree.ElementTree as ET
from collections.abc import Callable
from pathlib import Path

import pytest

from tubempc.cli import main
from tubempc.compare import CompareReport

WriteRuns = Callable[..., list[Path]]


def run(capsys: pytest.CaptureFixture[str], *args: str | Path) -> tuple[int, str, str]:
    with pytest.raises(SystemExit) as exc:
        main(["compare", *(str(a) for a in args), "--workers", "1", "--no-progress"])
    out = capsys.readouterr()
    return int(exc.value.code or 0), out.out, out.err


def report(folder: Path) -> CompareReport:
    return CompareReport.model_validate_json((folder / "compare.json").read_text(encoding="utf-8"))


def test_same_missions_other_noise_no_change_exits_0(capsys: pytest.CaptureFixture[str], recorded: dict[str, Path],
                                                     mission_scenario: Path, tmp_path: Path) -> None:
    out_dir = tmp_path / "out"
    code, out, _ = run(capsys, recorded["before"], recorded["after"], "--scenario", mission_scenario,
                       "--out", out_dir)
    assert code == 0, out
    assert "NO REGRESSION" in out and "8 runs paired by key" in out
    rep = report(out_dir)
    assert rep.verdict == "no regression" and rep.paired
    statuses = {m.name: m.status for m in rep.metrics}
    # every judged metric is shown to stay within its tolerance (not merely "not shown to regress")
    assert {s for n, s in statuses.items() if n != "duration_s"} == {"ok"}
    assert statuses["duration_s"] == "not_judged"
    for name in ("check.obstacle_clearance.margin", "min_clearance_m", "tube_ratio", "entry_s.R3",
                 "transition_s.R5->R3", "check.spec_trajectory.verdict", "verdict", "input_usage"):
        assert name in statuses
    suite = ET.parse(out_dir / "junit.xml").getroot()
    assert int(suite.get("tests", "0")) == len(rep.metrics)  # one case per metric
    assert suite.get("failures") == "0"
    assert (out_dir / "compare.html").read_text(encoding="utf-8").startswith("<!DOCTYPE html>")


def test_path_moved_3cm_towards_an_obstacle_exits_1_naming_clearance(
        capsys: pytest.CaptureFixture[str], certified: dict[str, Path], mission_scenario: Path, tmp_path: Path) -> None:
    out_dir = tmp_path / "out"
    code, out, _ = run(capsys, certified["before"], certified["moved"], "--scenario", mission_scenario,
                       "--out", out_dir)
    assert code == 1
    regressed_section = out.split("REGRESSED")[1].split("WITHIN TOLERANCE")[0]
    assert "check.obstacle_clearance.margin" in regressed_section
    assert "min_clearance_m" in regressed_section
    assert out.index("REGRESSED") < out.index("WITHIN TOLERANCE")  # regressions first
    by_name = {m.name: m for m in report(out_dir).metrics}
    for name in ("check.obstacle_clearance.margin", "min_clearance_m"):
        m = by_name[name]
        assert m.status == "regressed"
        # the path moved 3 cm towards R9: the clearance shrinks by 3 cm, up to the MoCap noise's effect on the
        # sampled minimum (0.5 mm standard deviation)
        assert m.difference == pytest.approx(-0.03, abs=0.003)
        assert m.p_worse is not None and m.p_worse < 0.05
    failures = {c.get("name") for c in ET.parse(out_dir / "junit.xml").getroot().iter("testcase")
                if c.find("failure") is not None}
    assert {"check.obstacle_clearance.margin", "min_clearance_m"} <= failures
    page = (out_dir / "compare.html").read_text(encoding="utf-8")
    notable = [m for m in by_name.values() if m.status in {"regressed", "improved"}
               or (m.status == "cannot_tell" and abs(m.worse_by or 0) > (m.tolerance or 0))]
    assert page.count("data:image/png;base64,") == len(notable) >= 2  # one plot per regressed or notable metric


def test_four_runs_a_side_small_shift_cannot_tell_exits_2(capsys: pytest.CaptureFixture[str],
                                                          recorded: dict[str, Path], mission_scenario: Path) -> None:
    code, out, _ = run(capsys, recorded["before"] / "mission[0-3].mcap", recorded["few"], "--scenario",
                       mission_scenario)
    assert code == 2
    assert "CANNOT TELL" in out and "too few runs to tell" in out and "NO REGRESSION" not in out
    assert "min_clearance_m" in out.split("CANNOT TELL")[1]


def test_pass_to_fail_of_one_pair_regresses_whatever_the_statistics(
        capsys: pytest.CaptureFixture[str], recorded: dict[str, Path], mission_scenario: Path, tmp_path: Path,
        write_runs: WriteRuns) -> None:
    after = tmp_path / "after"
    write_runs(after, [300, 301, 302, 303], shift_m=[0.0, 0.0, 0.45, 0.0])  # mission2 drives into R9
    code, out, _ = run(capsys, recorded["before"] / "mission[0-3].mcap", after, "--scenario", mission_scenario)
    assert code == 1  # four pairs are too few for any test, yet a pass that turned into a fail regresses
    regressed = out.split("REGRESSED")[1].split("CANNOT TELL")[0]
    assert "check.obstacle_clearance.verdict" in regressed and "mission2: pass -> fail" in regressed


def test_certificate_folders_are_read_like_logs(capsys: pytest.CaptureFixture[str], recorded: dict[str, Path],
                                                certified: dict[str, Path], mission_scenario: Path,
                                                tmp_path: Path) -> None:
    code, out, _ = run(capsys, certified["before"], certified["moved"], "--scenario", mission_scenario, "--json")
    assert code == 1
    from_certs = CompareReport.model_validate_json(out)
    assert from_certs.before.kind == "certificates" and from_certs.paired
    code, out, _ = run(capsys, recorded["before"], recorded["moved"], "--scenario", mission_scenario, "--json")
    assert code == 1
    from_logs = CompareReport.model_validate_json(out)
    assert from_logs.before.kind == "logs"
    assert [(m.name, m.status, m.difference) for m in from_certs.metrics] == \
        [(m.name, m.status, m.difference) for m in from_logs.metrics]


def test_unpaired_runs_are_two_samples(capsys: pytest.CaptureFixture[str], certified: dict[str, Path],
                                       mission_scenario: Path) -> None:
    code, out, _ = run(capsys, certified["before"], certified["moved"], "--scenario", mission_scenario, "--unpaired",
                       "--json")
    assert code == 1
    rep = CompareReport.model_validate_json(out)
    clearance = next(m for m in rep.metrics if m.name == "min_clearance_m")
    assert not rep.paired and clearance.status == "regressed"
    assert clearance.test is not None and clearance.test.startswith("Mann-Whitney")
    code, _, _ = run(capsys, certified["before"], certified["after"], "--scenario", mission_scenario, "--unpaired")
    assert code == 0


def test_tolerances_beside_the_scenario_and_on_the_command_line(capsys: pytest.CaptureFixture[str],
                                                                certified: dict[str, Path], mission_scenario: Path,
                                                                tmp_path: Path) -> None:
    scenario = tmp_path / "lab.yaml"
    shutil.copy(mission_scenario, scenario)
    (tmp_path / "lab.compare.yaml").write_text(
        "confidence: 0.9\ntolerances: {check_margin: 0.05, min_clearance_m: 0.05, workspace_margin_m: 0.05}\n",
        encoding="utf-8")
    code, out, _ = run(capsys, certified["before"], certified["moved"], "--scenario", scenario, "--json")
    assert code == 0, out
    rep = CompareReport.model_validate_json(out)
    assert rep.confidence == 0.9 and rep.tolerances_source.endswith("lab.compare.yaml")
    code, out, _ = run(capsys, certified["before"], certified["moved"], "--scenario", scenario,
                       "--tol", "min_clearance_m=0.02")
    assert code == 1
    assert "min_clearance_m" in out.split("REGRESSED")[1].split("WITHIN")[0]
    assert "check.obstacle_clearance.margin" not in out.split("REGRESSED")[1].split("WITHIN")[0]


@pytest.mark.parametrize(("case", "words"), [
    ("missing", "file or folder not found"),
    ("empty", "folder holds no"),
    ("bad-cert", "not a JSON certificate"),
    ("other-scenario", "certified against another scenario"),
    ("unusable-log", "cannot be certified"),
])
def test_unusable_input_is_one_line_exit_3(capsys: pytest.CaptureFixture[str], recorded: dict[str, Path],  # noqa: PLR0917
                                           certified: dict[str, Path], mission_scenario: Path, tmp_path: Path,
                                           case: str, words: str) -> None:
    side = tmp_path / case
    if case == "empty":
        side.mkdir()
    elif case == "bad-cert":
        side.mkdir()
        (side / "run.json").write_text("{not json", encoding="utf-8")
        side = side / "*.json"
    elif case == "unusable-log":
        side.mkdir()
        shutil.copy(Path(__file__).resolve().parents[2] / "logs" / "truncated.bag", side / "cut.bag")
    elif case == "other-scenario":
        with pytest.raises(SystemExit):
            main(["certify", str(recorded["before"] / "mission0.mcap"), "--scenario", "nexus-sml", "--spec",
                  "G[0,inf) !obs_4", "--out", str(side / "run"), "--no-report", "-q"])
        capsys.readouterr()
    code, _, err = run(capsys, certified["before"], side, "--scenario", mission_scenario)
    assert code == 3
    lines = err.strip().splitlines()
    assert len(lines) == 1 and words in lines[0] and "Traceback" not in err
    assert str(side).removesuffix("*.json") in lines[0]  # names the file or folder


def test_bad_tolerances_exit_3_naming_the_option_or_file(capsys: pytest.CaptureFixture[str],
                                                         certified: dict[str, Path], mission_scenario: Path,
                                                         tmp_path: Path) -> None:
    code, _, err = run(capsys, certified["before"], certified["after"], "--scenario", mission_scenario,
                       "--tol", "min_clearance_m=lots")
    assert code == 3 and "--tol 'min_clearance_m=lots'" in err
    typo = tmp_path / "tol.yaml"
    typo.write_text("tolerances: {min_clearence_m: 0.05}\n", encoding="utf-8")  # a typo is not silently ignored
    code, _, err = run(capsys, certified["before"], certified["after"], "--scenario", mission_scenario,
                       "--tolerances", typo)
    assert code == 3 and str(typo) in err and "'min_clearence_m' names no judged metric" in err


def test_pairing_by_pattern_or_certificate_field(capsys: pytest.CaptureFixture[str], recorded: dict[str, Path],
                                                 mission_scenario: Path, tmp_path: Path,
                                                 write_runs: WriteRuns) -> None:
    # the same five missions recorded again under other names (and the same seeds)
    write_runs(tmp_path / "after", range(5), names=[f"tuesday-mission{k}" for k in range(5)])
    certs = {}
    for side, logs in (("before", [recorded["before"] / f"mission{k}.mcap" for k in range(5)]),
                       ("after", [tmp_path / "after"])):
        certs[side] = tmp_path / f"{side}-certs"
        with pytest.raises(SystemExit):
            main(["certify", *(str(p) for p in logs), "--scenario", str(mission_scenario), "--out",
                  str(certs[side]), "--no-report", "--workers", "1", "--no-progress", "-q"])
    capsys.readouterr()

    def compare(*extra: str) -> CompareReport:
        _, out, _ = run(capsys, certs["before"], certs["after"], "--scenario", mission_scenario, "--json", *extra)
        return CompareReport.model_validate_json(out)

    by_name = compare()
    assert not by_name.paired and "have no partner" in by_name.pairing
    by_pattern = compare("--pair-pattern", r"mission\d")
    assert by_pattern.paired and by_pattern.pairing == "5 runs paired by key"
    by_seed = compare("--pair-by", "generator.seed")
    assert by_seed.paired
    # the same seeds are the same runs: every paired difference is exactly zero
    assert all(m.difference == 0 for m in by_seed.metrics if m.difference is not None)
    code, _, err = run(capsys, certs["before"], certs["after"], "--scenario", mission_scenario,
                       "--pair-by", "generator.nothing")
    assert code == 3 and "has no field 'nothing'" in err
