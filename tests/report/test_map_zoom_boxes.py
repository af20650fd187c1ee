"""On a large map the violation call-outs and the run's numbers stay off the dashed boxes of the zoomed panels."""

from __future__ import annotations

from collections.abc import Callable
from pathlib import Path
from typing import Any

import numpy as np
import pandas as pd
from matplotlib.patches import Rectangle
from matplotlib.transforms import Bbox

from tubempc.scenario import load_scenario
from verify.certificate import Certificate
from verify.workspace_map import map_texts, text_box, workspace_map

OUTDOOR = Path(__file__).resolve().parents[2] / "docs" / "examples" / "outdoor-150m.yaml"


def test_labels_stay_off_the_zoom_boxes(make_result: Callable[..., Any]) -> None:
    """Four violations close together on the 150 m field: three zoom boxes; before, five labels (two call-outs and
    three run numbers) sat on the boxes' dashed outlines."""
    scenario = load_scenario(OUTDOOR)
    xy = np.array([(10, 10), (35.4, 43.2), (55, 75), (95, 90), (135, 85), (60, 95), (20, 90)], dtype=float)
    arc = np.concatenate([[0.0], np.cumsum(np.hypot(*np.diff(xy, axis=0).T))])
    t = np.arange(0.0, arc[-1] / 1.2, 0.1)
    traj = pd.DataFrame({"t_s": t, "x_m": np.interp(t * 1.2, arc, xy[:, 0]), "y_m": np.interp(t * 1.2, arc, xy[:, 1]),
                         "theta_rad": 0.05 * t})
    t_end = float(t[-1])
    checks = [{"name": f"check_{k}", "verdict": "fail", "margin": -0.1, "margin_unit": "m",
               "first_violation_time": t_end * (0.3 + 0.04 * k), "subformula": f"F[{k},{k + 5}] mission_x"}
              for k in range(4)]
    run = [{"region": r.name, "time": t_end * i / (2 * len(scenario.regions))} for i, r in enumerate(scenario.regions)]
    cert = Certificate.model_validate({**make_result().certificate, "verdict": "fail", "formula": scenario.spec,
                                       "checks": checks, "timed_run": run, "duration_s": t_end})
    fig = workspace_map(cert, scenario, traj, None).figure
    ax = fig.axes[0]
    renderer = fig.canvas.get_renderer()  # type: ignore[attr-defined]
    boxes = [Bbox.from_extents(*ax.transData.transform((p.get_x(), p.get_y())),
                               *ax.transData.transform((p.get_x() + p.get_width(), p.get_y() + p.get_height())))
             for p in ax.patches if isinstance(p, Rectangle) and p.get_linestyle() == "--"]
    assert len(boxes) == 3
    labels = [(t.get_text(), text_box(t, renderer)) for t in map_texts(fig) if t.axes is ax and t.get_visible()]
    assert sum("violated" in text for text, _ in labels) == 4
    on_boxes = [text for text, box in labels if any(box.overlaps(z) for z in boxes)]
    assert not on_boxes, on_boxes
