"""Signal atoms in the online monitor: close() gives certify's verdicts on random runs whose formula uses a signal,
decisions are final, pose samples wait (boundedly) for the signals, and late messages never make a pass."""

from __future__ import annotations

import dataclasses
from pathlib import Path

import numpy as np
import pytest
from hypothesis import given
from hypothesis import strategies as st

from tubempc.scenario import Scenario, SignalSpec, load_scenario
from tubempc.strategies import SIGNAL_LEVELS, Trajectory, signal_messages, trajectories
from verify import certify_data
from verify.ingest import LogData, PoseStream
from verify.ingest.fields import SignalStream
from verify.online import Decision, OnlineMonitor
from verify.online.monitor import feed_log_data

ROOT = Path(__file__).resolve().parents[2]
#: polygon regions (room, table: unsafe) and a disc (dock); signals slow (<= 0.5 m/s) and crawl (<= 0.3 m/s)
SCENARIO = load_scenario(ROOT / "docs" / "examples" / "diffdrive-room.yaml")
FORMULAS = ("G[0,inf) slow", "F[0,5] !crawl", "G[0,inf) (in_room -> slow)", "slow U[0,8] !in_room",
            "G[0,inf) F[0,2] crawl", "F[1,4] G[0,1] slow", "G[0,10] in_room & G[0,inf) (!table & slow)")
LEVELS = SIGNAL_LEVELS  # around the thresholds of slow (0.5) and crawl (0.3), and NaN
T0 = 1_700_000_000 * 10**9


def _scenario(rate_hz: float | None) -> Scenario:
    """The example's signals on a topic of their own (a signal on the pose topic shares the pose's samples: the
    tests here push signal messages at their own times)."""
    signals = {k: SignalSpec(**{**v.model_dump(), "rate_hz": rate_hz, "topic": "/wheel_speed"})
               for k, v in SCENARIO.signals.items()}
    return SCENARIO.model_copy(update={"signals": signals})


def _streams(sc: Scenario, messages: list[tuple[int, float]]) -> dict[str, SignalStream]:
    """As ``verify.ingest.fields.read_signals``: sorted, one value per instant (NaN where duplicates disagree), the
    period from rate_hz or the median spacing."""
    out: dict[str, SignalStream] = {}
    t = np.array([m[0] for m in messages], dtype=np.int64)
    v = np.array([m[1] for m in messages], dtype=np.float64)
    order = np.argsort(t, kind="stable")
    t, v = t[order], v[order]
    tu, first = np.unique(t, return_index=True)
    lo, hi = np.minimum.reduceat(v, first), np.maximum.reduceat(v, first)
    value = np.where(lo != hi, np.nan, v[first])
    for name, spec in sc.signals.items():
        period = round(1e9 / spec.rate_hz) if spec.rate_hz is not None else (
            int(np.median(np.diff(tu))) if tu.shape[0] >= 2 else 0)
        out[name] = SignalStream(name, spec, tu, value.copy(), period, "header",
                                 follows_pose=spec.topic == sc.topics.pose)
    return out


def _log(traj: Trajectory, signals: dict[str, SignalStream]) -> LogData:
    t_s, xy, yaw = traj.arrays()
    t_ns = T0 + np.round(t_s * 1e9).astype(np.int64)
    pose = PoseStream(t_ns, xy[:, 0] + 1.6, xy[:, 1] + 1.1, yaw)
    n = int(t_ns.size)
    counts = {"read": n, "judged": n, "merged_duplicates": 0, "conflicting_duplicates": 0}
    return LogData("<random run>", "in-memory", "0" * 64, "sha256", "header", T0, pose,
                   {"topic": "/odom", "type": "nav_msgs/msg/Odometry"}, None, None, None, (), None,
                   {"notes": [], "missing_definitions": []}, False, pose_samples=pose, time_base_requested="header",
                   samples={"pose": {**counts, "retimed": 0}}, signals=signals)


@st.composite
def cases(draw: st.DrawFn) -> tuple[Scenario, str, LogData, list[tuple[int, float]], int]:
    rate = draw(st.sampled_from((10.0, None)))
    sc = _scenario(rate)
    traj = draw(trajectories(rate_hz=10.0, max_samples=120, max_speed_mps=0.45, box_m=1.5))
    end_ns = T0 + round(traj.t_s[-1] * 1e9)
    messages = list(draw(signal_messages(T0, end_ns, levels=LEVELS)))
    return sc, draw(st.sampled_from(FORMULAS)), _log(traj, _streams(sc, messages)), messages, draw(
        st.sampled_from((1, 7)))


