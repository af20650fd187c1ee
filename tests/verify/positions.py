"""Positions and general-engine values shared by the tests of the judging core (``test_explain.py``,
``test_regular.py`` and the ``test_mutants_*.py`` files written for mutation testing)."""

from __future__ import annotations

import numpy as np

from tubempc.mitl import Formula
from verify.geometry import gap_bounds
from verify.monitor.engine import Positions, Truth, evaluate_at_points
from verify.monitor.grid import Grid
from verify.semantics.trajectory import interleave, trajectory_positions

__all__ = ["engine_on_grid", "with_gaps"]


def with_gaps(times_ns: list[int]) -> Positions:
    """Samples at ``times_ns`` with the open gap between each two as a position of its own (the trajectory
    semantics' positions)."""
    start, stop, point = [], [], []
    for k, t in enumerate(times_ns):
        if k:
            start.append(times_ns[k - 1] + 1)
            stop.append(t - 1)
            point.append(False)
        start.append(t)
        stop.append(t)
        point.append(True)
    return Positions(np.array(start, dtype=np.int64), np.array(stop, dtype=np.int64), np.array(point),
                     times_ns[-1])


def engine_on_grid(f: Formula, grid: Grid, margins: dict[str, np.ndarray], step: np.ndarray
                   ) -> tuple[dict[Formula, Truth], np.ndarray, np.ndarray]:
    """The general engine's values on the grid's interleaved positions, the index of every sample and of every gap."""
    t_ns = grid.t0_ns + grid.dt_ns * np.arange(grid.n, dtype=np.int64)
    pos, point_at, gap_at = trajectory_positions(t_ns)
    values = {}
    for name, m in margins.items():
        gb = gap_bounds(m, step)
        values[name] = interleave(m, m, gb.lo, gb.hi, point_at=point_at, gap_at=gap_at, size=pos.size)
    return evaluate_at_points(f, pos, values), point_at, gap_at
