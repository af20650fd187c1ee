"""The one closed loop running ``TubeMPC`` gives the trajectory of the tube MPC's previous loop
(``tubempc.control.reference_loop``): the nominal states, every solve, the arrivals and the verdict bit for bit;
the real states and inputs to 1e-12."""

from __future__ import annotations

import numpy as np
import pytest

from tubempc.control import ClosedLoopResult, Target, hold_position, run_closed_loop
from tubempc.control.reference_loop import run_closed_loop_reference
from tubempc.scenario import builtin_scenario, scenario_from_dict

SCENARIO = builtin_scenario()
# The previous loop integrated the linear world model over a whole MPC step in closed form (x = x_hat + q with
# q_k = a^k q_0 + sum_j a^(k-1-j) w_j, and the input from that q); the one loop steps the plant per sample from the
# controller's body-frame command (rotated back to the world frame). The same terms summed in another order:
# 1e-15 m to 3e-14 m measured on these runs, and the tube recursion (factor 1 - sigma dt < 1) does not let it grow.
ROUNDING = 1e-12


def _assert_same_run(new: ClosedLoopResult, old: ClosedLoopResult) -> None:
    assert np.array_equal(new.t_s, old.t_s)
    assert np.array_equal(new.x_hat, old.x_hat)  # the nominal: the same bits
    assert [(r.t_s, r.status, r.success, r.iterations, r.backup, r.target) for r in new.solver] == \
        [(r.t_s, r.status, r.success, r.iterations, r.backup, r.target) for r in old.solver]
    assert new.arrivals == old.arrivals
    assert (new.ok, new.reason, new.tube_radius_m, new.sigma, new.seed, new.disturbance, new.disturbance_params) == \
        (old.ok, old.reason, old.tube_radius_m, old.sigma, old.seed, old.disturbance, old.disturbance_params)
    for name in ("x", "x_measured", "u_world", "u_body"):
        gap = float(np.max(np.abs(getattr(new, name) - getattr(old, name))))
        assert gap <= ROUNDING, (name, gap)


TOUR = [Target("R2"), hold_position("R2", 25.0), Target("R3")]


@pytest.mark.parametrize(("disturbance", "noise_m", "seed", "t_end_s"),
                         [("random", 0.0, 0, None), ("worst", 0.0, 1, None), ("worst", 0.001, 2, None),
                          ("sine", 0.002, 3, None), ("random", 0.001, 4, 31.37)])
def test_the_one_loop_gives_the_previous_loops_trajectory(disturbance: str, noise_m: float, seed: int,
                                                          t_end_s: float | None) -> None:
    kwargs = {"disturbance": disturbance, "seed": seed, "mocap_noise_m": noise_m, "t_end_s": t_end_s}
    new = run_closed_loop(SCENARIO, TOUR, **kwargs)  # type: ignore[arg-type]
    old = run_closed_loop_reference(SCENARIO, TOUR, **kwargs)  # type: ignore[arg-type]
    assert sum(a.departure_s is not None for a in new.arrivals) == 2  # the runs switch targets twice
    _assert_same_run(new, old)


@pytest.mark.parametrize(("disturbance", "noise_m", "seed", "t_end_s"),
                         [("worst", 0.0, 5, None), ("random", 0.001, 6, 9.37)])
def test_the_one_loop_gives_the_previous_loops_trajectory_on_the_body_model(disturbance: str, noise_m: float,
                                                                            seed: int, t_end_s: float | None) -> None:
    data = SCENARIO.to_dict()
    data["dynamics"] = {"model": "body", "theta_max": 1.0}
    sc = scenario_from_dict(data)
    kwargs = {"disturbance": disturbance, "seed": seed, "mocap_noise_m": noise_m, "t_end_s": t_end_s}
    new = run_closed_loop(sc, [Target("R3")], **kwargs)  # type: ignore[arg-type]
    old = run_closed_loop_reference(sc, [Target("R3")], **kwargs)  # type: ignore[arg-type]
    _assert_same_run(new, old)


def test_a_different_run_is_caught() -> None:
    """The comparison can fail: another seed of the same mission differs beyond the rounding."""
    new = run_closed_loop(SCENARIO, [Target("R2")], disturbance="random", seed=0, t_end_s=3.0)
    old = run_closed_loop_reference(SCENARIO, [Target("R2")], disturbance="random", seed=1, t_end_s=3.0)
    with pytest.raises(AssertionError):
        _assert_same_run(new, old)


@pytest.mark.parametrize("noise_m", [0.0, 0.001])
def test_the_one_loop_gives_the_previous_loops_trajectory_under_a_switching_signal(noise_m: float) -> None:
    """The falsifier's signal: the outward push on every other interval (decided per MPC step), values between."""
    from tubempc.falsify.signals import SwitchSignal

    bound = SCENARIO.disturbance.bound
    values = np.array([[0.0, 0.0, 0.0], [0.6, -0.5, 0.1], [0.0, 0.0, 0.0], [-0.3, 0.9, 0.0]]) * bound
    signal = SwitchSignal(bound=bound, switch_s=(4.0, 9.0, 15.0), first_outward=True, values=values)
    new = run_closed_loop(SCENARIO, [Target("R2")], disturbance=signal, seed=7, mocap_noise_m=noise_m, t_end_s=20.0)
    old = run_closed_loop_reference(SCENARIO, [Target("R2")], disturbance=signal, seed=7, mocap_noise_m=noise_m,
                                    t_end_s=20.0)
    _assert_same_run(new, old)