def _push_delayed(mon: OnlineMonitor, log: LogData, messages: list[tuple[int, float]], update_every: int,
                  delay_ns: list[int]) -> list[Decision]:
    """The raw signal messages (both signals, duplicates included), each delivered ``delay_ns`` (< 1 s) after its
    time, so out of order; the pose samples in time order, each 1 s after its time (a recorder that buffers the
    poses): every message arrives before the pose samples it bears on, as a message must to be judged."""
    events: list[tuple[int, int, int]] = [(int(t) + 10**9, 0, i) for i, t in enumerate(log.pose.t_ns.tolist())]
    events += [(t + delay_ns[i % len(delay_ns)], 1, i) for i, (t, _) in enumerate(messages)]
    events.sort()
    out: list[Decision] = []
    poses = 0
    for _, kind, i in events:
        if kind == 0:
            mon.push_pose(int(log.pose.t_ns[i]), float(log.pose.x_m[i]), float(log.pose.y_m[i]))
            poses += 1
            if poses % update_every == 0:
                out += mon.update()
        else:
            for name in sorted(log.signals):
                mon.push_signal(name, *messages[i])
    return out + mon.update()


def _check(mon: OnlineMonitor, decided: list[Decision], log: LogData, sc: Scenario, spec: str) -> None:
    cert = certify_data(log, sc, spec=spec).certificate
    res = mon.close()
    exact = all(not f.hold_mismatch() for f in mon._feeds.values())
    got = {c.name: c.verdict for c in res.checks}
    want = {c["name"]: c["verdict"] for c in cert["checks"]}
    if exact:
        assert got == want, (got, want, spec)
        assert res.verdict == cert["verdict"]
        final = {**got, **{o.name: o.verdict for o in res.state.obligations}}
        for d in decided:  # a decision made before close is the final verdict
            assert final[d.name] == d.verdict, (d, final)
    else:  # a rate-less signal judged with another hold than offline's: never a pass online that is not offline
        for name, verdict in got.items():
            assert verdict != "pass" or want[name] == "pass" or not name.startswith("spec"), (name, got, want)


@given(cases())
def test_random_runs_with_a_signal_atom_close_equals_certify(case: tuple[Scenario, str, LogData,
                                                                         list[tuple[int, float]], int]) -> None:
    sc, spec, log, _, update_every = case
    mon = OnlineMonitor(sc, spec=spec)
    decided = feed_log_data(mon, log, update_every=update_every)
    _check(mon, decided, log, sc, spec)


@given(cases(), st.lists(st.integers(0, 900_000_000), min_size=1, max_size=5))
def test_signal_messages_out_of_order_within_the_lag(case: tuple[Scenario, str, LogData, list[tuple[int, float]],
                                                                 int], delays: list[int]) -> None:
    """Raw messages (duplicates included) delivered up to 0.9 s late, out of order, but before the pose samples
    they bear on: the same verdicts as offline, which sorts them."""
    sc, spec, log, messages, update_every = case
    mon = OnlineMonitor(sc, spec=spec, max_signal_lag_s=1.0)
    decided = _push_delayed(mon, log, messages, update_every, delays)
    assert all(f.late == 0 for f in mon._feeds.values())
    _check(mon, decided, log, sc, spec)


def _run(n: int, silent_after: int, *, lag_s: float = 1.0) -> OnlineMonitor:
    """A robot standing in the room at 10 Hz; the speed signal (0.1 m/s, rate 10 Hz) stops after ``silent_after``
    messages."""
    sc = _scenario(10.0)
    mon = OnlineMonitor(sc, spec="G[0,inf) slow", max_signal_lag_s=lag_s, max_pending=10)
    for i in range(n):
        t = T0 + i * 100_000_000
        if i < silent_after:
            mon.push_signal("slow", t, 0.1)
        mon.push_pose(t, 1.0, 0.5)
    return mon


