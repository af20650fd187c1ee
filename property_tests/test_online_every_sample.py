"""The online monitor with ``update()`` after every pose sample: the same decisions, at the same call, as judging at
every call, and the same decisions and times as a batched feed.

An update may leave the buffered samples buffered when they cannot decide anything (``verify.online.quiet``). On
random runs with faults (as ``test_online_monitor``: NaN, dropouts, jitter, duplicate stamps, a nominal state
drifting out of the tube, a command outside the box, no nominal, no commands; straight runs across regions, starts
on a region's boundary) and formulas with
bounded, unbounded and nested windows: a monitor that judges at every update (the test switched off) and one that
may wait return, call by call, the same decisions (name, verdict, time, margin, first violation); both equal a feed
that calls ``update()`` only at the end; and ``close()`` gives the same checks. A decision states a margin only if
it was final when decided, and then it is the one ``close()`` states (the certificate's). (A duplicate stamp with other
values makes its sample unknown only while the sample waits, and else keeps the formula from passing: that depends
on when the sample was judged, as it always has, so the duplicates here agree.)
"""

from __future__ import annotations

import numpy as np
from hypothesis import HealthCheck, example, given, settings
from hypothesis import strategies as st

from tubempc.scenario import builtin_scenario
from verify.online import Decision, OnlineMonitor

SC = builtin_scenario()
T0 = 1_767_225_600 * 10**9
FORMULAS = [  # window ends off the batches' boundaries, so that a late decision would show
    SC.spec,
    "G[0,inf) !(obs_1 | obs_2 | obs_3 | obs_4)",
    "F[0.37,2.91] mission_1 & G[0,2.13] !obs_1",
    "F[0.53,2.2] (mission_1 | mission_2) & G[0,4.07] (mission_1 -> !obs_2)",
    "!F[0.51,2.3] mission_2 | G[0.23,inf) !obs_3",
    "F[0,inf) mission_1 & F[0,inf) mission_2 & G[0,inf) !mission_1",
    "G[0,1.19] !mission_1 | F[0,2.41] true",
    "G[0,inf) F[0,1.5] mission_1",  # nested: judged at every update
    "mission_1 U[0,3] !mission_1",
]
FAULTS = ["dropouts", "jitter", "fast", "nan", "tube", "input", "no_nominal", "no_cmd", "duplicates", "near", "line"]


