"""The test session never reads or writes the user's abstraction cache (conftest.py points it at a temporary folder)."""

from __future__ import annotations

import os
import tempfile
from pathlib import Path

import pytest

from tubempc.planning.wts import cache_dir


def test_abstraction_cache_is_a_fresh_temporary_folder() -> None:
    if os.environ.get("TUBEMPC_TEST_CACHE"):
        pytest.skip("a cache folder was chosen on purpose (TUBEMPC_TEST_CACHE)")
    cache = cache_dir().resolve()
    assert cache.is_relative_to(Path(tempfile.gettempdir()).resolve())
    assert not cache.is_relative_to((Path.home() / ".cache").resolve())
