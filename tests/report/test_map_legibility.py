"""The map reads at any scale: no two text annotations overlap (matplotlib text extents), names are printed once,
every violation is named beside its marker, and a large map gets zoomed panels; the obligations and the report's
page order tell the story."""

from __future__ import annotations

import itertools
from collections.abc import Callable
from pathlib import Path
from typing import Any

import numpy as np
import pandas as pd
import pytest
from matplotlib.backends.backend_agg import FigureCanvasAgg

from tubempc.scenario import Scenario, builtin_scenario, load_scenario
from verify.certificate import Certificate
from verify.figures import render_figures
from verify.judging import judge_formula
from verify.report import write_reports
from verify.semantics.timed_run import parse_spec
from verify.workspace_map import map_texts, text_box, workspace_figure, workspace_map

OUTDOOR = Path(__file__).resolve().parents[2] / "docs" / "examples" / "outdoor-150m.yaml"


def _patrol(points: list[tuple[float, float]], speed_mps: float, rate_hz: float = 10.0) -> pd.DataFrame:
    xy = np.asarray(points, dtype=float)
    arc = np.concatenate([[0.0], np.cumsum(np.hypot(*np.diff(xy, axis=0).T))])
    t = np.arange(0.0, arc[-1] / speed_mps, 1.0 / rate_hz)
    return pd.DataFrame({"t_s": t, "x_m": np.interp(t * speed_mps, arc, xy[:, 0]),
                         "y_m": np.interp(t * speed_mps, arc, xy[:, 1]), "theta_rad": 0.05 * t})


def _crowded_certificate(base: dict[str, Any], scenario: Scenario, trajectory: pd.DataFrame,
                         n_violations: int) -> Certificate:
    """Several failed checks with violations close together in time (their labels compete for the same space),
    and a long timed run (numbered markers everywhere)."""
    t_end = float(trajectory["t_s"].iloc[-1])
    checks: list[dict[str, Any]] = []
    for k in range(n_violations):
        checks.append({"name": f"check_{k}", "verdict": "fail", "margin": -0.1, "margin_unit": "m",
                       "first_violation_time": t_end * (0.3 + 0.04 * k), "subformula": f"F[{k},{k + 5}] mission_x"})
    run = [{"region": r.name, "time": t_end * i / (2 * len(scenario.regions))} for i, r in enumerate(scenario.regions)]
    return Certificate.model_validate({**base, "verdict": "fail", "formula": scenario.spec,
                                       "checks": checks, "timed_run": run, "duration_s": t_end})


def _assert_no_overlap(fig: Any) -> None:
    renderer = FigureCanvasAgg(fig).get_renderer() if not isinstance(fig.canvas, FigureCanvasAgg) else \
        fig.canvas.get_renderer()
    texts = [t for t in map_texts(fig) if t.axes is fig.axes[0]]
    boxes = [(t.get_text(), text_box(t, renderer)) for t in texts]
    assert len(boxes) >= 8  # the map has something to place
    for (a, box_a), (b, box_b) in itertools.combinations(boxes, 2):
        assert not box_a.overlaps(box_b), f"{a!r} overlaps {b!r}"


@pytest.mark.parametrize("scale", ["lab-5m", "field-150m"])
def test_map_annotations_never_overlap(scale: str, make_result: Callable[..., Any], tmp_path: Path) -> None:
    if scale == "lab-5m":
        scenario = builtin_scenario()
        trajectory = _patrol([(-1.99, -1.78), (-0.6, -0.5), (0.16, 0.40), (1.3, -0.4), (2.02, -1.63)], 0.15)
    else:
        scenario = load_scenario(OUTDOOR)
        trajectory = _patrol([(10, 10), (35.4, 43.2), (55, 75), (95, 90), (135, 85), (60, 95), (20, 90)], 1.2)
    cert = _crowded_certificate(make_result().certificate, scenario, trajectory, n_violations=4)
    result = make_result()
    written = write_reports(type(result)(cert.to_json_dict(), 1, trajectory), scenario, tmp_path)
    assert {"report.html", "figures/workspace.png", "figures/obligations.png"} <= set(written)
    rendered = workspace_map(cert, scenario, trajectory, None)
    # the figure checked below is the report's map, byte for byte
    assert workspace_figure(cert, scenario, trajectory, None) == written["figures/workspace.png"].read_bytes()
    _assert_no_overlap(rendered.figure)
    shown = [t.get_text() for t in map_texts(rendered.figure) if t.axes is rendered.figure.axes[0]]
    # every violation names what failed beside its marker, even where labels crowd
    for k in range(4):
        assert any(f"F[{k},{k + 5}] mission_x violated" in text for text in shown), shown
    # names once: the outdoor regions' labels equal their names and are not repeated ("pond", never "pond: pond")
    for region in scenario.regions:
        assert sum(text.startswith(region.name) for text in shown) <= 1
    if scale == "field-150m":
        assert "pond" in shown and not any("pond:" in text for text in shown)
        assert len(rendered.figure.axes) >= 3  # map, colour bar, and zoomed panels around the violations


def test_labels_without_placement_would_overlap(make_result: Callable[..., Any]) -> None:
    """The crowded field map is a real test of the placement: the same texts all at offset 0 do overlap."""
    scenario = load_scenario(OUTDOOR)
    trajectory = _patrol([(10, 10), (35.4, 43.2), (55, 75), (95, 90), (135, 85), (60, 95), (20, 90)], 1.2)
    cert = _crowded_certificate(make_result().certificate, scenario, trajectory, 4)
    fig = workspace_map(cert, scenario, trajectory, None).figure
    for text in map_texts(fig):
        text.set_position((0.0, 0.0))
    with pytest.raises(AssertionError, match="overlaps"):
        _assert_no_overlap(fig)


