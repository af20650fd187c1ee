"""Tightening soundness: nominal state and input in the tightened sets plus |q| <= r_q imply the real ones are safe.

The sets under test are the controller's (``tubempc.control.design_tube``): obstacles (every region other than the
transition's source and target) grown by ``clearance_m``, the workspace shrunk to ``workspace_x`` x
``workspace_y``, the nominal input in ``u_box`` (and the planar disc ``planar_disc_mps`` for world-frame inputs),
the nominal heading within ``theta_bound_rad`` (body-frame model). The original constraints are checked here with
our own arithmetic: the robot disc M(p, eta) does not meet any obstacle, lies in the workspace, the command the
robot receives (``DynamicsModel.body_command``, logged on cmd_vel in the body frame, see the log contract) is in
the box ``|cmd_i| <= max_abs[i]``, and the real heading respects ``theta_max``.

Drawn nominal points sit on the boundaries of the tightened sets and q points at the constraint (the tight case):
the implication then holds with equality, so any smaller tightening is caught (see the last test).
Tolerance 1e-9: the quantities are O(1) metres or m/s combined in a handful of floating-point operations, so the
rounding error is below 1e-14; 1e-9 only absorbs that, while any missing tightening term is at least 1e-4.
"""

from __future__ import annotations

import dataclasses
import math

import numpy as np
from hypothesis import HealthCheck, Phase, assume, find, given, settings
from hypothesis import strategies as st

from tubempc import strategies
from tubempc.control import DynamicsModel, TubeDesign, design_tube, model_for
from tubempc.errors import DesignError
from tubempc.scenario import Scenario

TOL = 1e-9  # see the module docstring


@dataclasses.dataclass(frozen=True, slots=True)
class TubeCase:
    scenario: Scenario
    source: str
    target: str
    p_hat: tuple[float, float]
    theta_hat: float
    u_hat: tuple[float, float, float]
    q: tuple[float, float, float]


def _unit(angle: float) -> np.ndarray:
    return np.array([math.cos(angle), math.sin(angle)])


@st.composite
def tube_cases(draw: st.DrawFn, clearance_m: float | None = None) -> TubeCase:
    scenario = draw(strategies.scenarios(models=("world", "body"), delta_bar=(0.0, 0.05)))
    model = model_for(scenario)
    try:
        design = _design(scenario, model, clearance_m)
    except DesignError:
        assume(False)
        raise  # unreachable: assume(False) raises
    safe = [r.name for r in scenario.safe_regions]
    source = draw(st.sampled_from(safe))
    target = draw(st.sampled_from(safe))
    obstacles = [r for r in scenario.regions if r.name not in (source, target)]
    angle = st.integers(0, 359).map(math.radians)
    # nominal position on a boundary of the tightened state set (or anywhere inside it)
    mode = draw(st.sampled_from(["obstacle", "wall", "free"] if obstacles else ["wall", "free"]))
    wx, wy = design.workspace_x, design.workspace_y
    frac = st.integers(0, 100).map(lambda k: k / 100)
    if mode == "obstacle":
        ob = draw(st.sampled_from(obstacles))
        p = np.array(ob.center) + (ob.radius + design.clearance_m) * _unit(draw(angle))
    elif mode == "wall":
        side = draw(st.integers(0, 3))
        s = draw(frac)
        p = np.array([
            [wx[0], wy[0] + s * (wy[1] - wy[0])], [wx[1], wy[0] + s * (wy[1] - wy[0])],
            [wx[0] + s * (wx[1] - wx[0]), wy[0]], [wx[0] + s * (wx[1] - wx[0]), wy[1]],
        ][side])
    else:
        p = np.array([wx[0] + draw(frac) * (wx[1] - wx[0]), wy[0] + draw(frac) * (wy[1] - wy[0])])
    assume(wx[0] - 1e-12 <= p[0] <= wx[1] + 1e-12 and wy[0] - 1e-12 <= p[1] <= wy[1] + 1e-12)
    assume(all(math.dist(p, ob.center) >= ob.radius + design.clearance_m - 1e-12 for ob in obstacles))
    theta_bound = design.theta_bound_rad if design.theta_bound_rad is not None else math.pi
    theta_hat = draw(st.sampled_from([-1.0, 1.0, 0.0, 0.5])) * theta_bound
    # nominal input on the boundary of the tightened input set
    if design.planar_disc_mps is not None:
        planar = design.planar_disc_mps * draw(st.sampled_from([1.0, 0.5, 0.0])) * _unit(draw(angle))
        u_xy = (float(planar[0]), float(planar[1]))
    else:
        u_xy = (design.u_box[0] * draw(st.sampled_from([1.0, -1.0, 0.3])),
                design.u_box[1] * draw(st.sampled_from([1.0, -1.0, 0.3])))
    u_hat = (u_xy[0], u_xy[1], design.u_box[2] * draw(st.sampled_from([1.0, -1.0, 0.0])))
    # q with |q| = r_q (or less), pointing at the nearest constraint, or anywhere
    r_q = design.radius_m
    if draw(st.booleans()) and obstacles:
        ob = min(obstacles, key=lambda o: math.dist(p, o.center) - o.radius)
        direction = np.append((np.array(ob.center) - p) / max(math.dist(p, ob.center), 1e-12), 0.0)
    else:
        direction = np.array([draw(st.integers(-10, 10)) for _ in range(3)], dtype=float)
        if not direction.any():
            direction = np.array([1.0, 0.0, 0.0])
    q = r_q * draw(st.sampled_from([1.0, 0.5])) * direction / np.linalg.norm(direction)
    return TubeCase(scenario=scenario, source=source, target=target, p_hat=(float(p[0]), float(p[1])),
                    theta_hat=theta_hat, u_hat=u_hat, q=(float(q[0]), float(q[1]), float(q[2])))