def test_pose_samples_wait_for_the_signal_at_most_the_lag() -> None:
    mon = _run(600, 600)
    assert mon.counts["pose"] == 600 and len(mon._pose.t) <= 10 + 1  # judged as the signal covers them
    assert len(mon._feeds["slow"].t) <= 10 + 2  # messages kept: from the one held at the last judged sample on
    mon = _run(600, 50, lag_s=1.0)
    mon.update()
    assert len(mon._pose.t) <= 10 + 11  # a silent signal: no more than the lag (10 samples) and one batch wait
    res = mon.close()
    assert res.checks[0].verdict == "inconclusive"  # the silence is unknown: G slow cannot pass
    assert mon.retained_positions < 200


def test_a_late_message_makes_the_formula_unable_to_pass() -> None:
    mon = _run(100, 100)
    mon.push_signal("slow", T0 + 99 * 100_000_000 + 50_000_000, 0.1)  # after the last pose sample: in time
    mon.update()
    assert mon.close().verdict == "pass"
    mon = _run(100, 100, lag_s=0.5)
    mon.update()
    mon.push_signal("slow", T0 + 10 * 100_000_000 + 1, 0.1)  # for an instant judged already
    res = mon.close()
    assert mon.signal_counts["slow"]["late"] == 1
    spec = next(c for c in res.checks if c.name == "spec_trajectory")
    assert spec.verdict == "inconclusive" and "arrived after" in spec.details["reason"]
    assert res.verdict == "inconclusive"


def test_a_rateless_hold_the_whole_stream_changes_never_passes() -> None:
    """Without rate_hz the hold is the median spacing so far: messages every 0.3 s early (hold 0.45 s) then every
    0.1 s (the whole stream's hold: 0.15 s) -- the early 0.3 s stretches were judged held; offline they are
    unknown, so the online formula cannot pass."""
    sc = _scenario(None)
    times = [T0 + k * 300_000_000 for k in range(20)]
    times += [times[-1] + k * 100_000_000 for k in range(1, 200)]
    mon = OnlineMonitor(sc, spec="G[0,inf) slow", max_pending=5)
    for t in times:
        mon.push_signal("slow", t, 0.1)
        mon.push_pose(t, 1.0, 0.5)
    res = mon.close()
    assert mon._feeds["slow"].hold_mismatch()
    log = _log(Trajectory(tuple((t - T0) * 1e-9 for t in times), tuple((-0.6, -0.6) for _ in times),
                          tuple(0.0 for _ in times)), _streams(sc, [(t, 0.1) for t in times]))
    cert = certify_data(log, sc, spec="G[0,inf) slow").certificate
    assert cert["checks"][0]["verdict"] == "inconclusive" == res.checks[0].verdict


def test_a_signal_the_formula_does_not_use_is_ignored_and_unknown_names_are_errors() -> None:
    mon = OnlineMonitor(_scenario(10.0), spec="G[0,inf) in_room")
    mon.push_signal("crawl", T0, 0.0)
    assert mon.signal_ignored == 1
    with pytest.raises(KeyError, match="nope"):
        mon.push_signal("nope", T0, 0.0)


def test_dataclass_of_decision_keeps_its_fields() -> None:
    d = Decision("G[0,inf) slow", "fail", 1.0, -0.1, 0.5, "m/s")
    assert "margin -0.1 m/s" in d.line()
    assert dataclasses.replace(d, unit=None).line().endswith("(violated at 0.50 s)")


def test_nested_regions_make_one_timed_run_entry_with_both_labels() -> None:
    """The table lies in the room: a sample inside both is one entry ``room+table`` carrying both labels (as
    ``verify.semantics.timed_run.timed_run_of_sets``), so ``G (table -> in_room)`` holds on the timed run."""
    sc = _scenario(10.0)
    n = 60
    traj = Trajectory(tuple(i * 0.1 for i in range(n)), tuple((0.0, -0.3 + i * 0.01) for i in range(n)),
                      tuple(0.0 for _ in range(n)))
    log = _log(traj, _streams(sc, [(T0, 0.1)]))
    for spec in ("G[0,inf) (table -> in_room)", "F[0,inf) (table & !in_room)", "G[0,inf) (table -> slow)"):
        mon = OnlineMonitor(sc, spec=spec)
        feed_log_data(mon, log, update_every=7)
        res = mon.close()
        cert = certify_data(log, sc, spec=spec).certificate
        assert [(c.name, c.verdict) for c in res.checks] == [(c["name"], c["verdict"]) for c in cert["checks"]]
        entries = [e[0] for e in mon._run_log.entries]
        assert entries == [e["region"] for e in cert["timed_run"]] == ["room", "room+table"]