def test_missed_window_reads_as_a_failed_obligation() -> None:
    """F[30,50] mission_2 reached at ~56 s: its own panel fails at 50 s although the target's margin turns positive
    afterwards; the unbounded safety obligation is judged on its own (not hidden as undecided)."""
    scenario = builtin_scenario()
    r1, r3 = scenario.region("R1").center, scenario.region("R3").center
    t = np.arange(0.0, 60.0, 0.05)
    s = np.clip((t - 40.0) / 16.0, 0.0, 1.0)
    traj = pd.DataFrame({"t_s": t, "x_m": r1[0] + s * (r3[0] - r1[0]), "y_m": r1[1] + s * (r3[1] - r1[1])})
    t_ns = np.round(traj["t_s"].to_numpy() * 1e9).astype(np.int64)
    judged = judge_formula(parse_spec(scenario.spec), t_ns, traj["x_m"].to_numpy(), traj["y_m"].to_numpy(), scenario,
                           time0_ns=0, max_speed_mps=scenario.max_speed_mps)
    obs = {o.formula: o for o in judged.panels}
    late = obs["F[30,50] mission_2"]
    assert late.verdict == "fail" and late.first_violation_ns * 1e-9 == pytest.approx(50.0)
    assert late.window_s == (30.0, 50.0)
    assert float(late.curve[-1]) > 0  # reached, but after the window
    assert obs["G[0,inf) !(obs_1 | obs_2 | obs_3 | obs_4)"].verdict == "pass"


def test_page_order_and_readable_formula(tmp_path: Path, make_result: Callable[..., Any]) -> None:
    result = make_result(verdict="fail")
    cert = {**result.certificate, "formula": "G[0,inf) !obs_1 & F[30,50] mission_2",
            "data_quality": {"zeros": {"a": 0, "b": 0}, "dropouts": {"count": 3}}}
    written = write_reports(type(result)(cert, 1, result.trajectory, result.nominal, result.inputs), builtin_scenario(),
                            tmp_path)
    page = written["report.html"].read_text()
    order = [page.index(h) for h in ("<h2>Checks</h2>", "<h2>Map and obligations</h2>", "<h2>States and inputs</h2>",
                                     "<h2>Data quality</h2>", "<h2>Certificate details</h2>")]
    assert order == sorted(order)
    assert page.index('id="fig-workspace"') < page.index('id="fig-obligations"') < page.index('id="fig-states"')
    assert "<details><summary><h2>Data quality</h2>" in page
    # a check that did not run is said right under the checks table, not only in the collapsed details
    assert page.index("not checked: signals (the scenario names no signal)") < page.index("<h2>Map and obligations")
    assert page.index("dropouts.count") < page.index("zeros.a")  # the finding that reports something comes first
    md = written["report.md"].read_text()
    assert "!obs_1 & F[30,50]" in md.replace("\\[", "[").replace("\\]", "]") and "&amp;" not in md


def test_theta_is_unwrapped_and_times_have_sensible_precision(tmp_path: Path,
                                                             make_result: Callable[..., Any]) -> None:
    result = make_result(verdict="fail")
    theta = np.mod(np.linspace(0, 12 * np.pi, len(result.trajectory)) + np.pi, 2 * np.pi) - np.pi  # a sawtooth
    traj = result.trajectory.assign(theta_rad=theta)
    cert = Certificate.model_validate(result.certificate)
    figs = {f.stem: f for f in render_figures(cert, builtin_scenario(), trajectory=traj, nominal=None, inputs=None,
                                              robustness=None)}
    assert "states" in figs
    from verify.figures import _unwrapped

    unwrapped = _unwrapped(traj)["theta_rad"].to_numpy()
    assert np.max(np.abs(np.diff(unwrapped))) < 1.0 and unwrapped[-1] > 30.0
    md = write_reports(result, builtin_scenario(), tmp_path)["report.md"].read_text()
    assert "| 12.50 s |" in md and "| R3 | 19.20 s |" in md


def test_polygon_workspace_and_regions_are_drawn_and_named(make_result: Callable[..., Any]) -> None:
    """Any robot's scenario: a polygon workspace and polygon regions are drawn as polygons, named beside them."""
    from tubempc.scenario import scenario_from_dict

    data = load_scenario(OUTDOOR).to_dict()
    data["workspace"] = {"polygon": [[0, 0], [150, 0], [150, 100], [60, 100], [0, 60]]}
    data["regions"][1] = {"name": "survey_a", "polygon": [[45, 65], [68, 66], [64, 85], [47, 82]],
                          "labels": ["survey_a"]}
    scenario = scenario_from_dict(data, source="<polygons>")
    trajectory = _patrol([(10, 10), (35.4, 43.2), (55, 75), (95, 90)], 1.2)
    rendered = workspace_map(_crowded_certificate(make_result().certificate, scenario, trajectory, 2), scenario,
                             trajectory, None)
    _assert_no_overlap(rendered.figure)
    shown = [t.get_text() for t in map_texts(rendered.figure)]
    assert "survey_a" in shown
    from matplotlib.patches import Polygon

    polygons = [p for p in rendered.figure.axes[0].patches if isinstance(p, Polygon)]
    assert len(polygons) >= 2  # the workspace outline and the survey field
