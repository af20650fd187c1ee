"""An update after every pose sample judges only when something can be decided (``verify.online.quiet``)."""

from __future__ import annotations

from typing import Any

from tubempc.scenario import builtin_scenario
from verify.online import OnlineMonitor

SC = builtin_scenario()
T0 = 1_767_225_600 * 10**9
DT = 10_000_000


def _counted(mon: OnlineMonitor) -> list[int]:
    calls = [0]
    judge = mon._process

    def counting(*args: Any, **kwargs: Any) -> None:
        calls[0] += 1
        judge(*args, **kwargs)

    mon._process = counting  # type: ignore[method-assign]
    return calls


def test_a_quiet_stretch_is_judged_in_batches_and_a_violation_at_once() -> None:
    """Standing still in R2 (no region, no obstacle, no window end) for 3 s with an update per sample: judged at
    the first sample and then once per ``max_pending`` samples; a step into obstacle R6 is judged and reported at
    the update right after it, with its time."""
    mon = OnlineMonitor(SC, spec="G[0,inf) !obs_1 & F[0,inf) mission_1")
    calls = _counted(mon)
    x, y = SC.regions[1].center
    for i in range(300):
        t = T0 + i * DT
        mon.push_nominal(t, x, y)
        mon.push_pose(t, x, y)
        mon.push_cmd(t, 0.0, 0.0, 0.0)
        assert mon.update() == []
    assert calls[0] <= 6  # judging at every call: 300
    t = T0 + 300 * DT
    ox, oy = SC.regions[5].center  # R6: obs_1
    mon.push_nominal(t, ox, oy)
    mon.push_pose(t, ox, oy)
    got = {d.name: d for d in mon.update()}
    assert got["G[0,inf) !obs_1"].verdict == "fail" and got["G[0,inf) !obs_1"].time_s == 3.0
    assert got["obstacle_clearance"].verdict == "fail"


def test_a_command_outside_the_box_is_reported_at_its_update() -> None:
    mon = OnlineMonitor(SC, spec="G[0,inf) !obs_1")
    x, y = SC.regions[1].center
    for i in range(50):
        t = T0 + i * DT
        mon.push_pose(t, x, y)
        mon.push_cmd(t, 0.0, 0.0, 0.0)
        assert mon.update() == []
    mon.push_cmd(T0 + 50 * DT, 5.0, 0.0, 0.0)
    got = mon.update()
    assert [(d.name, d.verdict, d.time_s) for d in got] == [("input_box", "fail", 0.5)]


def _judging_log(mon: OnlineMonitor, *, run: bool = False) -> list[str]:
    """Records which part of the judging runs: the trajectory semantics, the per-sample checks on poses, the
    commands, the nominal states (``run``: and the timed-run semantics)."""
    log: list[str] = []

    def logging(name: str, fn: Any) -> Any:
        def logged(*args: Any, **kwargs: Any) -> Any:
            log.append(name)
            return fn(*args, **kwargs)

        return logged

    parts = [("trajectory", mon._traj.evaluation, "step"), ("poses", mon._checks, "feed_poses"),
             ("cmd", mon._checks, "feed_cmd"), ("nominal", mon._checks, "feed_nominal")]
    for name, obj, attr in parts + ([("run", mon._run.evaluation, "step")] if run else []):
        setattr(obj, attr, logging(name, getattr(obj, attr)))
    return log


def test_a_quiet_stretch_is_judged_one_stream_per_update() -> None:
    """Standing still in R2 for 10 s with an update per sample: every stream's samples are judged (the buffers stay
    below ``max_pending``), and no update judges more than one stream (a pose batch takes two updates: the
    trajectory semantics, then the per-sample checks), so that no single update pays for all of them."""
    mon = OnlineMonitor(SC, spec="G[0,inf) !obs_1 & F[0,inf) mission_1")
    x, y = SC.regions[1].center
    log = _judging_log(mon)
    per_update = []
    for i in range(1000):
        t = T0 + i * DT
        mon.push_nominal(t, x, y)
        mon.push_pose(t, x, y)
        mon.push_cmd(t, 0.0, 0.0, 0.0)
        before = len(log)
        assert mon.update() == []
        per_update.append(log[before:])
        assert max(len(mon._pose.t), len(mon._nom.t), len(mon._cmd.t)) < mon.max_pending
    assert per_update[0] == ["nominal", "trajectory", "poses", "cmd"]  # the first samples are judged at once
    assert max(len(parts) for parts in per_update[1:]) == 1
    assert {"trajectory", "poses", "cmd", "nominal"} <= {p for parts in per_update[1:] for p in parts}
    assert mon.counts == {"pose": 1000, "nominal": 1000, "cmd": 1000}


def test_a_command_outside_the_box_judges_the_commands_alone() -> None:
    """A command outside the box while the poses stay quiet: the update that follows judges the commands only and
    returns the input box's failure with its time; the pose samples stay buffered."""
    mon = OnlineMonitor(SC, spec="G[0,inf) !obs_1")
    x, y = SC.regions[1].center
    for i in range(50):
        t = T0 + i * DT
        mon.push_pose(t, x, y)
        mon.push_cmd(t, 0.0, 0.0, 0.0)
        mon.update()
    log = _judging_log(mon)
    mon.push_pose(T0 + 50 * DT, x, y)
    mon.push_cmd(T0 + 50 * DT, 5.0, 0.0, 0.0)
    got = mon.update()
    assert [(d.name, d.verdict, d.time_s) for d in got] == [("input_box", "fail", 0.5)]
    assert log == ["cmd"] and mon._pose.t
    assert mon.close().verdict == "fail"


def test_an_entry_judges_the_formula_and_leaves_the_checks_for_the_next_update() -> None:
    """Driving into R1 at 0.2 m/s with an update per sample: the update after the sample that enters it judges the
    two semantics of the formula and returns the F's decision with that sample's time, as judging at every call;
    the per-sample checks of those poses, the nominal states and the commands (none of which can decide anything
    then) wait for the next updates, so that the deciding update does not pay for them."""
    spec = "F[0,inf) mission_1 & G[0,inf) !obs_1"
    cx, cy = SC.region("R1").center
    mons = [OnlineMonitor(SC, spec=spec) for _ in range(2)]
    mons[1]._quiet.enabled = False  # judges at every call
    log = _judging_log(mons[0], run=True)
    per_update: list[tuple[list[str], list[tuple[str, str, float]]]] = []
    judged: list[list[tuple[str, str, float]]] = []
    for i in range(300):
        t, y = T0 + i * DT, cy + 0.6 - 0.002 * i
        before = len(log)
        for m in mons:
            m.push_nominal(t, cx, y)
            m.push_pose(t, cx, y)
            m.push_cmd(t, 0.0, 0.0, 0.0)
        got = [(d.name, d.verdict, d.time_s) for d in mons[0].update()]
        per_update.append((log[before:], got))
        judged.append([(d.name, d.verdict, d.time_s) for d in mons[1].update()])
    assert [got for _, got in per_update] == judged  # the same decisions at the same calls
    k = next(i for i, (_, got) in enumerate(per_update) if got)
    parts, decided = per_update[k]
    assert decided == [("F[0,inf) mission_1", "pass", 2.1)]  # the disc inside R1: 0.6 - 0.002 i = 0.45 - 0.27 (+ ulps)
    assert sorted(parts) == ["run", "trajectory"]  # the formula alone
    assert per_update[k + 1][0] == ["poses"]  # the per-sample checks of those poses at the next update
    assert mons[0].close().checks == mons[1].close().checks
