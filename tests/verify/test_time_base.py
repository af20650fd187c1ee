"""Time bases: no sample is dropped, a time base that cannot order the samples never yields a pass.

Each test is a reproducer of a false pass (or a false fail) through header stamps: a repeated stamp hiding a pose
inside an obstacle, a publisher that never sets its stamps, one negative or 1970 stamp moving time 0, and a log on a
simulated clock that must stay valid.
"""

from __future__ import annotations

from collections.abc import Callable
from pathlib import Path
from typing import Any

import numpy as np
import pytest

from tubempc.scenario import Scenario
from verify import certify_log
from verify.ingest.timebase import choose_time_base, header_outliers, judged_samples

from .conftest import TIME0_NS

MakeLog = Callable[..., Path]


@pytest.fixture
def good(scenario: Scenario, paper_traj: Callable[..., Any]) -> Any:
    return paper_traj(scenario, rate_hz=20.0)


def _obstacle_centre(scenario: Scenario) -> tuple[float, float]:
    c = scenario.unsafe_regions[0].center
    return float(c[0]), float(c[1])


def _with_pose(traj: Any, k: int, xy: tuple[float, float], traj_cls: type) -> Any:
    x, y = traj.x.copy(), traj.y.copy()
    x[k], y[k] = xy
    return traj_cls(traj.t_s, x, y, traj.theta, nominal=traj.nominal, cmd=traj.cmd)


def _stamp(traj: Any, k: int) -> int:
    return TIME0_NS + round(float(traj.t_s[k]) * 1e9)


@pytest.mark.parametrize("fmt", ["bag", "mcap"])
@pytest.mark.parametrize("swap", [False, True])
def test_repeated_stamp_inside_an_obstacle_fails_in_either_order(  # noqa: PLR0917 (fixtures + parameters)
        make_log: MakeLog, scenario: Scenario, good: Any, traj_cls: type, fmt: str, swap: bool) -> None:
    """Pose k+1 carries pose k's stamp and sits at an obstacle's centre: whichever is read first, it is judged."""
    k = 1000
    bad = k if swap else k + 1
    traj = _with_pose(good, bad, _obstacle_centre(scenario), traj_cls)
    log = make_log(fmt, traj, pose_stamps_ns={k + 1: _stamp(good, k)})
    cert = certify_log(log, scenario).certificate
    assert cert["verdict"] == "fail"
    clearance = next(c for c in cert["checks"] if c["name"] == "obstacle_clearance")
    assert clearance["verdict"] == "fail" and clearance["margin"] < 0
    assert cert["samples"]["pose"]["conflicting_duplicates"] == 2
    assert cert["samples"]["pose"]["read"] == cert["samples"]["pose"]["judged"] == len(good.t_s)
    assert cert["time_base"] == "header"


def test_repeated_stamp_that_agrees_is_merged_and_passes(make_log: MakeLog, scenario: Scenario, good: Any,
                                                         traj_cls: type) -> None:
    k = 1000
    traj = _with_pose(good, k + 1, (float(good.x[k]), float(good.y[k])), traj_cls)
    theta = traj.theta.copy()
    theta[k + 1] = theta[k]
    traj = traj_cls(traj.t_s, traj.x, traj.y, theta, nominal=traj.nominal, cmd=traj.cmd)
    cert = certify_log(make_log("mcap", traj, pose_stamps_ns={k + 1: _stamp(good, k)}), scenario).certificate
    assert cert["samples"]["pose"]["merged_duplicates"] == 1
    assert cert["samples"]["pose"]["judged"] == len(good.t_s) - 1
    assert cert["verdict"] == "pass"


def test_repeated_stamp_that_disagrees_in_free_space_is_not_a_pass(make_log: MakeLog, scenario: Scenario,
                                                                   good: Any, traj_cls: type) -> None:
    """Two positions at one instant: the formula cannot be decided there (never a silent pick of one)."""
    k = 1000
    moved = (float(good.x[k]) + 0.005, float(good.y[k]))  # inside the tube (radius 0.01 m)
    traj = _with_pose(good, k + 1, moved, traj_cls)
    cert = certify_log(make_log("mcap", traj, pose_stamps_ns={k + 1: _stamp(good, k)}), scenario).certificate
    assert cert["verdict"] == "inconclusive"
    spec = next(c for c in cert["checks"] if c["name"] == "spec_trajectory")
    assert spec["verdict"] == "inconclusive"


