"""Figures drawn by forked workers are the figures drawn in-process, byte for byte; workers are used only where a
fork is safe; garbage collection is back on afterwards."""

from __future__ import annotations

import gc
import threading
from collections.abc import Callable
from typing import Any

import pytest

from tubempc.scenario import builtin_scenario
from verify.certificate import Certificate
from verify.figures import figure_workers, render_figures


def _render(result: Any, workers: int) -> list[tuple[str, str, bytes]]:
    specs = render_figures(Certificate.model_validate(result.certificate), builtin_scenario(),
                           trajectory=result.trajectory, nominal=result.nominal, inputs=result.inputs,
                           robustness=None, workers=workers)
    return [(s.stem, s.caption, s.png) for s in specs]


@pytest.mark.slow
def test_forked_figures_are_the_in_process_figures(make_result: Callable[..., Any]) -> None:
    result = make_result(verdict="fail")
    here = _render(result, 1)
    assert [stem for stem, _, _ in here] == ["workspace", "obligations", "clearance", "states", "tube", "inputs",
                                             "sampling"]
    assert _render(result, 2) == here
    assert gc.isenabled()


def test_no_fork_beside_other_threads() -> None:
    """A process with another thread running (a progress bar, a server) draws its figures itself: a fork would copy
    locks that thread may hold."""
    stop = threading.Event()
    thread = threading.Thread(target=stop.wait)
    thread.start()
    try:
        assert figure_workers() == 1
    finally:
        stop.set()
        thread.join()
