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

import math

import numpy as np
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from tubempc.scenario import Scenario, SignalSpec, builtin_scenario
from verify.certify import certify_data  # the offline judgement of in-memory samples, as certify_log runs it
from verify.ingest.fields import SignalStream
from verify.ingest.log import LogData, _stream
from verify.ingest.timebase import judged_samples
from verify.online import OnlineMonitor

SC = builtin_scenario()
T0 = 1_767_225_600 * 10**9
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


#: the built-in scenario with a signal atom: a speed topic at 50 Hz, ``calm`` while it is at most 0.5
SC_SIGNAL = SC.model_copy(update={"signals": {"calm": SignalSpec(topic="/speed", field="data", op="<=", value=0.5,
                                                                  unit="m/s", rate_hz=50.0)}})
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


def _signal_stream(messages: list[tuple[int, float]]) -> SignalStream:
    """As ``verify.ingest.fields.read_signals``: sorted, one value per instant (NaN where duplicates disagree)."""
    t = np.array([m[0] for m in messages], dtype=np.int64)
    v = np.array([m[1] for m in messages])
    order = np.argsort(t, kind="stable")
    t, v = t[order], v[order]
    tu, first = np.unique(t, return_index=True)
    lo, hi = np.minimum.reduceat(v, first), np.maximum.reduceat(v, first)
    spec = SC_SIGNAL.signals["calm"]
    assert spec.rate_hz is not None
    return SignalStream("calm", spec, tu, np.where(lo != hi, np.nan, v[first]), round(1e9 / spec.rate_hz), "header")


def _offline(run: dict[str, object], spec: str, sc: Scenario = SC) -> dict[str, object]:
    t, x, y = run["t"], run["x"], run["y"]
    assert isinstance(t, np.ndarray) and isinstance(x, np.ndarray) and isinstance(y, np.ndarray)
    dup = run["dup"]
    assert isinstance(dup, list)
    rt, rx, ry = list(t), list(x), list(y)  # reading order: a duplicate right after its sample
    for _, (k, dx, dy) in sorted(enumerate(dup), key=lambda e: (e[1][0], e[0]), reverse=True):
        rt.insert(k + 1, t[k])  # inserting the last drawn first keeps duplicates of one sample in drawing order
        rx.insert(k + 1, dx)
        ry.insert(k + 1, dy)
    ta, xa, ya = np.array(rt, dtype=np.int64), np.array(rx), np.array(ry)
    pose, every, _ = _stream(ta, xa, ya, np.zeros(ta.shape[0]))
    nominal = None
    if run["nominal"] is not None:
        nt, nx, ny = run["nominal"]  # type: ignore[misc]
        nominal = _stream(nt, nx, ny, np.zeros(nt.shape[0]))[0]
    cmd_t = cmd_u = None
    if run["cmd"] is not None:
        ct, cu = run["cmd"]  # type: ignore[misc]
        js = judged_samples(ct, cu)
        cmd_t, cmd_u = ct[js.all_index], cu[js.all_index]
    signals = {"calm": _signal_stream(run["signal"])} if run.get("signal") else {}  # type: ignore[arg-type]
    log = LogData("memory", "mcap", "", "sha256", "header", int(pose.t_ns[0]), pose, {}, nominal, cmd_t, cmd_u,
                  (), None, {}, False, pose_samples=every, signals=signals)
    return certify_data(log, sc, spec=spec).certificate


def _online(run: dict[str, object], spec: str, update_every: int, sc: Scenario = SC
            ) -> tuple[OnlineMonitor, list[tuple[str, str]]]:
    mon = OnlineMonitor(sc, spec=spec)
    signal: list[tuple[int, float]] = run.get("signal") or []  # type: ignore[assignment]
    m = 0
    t, x, y = run["t"], run["x"], run["y"]
    assert isinstance(t, np.ndarray) and isinstance(x, np.ndarray) and isinstance(y, np.ndarray)
    dups: dict[int, list[tuple[float, float]]] = {}
    for k, dx, dy in run["dup"]:  # type: ignore[attr-defined]
        dups.setdefault(k, []).append((dx, dy))
    nom, cmd = run["nominal"], run["cmd"]
    seen: list[tuple[str, str]] = []
    j = 0
    for i in range(t.shape[0]):
        while nom is not None and j < nom[0].shape[0] and nom[0][j] <= t[i]:  # type: ignore[index]
            mon.push_nominal(int(nom[0][j]), float(nom[1][j]), float(nom[2][j]))  # type: ignore[index]
            j += 1
        while m < len(signal) and signal[m][0] <= t[i]:  # the signal's messages up to this pose sample
            mon.push_signal("calm", *signal[m])
            m += 1
        mon.push_pose(int(t[i]), float(x[i]), float(y[i]))
        for dx, dy in dups.get(i, []):
            mon.push_pose(int(t[i]), dx, dy)
        if cmd is not None:
            mon.push_cmd(int(cmd[0][i]), *(float(u) for u in cmd[1][i]))  # type: ignore[index]
        if update_every and i % update_every == 0:
            for d in mon.update():
                assert d.time_s <= (int(t[i]) - int(t[0])) * 1e-9 + 1e-9  # never before the deciding sample
                seen.append((d.name, d.verdict))
    while nom is not None and j < nom[0].shape[0]:  # type: ignore[index]
        mon.push_nominal(int(nom[0][j]), float(nom[1][j]), float(nom[2][j]))  # type: ignore[index]
        j += 1
    for s_ns, value in signal[m:]:
        mon.push_signal("calm", s_ns, value)
    seen.extend((d.name, d.verdict) for d in mon.update())
    return mon, seen


