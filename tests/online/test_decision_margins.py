"""A decision states its margin only when that margin is final at the decision's time, and then it is the
certificate's; so the decisions (verdict, time, margin) are the same whatever the batching (issue 22: an ``F``
decided early had no margin when updated per sample and its final margin when the samples came in one batch)."""

from __future__ import annotations

from typing import Any

import numpy as np
import pytest

from property_tests.online_runs import SC, T0, offline_certificate
from verify.online import Decision, OnlineMonitor

SPEC = "F[0.53,2.2] mission_1 & G[0,4.07] !obs_2"


def _run_into_r1() -> dict[str, object]:
    """100 Hz for 5 s: from 1.2 m beside R1 straight into it (inside after about 0.8 s), then staying."""
    n = 500
    t = T0 + np.arange(n, dtype=np.int64) * 10_000_000
    cx, cy = SC.region("R1").center
    x = cx + np.maximum(1.2 - np.arange(n) * 0.01, 0.0)
    y = np.full(n, float(cy))
    return {"t": t, "x": x, "y": y, "nominal": (t, x, y), "cmd": None, "dup": []}


def _decisions(run: dict[str, object], every: int, pending: int = 1000) -> tuple[OnlineMonitor, list[Decision]]:
    """Push the run's pose and nominal samples; ``update()`` every ``every`` pose samples (0: at the end only; the
    samples are judged at the latest once ``pending`` wait)."""
    mon = OnlineMonitor(SC, spec=SPEC, max_pending=pending)
    t, x, y = run["t"], run["x"], run["y"]
    assert isinstance(t, np.ndarray) and isinstance(x, np.ndarray) and isinstance(y, np.ndarray)
    out: list[Decision] = []
    for i in range(t.shape[0]):
        mon.push_nominal(int(t[i]), float(x[i]), float(y[i]))
        mon.push_pose(int(t[i]), float(x[i]), float(y[i]))
        if every and (i + 1) % every == 0:
            out.extend(mon.update())
    out.extend(mon.update())
    return mon, out


@pytest.mark.parametrize("every", [1, 37, 0])
@pytest.mark.parametrize("pending", [100, 1000])
def test_a_decision_states_a_margin_only_once_final(every: int, pending: int) -> None:
    run = _run_into_r1()
    mon, decisions = _decisions(run, every, pending)
    f = next(d for d in decisions if d.name == "F[0.53,2.2] mission_1")
    assert f.verdict == "pass" and f.time_s < 2.2 and f.margin is None  # final only once the window has ended
    mon.close()
    cert = offline_certificate(run, SPEC)
    entries: list[dict[str, Any]] = [*cert["obligations"], *cert["checks"]]  # type: ignore[misc]
    want = {e.get("formula", e.get("name")): e["margin"] for e in entries}
    assert want[f.name] is not None  # ... and stated at the end
    final = {c.name: c.margin for c in (*mon.state().obligations, *mon.state().checks)}
    assert final[f.name] == pytest.approx(want[f.name], abs=2e-9)
    stated = [d for d in (*decisions, *mon.final_decisions) if d.margin is not None]
    assert stated  # the G's and the checks' margins, final when decided
    for d in stated:
        assert d.margin == pytest.approx(want[d.name], abs=2e-9), d.name


def test_the_decisions_do_not_depend_on_the_batching() -> None:
    run = _run_into_r1()
    seen = [sorted((d.name, d.verdict, d.time_s, d.margin, d.first_violation_s)
                   for d in _decisions(run, every, pending)[1]) for every in (1, 37, 0) for pending in (100, 1000)]
    assert all(s == seen[0] for s in seen)
