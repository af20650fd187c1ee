"""The map's axis labels stay inside the figure, whatever the workspace's shape."""

from __future__ import annotations

from collections.abc import Callable
from pathlib import Path
from typing import Any

import pytest

from tubempc.scenario import builtin_scenario, scenario_from_dict
from verify.certificate import Certificate
from verify.workspace_map import workspace_map

OUTDOOR = Path(__file__).resolve().parents[2] / "docs" / "examples" / "outdoor-150m.yaml"


@pytest.mark.parametrize("box", [((-1000.5, 2500.0), (-30.0, 30.0)),  # a long outdoor run: the map fills its width
                                 ((-2.5, 2.5), (-2.5, 2.5)), ((-150.0, 20.0), (-1250.5, 30.0))])
def test_the_y_label_and_ticks_are_inside_the_figure(box: tuple[tuple[float, float], tuple[float, float]],
                                                     make_result: Callable[..., Any]) -> None:
    data = builtin_scenario().to_dict()
    (x0, x1), (y0, y1) = box
    data["workspace"] = {"x": [x0, x1], "y": [y0, y1]}
    data["regions"] = [{"name": "lab", "center": [0.0, 0.0], "radius": 1.0, "labels": ["in_lab"]}]
    data["spec"] = "F in_lab"
    data.pop("initial_region", None)
    sc = scenario_from_dict(data)
    result = make_result(verdict="pass")
    fig = workspace_map(Certificate.model_validate(result.certificate), sc, result.trajectory, None).figure
    renderer = fig.canvas.get_renderer()
    for ax in fig.axes[:1]:
        left = ax.yaxis.get_tightbbox(renderer)
        assert left is not None and left.x0 >= 0.0, (box, left)
        assert ax.get_ylabel() == "y [m]"


def test_a_zoom_box_near_the_edge_stays_inside_the_map_frame(make_result: Callable[..., Any]) -> None:
    """A violation at the workspace's corner: its dashed zoom box is moved inside the frame (it reached past it)."""
    import numpy as np
    import pandas as pd
    from matplotlib.patches import Rectangle

    from tubempc.scenario import load_scenario

    sc = load_scenario(str(OUTDOOR))
    t = np.arange(0.0, 100.0, 0.1)
    traj = pd.DataFrame({"t_s": t, "x_m": 1.5 * t, "y_m": np.full_like(t, 0.6), "theta_rad": np.zeros_like(t)})
    base = make_result(verdict="fail").certificate
    cert = Certificate.model_validate({**base, "verdict": "fail", "timed_run": [], "checks": [
        {"name": "workspace", "verdict": "fail", "margin": -0.1, "margin_unit": "m", "first_violation_time": 0.0}]})
    fig = workspace_map(cert, sc, traj, None).figure
    main = fig.axes[0]
    (x_lo, x_hi), (y_lo, y_hi) = main.get_xlim(), main.get_ylim()
    boxes = [p for p in main.patches if isinstance(p, Rectangle) and p.get_linestyle() == "--"]
    assert boxes
    for box in boxes:
        x, y, w, h = box.get_x(), box.get_y(), box.get_width(), box.get_height()
        assert x >= x_lo and y >= y_lo and x + w <= x_hi and y + h <= y_hi, (x, y, w, h, main.get_xlim())
