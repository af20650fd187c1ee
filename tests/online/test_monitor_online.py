"""The online monitor: close() gives certify_log's verdicts on every example log; verdicts are monotone, reported
at the deciding sample, and the retained memory does not grow with the length of the run."""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np
import pytest

from tubempc.scenario import builtin_scenario, load_scenario
from verify import certify_log
from verify.ingest import read_log
from verify.online import MonitorClosedError, OnlineMonitor, feed_log_data

LOGS = Path(__file__).resolve().parents[2] / "logs"
#: every example log; diffdrive_odom.bag is judged against its own scenario (polygon regions and signal atoms)
#: two_robots.bag (several robots) has its own monitor: tests/verify/test_fleet.py::test_online_close_equals_certify
EXAMPLES = sorted(p.name for p in LOGS.iterdir() if p.suffix in (".bag", ".mcap") and p.name != "two_robots.bag")
OWN_SCENARIO = {"diffdrive_odom.bag": LOGS.parent / "docs" / "examples" / "diffdrive-room.yaml"}


def _same_margin(a: float | None, b: float | None) -> bool:
    """Certificates round to 1e-9 and turn infinities into null; the fast offline path computes distances with
    sqrt(dx*dx + dy*dy) (a few ulps from hypot), far below that rounding."""
    a = None if a is None or not math.isfinite(a) else a
    return (a is None and b is None) or (a is not None and b is not None and abs(a - b) <= 2e-9)


@pytest.mark.parametrize("name", EXAMPLES)
@pytest.mark.parametrize("update_every", [1, 37])
def test_close_equals_certify_log(name: str, update_every: int) -> None:
    sc = load_scenario(OWN_SCENARIO[name]) if name in OWN_SCENARIO else builtin_scenario()
    salvage = name == "truncated.bag"
    log = read_log(LOGS / name, sc, salvage=salvage)
    cert = certify_log(LOGS / name, sc, salvage=salvage).certificate
    mon = OnlineMonitor(sc)
    feed_log_data(mon, log, update_every=update_every)
    res = mon.close(partial=log.partial)
    assert res.verdict == cert["verdict"]
    assert [c.name for c in res.checks] == [c["name"] for c in cert["checks"]]
    for got, want in zip(res.checks, cert["checks"], strict=True):
        assert got.verdict == want["verdict"], got.name
        if got.name == "spec_timed_run":  # its temporal margin needs the whole run, which the monitor does not keep
            continue
        if got.name == "spec_trajectory" and got.verdict == "fail":
            # a fail's margin is the optimistic bound; the engines bound the gaps between samples differently, by
            # less than the distance the robot can travel in one sample period (v_max * dt)
            step_m = sc.max_speed_mps / sc.mocap.rate_hz
            assert got.margin is not None and want["margin"] is not None and got.margin < 0 and want["margin"] < 0
            assert abs(got.margin - want["margin"]) <= step_m, (got.margin, want["margin"])
            continue
        assert _same_margin(got.margin, want["margin"]), (got.name, got.margin, want["margin"])
        first = None if got.first_violation_ns is None else round((got.first_violation_ns - log.time0_ns) * 1e-9, 9)
        assert first == want["first_violation_time"], got.name


def test_violation_reported_at_the_deciding_sample() -> None:
    """obstacle_touch.bag: the disc first intersects R8 at one sample; the clearance check and G !obs are decided
    at that sample's time, while the run goes on (not at the end of the log)."""
    sc = builtin_scenario()
    log = read_log(LOGS / "obstacle_touch.bag", sc)
    mon = OnlineMonitor(sc)
    seen: dict[str, float] = {}
    for i in range(log.pose.t_ns.size):
        mon.push_pose(int(log.pose.t_ns[i]), float(log.pose.x_m[i]), float(log.pose.y_m[i]))
        for d in mon.update():
            seen.setdefault(d.name, (int(log.pose.t_ns[i]) - log.time0_ns) * 1e-9)
            assert d.time_s <= (int(log.pose.t_ns[i]) - log.time0_ns) * 1e-9 + 1e-9
    cert = certify_log(LOGS / "obstacle_touch.bag", sc).certificate
    first = next(c for c in cert["checks"] if c["name"] == "obstacle_clearance")["first_violation_time"]
    assert seen["obstacle_clearance"] == pytest.approx(first, abs=1e-9)
    obligation = next(k for k in seen if k.startswith("G[0,inf)"))
    assert seen[obligation] == pytest.approx(first, abs=1e-9)
    assert first < (int(log.pose.t_ns[-1]) - log.time0_ns) * 1e-9 - 1.0


