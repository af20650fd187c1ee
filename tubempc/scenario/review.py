"""Judging a valid scenario for a use: what keeps the planner from it, and geometry the certifier warns about.

input: a ``Scenario`` (already validated field by field) -> output: ``planning_problems``, ``(field, problem)`` pairs
(empty: the planner and the controller can use it; ``Scenario.require_planning`` raises on the first), and
``certification_warnings``, one line each naming the field (the certificate lists them; they never fail a log).
"""

from __future__ import annotations

import math
from typing import TYPE_CHECKING

from tubempc.mitl import atoms
from tubempc.scenario.polygon import disc_within_polygon, polygon_within_polygon

if TYPE_CHECKING:
    from tubempc.scenario.model import Region, Scenario

__all__ = ["certification_warnings", "planning_problems"]


def planning_problems(sc: Scenario) -> list[tuple[str, str]]:
    """Missing fields, a unicycle input model, polygon shapes, overlapping regions, regions that do not fit inside
    the workspace or cannot contain the robot (see ``Scenario.planning_problems``)."""
    return [*_field_problems(sc), *_region_problems(sc)]


def _field_problems(sc: Scenario) -> list[tuple[str, str]]:
    out: list[tuple[str, str]] = []
    if sc.robots:
        out.append(("robots", "the planner and the controller are single-robot: a scenario with robots: is for "
                              "certification"))
    for field, value in (("disturbance", sc.disturbance_spec), ("tube", sc.tube_spec),
                         ("mpc", sc.mpc_spec), ("initial_region", sc.initial_region_name)):
        if value is None:
            out.append((field, "required for planning and simulation but missing from the scenario"))
    if sc.inputs.model != "holonomic":
        out.append(("inputs.model", f"{sc.inputs.model}: the paper's tube MPC needs a fully actuated "
                                    "(holonomic) input model"))
    used = sorted(atoms(sc.formula) & set(sc.signals))
    if used:
        out.append(("spec", f"signal atom(s) {', '.join(used)} can be certified but not planned for"))
    if not sc.workspace.is_box:
        out.append(("workspace", "the planner needs a box workspace (x, y), not a polygon"))
    return out


def _region_problems(sc: Scenario) -> list[tuple[str, str]]:
    out: list[tuple[str, str]] = []
    eta = sc.robot.radius
    discs: list[tuple[int, Region]] = [(i, r) for i, r in enumerate(sc.regions)
                                       if r.disc_center is not None and r.disc_radius is not None]
    for i, r in enumerate(sc.regions):
        if r.polygon is not None:
            out.append((f"regions[{i}]", f"{r.name} is a polygon: the planner needs disc regions"))
    if sc.workspace.is_box:
        for i, r in discs:
            if not sc.workspace.contains_disc(r.center, r.radius):
                out.append((f"regions[{i}]", f"{r.name} does not fit inside the workspace"))
    for i, r in discs:
        if not r.unsafe and r.radius <= eta:
            out.append((f"regions[{i}]", f"{r.name}: radius {r.radius} m cannot contain the robot disc of "
                                         f"radius {eta} m"))
    for k, (_, a) in enumerate(discs):
        for _, b in discs[k + 1 :]:
            d = math.dist(a.center, b.center)
            if d < a.radius + b.radius:
                out.append(("regions", f"{a.name} and {b.name} overlap (centres {d:.3f} m apart)"))
    return out


def certification_warnings(sc: Scenario) -> list[str]:
    """Regions that reach outside the workspace, overlap or nest, or cannot contain the robot disc (see
    ``Scenario.certification_warnings``)."""
    out: list[str] = []
    ws = sc.workspace
    wx0, wy0, wx1, wy1 = ws.bounds
    eta = sc.robot.radius
    for i, r in enumerate(sc.regions):
        x0, y0, x1, y1 = r.bounds
        if ws.polygon is None:
            if x0 < wx0 or y0 < wy0 or x1 > wx1 or y1 > wy1:
                out.append(f"regions[{i}] ({r.name}): reaches outside the workspace box")
        elif not (polygon_within_polygon(r.polygon, ws.polygon) if r.polygon is not None
                  else disc_within_polygon(r.center, r.radius, ws.polygon)):
            out.append(f"regions[{i}] ({r.name}): reaches outside the workspace polygon")
        if not r.unsafe:
            w, h = x1 - x0, y1 - y0
            if min(w, h) <= 2 * eta:
                out.append(f"regions[{i}] ({r.name}): too small to contain the robot disc of radius {eta} m "
                           "(its labels can never hold under Definition 3)")
    for i, a in enumerate(sc.regions):
        for j in range(i + 1, len(sc.regions)):
            b = sc.regions[j]
            ax0, ay0, ax1, ay1 = a.bounds
            bx0, by0, bx1, by1 = b.bounds
            if ax0 < bx1 and bx0 < ax1 and ay0 < by1 and by0 < ay1:
                if a.is_disc and b.is_disc and math.dist(a.center, b.center) >= a.radius + b.radius:
                    continue
                out.append(f"regions[{i}] ({a.name}) and regions[{j}] ({b.name}) may overlap: where both "
                           "contain the robot, both sets of labels hold")
    return out