@pytest.mark.parametrize("fmt", ["bag", "mcap"])
def test_stamps_never_set_fall_back_to_log_time(make_log: MakeLog, scenario: Scenario, good: Any, traj_cls: type,
                                                fmt: str) -> None:
    """All header stamps zero: auto judges on log time (noted) and finds the pose inside an obstacle."""
    n = len(good.t_s)
    zeros = dict.fromkeys(range(n), 0)
    bad = _with_pose(good, 700, _obstacle_centre(scenario), traj_cls)
    cert = certify_log(make_log(fmt, bad, pose_stamps_ns=zeros), scenario).certificate
    assert cert["time_base"] == "log" and cert["time_base_requested"] == "auto"
    assert "cannot order" in cert["time_base_note"]
    assert cert["duration_s"] == pytest.approx(100.0)
    assert cert["samples"]["pose"]["judged"] == n
    assert cert["verdict"] == "fail"
    clean = certify_log(make_log(fmt, good, pose_stamps_ns=zeros), scenario)
    assert clean.verdict == "pass" and clean.certificate["time_base"] == "log"
    forced = certify_log(make_log(fmt, good, pose_stamps_ns=zeros), scenario, time_base="header").certificate
    assert forced["verdict"] == "inconclusive" and "cannot order" in forced["verdict_reason"]


@pytest.mark.parametrize("stamp_ns", [-5 * 10**9, 0, 1 * 10**9, 86_400 * 10**9])
def test_one_outlier_stamp_does_not_move_time_zero(make_log: MakeLog, scenario: Scenario, good: Any,
                                                   stamp_ns: int) -> None:
    """A negative, zero or 1970 stamp among good ones: re-timed from its log time, the good run still passes."""
    log = make_log("mcap", good, pose_stamps_ns={600: stamp_ns})
    cert = certify_log(log, scenario).certificate
    assert cert["time0_ns"] == TIME0_NS
    assert cert["duration_s"] == pytest.approx(100.0)
    assert cert["samples"]["pose"]["retimed"] == 1
    assert cert["verdict"] == "pass"


def test_simulated_clock_stays_valid(make_log: MakeLog, scenario: Scenario, good: Any) -> None:
    """Stamps on a sim clock starting at 3 s, recorded with wall-clock log times: header base, and it can pass."""
    log = make_log("mcap", good, header_offset_ns=3 * 10**9 - TIME0_NS)
    cert = certify_log(log, scenario).certificate
    assert cert["time_base"] == "header" and "time_base_note" not in cert
    assert cert["time0_ns"] == 3 * 10**9
    assert cert["samples"]["pose"]["retimed"] == 0
    assert cert["verdict"] == "pass"


def test_certificate_states_the_judged_span(make_log: MakeLog, scenario: Scenario, good: Any) -> None:
    cert = certify_log(make_log("bag", good), scenario).certificate
    assert cert["judged_span_s"] == [0.0, pytest.approx(100.0)]
    assert cert["samples"]["pose"] == {"read": len(good.t_s), "judged": len(good.t_s), "merged_duplicates": 0,
                                       "conflicting_duplicates": 0, "retimed": 0}
    assert cert["samples"]["cmd_vel"]["read"] == len(good.t_s)


def test_outliers_found_by_neighbours_and_epoch() -> None:
    t = TIME0_NS + np.arange(200, dtype=np.int64) * 10_000_000
    t[[5, 50, 120]] = [0, -3, 2 * 10**9]
    t[150] += 40 * 10**9  # far from its neighbours
    assert np.flatnonzero(header_outliers(t)).tolist() == [5, 50, 120, 150]
    sim = 3 * 10**9 + np.arange(200, dtype=np.int64) * 10_000_000  # sim clock: nothing is an outlier
    assert not header_outliers(sim).any()
    jump = np.concatenate([sim[:100], sim[100:] + 60 * 10**9])  # a real gap in a monotonic clock is no outlier
    assert not header_outliers(jump).any()


def test_choose_time_base_rules() -> None:
    log = TIME0_NS + np.arange(100, dtype=np.int64) * 10_000_000
    ok = choose_time_base(log - 2_000_000, log, "auto")
    assert ok.name == "header" and ok.usable and ok.note is None
    dup = (log - 2_000_000).copy()
    dup[1::2] = dup[::2]  # half the stamps repeat
    assert choose_time_base(dup, log, "auto").name == "log"
    forced = choose_time_base(dup, log, "header")
    assert forced.name == "header" and not forced.usable
    back = (log - 2_000_000)[::-1].copy()
    assert choose_time_base(back, log, "auto").name == "log"
    one = (log - 2_000_000).copy()
    one[40] = 0
    tb = choose_time_base(one, log, "auto")
    assert tb.name == "header" and tb.retimed == 1 and int(tb.t_ns[40]) == int(log[40]) - 2_000_000
    with pytest.raises(ValueError, match="time_base"):
        choose_time_base(log, log, "wall")


def test_judged_samples_merge_and_conflict() -> None:
    t = np.array([3, 1, 2, 2, 2, 4], dtype=np.int64)
    v = np.array([[0.0], [1.0], [2.0], [2.0], [5.0], [np.nan]])
    js = judged_samples(t, v)
    assert js.t_ns.tolist() == [1, 2, 3, 4]
    assert js.conflict.tolist() == [False, True, False, False]
    assert js.merged == 1 and js.conflicting == 3
    assert sorted(js.all_index.tolist()) == [0, 1, 2, 4, 5]
