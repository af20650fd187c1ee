"""Algorithm 1 as the planner calls it: a picklable result per ordered pair, failures as values."""

from __future__ import annotations

import itertools
import pickle

import pytest

from tubempc.control import transition_time
from tubempc.scenario import builtin_scenario

SCENARIO = builtin_scenario()


def test_transition_result_is_complete_and_picklable() -> None:
    res = transition_time(SCENARIO, "R2", "R3")
    assert res.ok and res.reason is None
    assert res.t_ij_s is not None and res.arrival_s is not None and res.arrival_s <= res.t_ij_s
    # disturbance "none": the real state is the nominal one up to rounding
    assert res.max_tube_error_m is not None and res.max_tube_error_m < 1e-12
    assert res.min_clearance_m is not None and res.min_clearance_m >= 0
    assert pickle.loads(pickle.dumps(res)) == res


@pytest.mark.parametrize(("source", "target", "match"), [
    ("R1", "R6", "unsafe"),
    ("R1", "R1", "same region"),
    ("R1", "R99", "unknown region"),
])
def test_impossible_pairs_are_values_with_a_reason(source: str, target: str, match: str) -> None:
    res = transition_time(SCENARIO, source, target)
    assert not res.ok and res.reason is not None and match in res.reason and res.t_ij_s is None


def test_design_check_failure_is_reported() -> None:
    data = SCENARIO.to_dict()
    data["mpc"]["eps"] = 0.2
    from tubempc.scenario import scenario_from_dict

    res = transition_time(scenario_from_dict(data), "R1", "R2")
    assert not res.ok and res.reason is not None and res.reason.startswith("design check:")


@pytest.mark.slow
def test_every_ordered_pair_of_safe_regions_completes() -> None:
    names = [r.name for r in SCENARIO.safe_regions]
    for source, target in itertools.permutations(names, 2):
        res = transition_time(SCENARIO, source, target, disturbance="worst", seed=1)
        assert res.ok, (source, target, res.reason)
        assert res.min_clearance_m is not None and res.min_clearance_m >= -1e-12
