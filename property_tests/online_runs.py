"""Runs fed to the online monitor and to the offline certifier, shared by the online == offline properties
(``property_tests/test_online_monitor.py``) and the first-violation examples (``tests/online/test_first_violation.py``).

A run is a dict: pose stamps ``t`` (ns) with ``x``, ``y``; ``nominal`` ``(t, x, y)`` or None; ``cmd`` ``(t, u)`` or
None; ``dup``: duplicate pose samples ``(index, x, y)``; optionally ``signal``: messages ``(t_ns, value)`` of the
signal ``calm``. ``offline_certificate`` judges it as ``certify_log`` would after reading it; ``online_run`` pushes it
sample by sample into an ``OnlineMonitor`` (``update()`` every ``update_every`` pose samples).
"""

from __future__ import annotations

import math

import numpy as np

from tubempc.scenario import Scenario, SignalSpec, builtin_scenario
from verify.certify import certify_data  # the offline judgement of in-memory samples, as certify_log runs it
from verify.ingest.fields import SignalStream
from verify.ingest.log import LogData, _stream
from verify.ingest.timebase import judged_samples
from verify.online import OnlineMonitor

__all__ = ["SC", "SC_SIGNAL", "T0", "offline_certificate", "online_run", "same_time"]

SC = builtin_scenario()
T0 = 1_767_225_600 * 10**9

#: the built-in scenario with a signal atom: a speed topic at 50 Hz, ``calm`` while it is at most 0.5
SC_SIGNAL = SC.model_copy(update={"signals": {"calm": SignalSpec(topic="/speed", field="data", op="<=", value=0.5,
                                                                  unit="m/s", rate_hz=50.0)}})
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


def offline_certificate(run: dict[str, object], spec: str, sc: Scenario = SC) -> dict[str, object]:
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


def online_run(run: dict[str, object], spec: str, update_every: int, sc: Scenario = SC
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


def same_time(a: float | None, b: float | None) -> bool:
    a = None if a is None or not math.isfinite(a) else a
    return (a is None and b is None) or (a is not None and b is not None and abs(a - b) <= 2e-9)
