"""A scenario without ``robots:`` is certified exactly as before fleets existed: same scenario hash, and the same
certificate byte for byte apart from the certificate version (fixtures written by the single-robot certifier)."""

from __future__ import annotations

import json
from pathlib import Path

import pytest

from verify.certify import certify_log

ROOT = Path(__file__).resolve().parents[2]
FIXTURES = Path(__file__).parent / "fixtures" / "single_robot"
CASES = [("obstacle_touch.bag", "nexus-sml"), ("diffdrive_odom.bag", "docs/examples/diffdrive-room.yaml"),
         ("tube_breach.mcap", "nexus-sml")]


@pytest.mark.parametrize(("log", "scenario"), CASES)
def test_single_robot_certificate_is_byte_identical(log: str, scenario: str, monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.chdir(ROOT)
    got = certify_log(f"logs/{log}", scenario).certificate
    want = json.loads((FIXTURES / f"{log}.json").read_text())
    assert got["scenario_sha256"] == want["scenario_sha256"]
    got.pop("certificate_version")
    want.pop("certificate_version")
    assert json.dumps(got, indent=2) == json.dumps(want, indent=2)
