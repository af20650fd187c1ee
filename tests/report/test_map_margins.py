"""The map's axis labels stay inside the figure, whatever the workspace's shape."""

from __future__ import annotations

from collections.abc import Callable
from typing import Any

import pytest

from tubempc.scenario import builtin_scenario, scenario_from_dict
from verify.certificate import Certificate
from verify.workspace_map import workspace_map


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
