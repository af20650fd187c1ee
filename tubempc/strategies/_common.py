"""What every strategy module shares: hypothesis (from the ``testing`` extra: one error naming it) and value types."""

from __future__ import annotations

import math

import numpy as np
import numpy.typing as npt

try:
    from hypothesis import strategies as st
except ImportError:  # hypothesis comes with the 'testing' extra: one error naming it (exit 4)
    from runkit.errors import MissingExtraError
    from runkit.extras import require

    try:
        require("testing", feature="tubempc.strategies")
    except MissingExtraError as missing:
        raise missing from None
    raise

__all__ = ["FloatArray", "Matrix", "Vector", "centi", "st"]

FloatArray = npt.NDArray[np.float64]
Matrix = tuple[tuple[float, ...], ...]
Vector = tuple[float, ...]


def centi(lo: float, hi: float) -> st.SearchStrategy[float]:
    """Floats on a 1 cm grid in [lo, hi]: short reprs that paste well into ``@example``."""
    return st.integers(math.ceil(lo * 100 - 1e-9), math.floor(hi * 100 + 1e-9)).map(lambda k: k / 100)
