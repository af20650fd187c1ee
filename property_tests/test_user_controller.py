"""The recipe of docs/property-testing.md, "Your own controller": hypothesis draws workspaces and disturbances, the
user's controller runs in the closed loop, the certifier judges the run (kept identical to the page)."""

from __future__ import annotations

import math

from hypothesis import assume, given, settings
from hypothesis import strategies as st

from examples.controllers.pure_pursuit import pure_pursuit
from tubempc import strategies
from tubempc.control import Target
from tubempc.control.user import run_controller
from tubempc.rosio.memory import in_memory_log
from tubempc.scenario import Scenario
from verify import certify_data


def as_unicycle(scenario: Scenario) -> Scenario:
    """The drawn workspace for a differential-drive robot: v <= 0.2 m/s, w <= 1 rad/s."""
    data = scenario.to_dict()
    data["inputs"] = {"model": "unicycle", "max_abs": [0.2, 1.0]}
    return Scenario.model_validate(data)


def clearance_of_segment(scenario: Scenario, a: tuple[float, float], b: tuple[float, float]) -> float:
    """Least distance from the robot disc on the straight segment a-b to an unsafe region."""
    out = math.inf
    for r in scenario.unsafe_regions:
        ab = (b[0] - a[0], b[1] - a[1])
        s = ((r.center[0] - a[0]) * ab[0] + (r.center[1] - a[1]) * ab[1]) / max(ab[0] ** 2 + ab[1] ** 2, 1e-12)
        s = min(max(s, 0.0), 1.0)
        out = min(out, math.dist((a[0] + s * ab[0], a[1] + s * ab[1]), r.center) - r.radius - scenario.robot.radius)
    return out


@settings(max_examples=6, deadline=None)
@given(strategies.scenarios(min_regions=4, max_unsafe=2), st.data(),
       st.sampled_from(["none", "random", "bias", "sine", "worst"]), st.integers(0, 2**16))
def test_pure_pursuit_keeps_clear_when_the_straight_path_is_clear(drawn: Scenario, data: st.DataObject,
                                                                   disturbance: str, seed: int) -> None:
    scenario = as_unicycle(drawn)
    start, goal = data.draw(st.permutations([r.name for r in scenario.safe_regions]))[:2]
    a, b = scenario.region(start).center, scenario.region(goal).center
    assume(clearance_of_segment(scenario, a, b) >= 0.1)  # the controller follows the segment: it must be clear
    run = run_controller(scenario, pure_pursuit(), [Target(goal)], start_region=start, disturbance=disturbance,
                         seed=seed)
    assert run.ok, run.reason
    result = certify_data(in_memory_log(run, scenario), scenario,
                          checks=["obstacle_clearance", "workspace", "input_box"])
    assert result.verdict == "pass", [(c["name"], c["verdict"], c["margin"]) for c in result.certificate["checks"]]
