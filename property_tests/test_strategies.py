"""The public strategies keep their promises (they are an API: labs build their own property tests on them).

Sampled checks of the stated constants: relative slack 1e-9 absorbs floating-point rounding of O(1) quantities
(sin, matrix products: a few ulps), far below any real breach of a bound.
"""

from __future__ import annotations

import math

import numpy as np
from hypothesis import find, given, settings
from hypothesis import strategies as st

from tubempc import strategies
from tubempc.scenario import Scenario
from tubempc.strategies import ControlAffineDynamics, LogFault, Trajectory, apply_sample_fault

SLACK = 1e-9  # see the module docstring
points = st.lists(st.integers(-500, 500).map(lambda k: k / 100), min_size=3, max_size=3)


@given(strategies.dynamics(), points, points)
def test_dynamics_constants_hold(dyn: ControlAffineDynamics, a: list[float], b: list[float]) -> None:
    x = np.array(a[: dyn.dim])
    y = np.array(b[: dyn.dim])
    dist = float(np.linalg.norm(x - y))
    assert np.linalg.norm(dyn.f(x) - dyn.f(y)) <= dyn.l_f * dist * (1 + SLACK) + SLACK
    assert np.linalg.norm(dyn.g(x) - dyn.g(y), 2) <= dyn.l_g * dist * (1 + SLACK) + SLACK
    gx = dyn.g(x)
    assert float(np.linalg.eigvalsh((gx + gx.T) / 2).min()) >= dyn.g_min - SLACK
    assert np.linalg.norm(gx, 2) <= dyn.g_max * (1 + SLACK)


def test_dynamics_cover_g_min_below_one_and_large_nominal_inputs() -> None:
    cfg = settings(database=None, derandomize=True, max_examples=500)
    assert find(strategies.dynamics(), lambda d: d.g_min < 1 and d.l_g > 0, settings=cfg).g_min < 1
    assert find(strategies.nominal_inputs(2), lambda u: u.max_norm > 1, settings=cfg).max_norm > 1


@given(st.data(), st.integers(1, 3), st.integers(0, 300).map(lambda k: k / 10))
def test_inputs_and_disturbances_are_bounded(data: st.DataObject, dim: int, t_s: float) -> None:
    u = data.draw(strategies.nominal_inputs(dim))
    assert np.linalg.norm(u(t_s)) <= u.max_norm * (1 + SLACK)
    d = data.draw(strategies.disturbances(dim))
    q = np.array(data.draw(st.lists(st.integers(-5, 5), min_size=dim, max_size=dim)), dtype=float)
    assert np.linalg.norm(d(t_s, q)) <= d.bound * (1 + SLACK)
    if d.kind == "adversarial" and q.any():
        assert np.allclose(d(t_s, q), d.bound * q / np.linalg.norm(q))


@given(strategies.scenarios(models=("world", "body")))
def test_scenarios_are_valid_and_the_robot_fits(sc: Scenario) -> None:
    eta = sc.robot.radius
    assert sc.region(sc.initial_region).unsafe is False
    assert all(r.radius - eta >= 0.15 - SLACK or eta <= 0.06 for r in sc.safe_regions)
    labels = {lab for r in sc.regions for lab in r.labels}
    assert all(f"obs_{k}" in labels for k in range(1, len(sc.unsafe_regions) + 1))


@given(strategies.trajectories(max_samples=200, max_speed_mps=0.3))
def test_trajectories_respect_the_speed_bound(traj: Trajectory) -> None:
    t, xy, yaw = traj.arrays()
    assert np.all(np.diff(t) > 0)
    speed = np.hypot(*np.diff(xy, axis=0).T) / np.diff(t)
    assert float(speed.max(initial=0.0)) <= 0.3 * (1 + SLACK)
    assert np.all(np.abs(yaw) <= math.pi)


@given(strategies.log_faults(max_index=50, places=[(9.0, 9.0)]), st.integers(1, 50))
def test_sample_faults_do_what_they_say(fault: LogFault, n: int) -> None:
    """Each fault changes exactly the rows its docstring names, and nothing else."""
    stamps = np.arange(n, dtype=np.int64) * 10_000_000 + 10**18
    xyz = np.arange(3 * n, dtype=float).reshape(n, 3)
    quat = np.tile([0.0, 0.0, 0.0, 1.0], (n, 1))
    s, x, q = apply_sample_fault(fault, stamps, xyz, quat)
    assert np.array_equal(stamps, np.arange(n) * 10_000_000 + 10**18)  # inputs untouched
    start = fault.start % n
    rows = np.arange(start, min(start + fault.count, n))
    others = np.setdiff1d(np.arange(n), rows)
    if fault.kind == "drop":
        kept = others if others.size else np.array([0])
        assert np.array_equal(s, stamps[kept]) and np.array_equal(x, xyz[kept]) and np.array_equal(q, quat[kept])
        return
    assert len(s) == len(x) == len(q) == n
    changed_s = np.flatnonzero(s != stamps)
    changed_x = np.flatnonzero(np.any((x != xyz) & ~(np.isnan(x) & np.isnan(xyz)), axis=1))
    changed_q = np.flatnonzero(np.any(q != quat, axis=1))
    if fault.kind == "reorder":
        if n == 1:
            assert changed_s.size == 0
        else:
            other = (start + fault.count) % n
            other = (start + 1) % n if other == start else other
            assert sorted(changed_s.tolist()) == sorted({start, other})
            assert s[start] == stamps[other] and s[other] == stamps[start]
            assert np.array_equal(x[start], xyz[other])
    elif fault.kind == "nan":
        assert np.isnan(x[rows, :2]).all() and changed_x.tolist() == rows.tolist()
        assert changed_s.size == 0 and changed_q.size == 0
    elif fault.kind == "zero_quaternion":
        assert changed_q.tolist() == rows.tolist() and not q[rows].any()
        assert changed_s.size == 0 and changed_x.size == 0
    elif fault.kind == "duplicate_stamp":
        if n >= 2:
            k = min(start, n - 2)
            assert changed_s.tolist() == [k + 1] and s[k + 1] == s[k]
            assert changed_x.tolist() == [k + 1] and tuple(x[k + 1, :2]) == (9.0, 9.0)
    elif fault.kind == "zero_stamps":
        assert not s.any() and changed_x.size == 0
    elif fault.kind in ("negative_stamp", "stamp_1970"):
        assert changed_s.tolist() == [start] and changed_x.size == 0
        assert s[start] == (-5 * 10**9 if fault.kind == "negative_stamp" else 10**9)
    else:
        assert changed_s.size == changed_x.size == changed_q.size == 0
