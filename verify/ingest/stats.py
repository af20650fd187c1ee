"""``median``: numpy's median without the import it makes on first use.

``np.median`` of floating values checks for NaN through ``numpy.ma``, which it imports on first use: about 12 ms
of CPU in every fresh process (a batch worker, a CLI run), more than the rest of a small log's reading. This one
takes the same middle element(s) with ``np.partition`` and averages them with ``np.mean`` as numpy does: the same
value, NaN when any value is NaN.
"""

from __future__ import annotations

from typing import Any

import numpy as np
import numpy.typing as npt

__all__ = ["median"]


def median(values: npt.ArrayLike, axis: int | None = None) -> Any:
    """``np.median(values, axis=axis)`` for ``axis`` None (a scalar) or an axis of a 2-D array (an array)."""
    a = np.asarray(values)
    flat = a.ravel() if axis is None else a
    ax = 0 if axis is None else axis
    n = flat.shape[ax]
    if n == 0:
        return np.median(a, axis=axis)  # numpy's own warning and NaN
    k = n // 2
    kth = [k - 1, k] if n % 2 == 0 else [k]
    mid = np.take(np.partition(flat, kth, axis=ax), kth, axis=ax)
    out = np.mean(mid, axis=ax)
    if flat.dtype.kind in "fc":
        nan = np.isnan(flat).any(axis=ax)
        if axis is None:
            return np.float64(np.nan) if nan else out
        return np.where(nan, np.nan, out)
    return out
