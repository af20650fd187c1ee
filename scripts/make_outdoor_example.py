"""Write a long outdoor-scale log for ``docs/examples/outdoor-150m.yaml`` (deterministic, no solver).

Run: ``python3 scripts/make_outdoor_example.py --out /tmp/outdoor`` -> ``/tmp/outdoor/outdoor_long.mcap``; then
``tubempc certify /tmp/outdoor/outdoor_long.mcap --scenario docs/examples/outdoor-150m.yaml --out /tmp/outdoor/r``.

The robot patrols base -> survey_a -> dock -> charger along waypoints at 1.2 m/s, with a small smooth wobble. Two
faults are built in, the ones a report must make visible on a 150 m map: at ~55 s the path grazes the 1.2 m
``rock`` (``G !(... rock ...)`` fails there), and it reaches ``dock`` at ~280 s, after the window ``[200, 260]``
closed (a missed window). ``F[350,inf) charger`` is met at the end (~425 s), so only those two faults fail.
"""

from __future__ import annotations

import argparse
import itertools
from pathlib import Path

import numpy as np

from tubempc.control.closed_loop import ClosedLoopResult, Target
from tubempc.rosio import write_log
from tubempc.scenario import load_scenario

SCENARIO = Path(__file__).resolve().parent.parent / "docs" / "examples" / "outdoor-150m.yaml"
RATE_HZ = 10.0
SPEED_MPS = 1.2

# (x, y, dwell after arriving [s]); the path passes 1.6 m from rock's centre: the 0.5 m disc overlaps it by 0.1 m
WAYPOINTS = ((10.0, 10.0, 5.0), (35.4, 43.2, 0.0), (55.0, 75.0, 145.0), (95.0, 90.0, 0.0),
             (135.0, 85.0, 45.0), (60.0, 95.0, 0.0), (20.0, 90.0, 10.0))


def _path() -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    knots_t, knots_x, knots_y = [0.0], [WAYPOINTS[0][0]], [WAYPOINTS[0][1]]
    t = WAYPOINTS[0][2]
    knots_t.append(t)
    knots_x.append(WAYPOINTS[0][0])
    knots_y.append(WAYPOINTS[0][1])
    for (x0, y0, _), (x1, y1, dwell) in itertools.pairwise(WAYPOINTS):
        t += float(np.hypot(x1 - x0, y1 - y0)) / SPEED_MPS
        knots_t += [t, t + dwell]
        knots_x += [x1, x1]
        knots_y += [y1, y1]
        t += dwell
    ts = np.arange(0.0, t + 1e-9, 1.0 / RATE_HZ)
    return ts, np.interp(ts, knots_t, knots_x), np.interp(ts, knots_t, knots_y)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__)
    parser.add_argument("--out", type=Path, required=True)
    out: Path = parser.parse_args().out
    out.mkdir(parents=True, exist_ok=True)
    scenario = load_scenario(SCENARIO)
    t, x, y = _path()
    wobble = 0.01 * np.sin(2 * np.pi * t / 37.0)  # smooth, well inside the speed bound
    theta = np.arctan2(np.gradient(y), np.gradient(x) + 1e-12)
    real = np.column_stack([x + wobble, y - wobble, theta])
    nominal = np.column_stack([x, y, theta])
    vel = np.column_stack([np.gradient(real[:, 0], t), np.gradient(real[:, 1], t), np.zeros_like(t)])
    c, s = np.cos(theta), np.sin(theta)
    body = np.column_stack([c * vel[:, 0] + s * vel[:, 1], -s * vel[:, 0] + c * vel[:, 1], np.zeros_like(t)])
    result = ClosedLoopResult(
        t_s=t, x=real, x_measured=real, x_hat=nominal, u_world=vel, u_body=body, solver=(), arrivals=(),
        targets=tuple(Target(r) for r in ("survey_a", "dock", "charger")), start_region="base",
        tube_radius_m=scenario.tube_radius_m, sigma=0.0, seed=0, disturbance="none", disturbance_params={},
        mocap_noise_m=0.0, ok=True, reason=None)
    path = write_log(result, scenario, out / "outdoor_long.mcap", metadata={"example": "outdoor patrol (synthetic)"})
    print(path)


if __name__ == "__main__":
    main()
