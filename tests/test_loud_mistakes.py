"""Mistakes a new user makes are loud: exit 3 and one stderr line that names the file, the field and the problem.

Each case ran silently (exit 0), hid the useful problem, or ended in an internal error (exit 70) before.
"""

from __future__ import annotations

import os
import subprocess
import sys
from pathlib import Path

import pytest

from tubempc.cli import EXIT_UNUSABLE, main

ROOT = Path(__file__).resolve().parents[1]
LOG = ROOT / "logs" / "diffdrive_odom.bag"
LAB = """name: lab
workspace: {x: [0, 5], y: [0, 4]}
robot: {radius: 0.3}
inputs: {model: unicycle, max_abs: [0.5, 1.0]}
topics: {pose: /odom}
regions:
  - {name: dock, center: [4.4, 3.3], radius: 0.5, labels: [dock]}
spec: F dock
"""


def cli(capsys: pytest.CaptureFixture[str], *args: str | Path) -> tuple[int, str, str]:
    with pytest.raises(SystemExit) as done:
        main([str(a) for a in args])
    out = capsys.readouterr()
    return int(done.value.code or 0), out.out, out.err


def _one_error_line(code: int, err: str) -> str:
    assert code == EXIT_UNUSABLE, err
    lines = err.strip().splitlines()
    assert len(lines) == 1 and lines[0].startswith("tubempc: error: "), err
    return lines[0]


def _scenario(tmp_path: Path, text: str) -> Path:
    path = tmp_path / "lab.yaml"
    path.write_text(text)
    return path


