"""Long series -> the rows a figure draws: every bucket's extremes, its gaps and the rows at chosen times.

input: a frame in time order (``t_s`` and value columns) -> output: a subset of its rows, in order. Drawing a
million samples into 800 pixel columns shows nothing more than the minimum and the maximum of each column's
samples: the envelope keeps, per bucket of consecutive rows, the rows of every value column's minimum and maximum,
the first non-finite row (a gap stays a gap), and the rows nearest each time in ``keep_t_s`` (the violations a
figure marks), so no excursion, gap or violation drops out of a figure. The figure modules (``verify.figures``,
``verify.workspace_map``) decimate through this one rule.
"""

from __future__ import annotations

import math
from collections.abc import Sequence

import numpy as np
import pandas as pd

__all__ = ["ENVELOPE_BUCKETS", "envelope"]

#: time series keep the extremes of each of this many buckets (about one per pixel column of a figure)
ENVELOPE_BUCKETS = 1_000


def envelope(frame: pd.DataFrame, columns: Sequence[str], *, buckets: int = ENVELOPE_BUCKETS,
             keep_t_s: Sequence[float] = ()) -> pd.DataFrame:
    """The rows of ``frame`` a figure needs (see the module docstring); ``frame`` itself when it has at most
    ``4 * buckets`` rows."""
    n = len(frame)
    if n <= 4 * buckets:
        return frame
    k = math.ceil(n / buckets)
    pad = (-n) % k
    keep = [np.array([0, n - 1])]
    for col in columns:
        v = frame[col].to_numpy(dtype=float)
        blocks = np.concatenate([v, np.full(pad, v[-1])]).reshape(-1, k)
        offsets = np.arange(blocks.shape[0]) * k
        bad = ~np.isfinite(blocks)
        keep.append(np.where(bad, np.inf, blocks).argmin(axis=1) + offsets)
        keep.append(np.where(bad, -np.inf, blocks).argmax(axis=1) + offsets)
        has_gap = bad.any(axis=1)
        keep.append((bad.argmax(axis=1) + offsets)[has_gap])
    if len(keep_t_s) and "t_s" in frame.columns:
        t = frame["t_s"].to_numpy(dtype=float)
        at = np.searchsorted(t, np.asarray([x for x in keep_t_s if math.isfinite(x)], dtype=float))
        keep.append(np.concatenate([at - 1, at]))
    return frame.iloc[np.unique(np.clip(np.concatenate(keep), 0, n - 1))]
