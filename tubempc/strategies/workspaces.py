"""Workspaces: non-overlapping circular regions in a box (some unsafe) and robot radii that fit."""

from __future__ import annotations

import math
from collections.abc import Sequence
from typing import Any, Literal

from tubempc.scenario import Scenario, scenario_from_dict
from tubempc.strategies._common import centi, st


def robot_radii(max_radius_m: float, min_radius_m: float = 0.05) -> st.SearchStrategy[float]:
    """Robot disc radii ``eta`` in [min_radius_m, max_radius_m) on a 1 cm grid (strictly below the maximum)."""
    if not 0 < min_radius_m < max_radius_m:
        raise ValueError(f"min_radius_m={min_radius_m!r} must lie in (0, max_radius_m={max_radius_m!r})")
    return centi(min_radius_m, max_radius_m - 0.01).filter(lambda r: r < max_radius_m)


@st.composite
def scenarios(draw: st.DrawFn, *, min_regions: int = 2, max_regions: int = 6, max_unsafe: int = 3,
              cell_m: float = 1.2, grid: tuple[int, int] = (4, 4), region_radius_m: tuple[float, float] = (0.3, 0.5),
              delta_bar: tuple[float, float] = (0.0, 0.03), spec: st.SearchStrategy[str] | None = None,
              room_m: float = 0.15, models: Sequence[Literal["world", "body"]] = ("world",),
              ) -> Scenario:
    """Scenarios with ``min_regions..max_regions`` non-overlapping circular regions in a box, some unsafe.

    The box is a ``grid`` of square cells of side ``cell_m``; each region sits in its own cell (distinct cells,
    jittered centre), so regions never overlap and always fit. At least one region is safe (the initial one), at
    most ``max_unsafe`` are unsafe; safe region ``k`` carries label ``mission_k``, unsafe region ``k`` label
    ``obs_k``. The robot radius is at most the smallest safe region's radius minus ``room_m``, and minus the
    terminal ball plus the tube radius of the drawn disturbance bound, ``sigma_low`` and model (so that the
    controller's design check passes unless ``region_radius_m`` is too small for that; ``room_m=0`` allows any
    radius that fits). ``models`` lists the dynamics models to draw from (``body`` gets a heading restriction in
    [0.3, 1.2] rad). ``spec`` draws the MITL text (it may only use those labels); by default: always avoid every
    obstacle and eventually visit ``mission_1``.
    The value is built through ``scenario_from_dict``, so the scenario model's own validation applies.
    """
    nx, ny = grid
    if not 1 <= min_regions <= max_regions <= nx * ny:
        raise ValueError(f"need 1 <= min_regions={min_regions} <= max_regions={max_regions} <= {nx * ny} cells")
    r_lo, r_hi = region_radius_m
    if not 0 < r_lo <= r_hi < cell_m / 2:
        raise ValueError(f"region_radius_m={region_radius_m!r} must satisfy 0 < lo <= hi < cell_m/2={cell_m / 2}")
    cells = draw(st.lists(st.tuples(st.integers(0, nx - 1), st.integers(0, ny - 1)), min_size=min_regions,
                          max_size=max_regions, unique=True))
    n_unsafe = draw(st.integers(0, min(max_unsafe, len(cells) - 1)))
    x0 = -nx * cell_m / 2
    y0 = -ny * cell_m / 2
    regions: list[dict[str, Any]] = []
    n_safe = 0
    n_obs = 0
    for i, (cx, cy) in enumerate(cells):
        radius = draw(centi(r_lo, r_hi))
        slack = cell_m / 2 - radius
        jx = draw(centi(-slack, slack))
        jy = draw(centi(-slack, slack))
        unsafe = i >= len(cells) - n_unsafe
        if unsafe:
            n_obs += 1
            labels = [f"obs_{n_obs}"]
        else:
            n_safe += 1
            labels = [f"mission_{n_safe}"]
        regions.append({
            "name": f"R{i + 1}",
            "center": [round(x0 + (cx + 0.5) * cell_m + jx, 6), round(y0 + (cy + 0.5) * cell_m + jy, 6)],
            "radius": radius, "labels": labels, "unsafe": unsafe,
        })
    bound = draw(centi(*delta_bar))
    sigma_low = draw(st.sampled_from([1.0, 2.0, 4.0]))
    model = draw(st.sampled_from(list(models)))
    theta_max = draw(centi(0.3, 1.2)) if model == "body" else None
    g_min = math.cos(theta_max) if theta_max is not None else 1.0
    # room for the terminal ball eps/sqrt(min P) = 0.07/sqrt(0.5) and the tube radius of the drawn parameters
    need = 0.07 / math.sqrt(0.5) + bound / (sigma_low * g_min) + 0.005
    room = max(room_m, need) if room_m > 0 else 0.0
    smallest_safe = min(r["radius"] for r in regions if not r["unsafe"])
    eta = draw(robot_radii(max(min(smallest_safe - room, 0.35), 0.06)))
    obstacles = [f"obs_{k}" for k in range(1, n_obs + 1)]
    if spec is None:
        avoid = f"G[0,inf) !({' | '.join(obstacles)}) & " if obstacles else ""
        text = f"{avoid}F[0,inf) mission_1"
    else:
        text = draw(spec)
    data: dict[str, Any] = {
        "name": "hypothesis",
        "workspace": {"x": [x0, -x0], "y": [y0, -y0]},
        "robot": {"radius": eta},
        "inputs": {"max_abs": [0.2, 0.2, 0.2]},
        "disturbance": {"bound": bound},
        "tube": {"sigma_low": sigma_low},
        "mpc": {"h": 0.1, "horizon": 1.2, "Q": [0.5, 0.5, 0.5], "R": [0.5, 0.5, 0.5], "P": [0.5, 0.5, 0.5],
                "eps": 0.07},
        "regions": regions,
        "initial_region": "R1",
        "spec": text,
    }
    if theta_max is not None:
        data["dynamics"] = {"model": "body", "theta_max": theta_max}
    return scenario_from_dict(data, source="<tubempc.strategies.scenarios>")