def _design(scenario: Scenario, model: DynamicsModel, clearance_m: float | None = None) -> TubeDesign:
    """The controller's design; ``clearance_m`` replaces its obstacle clearance (to show the check has teeth)."""
    design = design_tube(scenario, model)
    return dataclasses.replace(design, clearance_m=clearance_m) if clearance_m is not None else design


def violations(case: TubeCase, clearance_m: float | None = None) -> list[str]:
    """Original constraints that the real state or command violates (empty when the tightening is sound)."""
    sc = case.scenario
    model = model_for(sc)
    design = _design(sc, model, clearance_m)
    eta = sc.robot.radius
    q = np.array(case.q)
    p = np.array(case.p_hat) + q[:2]
    theta = case.theta_hat + q[2]
    u = np.array(case.u_hat) - design.sigma * q
    out: list[str] = []
    for r in sc.regions:
        if r.name in (case.source, case.target):
            continue
        gap = math.dist(p, r.center) - r.radius - eta
        if gap < -TOL:
            out.append(f"robot disc meets {r.name} by {-gap:.3g} m")
    ws = sc.workspace
    for axis, lo_hi, v in (("x", ws.x, p[0]), ("y", ws.y, p[1])):
        if v - eta < lo_hi[0] - TOL or v + eta > lo_hi[1] + TOL:
            out.append(f"robot disc leaves the workspace along {axis}")
    cmd = model.body_command(np.array([p[0], p[1], theta]), u)
    for i, (c, m) in enumerate(zip(cmd, sc.inputs.max_abs, strict=True)):
        if abs(c) > m + TOL:
            out.append(f"body-frame command {i} = {c:.6g} exceeds {m}")
    if model.theta_max_rad is not None and abs(theta) > model.theta_max_rad + TOL:
        out.append(f"heading {theta:.6g} leaves |theta| <= {model.theta_max_rad}")
    return out


@given(tube_cases())
@settings(suppress_health_check=[HealthCheck.too_slow, HealthCheck.filter_too_much])
def test_tightened_sets_plus_tube_imply_original_constraints(case: TubeCase) -> None:
    assert violations(case) == []


def _halved_clearance(case: TubeCase) -> float:
    sc = case.scenario
    return sc.robot.radius + design_tube(sc, model_for(sc)).radius_m / 2


@st.composite
def _cases_against_halved_clearance(draw: st.DrawFn) -> TubeCase:
    """A drawn case moved onto the boundary of its nearest obstacle grown by the weaker clearance, q at r_q."""
    case = draw(tube_cases())
    sc = case.scenario
    r_q = design_tube(sc, model_for(sc)).radius_m
    obstacles = [r for r in sc.regions if r.name not in (case.source, case.target)]
    assume(r_q > 1e-3 and obstacles)
    p = np.array(case.p_hat)
    ob = min(obstacles, key=lambda o: math.dist(p, o.center) - o.radius)
    d = (p - np.array(ob.center)) / max(math.dist(p, ob.center), 1e-12)
    new_p = np.array(ob.center) + (ob.radius + _halved_clearance(case)) * d
    q = np.append(-d * r_q, 0.0)
    return dataclasses.replace(case, p_hat=(float(new_p[0]), float(new_p[1])),
                               q=(float(q[0]), float(q[1]), float(q[2])))


def test_a_smaller_obstacle_clearance_is_caught() -> None:
    """The check has teeth: growing obstacles by eta + r_q/2 instead of eta + r_q admits a collision."""
    found = find(_cases_against_halved_clearance(),
                 lambda c: any("meets" in v for v in violations(c, _halved_clearance(c))),
                 settings=settings(max_examples=300, derandomize=True, database=None, deadline=None,
                                   phases=[Phase.generate],  # any witness will do; shrinking only costs time
                                   suppress_health_check=list(HealthCheck)))
    assert any("meets" in v for v in violations(found, _halved_clearance(found)))