def _same(a: float | None, b: float | None) -> bool:
    a = None if a is None or not math.isfinite(a) else a
    return (a is None and b is None) or (a is not None and b is not None and abs(a - b) <= 2e-9)


FAULTS = ["dropouts", "jitter", "fast", "nan", "tube", "input", "no_nominal", "no_cmd", "duplicates"]


@settings(deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(seed=st.integers(0, 2**32 - 1), n=st.integers(2, 600), spec=st.sampled_from(FORMULAS),
       update_every=st.sampled_from([0, 1, 7, 64]),
       faults=st.fixed_dictionaries({f: st.booleans() for f in FAULTS}))
def test_close_equals_offline_on_random_runs(seed: int, n: int, spec: str, update_every: int,
                                             faults: dict[str, bool]) -> None:
    run = _run(np.random.default_rng(seed), n, faults)
    cert = _offline(run, spec)
    mon, seen = _online(run, spec, update_every)
    res = mon.close()
    late = mon._formula_late_conflicts  # a duplicate of a sample the formula had judged: it cannot pass
    for got, want in zip(res.checks, cert["checks"], strict=True):  # type: ignore[arg-type]
        if late and got.name.startswith("spec_"):
            assert got.verdict != "pass" or want["verdict"] == "pass"
            continue
        assert got.verdict == want["verdict"], (got.name, got.details)
        assert _same(got.margin, want["margin"]), (got.name, got.margin, want["margin"])
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
            assert _same(ob.margin, want["margin"]), (ob.name, ob.margin, want["margin"])
            assert _same(ob.first_violation_s, want["first_violation_time"]), (ob.name, ob.first_violation_s, want)
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
    mon, _ = _online(run, "G[0,inf) mission_1 & G[0,inf) !obs_1", 10)
    res = mon.close()
    assert res.verdict == "pass", res.checks
    assert _offline(run, "G[0,inf) mission_1 & G[0,inf) !obs_1")["verdict"] == "pass"


def test_samples_one_nanosecond_apart_leave_no_gap() -> None:
    """Two samples 1 ns apart have no instant between them (no gap position), as in the offline positions."""
    rng = np.random.default_rng(7)
    t = T0 + np.cumsum(rng.choice([1, 2, 3, 10_000_000], 400))
    x = -1.99 + np.cumsum(rng.normal(0.0, 0.002, 400))
    run = {"t": t, "x": x, "y": np.full(400, -1.78), "nominal": (t, x, np.full(400, -1.78)), "cmd": None,
           "dup": []}
    for spec in FORMULAS:
        cert = _offline(run, spec)
        for every in (1, 13, 0):
            mon, _ = _online(run, spec, every)
            res = mon.close()
            for got, want in zip(res.checks, cert["checks"], strict=True):  # type: ignore[arg-type]
                assert got.verdict == want["verdict"], (spec, got.name)
                assert _same(got.margin, want["margin"]), (spec, got.name, got.margin, want["margin"])


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
    cert = _offline(run, spec, SC_SIGNAL)
    mon, seen = _online(run, spec, update_every, SC_SIGNAL)
    res = mon.close()
    assert mon.signal_counts["calm"]["late"] == 0
    late = mon._formula_late_conflicts
    for got, want in zip(res.checks, cert["checks"], strict=True):  # type: ignore[arg-type]
        if late and got.name.startswith("spec_"):
            assert got.verdict != "pass" or want["verdict"] == "pass"
            continue
        assert got.verdict == want["verdict"], (got.name, got.details)
        assert _same(got.margin, want["margin"]), (got.name, got.margin, want["margin"])
    if not late:
        assert res.verdict == cert["verdict"]
        final = {c.name: c.verdict for c in (*res.state.checks, *res.state.obligations)}
        for name, verdict in seen:
            assert final[name] == verdict, name
