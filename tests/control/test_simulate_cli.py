"""`tubempc simulate`: writes the log, prints t_ij, |q| vs r_q and solver statistics; bad input exits 3."""

from __future__ import annotations

import subprocess
import sys
from pathlib import Path


def run(*args: str) -> subprocess.CompletedProcess[str]:
    return subprocess.run([sys.executable, "-m", "tubempc", "simulate", *args], capture_output=True, text=True,
                          timeout=300, check=False)


def test_simulate_writes_a_log_and_prints_the_summary(tmp_path: Path) -> None:
    out = tmp_path / "r2r3.mcap"
    proc = run("--from", "R2", "--to", "R3", "--disturbance", "worst", "--seed", "3", "--out", str(out))
    assert proc.returncode == 0, proc.stderr
    assert out.is_file()
    assert "t_ij = " in proc.stdout and "vs r_q = 0.01000 m" in proc.stdout
    assert "0 backups" in proc.stdout and "solve time median" in proc.stdout


def test_simulate_unsafe_target_is_one_line_exit_3(tmp_path: Path) -> None:
    proc = run("--to", "R7", "--out", str(tmp_path / "x.bag"))
    assert proc.returncode == 3
    assert "R7" in proc.stderr and "Traceback" not in proc.stderr and proc.stderr.strip().count("\n") == 0
