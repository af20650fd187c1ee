"""Shared fixtures of the regression tests: a planted controller bug."""

from __future__ import annotations

import dataclasses
from collections.abc import Callable
from typing import Any

import pytest

from tubempc.control import closed_loop


@pytest.fixture
def quarter_gain(monkeypatch: pytest.MonkeyPatch) -> Callable[[], None]:
    """Calling it plants the bug: the closed loop runs with a quarter of the designed ancillary gain (in this
    process only, so runs must use workers=1)."""

    def plant() -> None:
        design = closed_loop.design_tube

        def weak_design(*args: Any, **kwargs: Any) -> Any:
            tube = design(*args, **kwargs)
            return dataclasses.replace(tube, sigma=tube.sigma / 4)

        monkeypatch.setattr(closed_loop, "design_tube", weak_design)

    return plant
