"""The tube MPC as a protocol controller computes run_closed_loop's control law: a replay of that loop's measured
trajectory through ``TubeMPC.step`` gives its nominal states and solves bit for bit and its commands to 1e-12."""

from __future__ import annotations

import numpy as np
import pytest

from tubempc.control import ClosedLoopResult, Target, hold_position, run_closed_loop
from tubempc.control.tube_controller import TubeMPC
from tubempc.control.user import ControllerPlan, Reference, _reference
from tubempc.scenario import Scenario, builtin_scenario, scenario_from_dict

SCENARIO = builtin_scenario()
# The old loop forms the ancillary input from the tube error q it integrates (u = u_hat - sigma q, world model in
# closed form); the protocol's controller sees only the measurement and forms x_meas - x_hat, one more rounding
# (1e-17 m on 1 m values), and the body-frame rotation is per sample instead of vectorised over the run.
COMMAND_TOL = 1e-12


def _replay(scenario: Scenario, res: ClosedLoopResult, controller: TubeMPC) -> np.ndarray:
    """Step ``controller`` through ``res``'s samples with its measured states; the references switch at the
    departures ``res`` recorded. Checks the nominal at every sample; returns the commands."""
    refs = tuple(_reference(scenario, k, t) for k, t in enumerate(res.targets))
    start = tuple(float(v) for v in res.x[0])
    controller.reset(scenario, ControllerPlan(res.start_region, (start[0], start[1], start[2]), refs))
    departures = [a.departure_s for a in res.arrivals if a.departure_s is not None]
    commands = np.empty_like(res.u_body)
    for i, t in enumerate(res.t_s):
        index = sum(1 for d in departures if d <= t)
        ref: Reference = refs[index]
        commands[i] = controller.step(float(t), res.x_measured[i].copy(), ref)
        nominal = controller.nominal()
        assert np.array_equal(nominal, res.x_hat[i]), (i, nominal - res.x_hat[i])
    return commands


def _assert_same_solves(res: ClosedLoopResult, controller: TubeMPC) -> None:
    assert len(controller.records) == len(res.solver)
    for new, old in zip(controller.records, res.solver, strict=True):
        assert (new.t_s, new.status, new.success, new.iterations, new.backup, new.target) == \
            (old.t_s, old.status, old.success, old.iterations, old.backup, old.target)
    entered = {k: a.entered_terminal_s for k, a in enumerate(res.arrivals) if a.entered_terminal_s is not None}
    assert controller.entered_terminal_s == entered


@pytest.mark.parametrize(("disturbance", "noise_m", "seed"),
                         [("random", 0.0, 0), ("random", 0.002, 1), ("worst", 0.0, 2), ("sine", 0.001, 3)])
def test_replay_of_the_closed_loop_gives_its_nominal_solves_and_commands(disturbance: str, noise_m: float,
                                                                           seed: int) -> None:
    targets = [Target("R2"), hold_position("R2", 25.0), Target("R3")]
    res = run_closed_loop(SCENARIO, targets, disturbance=disturbance, seed=seed, mocap_noise_m=noise_m)
    assert res.ok, res.reason
    assert len([a for a in res.arrivals if a.departure_s is not None]) == 2  # the replay switches references
    controller = TubeMPC()
    commands = _replay(SCENARIO, res, controller)
    _assert_same_solves(res, controller)
    assert float(np.max(np.abs(commands - res.u_body))) <= COMMAND_TOL


def test_replay_with_the_rk4_nominal_worst_case_and_noise() -> None:
    """The world model under ``worst`` with MoCap noise runs the RK4 sample block, nominal included."""
    res = run_closed_loop(SCENARIO, [Target("R2")], disturbance="worst", seed=4, mocap_noise_m=0.001,
                          t_end_s=8.0)
    controller = TubeMPC(closed_form_nominal=False)
    commands = _replay(SCENARIO, res, controller)
    _assert_same_solves(res, controller)
    assert float(np.max(np.abs(commands - res.u_body))) <= COMMAND_TOL


def test_replay_on_the_body_frame_model() -> None:
    data = SCENARIO.to_dict()
    data["dynamics"] = {"model": "body", "theta_max": 1.0}
    sc = scenario_from_dict(data)
    res = run_closed_loop(sc, [Target("R3")], disturbance="worst", seed=5, t_end_s=8.0)
    controller = TubeMPC()
    commands = _replay(sc, res, controller)
    _assert_same_solves(res, controller)
    assert float(np.max(np.abs(commands - res.u_body))) <= COMMAND_TOL


def test_a_changed_law_is_caught_by_the_replay() -> None:
    """The replay can fail: a controller that resets its nominal to the measurement diverges from the loop."""

    class Resetting(TubeMPC):
        def step(self, t_s: float, state: np.ndarray, reference: Reference) -> np.ndarray:
            out = super().step(t_s, state, reference)
            self._nominal_block = self._nominal_block + (np.asarray(state) - self._x_hat)
            return out

    res = run_closed_loop(SCENARIO, [Target("R2")], disturbance="random", seed=0, t_end_s=2.0)
    with pytest.raises(AssertionError):
        _replay(SCENARIO, res, Resetting())
