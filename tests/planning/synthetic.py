"""Synthetic inputs for tests and benchmarks: a straight-line transition oracle and random workspaces.

A test fixture, not part of the installed package: tests import it as ``tests.planning.synthetic`` (the repository
root is on ``sys.path``: ``pythonpath`` in ``pyproject.toml``), and so do the abstraction's worker processes, which
load the oracle's module by that name (``build_wts`` preloads ``straight_line_oracle.__module__``).

input: a ``Scenario`` (and a ``numpy.random.Generator`` for random workspaces) -> output: ``SyntheticTransition``
values (time = straight-line length / speed, rounded up to the MPC step h; failing when the segment passes a
third region) and random ``Scenario`` values. Never used by the CLI: the real WTS comes from Algorithm 1.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from tubempc.scenario import Scenario, scenario_from_dict

__all__ = ["SYNTHETIC_SPEED_FRACTION", "SyntheticTransition", "random_scenario", "straight_line_oracle"]

SYNTHETIC_SPEED_FRACTION = 0.8  # of the per-axis input bound: a cruise speed below saturation


@dataclass(frozen=True, slots=True)
class SyntheticTransition:
    ok: bool
    reason: str | None
    t_ij_s: float | None
    arrival_s: float | None = None
    max_tube_error_m: float | None = None
    min_clearance_m: float | None = None


def _segment_distance(a: tuple[float, float], b: tuple[float, float], p: tuple[float, float]) -> float:
    ax, ay = a
    bx, by = b
    dx, dy = bx - ax, by - ay
    den = dx * dx + dy * dy
    s = 0.0 if den == 0 else max(0.0, min(1.0, ((p[0] - ax) * dx + (p[1] - ay) * dy) / den))
    return math.hypot(ax + s * dx - p[0], ay + s * dy - p[1])


def straight_line_oracle(scenario: Scenario, source: str, target: str, *, disturbance: str = "none",
                         seed: int = 0) -> SyntheticTransition:
    """Straight segment between the centres at a cruise speed; fails when the robot disc would touch a third region.

    ``disturbance`` and ``seed`` are accepted for the oracle protocol and ignored (the model is deterministic).
    """
    del disturbance, seed
    a, b = scenario.region(source), scenario.region(target)
    eta = scenario.robot.radius
    clearance = math.inf
    for r in scenario.regions:
        if r.name in (source, target):
            continue
        gap = _segment_distance(a.center, b.center, r.center) - r.radius - eta
        clearance = min(clearance, gap)
        if gap <= 0:
            return SyntheticTransition(False, f"the straight segment {source}->{target} passes region {r.name}",
                                       None, min_clearance_m=gap)
    speed = SYNTHETIC_SPEED_FRACTION * min(scenario.inputs.max_abs[0], scenario.inputs.max_abs[1])
    h = scenario.mpc.h
    length = math.dist(a.center, b.center)
    steps = max(1, math.ceil(length / speed / h - 1e-9))
    t = round(steps * h, 6)
    return SyntheticTransition(True, None, t, arrival_s=t, max_tube_error_m=0.0, min_clearance_m=clearance)


def random_scenario(rng: np.random.Generator, n_regions: int, *, spec: str, labels: dict[int, list[str]] | None = None,
                    unsafe_fraction: float = 0.1, spacing_m: float = 1.4) -> Scenario:
    """``n_regions`` regions of radius 0.45 m on a jittered grid; region ``i`` gets ``labels[i]``; about
    ``unsafe_fraction`` of the unlabelled regions (never region 0, the initial one) are obstacles labelled ``obs``."""
    side = math.ceil(math.sqrt(n_regions))
    half = side * spacing_m / 2
    radius = 0.45
    jitter = (spacing_m - 2 * radius) / 2 - 0.01
    labels = labels or {}
    regions = []
    for i in range(n_regions):
        row, col = divmod(i, side)
        cx = -half + spacing_m * (col + 0.5) + float(rng.uniform(-jitter, jitter))
        cy = -half + spacing_m * (row + 0.5) + float(rng.uniform(-jitter, jitter))
        unsafe = i != 0 and i not in labels and bool(rng.random() < unsafe_fraction)
        regions.append({"name": f"R{i}", "center": [round(cx, 3), round(cy, 3)], "radius": radius,
                        "labels": ["obs"] if unsafe else list(labels.get(i, [])), "unsafe": unsafe})
    if not any(r["unsafe"] for r in regions):
        regions.append({"name": "Robs", "center": [half + 1.0, half + 1.0], "radius": radius, "labels": ["obs"],
                        "unsafe": True})
    extent = half + 2.0
    data = {
        "name": f"random-{n_regions}",
        "workspace": {"x": [-extent, extent], "y": [-extent, extent]},
        "robot": {"radius": 0.27},
        "inputs": {"max_abs": [0.2, 0.2, 0.2]},
        "disturbance": {"bound": 0.02},
        "tube": {"sigma_low": 2.0},
        "mpc": {"h": 0.1, "horizon": 1.2, "Q": [0.5, 0.5, 0.5], "R": [0.5, 0.5, 0.5], "P": [0.5, 0.5, 0.5]},
        "regions": regions,
        "initial_region": "R0",
        "spec": spec,
    }
    return scenario_from_dict(data, source=f"<random {n_regions}>")
