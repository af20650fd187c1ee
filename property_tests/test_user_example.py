"""The user-facing example of docs/property-testing.md (kept identical, so the documented snippet runs in CI)."""

from __future__ import annotations

import numpy as np
from hypothesis import given

from tubempc import strategies
from tubempc.control import design_tube, model_for
from tubempc.scenario import Scenario
from tubempc.strategies import ControlAffineDynamics, DisturbanceSignal


@given(strategies.scenarios(min_regions=3, max_unsafe=2, models=("world", "body")))
def test_terminal_ball_and_tube_fit_every_safe_region(scenario: Scenario) -> None:
    tube = design_tube(scenario, model_for(scenario))
    for region in scenario.safe_regions:
        assert tube.terminal_radius_m + tube.radius_m + scenario.robot.radius <= region.radius


@given(strategies.dynamics(dims=(2,), g_min_range=(0.3, 1.0)), strategies.disturbances(2, kinds=("adversarial",)))
def test_outward_push_never_helps(dyn: ControlAffineDynamics, delta: DisturbanceSignal) -> None:
    q = np.array([0.3, -0.4])
    push = delta(0.0, q)
    g = dyn.g(np.zeros(2))
    # with u = -sigma q and the outward push, d|q|^2/2 at x = x_hat = 0 is <= -sigma g_min |q|^2 + delta_bar |q|
    sigma = 2.0
    rate = float(q @ (-sigma * g @ q + push))
    assert rate <= -sigma * dyn.g_min * float(q @ q) + delta.bound * float(np.linalg.norm(q)) + 1e-12  # rounding
