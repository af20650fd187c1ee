"""Plans for the built-in scenario, checked by the certifier's independent ``check_timed_run``."""

from __future__ import annotations

import json
from pathlib import Path

import pytest

from tubempc.planning import plan_from_wts
from tubempc.planning.synthetic import straight_line_oracle
from tubempc.planning.wts import build_wts
from tubempc.scenario import builtin_scenario


def certify(spec: str, run: list[tuple[str, float]], labels: dict[str, tuple[str, ...]]) -> str:
    check_timed_run = pytest.importorskip("verify.timedrun").check_timed_run
    return str(check_timed_run(spec, run, {k: list(v) for k, v in labels.items()}).verdict)


def test_builtin_plan_satisfies_the_paper_formula(tmp_path: Path) -> None:
    s = builtin_scenario()
    wts = build_wts(s, oracle=straight_line_oracle, cache_path=tmp_path, workers=1)
    p = plan_from_wts(wts, s.formula, initial=s.initial_region)
    assert p.run[0] == (s.initial_region, 0.0)
    assert certify(s.spec, list(p.run), s.labels()) == "pass"
    # re-timing centres the witnesses: F[30,50] at 40 and F[80,110] at 90 leave 10 s on every side
    assert p.margin_s == pytest.approx(10.0, abs=1e-6)  # LP optimum, rounded to the millisecond
    assert p.targets and p.targets[-1].region == "R1"
    data = p.to_json()
    assert data["run"][0] == {"region": "R1", "time": 0.0, "kind": "start", "labels": ["mission_1"]}
    json.dumps(data)


def test_targets_follow_the_run(tmp_path: Path) -> None:
    s = builtin_scenario()
    wts = build_wts(s, oracle=straight_line_oracle, cache_path=tmp_path, workers=1)
    p = plan_from_wts(wts, s.formula, initial=s.initial_region)
    arrivals = {(r, t) for (r, t), k in zip(p.run, p.kinds, strict=True) if k == "move"}
    assert {(t.region, t.arrival_s) for t in p.targets} <= arrivals
    for t in p.targets:
        assert t.depart_after_s is None or t.depart_after_s >= t.arrival_s


@pytest.mark.slow
def test_builtin_plan_with_the_real_controller(tmp_path: Path) -> None:
    pytest.importorskip("tubempc.control.algorithm1")
    s = builtin_scenario()
    wts = build_wts(s, cache_path=tmp_path)
    p = plan_from_wts(wts, s.formula, initial=s.initial_region)
    assert certify(s.spec, list(p.run), s.labels()) == "pass"
    assert p.margin_s > 0