def test_verdicts_are_monotone() -> None:
    sc = builtin_scenario()
    log = read_log(LOGS / "late_mission.mcap", sc)
    mon = OnlineMonitor(sc)
    decided: dict[str, str] = {}
    for i in range(0, log.pose.t_ns.size, 50):
        sl = slice(i, i + 50)
        for t, x, y in zip(log.pose.t_ns[sl], log.pose.x_m[sl], log.pose.y_m[sl], strict=True):
            mon.push_pose(int(t), float(x), float(y))
        st = mon.state()
        for c in (*st.checks, *st.obligations):
            if c.name in decided:
                assert c.decided and c.verdict == decided[c.name], c.name
            elif c.decided:
                decided[c.name] = c.verdict
    assert decided["F[30,50] mission_2"] == "fail"
    assert st.verdict == "fail"
    res = mon.close()
    for c in res.state.checks:
        if c.name in decided:
            assert c.verdict == decided[c.name]


@pytest.mark.parametrize(("spec", "window_s"), [(None, 110.0), ("G[0,inf) F[0,20] mission_1", 20.0)])
def test_memory_is_bounded_by_the_windows(spec: str | None, window_s: float) -> None:
    """The values held (positions, ticks and one array per node) stay within a few times the longest window times
    the rate, times 2 (samples and gaps), plus the batches between two drops; a run twice as long holds no more.
    The nested window is evaluated at every position (not only the first), so it is the one that
    keeps a window's worth of positions."""
    sc = builtin_scenario()
    held: list[int] = []
    for minutes in (3, 6):
        n = minutes * 60 * 100
        t = 10**18 + np.arange(n, dtype=np.int64) * 10_000_000
        mon = OnlineMonitor(sc, spec=spec, max_pending=100)
        peak = 0
        for i in range(n):
            mon.push_pose(int(t[i]), -1.99, -1.78)
            if i % 1000 == 999:
                peak = max(peak, mon.retained_positions)
        held.append(peak)
        assert mon.close().verdict == ("fail" if spec is None else "inconclusive")  # R3 never visited
    assert held[0] <= 4 * (2 * window_s * 100 + 2000)
    assert held[1] <= held[0] + 1000
    if spec is not None:
        assert held[0] >= window_s * 100  # the nested window's positions are really held


def test_push_after_close_and_out_of_order_are_errors_or_counted() -> None:
    mon = OnlineMonitor(builtin_scenario())
    mon.push_pose(10, -1.99, -1.78)
    mon.push_pose(5, -1.99, -1.78)
    mon.push_pose(10, -1.99, -1.78)
    assert mon.out_of_order["pose"] == 1 and mon.duplicates["pose"] == 1 and mon.counts["pose"] == 1
    mon.close()
    with pytest.raises(MonitorClosedError):
        mon.push_pose(20, 0.0, 0.0)


def test_out_of_order_sample_never_passes() -> None:
    """A sample dropped for arriving late was not judged: the run cannot be certified as pass."""
    sc = builtin_scenario()
    log = read_log(LOGS / "demo.mcap", sc)
    mon = OnlineMonitor(sc)
    feed_log_data(mon, log)
    assert mon.state().verdict != "pass"
    mon.push_pose(int(log.pose.t_ns[5]), 0.0, 0.0)
    res = mon.close()
    assert res.verdict == "inconclusive" and "out of time order" in (res.verdict_reason or "")


def test_only_the_selected_checks_are_judged() -> None:
    """As certify --checks: the other checks are neither reported nor part of the verdict (obstacle_touch fails
    only on the obstacle: without that check and the formula, the run passes)."""
    sc = builtin_scenario()
    log = read_log(LOGS / "obstacle_touch.bag", sc)
    want = certify_log(LOGS / "obstacle_touch.bag", sc, checks=["workspace", "tube"]).certificate
    mon = OnlineMonitor(sc, checks=["workspace", "tube"])
    feed_log_data(mon, log, update_every=10)
    res = mon.close()
    assert [c.name for c in res.checks] == [c["name"] for c in want["checks"]] == ["tube", "workspace"]
    assert res.verdict == want["verdict"] == "pass"
    assert not res.state.obligations


