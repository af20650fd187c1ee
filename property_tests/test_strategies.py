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


@given(strategies.log_faults(max_index=50), st.integers(1, 50))
def test_sample_faults_do_what_they_say(fault: LogFault, n: int) -> None:
    stamps = np.arange(n, dtype=np.int64) * 10_000_000
    xyz = np.arange(3 * n, dtype=float).reshape(n, 3)
    quat = np.tile([0.0, 0.0, 0.0, 1.0], (n, 1))
    s, x, q = apply_sample_fault(fault, stamps, xyz, quat)
    assert np.array_equal(stamps, np.arange(n) * 10_000_000)  # inputs untouched
    if fault.kind == "drop":
        assert 1 <= len(s) <= n and len(s) == len(x) == len(q)
    elif fault.kind == "reorder":
        assert sorted(s.tolist()) == stamps.tolist() and (n == 1 or not np.all(np.diff(s) > 0))
    elif fault.kind == "nan":
        assert np.isnan(x).any()
    elif fault.kind == "zero_quaternion":
        assert (np.linalg.norm(q, axis=1) == 0).any()
    else:
        assert np.array_equal(s, stamps) and np.array_equal(x, xyz)