def _run(rng: np.random.Generator, n: int, faults: dict[str, bool]) -> list[tuple[str, tuple[float, ...]]]:
    """The pushes of a random run, in arrival order: ("pose" | "nominal" | "cmd", (t, values...))."""
    dt = 10_000_000
    t = T0 + np.cumsum(np.where(rng.random(n) < (0.05 if faults["dropouts"] else 0.0),
                                rng.integers(2, 60, n) * dt, dt))
    if faults["jitter"]:
        t = np.maximum.accumulate(t + rng.integers(-3_000_000, 3_000_000, n) + np.arange(n))
    v = 0.6 if faults["fast"] else 0.15
    regions = SC.regions
    start = regions[int(rng.integers(0, len(regions)))].center
    xy = np.array(start) + np.cumsum(rng.normal(0.0, v * 0.01, (n, 2)), axis=0)
    if faults["line"]:  # straight across the regions at 0.8 m/s: entries and exits within a batch
        goal = np.array(regions[int(rng.integers(0, len(regions)))].center) - np.array(start)
        heading = goal / max(float(np.hypot(*goal)), 1e-9)
        xy = np.array(start) + np.outer(np.arange(n) * 0.008, heading)
    if faults["near"]:  # start on a region's boundary (the robot's disc touching it)
        r = regions[int(rng.integers(0, len(regions)))]
        xy = xy - xy[0] + np.array(r.center) + np.array([r.radius - SC.robot.radius, 0.0])
    x, y = xy[:, 0].copy(), xy[:, 1].copy()
    if faults["nan"]:
        x[rng.integers(0, n, max(1, n // 50))] = np.nan
    out: list[tuple[str, tuple[float, ...]]] = []
    drift = np.linspace(0.0, 0.05 if faults["tube"] else 0.005, n)
    u = rng.uniform(-0.19, 0.19, (n, 3))
    if faults["input"]:
        u[int(rng.integers(0, n))] = [0.25, 0.0, 0.0]
    for i in range(n):
        if not faults["no_nominal"]:
            out.append(("nominal", (int(t[i]) + int(rng.integers(-2, 3)) * 1_000_000, float(x[i] - drift[i]),
                                    float(y[i]))))
        out.append(("pose", (int(t[i]), float(x[i]), float(y[i]))))
        if faults["duplicates"] and rng.random() < 0.02:  # agreeing: merged (one that disagrees makes the sample
            out.append(("pose", (int(t[i]), float(x[i]), float(y[i]))))  # unknown only while it is not judged)
        if not faults["no_cmd"]:
            out.append(("cmd", (int(t[i]), *(float(c) for c in u[i]))))
    return out


def _key(d: Decision) -> tuple[object, ...]:
    return (d.name, d.verdict, d.time_s, d.margin, d.first_violation_s, d.unit)


def _feed(pushes: list[tuple[str, tuple[float, ...]]], spec: str, *, every: bool, wait: bool, pending: int
          ) -> tuple[OnlineMonitor, list[list[tuple[object, ...]]]]:
    """Per pose sample, the decisions the update after it returned (``every``), else one update at the end."""
    mon = OnlineMonitor(SC, spec=spec, max_pending=pending)
    if not wait:
        mon._quiet.enabled = False
    push = {"pose": mon.push_pose, "nominal": mon.push_nominal, "cmd": mon.push_cmd}
    calls: list[list[tuple[object, ...]]] = []
    for stream, args in pushes:
        push[stream](*args)  # type: ignore[operator]
        if every and stream == "pose":
            calls.append([_key(d) for d in mon.update()])
    calls.append([_key(d) for d in mon.update()])
    mon.close()
    calls.append([_key(d) for d in mon.final_decisions])
    return mon, calls


@settings(deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(seed=st.integers(0, 2**32 - 1), n=st.integers(2, 500), spec=st.sampled_from(FORMULAS),
       pending=st.sampled_from([100, 37, 1000]), faults=st.fixed_dictionaries({f: st.booleans() for f in FAULTS}))
@example(seed=0, n=214, spec=FORMULAS[3], pending=100,  # the F decided at 0.98 s: its margin final at 2.2 s only
         faults={f: f == "dropouts" for f in FAULTS})
@example(seed=0, n=499, spec=FORMULAS[2], pending=1000,  # a window between two entries of the timed run
         faults={f: f in ("jitter", "line") for f in FAULTS})
def test_an_update_per_sample_decides_as_judging_every_call(seed: int, n: int, spec: str, pending: int,
                                                             faults: dict[str, bool]) -> None:
    pushes = _run(np.random.default_rng(seed), n, faults)
    waiting, got = _feed(pushes, spec, every=True, wait=True, pending=pending)
    judging, want = _feed(pushes, spec, every=True, wait=False, pending=pending)
    assert got == want  # call by call: the same decisions at the same update
    batched, once = _feed(pushes, spec, every=False, wait=True, pending=pending)
    assert sorted(d for call in got for d in call) == sorted(d for call in once for d in call)
    for mon in (judging, batched):
        assert [(c.name, c.verdict, c.margin, c.first_violation_ns) for c in mon.close().checks] == \
            [(c.name, c.verdict, c.margin, c.first_violation_ns) for c in waiting.close().checks]
    final = waiting.close().state
    margins = {c.name: c.margin for c in (*final.obligations, *final.checks)}
    late = waiting._formula_late_conflicts  # a duplicate of a judged sample: the formula's checks cannot pass
    for name, _verdict, _time, margin, _first, _unit in (d for call in got for d in call):
        if margin is not None and not (late and str(name).startswith("spec_")):
            assert margins[str(name)] == margin, (name, margin)  # a stated margin is the final one
