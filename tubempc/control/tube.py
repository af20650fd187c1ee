"""Tube design with the corrected lemma, tightened sets, and the design check.

input: a ``Scenario`` and a ``DynamicsModel`` -> output: a frozen ``TubeDesign`` (sigma, r_q, tightened input
set, obstacle clearance, shrunk workspace, terminal radius), or ``DesignError`` naming the failing quantity when a
tightened set is empty or the terminal ball plus the tube plus the robot disc does not fit inside a safe region.

Input set: for world-frame inputs the planar velocity is constrained to the disc of radius
``min(max_abs[0], max_abs[1]) - sigma r_q`` so that the body-frame command ``R(theta)^T u`` stays in the box for
every heading; for body-frame inputs the box itself is shrunk by ``sigma r_q`` per component.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

from tubempc.control.dynamics import DynamicsModel
from tubempc.control.lemma import corrected_tube
from tubempc.errors import DesignError
from tubempc.scenario import Scenario

__all__ = ["TubeDesign", "design_tube"]


@dataclass(frozen=True, slots=True)
class TubeDesign:
    """Everything the FHOCP and the closed loop need from the tube lemma, for one scenario and model."""

    sigma: float
    radius_m: float  # r_q
    lipschitz: float
    g_min: float
    u_box: tuple[float, float, float]  # tightened per-component bound on u_hat
    planar_disc_mps: float | None  # tightened bound on |u_hat[:2]| (world-frame inputs), else None
    clearance_m: float  # eta + r_q: added to every obstacle radius
    workspace_x: tuple[float, float]  # shrunk by eta + r_q
    workspace_y: tuple[float, float]
    terminal_radius_m: float  # eps / sqrt(lambda_min(P))
    theta_bound_rad: float | None  # tightened heading restriction of the nominal

    @property
    def max_planar_speed_mps(self) -> float:
        if self.planar_disc_mps is not None:
            return self.planar_disc_mps
        return math.hypot(self.u_box[0], self.u_box[1])


def design_tube(scenario: Scenario, model: DynamicsModel) -> TubeDesign:
    """sigma = L/g_min + sigma_low, L = L_f + L_g max|u_hat|, r_q = delta_bar/(sigma_low g_min); check the sets."""
    u_max = scenario.inputs.max_abs
    gain = corrected_tube(l_f=model.l_f, l_g=model.l_g, u_hat_max=math.sqrt(sum(v * v for v in u_max)),
                          g_min=model.g_min, sigma_low=scenario.tube.sigma_low, delta_bar=scenario.disturbance.bound)
    radius = gain.radius_m
    stated = scenario.tube.radius
    if stated is not None:
        if stated < radius * (1 - 1e-12):
            raise DesignError(f"tube.radius={stated!r} m is below the invariant radius {radius:.6g} m of the corrected "
                              f"lemma (delta_bar / (sigma_low * g_min))")
        radius = stated
    dt = 1.0 / scenario.mocap.rate_hz
    if gain.sigma * dt >= 1.0:
        raise DesignError(f"ancillary gain sigma = {gain.sigma:.6g} times the MoCap period {dt:.6g} s is >= 1: the "
                          f"sampled law u = u_hat - sigma q does not keep |q| <= r_q (raise mocap.rate_hz or lower "
                          f"tube.sigma_low)")
    shrink = gain.sigma * radius
    if model.input_frame == "world":
        disc = min(u_max[0], u_max[1]) - shrink
        if disc <= 0:
            raise DesignError(f"tightened input set is empty: planar speed bound min(inputs.max_abs[0:2]) = "
                              f"{min(u_max[:2])!r} m/s minus sigma*r_q = {shrink:.6g} leaves {disc:.6g}")
        planar: float | None = disc
    else:
        planar = None
    box = tuple(v - shrink for v in u_max)
    for i, v in enumerate(box):
        if v <= 0:
            raise DesignError(f"tightened input set is empty: inputs.max_abs[{i}] = {u_max[i]!r} minus sigma*r_q = "
                              f"{shrink:.6g} leaves {v:.6g}")
    eta = scenario.robot.radius
    clearance = eta + radius
    ws = scenario.workspace
    wx = (ws.x[0] + clearance, ws.x[1] - clearance)
    wy = (ws.y[0] + clearance, ws.y[1] - clearance)
    for axis, (lo, hi) in (("x", wx), ("y", wy)):
        if lo >= hi:
            raise DesignError(f"tightened state set is empty: workspace.{axis} shrunk by eta + r_q = {clearance:.6g} m "
                              f"leaves [{lo:.6g}, {hi:.6g}]")
    terminal = scenario.mpc.terminal_radius_m
    for r in scenario.safe_regions:
        need = terminal + radius + eta
        if need > r.radius + 1e-12:
            raise DesignError(f"region {r.name}: terminal ball {terminal:.6g} m + tube r_q {radius:.6g} m + robot eta "
                              f"{eta:.6g} m = {need:.6g} m does not fit inside its radius {r.radius:.6g} m")
        cx, cy = r.center
        if not (wx[0] <= cx <= wx[1] and wy[0] <= cy <= wy[1]):
            raise DesignError(f"region {r.name}: its centre {r.center} lies outside the tightened workspace "
                              f"x in [{wx[0]:.6g}, {wx[1]:.6g}], y in [{wy[0]:.6g}, {wy[1]:.6g}]")
    theta_bound: float | None = None
    if model.theta_max_rad is not None:
        theta_bound = model.theta_max_rad - radius
        if abs(scenario.initial_heading) >= theta_bound:
            raise DesignError(f"initial_heading={scenario.initial_heading!r} rad is outside the tightened heading "
                              f"restriction |theta| < theta_max - r_q = {theta_bound:.6g} rad")
    return TubeDesign(sigma=gain.sigma, radius_m=radius, lipschitz=gain.lipschitz, g_min=model.g_min,
                      u_box=(box[0], box[1], box[2]), planar_disc_mps=planar, clearance_m=clearance, workspace_x=wx,
                      workspace_y=wy, terminal_radius_m=terminal, theta_bound_rad=theta_bound)
