"""``tubempc plan``: table, JSON, exit 1 with the obligation when no run exists (synthetic weights via the oracle
hook, so that the test does not run the MPC)."""

from __future__ import annotations

import json
from pathlib import Path

import pytest

import tubempc.planning.wts as wts_module
from tests.planning.synthetic import straight_line_oracle
from tubempc.cli import main


@pytest.fixture(autouse=True)
def synthetic(monkeypatch: pytest.MonkeyPatch, tmp_path: Path) -> None:
    monkeypatch.setattr(wts_module, "default_oracle", lambda: straight_line_oracle)
    monkeypatch.setenv(wts_module.CACHE_ENV, str(tmp_path / "cache"))


def run(args: list[str]) -> int:
    with pytest.raises(SystemExit) as info:
        main(args)
    code = info.value.code
    return code if isinstance(code, int) else 70


def test_plan_table_and_json(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    out = tmp_path / "plan.json"
    assert run(["plan", "--scenario", "nexus-sml", "--json", str(out), "--workers", "1"]) == 0
    text = capsys.readouterr().out
    assert "R3" in text and "margin" in text
    data = json.loads(out.read_text())
    assert data["run"][0]["region"] == "R1" and data["run"][0]["time"] == 0.0
    times = [e["time"] for e in data["run"]]
    assert times == sorted(times)


def test_no_run_exits_1_naming_the_obligation(capsys: pytest.CaptureFixture[str]) -> None:
    assert run(["plan", "--scenario", "nexus-sml", "--no-wait", "--workers", "1"]) == 1
    err = capsys.readouterr().err
    assert "F[30,50] mission_2" in err


def test_bad_spec_exits_3(capsys: pytest.CaptureFixture[str]) -> None:
    assert run(["plan", "--spec", "F[3,1] p", "--workers", "1"]) == 3


def test_dwell_modes(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    silent, observed = tmp_path / "silent.json", tmp_path / "observed.json"
    assert run(["plan", "--json", str(silent), "--workers", "1"]) == 0
    assert run(["plan", "--dwell", "observed", "--json", str(observed), "--workers", "1"]) == 0
    out = capsys.readouterr().out
    assert "waits: silent" in out and "waits: observed" in out
    s, o = json.loads(silent.read_text()), json.loads(observed.read_text())
    assert s["dwell"] == "silent" and o["dwell"] == "observed"
    assert {e["kind"] for e in s["run"]} == {"start", "move"}  # arrivals only
    assert "dwell" in {e["kind"] for e in o["run"]}
    # the silent run's R3 arrival lies inside F[30,50]; its departure from R1 is a target for the initial region
    assert any(e["region"] == "R3" and 30 <= e["time"] <= 50 for e in s["run"])
    assert s["targets"][0]["region"] == "R1" and s["targets"][0]["depart_after_s"] > 0
    assert run(["plan", "--dwell", "sometimes", "--workers", "1"]) != 0


def test_objective_time_is_the_default_and_margin_is_asked(tmp_path: Path) -> None:
    fast, wide = tmp_path / "time.json", tmp_path / "margin.json"
    assert run(["plan", "--json", str(fast), "--workers", "1"]) == 0
    assert run(["plan", "--objective", "margin", "--json", str(wide), "--workers", "1"]) == 0
    t, m = json.loads(fast.read_text()), json.loads(wide.read_text())
    assert t["objective"] == "time" and m["objective"] == "margin"
    assert t["run"][-1]["time"] == 80.0  # F[80,110] mission_1 met at the earliest possible time
    assert m["run"][-1]["time"] > 80.0 and m["margin_s"] > t["margin_s"]


def test_state_limit_exits_2_saying_how_to_raise_it(capsys: pytest.CaptureFixture[str]) -> None:
    assert run(["plan", "--max-states", "2", "--workers", "1"]) == 2
    err = capsys.readouterr().err
    assert "limit of 2 product states" in err and "--max-states" in err and "Traceback" not in err


def test_no_usable_transition_exits_3_naming_the_design_quantity(monkeypatch: pytest.MonkeyPatch,
                                                                 capsys: pytest.CaptureFixture[str]) -> None:
    from tests.planning.synthetic import SyntheticTransition

    def failing(*args: object, **kwargs: object) -> SyntheticTransition:
        return SyntheticTransition(False, "design check: tube radius 0.31 m exceeds the region radius 0.3 m", None)

    monkeypatch.setattr(wts_module, "default_oracle", lambda: failing)
    assert run(["plan", "--workers", "1"]) == 3
    err = capsys.readouterr().err
    assert "nexus-sml" in err and "every transition" in err and "tube radius 0.31 m" in err
    assert "mission" not in err  # the formula is not blamed
