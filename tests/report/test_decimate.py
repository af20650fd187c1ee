"""Decimation for figures keeps every extreme, gap and marked violation of a long log."""

from __future__ import annotations

import numpy as np
import pandas as pd

from verify.decimate import envelope
from verify.workspace_map import MAX_PATH_POINTS, _decimate


def _path(n: int) -> pd.DataFrame:
    t = np.arange(n) / 100.0
    return pd.DataFrame({"t_s": t, "x_m": np.cos(t / 50.0), "y_m": np.sin(t / 50.0)})


def test_envelope_keeps_spikes_gaps_and_marked_times() -> None:
    frame = _path(1_000_000)
    frame.loc[123_457, "x_m"] = 9.0  # a one-sample excursion
    frame.loc[500_001, "y_m"] = np.nan  # a one-sample gap
    kept = envelope(frame, ("x_m", "y_m"), keep_t_s=[7777.773])
    assert len(kept) <= 4 * 1_000 + 1_000 + 4
    assert kept["x_m"].max() == 9.0 and kept["y_m"].isna().any()
    assert {777_777, 777_778} <= set(kept.index)  # the rows around the marked time
    assert kept["x_m"].min() == frame["x_m"].min() and kept["y_m"].max() == frame["y_m"].max()
    small = _path(3_000)
    assert envelope(small, ("x_m",)) is small


def test_map_path_keeps_an_excursion_and_the_violation_sample() -> None:
    """The map's path of a long log keeps a one-sample excursion and the sample at a violation (a stride of 200
    rows dropped both before)."""
    frame = _path(1_000_000)
    frame.loc[400_123, "y_m"] = -5.0
    kept = _decimate(frame, [6000.011])
    assert len(kept) <= MAX_PATH_POINTS + 4
    assert kept["y_m"].min() == -5.0 and 600_002 in kept.index
