"""On a large map the violation call-outs and the run's numbers stay off the dashed boxes of the zoomed panels, and
the call-outs' leader lines cross no other zoom box and no label, at field and at lab scale."""

from __future__ import annotations

from collections.abc import Callable
from pathlib import Path
from typing import Any

import numpy as np
import pandas as pd
import pytest
from matplotlib.figure import Figure
from matplotlib.patches import Rectangle
from matplotlib.text import Annotation
from matplotlib.transforms import Bbox

from tubempc.scenario import Scenario, builtin_scenario, load_scenario
from verify.certificate import Certificate
from verify.workspace_map import map_texts, text_box, workspace_map

OUTDOOR = Path(__file__).resolve().parents[2] / "docs" / "examples" / "outdoor-150m.yaml"


def _crowded_map(make_result: Callable[..., Any], scenario: Scenario, points: list[tuple[float, float]],
                 speed_mps: float) -> Figure:
    """Four violations close together in time and a timed run through every region: labels compete for space."""
    xy = np.array(points, dtype=float)
    arc = np.concatenate([[0.0], np.cumsum(np.hypot(*np.diff(xy, axis=0).T))])
    t = np.arange(0.0, arc[-1] / speed_mps, 0.1)
    traj = pd.DataFrame({"t_s": t, "x_m": np.interp(t * speed_mps, arc, xy[:, 0]),
                         "y_m": np.interp(t * speed_mps, arc, xy[:, 1]), "theta_rad": 0.05 * t})
    t_end = float(t[-1])
    checks = [{"name": f"check_{k}", "verdict": "fail", "margin": -0.1, "margin_unit": "m",
               "first_violation_time": t_end * (0.3 + 0.04 * k), "subformula": f"F[{k},{k + 5}] mission_x"}
              for k in range(4)]
    run = [{"region": r.name, "time": t_end * i / (2 * len(scenario.regions))} for i, r in enumerate(scenario.regions)]
    cert = Certificate.model_validate({**make_result().certificate, "verdict": "fail", "formula": scenario.spec,
                                       "checks": checks, "timed_run": run, "duration_s": t_end})
    return workspace_map(cert, scenario, traj, None).figure


def _zoom_boxes(ax: Any) -> list[Bbox]:
    return [Bbox.from_extents(*ax.transData.transform((p.get_x(), p.get_y())),
                              *ax.transData.transform((p.get_x() + p.get_width(), p.get_y() + p.get_height())))
            for p in ax.patches if isinstance(p, Rectangle) and p.get_linestyle() == "--"]


def _crosses(a: np.ndarray, b: np.ndarray, box: Bbox) -> bool:
    """Whether the segment a-b (pixels) meets the rectangle ``box`` (Liang-Barsky clipping)."""
    d = b - a
    lo, hi = 0.0, 1.0
    for p, q in ((-d[0], a[0] - box.x0), (d[0], box.x1 - a[0]), (-d[1], a[1] - box.y0), (d[1], box.y1 - a[1])):
        if p == 0:
            if q < 0:
                return False
            continue
        r = q / p
        if p < 0:
            lo = max(lo, r)
        else:
            hi = min(hi, r)
        if lo > hi:
            return False
    return True


def _leader_problems(fig: Figure) -> list[str]:
    """Each call-out's leader line (from its text box's centre to its marker, the part outside the text) against
    the other labels' text boxes and the zoom boxes that do not hold its marker."""
    ax = fig.axes[0]
    renderer = fig.canvas.get_renderer()  # type: ignore[attr-defined]
    texts = [t for t in map_texts(fig) if t.axes is ax and t.get_visible()]
    boxes = {id(t): text_box(t, renderer) for t in texts}
    zooms = _zoom_boxes(ax)
    problems: list[str] = []
    callouts = [t for t in texts if isinstance(t, Annotation) and t.arrow_patch is not None]
    assert callouts
    for t in callouts:
        own = boxes[id(t)]
        end = np.asarray(ax.transData.transform(t.xy), dtype=float)
        start = np.array([(own.x0 + own.x1) / 2, (own.y0 + own.y1) / 2])
        # the part of the line outside its own text box: from where it leaves the box
        steps = np.linspace(0.0, 1.0, 400)
        outside = [k for k in steps if not own.contains(*(start + k * (end - start)))]
        if not outside:
            continue
        a = start + outside[0] * (end - start)
        for other in texts:
            if other is not t and _crosses(a, end, boxes[id(other)]):
                problems.append(f"{t.get_text()!r} crosses label {other.get_text()!r}")
        for z in zooms:
            if not z.contains(*end) and _crosses(a, end, z):
                problems.append(f"{t.get_text()!r} crosses a zoom box")
    return problems


FIELD = [(10, 10), (35.4, 43.2), (55, 75), (95, 90), (135, 85), (60, 95), (20, 90)]
LAB = [(-1.99, -1.78), (-0.6, -0.5), (0.16, 0.40), (1.3, -0.4), (2.02, -1.63)]


@pytest.mark.parametrize("scale", ["field-150m", "lab-5m"])
def test_leader_lines_cross_no_label_and_no_other_zoom_box(scale: str, make_result: Callable[..., Any]) -> None:
    """Before, on the 150 m field the call-outs' leader lines ran across the other violations' zoom boxes and
    across other labels (the labels themselves were already kept apart)."""
    if scale == "field-150m":
        fig = _crowded_map(make_result, load_scenario(OUTDOOR), FIELD, 1.2)
        assert len(_zoom_boxes(fig.axes[0])) == 3
    else:
        fig = _crowded_map(make_result, builtin_scenario(), LAB, 0.15)
    problems = _leader_problems(fig)
    assert not problems, problems
    shown = [t.get_text() for t in map_texts(fig) if t.axes is fig.axes[0]]
    assert sum("violated" in text for text in shown) == 4  # and no call-out was hidden to get there


def test_labels_stay_off_the_zoom_boxes(make_result: Callable[..., Any]) -> None:
    """Four violations close together on the 150 m field: three zoom boxes; before, five labels (two call-outs and
    three run numbers) sat on the boxes' dashed outlines."""
    fig = _crowded_map(make_result, load_scenario(OUTDOOR), FIELD, 1.2)
    ax = fig.axes[0]
    renderer = fig.canvas.get_renderer()  # type: ignore[attr-defined]
    boxes = _zoom_boxes(ax)
    assert len(boxes) == 3
    labels = [(t.get_text(), text_box(t, renderer)) for t in map_texts(fig) if t.axes is ax and t.get_visible()]
    assert sum("violated" in text for text, _ in labels) == 4
    on_boxes = [text for text, box in labels if any(box.overlaps(z) for z in boxes)]
    assert not on_boxes, on_boxes
