"""The CLI frame: help lists the subcommands; errors become one stderr line and a documented exit code."""

from __future__ import annotations

import subprocess
import sys
from pathlib import Path

import pytest

from tubempc.cli import EXIT_UNUSABLE


def run(*args: str) -> subprocess.CompletedProcess[str]:
    return subprocess.run([sys.executable, "-m", "tubempc", *args], capture_output=True, text=True, timeout=120,
                          check=False)


def test_help_lists_subcommands() -> None:
    out = run("--help")
    assert out.returncode == 0
    for name in ("certify", "plan", "simulate", "regress", "demo", "scenario", "spec"):
        assert name in out.stdout


def test_spec_error_is_one_line_exit_3() -> None:
    out = run("spec", "F[1,2 a")
    assert out.returncode == EXIT_UNUSABLE
    assert out.stderr.strip().count("\n") == 0
    assert "column 7" in out.stderr and "Traceback" not in out.stderr


def test_spec_canonical() -> None:
    out = run("spec", "G[0,inf)!(obs_1|obs_2)&F[30,50]m")
    assert out.returncode == 0
    assert out.stdout.strip() == "G[0,inf) !(obs_1 | obs_2) & F[30,50] m"


def test_scenario_show_and_validate(tmp_path: Path) -> None:
    out = run("scenario", "show")
    assert out.returncode == 0 and "nexus-sml" in out.stdout
    path = tmp_path / "mine.yaml"
    path.write_text(out.stdout)
    ok = run("scenario", "validate", str(path))
    assert ok.returncode == 0 and "9 regions" in ok.stdout
    path.write_text(out.stdout.replace("radius: 0.27", "radius: -1"))
    bad = run("scenario", "validate", str(path))
    assert bad.returncode == EXIT_UNUSABLE
    assert str(path) in bad.stderr and "robot.radius" in bad.stderr
    assert bad.stderr.strip().count("\n") == 0


@pytest.mark.parametrize("args", [("scenario", "validate", "/nonexistent/s.yaml")])
def test_missing_file(args: tuple[str, ...]) -> None:
    out = run(*args)
    assert out.returncode == EXIT_UNUSABLE and "file not found" in out.stderr
