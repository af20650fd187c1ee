"""The online monitor's input streams: samples pushed in time order -> the samples buffered until judged, and what
was done with the others.

input: the samples of one stream (pose, nominal state or command: absolute ns and values), in time order -> output:
the buffered samples (one list per column: cheap appends, one numpy conversion per judging), and the counts of
samples judged, merged with the sample at the same time, conflicting with it, and out of time order (never judged),
as ``verify.ingest.timebase.judged_samples`` counts them offline.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np
import numpy.typing as npt

from verify.ingest.timebase import AGREE_TOL

__all__ = ["StreamInput"]

FloatArray = npt.NDArray[np.float64]
IntArray = npt.NDArray[np.int64]


@dataclass(slots=True, eq=False)
class StreamInput:
    """One input stream: its buffered samples (``t`` and the ``cols``), the time and values of the first sample at
    its last time, and its counts."""

    name: str
    cols: tuple[list[float], ...]
    t: list[int] = field(default_factory=list)
    last_ns: int = -(2**63)
    last_values: tuple[float, ...] = ()
    judged: int = 0  # samples taken out of the buffer to be judged
    duplicates: int = 0  # samples at the last time again
    merged: int = 0  # ... whose values agree with the first one there
    conflicting: int = 0  # ... whose values do not
    out_of_order: int = 0  # samples before the last time (never judged)

    @classmethod
    def of(cls, name: str, width: int) -> StreamInput:
        return cls(name, tuple([] for _ in range(width)))

    @property
    def count(self) -> int:
        """Samples accepted (judged or buffered)."""
        return self.judged + len(self.t)

    def repeat(self, t_ns: int, values: tuple[float, ...]) -> bool:
        """A sample at or before the last time. Before: counted out of order, never judged. At the same time:
        merged when its values agree with the first sample there, else a conflict (True: the caller decides what
        a conflict means for its stream)."""
        if t_ns != self.last_ns:
            self.out_of_order += 1
            return False
        self.duplicates += 1
        if all(abs(a - b) <= AGREE_TOL or (math.isnan(a) and math.isnan(b))
               for a, b in zip(self.last_values, values, strict=True)):
            self.merged += 1
            return False
        self.conflicting += 1
        return True

    def take(self, k: int | None = None) -> tuple[IntArray, list[FloatArray]]:
        """The first ``k`` buffered samples (all: None) as arrays, out of the buffer and counted judged."""
        k = len(self.t) if k is None else k
        t = np.array(self.t[:k], dtype=np.int64)
        cols = [np.array(c[:k], dtype=np.float64) for c in self.cols]
        if k == len(self.t):
            self.t.clear()
            for c in self.cols:
                c.clear()
        else:
            del self.t[:k]
            for c in self.cols:
                del c[:k]
        self.judged += k
        return t, cols
