"""Every committed example log in logs/ certifies with the verdict its README documents."""

from __future__ import annotations

import re
import subprocess
import sys
from pathlib import Path

import pytest

from tubempc.scenario import builtin_scenario
from verify import certify_log
from verify.errors import TruncatedLogError

LOGS = Path(__file__).resolve().parent.parent / "logs"
#: logs of robots other than the Nexus, judged against their own scenario (the README says which)
OWN_SCENARIO = {"diffdrive_odom.bag": LOGS.parent / "docs" / "examples" / "diffdrive-room.yaml",
                "two_robots.bag": LOGS.parent / "docs" / "examples" / "two-robots-warehouse.yaml"}


def _documented() -> dict[str, tuple[str, int]]:
    """file -> (expected verdict, exit code), read from the table in logs/README.md."""
    out: dict[str, tuple[str, int]] = {}
    for line in (LOGS / "README.md").read_text(encoding="utf-8").splitlines():
        m = re.match(r"\| `([^`]+)` \| [^|]+ \| ([a-z ]+) \| (\d) \|", line)
        if m:
            out[m.group(1)] = (m.group(2).strip(), int(m.group(3)))
    return out


def test_every_log_is_documented() -> None:
    files = {p.name for p in LOGS.iterdir() if p.suffix in (".bag", ".mcap", ".db3")}
    assert files == set(_documented())


@pytest.mark.parametrize(("name", "verdict", "code"), [(k, *v) for k, v in sorted(_documented().items())])
def test_example_log_verdict(name: str, verdict: str, code: int) -> None:
    path = LOGS / name
    before = path.read_bytes()
    if code == 3:
        with pytest.raises(TruncatedLogError, match=name):
            certify_log(path, builtin_scenario())
    else:
        result = certify_log(path, OWN_SCENARIO.get(name, builtin_scenario()))
        assert result.verdict == verdict
        assert result.exit_code == code
    assert path.read_bytes() == before  # input files are never modified


def test_late_mission_witness() -> None:
    result = certify_log(LOGS / "late_mission.mcap", builtin_scenario())
    spec = {c["name"]: c for c in result.certificate["checks"]}["spec_timed_run"]
    assert spec["verdict"] == "fail"
    assert spec["first_violation_time"] == pytest.approx(50.0)


def test_truncated_log_cli_and_salvage() -> None:
    cmd = [sys.executable, "-m", "tubempc", "certify", str(LOGS / "truncated.bag"), "--scenario", "nexus-sml"]
    plain = subprocess.run(cmd, capture_output=True, text=True, timeout=120, check=False)
    assert plain.returncode == 3
    assert plain.stderr.count("\n") == 1 and "truncated.bag" in plain.stderr and "Traceback" not in plain.stderr
    salvaged = subprocess.run([*cmd, "--salvage"], capture_output=True, text=True, timeout=120, check=False)
    assert salvaged.returncode == 2, salvaged.stdout + salvaged.stderr
    assert "inconclusive" in salvaged.stdout
