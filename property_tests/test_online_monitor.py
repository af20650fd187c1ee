"""The online monitor against the offline certifier on random runs with faults.

For random runs (the robot wandering among the built-in scenario's regions, sometimes faster than the speed bound),
random faults (NaN samples, dropouts, duplicate stamps that agree or disagree, a nominal state drifting out of the
tube, commands outside the box, no nominal / no commands) and formulas with bounded, unbounded and nested windows
(and ``U``, which the monitor evaluates at the end): ``close()`` gives the offline certifier's verdict for every
check, its margins and first violations, whatever the batching; every decision made during the run is the final
verdict (monotone); no decision is reported before the sample that made it. The same with a signal atom (a
50 Hz topic with jitter, silences and duplicates) in the formula, on top of the faults.
"""

from __future__ import annotations

import numpy as np
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from .online_runs import SC, SC_SIGNAL, T0, offline_certificate, online_run, same_time

FORMULAS = [
    SC.spec,
    "G[0,inf) F[0,1.5] mission_1 & G[0,2] G[0,0.5] !obs_1",
    "G[0,3] !(F[0,1] mission_2) | F[1,2] G[0,0.4] mission_1",
    "G[0,inf) (F[0,0.5] mission_1 & !obs_2) & (mission_1 U[0,2] mission_2)",
    "G[0,inf) !(obs_1 | obs_2 | obs_3 | obs_4)",
    "F[1,3] mission_1 & G[0,2] !obs_1",
    "G[0,inf) F[0,1.5] mission_1",
    "F[0,2] G[0,0.5] !mission_1",
    "G[0,4] (mission_1 -> F[0,1] !mission_1)",
    "!F[0.5,2] mission_2 | G[0.2,inf) !obs_3",
    "mission_1 & F[0,inf) mission_2",
    "mission_1 U[0,3] !mission_1",
    "G[0,1] (F[0.2,0.6] mission_1 | G[0,0.3] !mission_1)",
]


