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
