"""Pure pursuit for a differential-drive robot: the example of a lab's own controller in tubempc's closed loop.

``PurePursuit`` follows the polyline of the plan's waypoints (the start, then each target region's centre) by
steering towards the point ``lookahead_m`` ahead of its projection on the path; it slows down near the last target
and stops inside it. ``pure_pursuit`` is the factory ``--controller examples.controllers.pure_pursuit:pure_pursuit``
names; ``corner_cutter`` is the same controller with a planted fault: a 1.6 m look-ahead, which cuts the corner
at W into the obstacle O of ``unicycle-lab.yaml``.
"""

from __future__ import annotations

import math
from collections.abc import Sequence

import numpy as np

from tubempc.control.user import ControllerPlan, Reference
from tubempc.scenario import Scenario


class PurePursuit:
    input_model = "unicycle"
    tube_radius_m = None

    def __init__(self, lookahead_m: float = 0.35, speed_mps: float = 0.25, stop_m: float = 0.03) -> None:
        self.lookahead_m = lookahead_m
        self.speed_mps = speed_mps
        self.stop_m = stop_m
        self._path = np.zeros((1, 2))
        self._segment = 0
        self._v_max = speed_mps
        self._w_max = 1.0

    def reset(self, scenario: Scenario, plan: ControllerPlan) -> None:
        self._path = np.array(plan.waypoints, dtype=float)
        self._segment = 0
        self._v_max = min(self.speed_mps, scenario.inputs.max_abs[0])
        self._w_max = scenario.inputs.max_abs[1]

    def _project(self, p: np.ndarray) -> tuple[int, float]:
        """The segment and the parameter of the point of the path nearest ``p`` (never going back)."""
        best = (math.inf, self._segment, 0.0)
        for k in range(self._segment, len(self._path) - 1):
            a, b = self._path[k], self._path[k + 1]
            ab = b - a
            s = float(np.clip(np.dot(p - a, ab) / max(float(np.dot(ab, ab)), 1e-12), 0.0, 1.0))
            d = float(np.linalg.norm(a + s * ab - p))
            if d < best[0]:
                best = (d, k, s)
        return best[1], best[2]

    def _ahead(self, segment: int, s: float) -> np.ndarray:
        """The point ``lookahead_m`` along the path from (segment, s)."""
        left = self.lookahead_m
        a, b = self._path[segment], self._path[segment + 1]
        point = a + s * (b - a)
        for k in range(segment, len(self._path) - 1):
            end = self._path[k + 1]
            length = float(np.linalg.norm(end - point))
            if length >= left:
                return point + (end - point) * (left / max(length, 1e-12))
            left -= length
            point = end
        return self._path[-1]

    def step(self, t_s: float, state: np.ndarray, reference: Reference) -> Sequence[float]:
        p, theta = np.asarray(state[:2], dtype=float), float(state[2])
        goal = self._path[-1]
        to_goal = float(np.linalg.norm(goal - p))
        if to_goal < self.stop_m:
            return (0.0, 0.0)
        self._segment, s = self._project(p)
        target = self._ahead(self._segment, s)
        alpha = math.atan2(target[1] - p[1], target[0] - p[0]) - theta
        alpha = math.atan2(math.sin(alpha), math.cos(alpha))
        v = min(self._v_max, 0.8 * to_goal) * max(math.cos(alpha), 0.0)
        w = 2.0 * self._v_max * math.sin(alpha) / self.lookahead_m
        return (v, float(np.clip(w, -self._w_max, self._w_max)))


def pure_pursuit() -> PurePursuit:
    """The working controller: a 0.35 m look-ahead."""
    return PurePursuit()


def corner_cutter() -> PurePursuit:
    """The planted fault: a 1.6 m look-ahead cuts the corner at W into obstacle O."""
    return PurePursuit(lookahead_m=1.6)
