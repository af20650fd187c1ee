"""``tubempc plan`` when the controller's design check fails for every transition: exit 3 with one line saying so
(not exit 1 blaming the formula). The oracle hook stands in for Algorithm 1, so the test does not run the MPC."""

from __future__ import annotations

from pathlib import Path

import pytest

import tubempc.planning.wts as wts_module
from tubempc.cli import main
from tubempc.control.algorithm1 import TransitionResult
from tubempc.scenario import Scenario


def _never(scenario: Scenario, source: str, target: str, **_: object) -> TransitionResult:
    return TransitionResult(source=source, target=target, ok=False, reason="the terminal set is unreachable",
                            t_ij_s=None, arrival_s=None, max_tube_error_m=None, min_clearance_m=None)


def test_every_transition_failing_is_exit_3_and_says_so(monkeypatch: pytest.MonkeyPatch, tmp_path: Path,
                                                         capsys: pytest.CaptureFixture[str]) -> None:
    monkeypatch.setattr(wts_module, "default_oracle", lambda: _never)
    monkeypatch.setenv(wts_module.CACHE_ENV, str(tmp_path / "cache"))
    with pytest.raises(SystemExit) as info:
        main(["plan", "--scenario", "nexus-sml", "--workers", "1"])
    assert info.value.code == 3
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1
    assert "every transition between regions failed the controller's design check (20 of 20)" in err[0]
    assert "R1 -> R2: the terminal set is unreachable" in err[0]
