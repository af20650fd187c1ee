"""Titles kept at their plain place where matplotlib's automatic placement would leave them there: the same pixels
as the automatic placement, on the report's figures and on axes whose title automatic placement does move."""

from __future__ import annotations

import io
from collections.abc import Callable
from typing import Any

import numpy as np
import pytest
from matplotlib.figure import Figure
from PIL import Image

import verify.workspace_map as wm
from tubempc.scenario import builtin_scenario
from verify.certificate import Certificate
from verify.figures import figure_builders


def _pixels(png: bytes) -> bytes:
    return Image.open(io.BytesIO(png)).convert("RGBA").tobytes()


def _both_ways(monkeypatch: pytest.MonkeyPatch, draw: Callable[[], bytes | None]) -> tuple[bytes, bytes]:
    fixed = draw()
    with monkeypatch.context() as m:
        m.setattr(wm, "_fix_title_positions", lambda fig: None)
        auto = draw()
    assert fixed is not None and auto is not None
    return _pixels(fixed), _pixels(auto)


@pytest.mark.slow
def test_report_figures_are_drawn_as_with_automatic_title_placement(make_result: Callable[..., Any],
                                                                     monkeypatch: pytest.MonkeyPatch) -> None:
    result = make_result(verdict="fail")
    builders = figure_builders(Certificate.model_validate(result.certificate), builtin_scenario(),
                               trajectory=result.trajectory, nominal=result.nominal, inputs=result.inputs)
    for build in builders:
        def draw(build: Callable[[], Any] = build) -> bytes | None:
            spec = build()
            return None if spec is None else spec.png

        fixed, auto = _both_ways(monkeypatch, draw)
        assert fixed == auto


def _titled(values: np.ndarray, *, top_ticks: bool = False, shared: bool = False) -> Figure:
    fig = Figure(figsize=(4.0, 4.0 if shared else 2.5))
    axes = fig.subplots(2 if shared else 1, 1, sharex=shared, squeeze=False)[:, 0]
    for ax in axes:
        ax.plot(np.arange(values.size), values)
        ax.set_title("a title at the left", loc="left")
        if top_ticks:
            ax.xaxis.tick_top()
    return fig


@pytest.mark.parametrize(("values", "top_ticks", "moved"), [
    (np.linspace(0.0, 3.0, 50), False, False),  # plain ticks: nothing can move the title
    (1e-6 * np.linspace(0.0, 3.0, 50), False, True),  # an offset text "1e-6" at the top left
    (1e4 + 1e-3 * np.linspace(0.0, 3.0, 50), False, True),  # an additive offset "+1e4"
    (np.linspace(0.0, 3.0, 50), True, True),  # tick labels on top
])
def test_titles_that_automatic_placement_moves_are_left_to_it(values: np.ndarray, top_ticks: bool, moved: bool,
                                                              monkeypatch: pytest.MonkeyPatch) -> None:
    fig = _titled(values, top_ticks=top_ticks)
    assert wm._title_needs_placing(fig.axes[0]) is moved
    fixed, auto = _both_ways(monkeypatch, lambda: wm.png_bytes(_titled(values, top_ticks=top_ticks)))
    assert fixed == auto


def test_shared_axes_with_hidden_tick_labels_keep_a_fixed_title(monkeypatch: pytest.MonkeyPatch) -> None:
    fig = _titled(np.linspace(0.0, 3.0, 50), shared=True)
    assert not any(wm._title_needs_placing(ax) for ax in fig.axes)
    fixed, auto = _both_ways(monkeypatch, lambda: wm.png_bytes(_titled(np.linspace(0.0, 3.0, 50), shared=True)))
    assert fixed == auto