def _run(rng: np.random.Generator, n: int, faults: dict[str, bool]) -> dict[str, object]:
    dt = 10_000_000
    t = T0 + np.cumsum(np.where(rng.random(n) < (0.05 if faults["dropouts"] else 0.0),
                                rng.integers(2, 60, n) * dt, dt))
    if faults["jitter"]:
        t = t + rng.integers(-3_000_000, 3_000_000, n)
        t = np.maximum.accumulate(t + np.arange(n))  # still increasing
    v = 0.15 if not faults["fast"] else 0.6
    start = SC.regions[int(rng.integers(0, len(SC.regions)))].center
    steps = rng.normal(0.0, v * 0.01, (n, 2))
    xy = np.array(start) + np.cumsum(steps, axis=0)
    x, y = xy[:, 0].copy(), xy[:, 1].copy()
    if faults["nan"]:
        k = rng.integers(0, n, max(1, n // 50))
        x[k] = np.nan
    nominal = None
    if not faults["no_nominal"]:
        drift = np.linspace(0.0, 0.05 if faults["tube"] else 0.005, n)
        nominal = (t + rng.integers(-2, 3, n) * 1_000_000, x - drift, y)
        nominal = (np.maximum.accumulate(nominal[0] + np.arange(n)), nominal[1], nominal[2])
    cmd = None
    if not faults["no_cmd"]:
        u = rng.uniform(-0.19, 0.19, (n, 3))
        if faults["input"]:
            u[int(rng.integers(0, n))] = [0.25, 0.0, 0.0]
        cmd = (t.copy(), u)
    dup_pose: list[tuple[int, float, float]] = []
    if faults["duplicates"]:
        for k in rng.integers(0, n, 4):
            same = bool(rng.random() < 0.5)
            dup_pose.append((int(k), float(x[k]) if same else float(x[k] + 0.3), float(y[k])))
    return {"t": t, "x": x, "y": y, "nominal": nominal, "cmd": cmd, "dup": dup_pose}


SIGNAL_FORMULAS = [
    "G[0,inf) calm",
    "F[0,2] !calm",
    "G[0,inf) (mission_1 -> calm)",
    "calm U[0,3] !mission_1",
    "G[0,1] F[0,0.5] calm",
    "G[0,inf) !obs_1 & F[0,inf) (mission_2 | !calm)",
]


def _signal(rng: np.random.Generator, t: np.ndarray) -> list[tuple[int, float]]:
    """Messages every 20 ms (+-3 ms) from before the first pose sample to after the last; one in 20 dropped (longer
    silences now and then), one in 30 repeated (same or another value); the value changes now and then, NaN too."""
    out: list[tuple[int, float]] = []
    s = int(t[0]) - int(rng.integers(0, 60_000_000))
    value = 0.2
    while s <= int(t[-1]) + 40_000_000:
        if rng.random() < 0.08:
            value = float(rng.choice([0.2, 0.45, 0.55, np.nan]))
        if rng.random() >= 0.05:
            out.append((s, value))
            if rng.random() < 1 / 30:
                out.append((s, value if rng.random() < 0.5 else 0.55))
        s += 20_000_000 + int(rng.integers(-3_000_000, 3_000_001)) + (int(rng.integers(0, 200_000_000))
                                                                       if rng.random() < 0.01 else 0)
    return out or [(int(t[0]), value)]


FAULTS = ["dropouts", "jitter", "fast", "nan", "tube", "input", "no_nominal", "no_cmd", "duplicates"]


@settings(deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(seed=st.integers(0, 2**32 - 1), n=st.integers(2, 600), spec=st.sampled_from(FORMULAS),
       update_every=st.sampled_from([0, 1, 7, 64]),
       faults=st.fixed_dictionaries({f: st.booleans() for f in FAULTS}))
def test_close_equals_offline_on_random_runs(seed: int, n: int, spec: str, update_every: int,
                                             faults: dict[str, bool]) -> None:
    run = _run(np.random.default_rng(seed), n, faults)
    cert = offline_certificate(run, spec)
    mon, seen = online_run(run, spec, update_every)
    res = mon.close()
    late = mon._formula_late_conflicts  # a duplicate of a sample the formula had judged: it cannot pass
    for got, want in zip(res.checks, cert["checks"], strict=True):  # type: ignore[arg-type]
        if late and got.name.startswith("spec_"):
            assert got.verdict != "pass" or want["verdict"] == "pass"
            continue
        assert got.verdict == want["verdict"], (got.name, got.details)
        assert same_time(got.margin, want["margin"]), (got.name, got.margin, want["margin"])
        first = None if got.first_violation_ns is None else round((got.first_violation_ns - int(run["t"][0])) * 1e-9,
                                                                   9)  # type: ignore[index]
        # every check's first violation too, the formula's (nested windows: G(F ...), U, X) included
        assert first == want["first_violation_time"], (got.name, first, want["first_violation_time"])
    if not late:
        assert res.verdict == cert["verdict"]
        # every obligation's final verdict, margin and first violation are the certificate's (its obligations: the
        # whole formula, then the conjuncts), whatever the batching
        offline = {o["formula"]: o for o in cert["obligations"]}  # type: ignore[index]
        for ob in res.state.obligations:
            want = offline[ob.name]
            assert ob.verdict == want["verdict"], (ob.name, ob.verdict, want["verdict"])
            assert same_time(ob.margin, want["margin"]), (ob.name, ob.margin, want["margin"])
            assert same_time(ob.first_violation_s, want["first_violation_time"]), (ob.name, ob.first_violation_s, want)
    final = {c.name: c.verdict for c in (*res.state.checks, *res.state.obligations)}
    for name, verdict in seen:
        assert final[name] == verdict, name  # monotone: a decision made during the run is the final one


def test_a_clean_run_passes_online() -> None:
    """The good case: a run that stays inside R1 with a close nominal state and small commands passes under a
    formula it satisfies."""
    run = _run(np.random.default_rng(3), 300, dict.fromkeys(FAULTS, False))
    run["x"] = np.full(300, -1.99)
    run["y"] = np.full(300, -1.78)
    run["nominal"] = (run["t"], np.full(300, -1.99), np.full(300, -1.78))  # type: ignore[assignment]
    mon, _ = online_run(run, "G[0,inf) mission_1 & G[0,inf) !obs_1", 10)
    res = mon.close()
    assert res.verdict == "pass", res.checks
    assert offline_certificate(run, "G[0,inf) mission_1 & G[0,inf) !obs_1")["verdict"] == "pass"


def test_samples_one_nanosecond_apart_leave_no_gap() -> None:
    """Two samples 1 ns apart have no instant between them (no gap position), as in the offline positions."""
    rng = np.random.default_rng(7)
    t = T0 + np.cumsum(rng.choice([1, 2, 3, 10_000_000], 400))
    x = -1.99 + np.cumsum(rng.normal(0.0, 0.002, 400))
    run = {"t": t, "x": x, "y": np.full(400, -1.78), "nominal": (t, x, np.full(400, -1.78)), "cmd": None,
           "dup": []}
    for spec in FORMULAS:
        cert = offline_certificate(run, spec)
        for every in (1, 13, 0):
            mon, _ = online_run(run, spec, every)
            res = mon.close()
            for got, want in zip(res.checks, cert["checks"], strict=True):  # type: ignore[arg-type]
                assert got.verdict == want["verdict"], (spec, got.name)
                assert same_time(got.margin, want["margin"]), (spec, got.name, got.margin, want["margin"])


@settings(deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(seed=st.integers(0, 2**32 - 1), n=st.integers(2, 400), spec=st.sampled_from(SIGNAL_FORMULAS),
       update_every=st.sampled_from([0, 1, 7, 64]),
       faults=st.fixed_dictionaries({f: st.booleans() for f in FAULTS}))
def test_close_equals_offline_with_a_signal_atom(seed: int, n: int, spec: str, update_every: int,
                                                 faults: dict[str, bool]) -> None:
    """A signal atom in the formula, pushed in time order among the pose samples: close() gives the offline
    verdicts, margins (in the signal's unit where it decides) and timed-run margins; decisions are final."""
    rng = np.random.default_rng(seed)
    run = _run(rng, n, faults)
    run["signal"] = _signal(rng, run["t"])  # type: ignore[arg-type]
    cert = offline_certificate(run, spec, SC_SIGNAL)
    mon, seen = online_run(run, spec, update_every, SC_SIGNAL)
    res = mon.close()
    assert mon.signal_counts["calm"]["late"] == 0
    late = mon._formula_late_conflicts
    for got, want in zip(res.checks, cert["checks"], strict=True):  # type: ignore[arg-type]
        if late and got.name.startswith("spec_"):
            assert got.verdict != "pass" or want["verdict"] == "pass"
            continue
        assert got.verdict == want["verdict"], (got.name, got.details)
        assert same_time(got.margin, want["margin"]), (got.name, got.margin, want["margin"])
    if not late:
        assert res.verdict == cert["verdict"]
        final = {c.name: c.verdict for c in (*res.state.checks, *res.state.obligations)}
        for name, verdict in seen:
            assert final[name] == verdict, name
