"""Sampled poses at a fixed rate with a bounded speed."""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from tubempc.strategies._common import FloatArray, centi, st


@dataclass(frozen=True, slots=True)
class Trajectory:
    """Sampled poses: ``t_s`` (seconds from time 0, increasing), ``xy_m`` (n x 2), ``yaw_rad`` (n)."""

    t_s: tuple[float, ...]
    xy_m: tuple[tuple[float, float], ...]
    yaw_rad: tuple[float, ...]

    def __post_init__(self) -> None:
        if not (len(self.t_s) == len(self.xy_m) == len(self.yaw_rad)) or not self.t_s:
            raise ValueError("t_s, xy_m and yaw_rad must have the same non-zero length")

    def arrays(self) -> tuple[FloatArray, FloatArray, FloatArray]:
        return np.array(self.t_s), np.array(self.xy_m, dtype=float).reshape(-1, 2), np.array(self.yaw_rad)


@st.composite
def trajectories(draw: st.DrawFn, *, rate_hz: float = 100.0, max_samples: int = 400, max_speed_mps: float = 0.2,
                 start: tuple[float, float] | None = None, box_m: float = 2.5) -> Trajectory:
    """Poses at ``rate_hz`` whose planar speed never exceeds ``max_speed_mps`` and which stay in
    ``[-box_m, box_m]^2``: piecewise-constant velocities (up to 6 segments), clipped at the box."""
    n = draw(st.integers(2, max_samples))
    dt = 1.0 / rate_hz
    x, y = start if start is not None else (draw(centi(-box_m, box_m)), draw(centi(-box_m, box_m)))
    yaw = draw(centi(-3.14, 3.14))
    segments = draw(st.lists(st.tuples(centi(-1.0, 1.0), centi(-1.0, 1.0), centi(-0.5, 0.5)), min_size=1,
                             max_size=6))
    ts, xys, yaws = [], [], []
    for i in range(n):
        ts.append(i * dt)
        xys.append((x, y))
        yaws.append(math.atan2(math.sin(yaw), math.cos(yaw)))
        vx, vy, wz = segments[i * len(segments) // n]
        norm = math.hypot(vx, vy)
        scale = max_speed_mps / max(norm, 1.0) if norm > 0 else 0.0
        x = min(max(x + vx * scale * dt, -box_m), box_m)
        y = min(max(y + vy * scale * dt, -box_m), box_m)
        yaw += wz * dt
    return Trajectory(t_s=tuple(ts), xy_m=tuple(xys), yaw_rad=tuple(yaws))
