"""The online monitor states the certificate's first violation for nested windows, ``U``, negations and
disjunctions (``verify.monitor.engine.explain``: a false ``F`` is shown at its window's end, a false ``G`` where its
argument first is, a conjunction at its earliest false conjunct, a negation or disjunction at the first position)."""

from __future__ import annotations

import numpy as np
import pytest

from property_tests.online_runs import SC, T0, offline_certificate, online_run, same_time


def _run_in_r1_then_away() -> dict[str, object]:
    """100 Hz: 1 s inside R1 (mission_1), then 5 s drifting to R3 (mission_2) and staying there."""
    n = 600
    t = T0 + np.arange(n, dtype=np.int64) * 10_000_000
    r1, r3 = SC.region("R1").center, SC.region("R3").center
    s = np.clip((np.arange(n) - 100) / 300.0, 0.0, 1.0)
    x = r1[0] + s * (r3[0] - r1[0])
    y = r1[1] + s * (r3[1] - r1[1])
    return {"t": t, "x": x, "y": y, "nominal": (t, x, y), "cmd": None, "dup": []}


@pytest.mark.parametrize("spec", ["G[0,inf) F[0,1.5] mission_1", "G[0,4] (mission_1 -> F[0,1] !mission_1)",
                                  "mission_1 U[0,3] mission_2", "!F[0.5,6] mission_2",
                                  "G[0,5] G[0,0.5] mission_1", "G[0,inf) mission_1 | F[0,0.5] mission_2",
                                  "F[0,0.3] mission_2 & G[0,inf) F[0,1] mission_1"])
@pytest.mark.parametrize("every", [0, 1, 37])
def test_online_first_violation_is_the_certificates(spec: str, every: int) -> None:
    run = _run_in_r1_then_away()
    cert = offline_certificate(run, spec)
    mon, _ = online_run(run, spec, every)
    res = mon.close()
    want = {c["name"]: c for c in cert["checks"]}
    t0 = int(run["t"][0])  # type: ignore[index]
    spec_check = next(c for c in res.checks if c.name == "spec_trajectory")
    assert spec_check.verdict == want["spec_trajectory"]["verdict"] == "fail"
    assert spec_check.first_violation_ns is not None
    got = round((spec_check.first_violation_ns - t0) * 1e-9, 9)
    assert got == want["spec_trajectory"]["first_violation_time"], (got, want["spec_trajectory"])
    offline = {o["formula"]: o for o in cert["obligations"]}
    for ob in res.state.obligations:
        assert same_time(ob.first_violation_s, offline[ob.name]["first_violation_time"]), (ob, offline[ob.name])