def test_the_lab_scenario_is_valid(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    """The base every case below breaks in one place."""
    code, _, err = cli(capsys, "scenario", "validate", _scenario(tmp_path, LAB), "--log", LOG)
    assert code == 0, err


def test_a_misspelt_key_is_named_beside_the_missing_one(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    path = _scenario(tmp_path, LAB.replace("robot: {radius: 0.3}", "robot: {raduis: 0.6}"))
    line = _one_error_line(*cli(capsys, "scenario", "validate", path)[::2])
    assert str(path) in line and "robot.raduis: unknown field (did you mean radius?" in line
    assert "robot.radius: required field is missing" in line


def test_every_problem_is_listed(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    path = _scenario(tmp_path, LAB.replace("robot: {radius: 0.3}", "robot: {raduis: 0.6}").replace(
        "max_abs: [0.5, 1.0]", "max_abs: [0.5, 1.0], modle: unicycle"))
    line = _one_error_line(*cli(capsys, "certify", LOG, "--scenario", path)[::2])
    assert "3 problems" in line and "inputs.modle: unknown field (did you mean model?" in line
    assert "robot.raduis" in line and "robot.radius: required field is missing" in line


def test_a_bow_tie_polygon_says_its_edges_cross_and_names_the_region(tmp_path: Path,
                                                                     capsys: pytest.CaptureFixture[str]) -> None:
    path = _scenario(tmp_path, LAB.replace("spec:", "  - {name: bench, polygon: [[1, 1], [2, 2], [2, 1], [1, 2]], "
                                                   "labels: [bench]}\nspec:"))
    line = _one_error_line(*cli(capsys, "scenario", "validate", path)[::2])
    assert "regions[1] (bench): polygon: its edges cross" in line and "zero area" not in line


def test_degrees_on_an_angular_velocity_are_refused_with_the_conversion(tmp_path: Path,
                                                                        capsys: pytest.CaptureFixture[str]) -> None:
    path = _scenario(tmp_path, LAB.replace("spec: F dock", "signals:\n  calm: {topic: /odom, field: "
                                           "twist.twist.angular.z, op: <, value: 86, unit: deg/s}\n"
                                           "spec: F dock & G calm"))
    line = _one_error_line(*cli(capsys, "certify", LOG, "--scenario", path)[::2])
    assert "signals.calm: unit: deg/s" in line and "rad/s (REP 103)" in line and "value: 1.50098" in line


def test_a_workspace_in_degrees_of_latitude_and_longitude_is_named_as_such(tmp_path: Path,
                                                                           capsys: pytest.CaptureFixture[str]) -> None:
    path = _scenario(tmp_path, LAB.replace("workspace: {x: [0, 5], y: [0, 4]}",
                                           "workspace: {x: [18.0700, 18.0708], y: [59.3490, 59.3496]}").replace(
        "center: [4.4, 3.3], radius: 0.5", "center: [18.0704, 59.3493], radius: 0.0001"))
    line = _one_error_line(*cli(capsys, "scenario", "validate", path)[::2])
    assert "workspace: 0.0008 m x 0.0006 m cannot contain the robot disc" in line
    assert "degrees of longitude/latitude" in line


@pytest.mark.parametrize("command", ["validate", "certify"])
@pytest.mark.parametrize("value", ["1e-300", "1" + "0" * 5000], ids=["tiny", "5001-digits"])
def test_out_of_range_numbers_are_exit_3_naming_the_field(tmp_path: Path, capsys: pytest.CaptureFixture[str],
                                                          command: str, value: str) -> None:
    """mocap.rate_hz: 1e-300 overflowed the tube check's period (exit 70); an integer of more than 4,300 digits
    escaped the YAML loader's error handling (exit 70)."""
    builtin = (ROOT / "tubempc" / "scenario" / "builtin" / "nexus-sml.yaml").read_text()
    assert builtin.count("mocap: {rate_hz: 100.0}") == 1
    path = _scenario(tmp_path, builtin.replace("mocap: {rate_hz: 100.0}", f"mocap: {{rate_hz: {value}}}"))
    args = ("scenario", "validate", path) if command == "validate" else ("certify", ROOT / "logs" / "demo.mcap",
                                                                         "--scenario", path)
    line = _one_error_line(*cli(capsys, *args)[::2])
    assert "mocap.rate_hz" in line and str(path) in line


@pytest.mark.parametrize("value", ["1e308", "1001"])
def test_noise_std_past_its_limit_is_exit_3_naming_the_field(tmp_path: Path, capsys: pytest.CaptureFixture[str],
                                                             value: str) -> None:
    """mocap.noise_std: 1e308 made the tube check's stated tolerance (3 sigma) infinite and the certificate
    invalid (exit 70, found by the fault campaign's scenario-limits family)."""
    builtin = (ROOT / "tubempc" / "scenario" / "builtin" / "nexus-sml.yaml").read_text()
    path = _scenario(tmp_path, builtin.replace("mocap: {rate_hz: 100.0}",
                                               f"mocap: {{rate_hz: 100.0, noise_std: {value}}}"))
    line = _one_error_line(*cli(capsys, "certify", ROOT / "logs" / "demo.mcap", "--scenario", path)[::2])
    assert "mocap.noise_std" in line and str(path) in line


def test_digest_without_a_scenario_is_refused(capsys: pytest.CaptureFixture[str]) -> None:
    """It printed the digest of the Nexus topics, which the log lacks: the same value for any such log."""
    line = _one_error_line(*cli(capsys, "digest", LOG)[::2])
    assert "give --scenario" in line and "--digest blake3" in line
    line = _one_error_line(*cli(capsys, "digest", LOG, "--scenario", "nexus-sml")[::2])
    assert str(LOG) in line and "pose topic /qualisys/nexus/pose is absent" in line
    code, out, _ = cli(capsys, "digest", LOG, "--digest", "sha256")
    assert code == 0 and out.split()[1:] == ["sha256", str(LOG)]


def test_a_batch_prints_each_error_once(tmp_path: Path) -> None:
    folder = tmp_path / "logs"
    folder.mkdir()
    (folder / "good.bag").write_bytes(LOG.read_bytes())
    (folder / "cut.bag").write_bytes(LOG.read_bytes()[:3000])
    scenario = _scenario(tmp_path, LAB)
    out = subprocess.run([sys.executable, "-m", "tubempc", "certify", str(folder), "--scenario", str(scenario),
                          "--workers", "1", "--no-progress"], capture_output=True, text=True, timeout=300,
                         check=False)
    assert out.returncode == EXIT_UNUSABLE
    both = out.stdout + out.stderr
    cut = str(folder / "cut.bag")
    assert out.stderr.count(f"tubempc: error: {cut}: ") == 1
    assert both.count("truncated") == 1, both


def test_falsify_keeps_no_files_outside_out(tmp_path: Path) -> None:
    """hypothesis wrote its .hypothesis/ cache into the working folder."""
    out = subprocess.run([sys.executable, "-m", "tubempc", "falsify", "--to", "R2", "--budget", "1", "--workers", "1",
                          "--out", str(tmp_path / "out")], capture_output=True, text=True, timeout=600, check=False,
                         cwd=tmp_path, env={k: v for k, v in os.environ.items() if k != "HYPOTHESIS_STORAGE_DIRECTORY"})
    assert out.returncode in (0, 1, 2), out.stderr
    assert sorted(p.name for p in tmp_path.iterdir()) == ["out"]
