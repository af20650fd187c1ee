"""Tube design with the corrected lemma and the design check: refused scenarios name the failing quantity."""

from __future__ import annotations

import math

import casadi as ca
import numpy as np
import pytest

from tubempc.control import body_model, design_tube, model_for, user_model, world_model
from tubempc.errors import DesignError
from tubempc.scenario import Scenario, builtin_scenario, scenario_from_dict


def _variant(**changes: object) -> Scenario:
    data = builtin_scenario().to_dict()
    for dotted, value in changes.items():
        node = data
        *path, last = dotted.split("__")
        for key in path:
            node = node[key]
        node[last] = value
    return scenario_from_dict(data)


def test_builtin_world_design_matches_corrected_lemma() -> None:
    sc = builtin_scenario()
    tube = design_tube(sc, model_for(sc))
    # world model: L = 0, g_min = 1 -> sigma = sigma_low, r_q = delta_bar / sigma_low
    assert tube.sigma == pytest.approx(2.0)
    assert tube.radius_m == pytest.approx(0.01)
    assert tube.planar_disc_mps == pytest.approx(0.2 - 2.0 * 0.01)
    assert tube.clearance_m == pytest.approx(0.27 + 0.01)
    assert tube.terminal_radius_m == pytest.approx(0.07 / math.sqrt(0.5))


def test_body_model_uses_g_min_and_input_norm() -> None:
    sc = _variant(dynamics={"model": "body", "theta_max": 1.0})
    tube = design_tube(sc, model_for(sc))
    g_min = math.cos(1.0)
    lip = 1.0 * math.sqrt(3 * 0.2**2)  # L = L_f + L_g max|u_hat| with L_f = 0, L_g = 1
    assert tube.sigma == pytest.approx(lip / g_min + 2.0)
    assert tube.radius_m == pytest.approx(0.02 / (2.0 * g_min))
    assert tube.planar_disc_mps is None
    assert tube.u_box[0] == pytest.approx(0.2 - tube.sigma * tube.radius_m)


def test_empty_tightened_input_set_is_refused() -> None:
    sc = _variant(disturbance__bound=0.5)  # r_q = 0.25, sigma r_q = 0.5 > 0.2
    with pytest.raises(DesignError, match="tightened input set is empty"):
        design_tube(sc, model_for(sc))


def test_region_too_small_for_terminal_ball_and_tube_is_refused() -> None:
    sc = _variant(mpc__eps=0.2)  # terminal radius 0.283 m + 0.01 + 0.27 > 0.45
    with pytest.raises(DesignError, match=r"region R1: terminal ball .* does not fit inside its radius 0.45"):
        design_tube(sc, model_for(sc))


def test_empty_tightened_workspace_is_refused() -> None:
    data = builtin_scenario().to_dict()
    data["workspace"] = {"x": [-2.5, 2.5], "y": [-0.3, 0.3]}
    data["robot"] = {"radius": 0.295}  # eta + r_q = 0.305 > half the workspace height
    data["regions"] = [{"name": "R1", "center": [0.0, 0.0], "radius": 0.3, "labels": ["mission_1", "mission_2",
                                                                                      "obs_1", "obs_2", "obs_3",
                                                                                      "obs_4"]}]
    sc = scenario_from_dict(data)
    with pytest.raises(DesignError, match=r"tightened state set is empty: workspace.y"):
        design_tube(sc, model_for(sc))


def test_stated_tube_radius_below_the_invariant_radius_is_refused() -> None:
    sc = _variant(tube={"sigma_low": 2.0, "radius": 0.005})
    with pytest.raises(DesignError, match="below the invariant radius"):
        design_tube(sc, model_for(sc))


def test_body_model_rejects_heading_restriction_out_of_range() -> None:
    with pytest.raises(DesignError, match="theta_max"):
        body_model(math.pi / 2)


def test_user_model_spot_check_accepts_true_constants() -> None:
    model = user_model(lambda x: -0.1 * x, lambda x: 2 * ca.SX.eye(3), l_f=0.1, l_g=0.0, g_min=2.0,
                       rng=np.random.default_rng(1))
    assert model.g_min == 2.0


@pytest.mark.parametrize(
    ("kwargs", "quantity"),
    [
        ({"l_f": 0.05, "l_g": 0.0, "g_min": 2.0}, "L_f"),
        ({"l_f": 0.1, "l_g": 0.0, "g_min": 2.5}, "g_min"),
    ],
)
def test_user_model_spot_check_refutes_wrong_constants(kwargs: dict[str, float], quantity: str) -> None:
    with pytest.raises(DesignError, match=quantity):
        user_model(lambda x: -0.1 * x, lambda x: 2 * ca.SX.eye(3), rng=np.random.default_rng(1), **kwargs)


def test_user_model_refutes_lipschitz_of_g() -> None:
    def g(x: ca.SX) -> ca.SX:
        c, s = ca.cos(x[2]), ca.sin(x[2])
        return ca.vertcat(ca.horzcat(c, -s, 0), ca.horzcat(s, c, 0), ca.horzcat(0, 0, 1))

    with pytest.raises(DesignError, match="L_g"):
        user_model(lambda x: ca.SX.zeros(3), g, l_f=0.0, l_g=0.5, g_min=0.4, theta_max_rad=1.1,
                   rng=np.random.default_rng(2))


def test_world_model_body_command_rotates() -> None:
    model = world_model()
    cmd = model.body_command(np.array([0.0, 0.0, math.pi / 2]), np.array([0.1, 0.0, 0.05]))
    # world +x seen from a robot facing +y is its -y axis
    assert cmd == pytest.approx([0.0, -0.1, 0.05], abs=1e-15)


def test_gain_too_high_for_the_mocap_rate_is_refused() -> None:
    sc = _variant(mocap={"rate_hz": 1.5})  # sigma * dt = 2 / 1.5 > 1
    with pytest.raises(DesignError, match="MoCap period"):
        design_tube(sc, model_for(sc))