def test_a_nested_window_decides_at_its_deciding_sample() -> None:
    """``G[0,10] G[0,5] mission_1``: the robot leaves R1 at 3.91 s; the inner window at time 0 is false from that
    sample on, so the formula fails then -- not when the inner window closes (5 s) -- and close() agrees."""
    sc = builtin_scenario()
    mon = OnlineMonitor(sc, spec="G[0,10] G[0,5] mission_1")
    seen: dict[str, float] = {}
    for i in range(1200):
        mon.push_pose(10**18 + i * 10_000_000, -1.99 + (0.0 if i < 300 else 0.002 * (i - 300)), -1.78)
        for d in mon.update():
            seen.setdefault(d.name, i / 100)
            assert d.time_s <= i / 100 + 1e-9
    assert seen["spec_trajectory"] == pytest.approx(3.91)
    assert seen["G[0,10] G[0,5] mission_1"] == pytest.approx(3.91)
    ob = mon.state().obligations[0]
    assert ob.first_violation_s == pytest.approx(3.91)  # the sample that shows it, not the window's position 0
    assert mon.close().checks[0].verdict == "fail"


def test_the_general_geometry_path_gives_the_same_verdicts() -> None:
    """Scenarios with other than disc regions go through verify.geometry's own functions per batch; on discs that
    path and the one-pass broadcast give the same checks, margins and decisions."""
    sc = builtin_scenario()
    log = read_log(LOGS / "obstacle_touch.bag", sc)
    results = []
    for discs in (True, False):
        mon = OnlineMonitor(sc)
        mon._geometry.discs = discs
        decisions = feed_log_data(mon, log, update_every=25)
        results.append((mon.close(), [(d.name, d.verdict, d.time_s) for d in decisions]))
    (fast, fast_d), (general, general_d) = results
    assert fast_d == general_d
    assert [(c.name, c.verdict, c.first_violation_ns) for c in fast.checks] == \
        [(c.name, c.verdict, c.first_violation_ns) for c in general.checks]
    for a, b in zip(fast.checks, general.checks, strict=True):
        assert _same_margin(a.margin, b.margin if b.margin is None or math.isfinite(b.margin) else None)


@pytest.mark.parametrize("update_every", [1, 2])
def test_motion_between_two_updates_is_judged(update_every: int) -> None:
    """Two samples clear of R6 on either side of it, 6.4 s apart: the straight path between them crosses R6, so
    G !obs_1 is undecided (the speed bound allows the crossing). Fed one sample per update, the gap between the two
    updates must still be judged (it was skipped: a pass)."""
    sc = builtin_scenario()
    cx, cy = sc.region("R6").center
    t0 = 1_767_225_600 * 10**9
    samples = [(t0, cx - 0.8, cy), (t0 + 6_400_000_000, cx + 0.8, cy), (t0 + 6_410_000_000, cx + 0.8, cy)]
    mon = OnlineMonitor(sc, spec="G[0,inf) !obs_1")
    for k, (t, x, y) in enumerate(samples):
        mon.push_pose(t, x, y)
        if (k + 1) % update_every == 0:
            mon.update()
    res = mon.close()
    spec = next(c for c in res.checks if c.name == "spec_trajectory")
    assert spec.verdict == "inconclusive"
    assert res.verdict != "pass"


def test_memory_does_not_grow_with_the_batch() -> None:
    """Large batches (``max_pending``) drop what no window needs at every batch once 1024 positions and ticks were
    appended, not only every 8 batches: the values held stay within a few batches' worth (8 batches of 1000 samples,
    two positions and a tick each, in every node, were held before)."""
    sc = builtin_scenario()
    n = 3 * 60 * 100
    t = 10**18 + np.arange(n, dtype=np.int64) * 10_000_000
    mon = OnlineMonitor(sc, max_pending=1000)
    peak = 0
    for i in range(n):
        mon.push_pose(int(t[i]), -1.99, -1.78)
        if i % 100 == 99:
            peak = max(peak, mon.retained_positions)
    assert peak <= 4 * (3 * 1000 + 1024)
