"""Retention for streaming evaluation: growing arrays addressed by global index, and the positions of one semantics.

input: values appended in time order, and the first index any consumer still needs -> output: views of the
retained slices (``Buffer``), and a ``Track``: the position spans (sample points and gaps, or timed-run entries), the
observation ticks and the end of observation, from which the stream nodes (``verify.online.stream``) and heads
(``verify.online.heads``) read.
"""

from __future__ import annotations

import numpy as np
import numpy.typing as npt

from verify.monitor.engine import Positions

__all__ = ["AT_START", "NEVER_NS", "Buffer", "Track", "floats", "ints"]

FloatArray = npt.NDArray[np.float64]
IntArray = npt.NDArray[np.int64]
#: "never known" for the known-time arrays
NEVER_NS = np.iinfo(np.int64).max
#: a witness at the position's own start
AT_START = np.iinfo(np.int64).min
#: elements a buffer has room for at first: a quiet batch of pose samples and its gaps (2 x 256 positions) and what
#: is retained fit without a new array (8 KiB of address space per buffer)
_FIRST_CAPACITY = 1024


class Buffer:
    """A growing 1-D array addressed by global index; the positions before ``base`` are dropped (amortised O(1))."""

    __slots__ = ("_a", "_off", "base", "stop")

    def __init__(self, dtype: type) -> None:
        self._a: npt.NDArray[np.generic] = np.empty(_FIRST_CAPACITY, dtype=dtype)
        self._off = 0
        self.base = 0  # global index of the first retained element
        self.stop = 0  # global index past the last element

    def _room(self, k: int) -> int:
        """Room for ``k`` more elements (moving the retained ones to the front, or to a larger array when they would
        fill more than half of it, when the end is reached); returns where they go. A new array is four times what
        it holds then, so that neither moves nor new arrays come at every append of a similar size."""
        n = self.stop - self.base
        if self._off + n + k > self._a.shape[0]:
            grow = 2 * (n + k) > self._a.shape[0]
            new = np.empty(max(_FIRST_CAPACITY, 4 * (n + k)), dtype=self._a.dtype) if grow else self._a
            new[:n] = self._a[self._off : self._off + n]
            self._a, self._off = new, 0
        return self._off + n

    def extend(self, values: npt.NDArray[np.generic]) -> None:
        k = values.shape[0]
        at = self._off + self.stop - self.base
        if at + k > self._a.shape[0]:
            at = self._room(k)
        self._a[at : at + k] = values
        self.stop += k

    def fill(self, value: float | int, k: int) -> None:
        """``k`` copies of ``value``."""
        at = self._off + self.stop - self.base
        if at + k > self._a.shape[0]:
            at = self._room(k)
        self._a[at : at + k] = value
        self.stop += k

    def view(self, g0: int, g1: int) -> npt.NDArray[np.generic]:
        if g0 < self.base or g1 > self.stop:
            raise IndexError(f"range [{g0}, {g1}) outside the retained [{self.base}, {self.stop})")
        return self._a[self._off + g0 - self.base : self._off + g1 - self.base]

    def at(self, g: int) -> float | int:
        return self._a[self._off + g - self.base].item()  # type: ignore[no-any-return]

    def drop_before(self, g: int) -> None:
        g = min(max(g, self.base), self.stop)
        self._off += g - self.base
        self.base = g


def floats(buf: Buffer, g0: int, g1: int) -> FloatArray:
    """The retained float values ``[g0, g1)`` of ``buf``."""
    return buf.view(g0, g1)  # type: ignore[return-value]


def ints(buf: Buffer, g0: int, g1: int) -> IntArray:
    """The retained integer values ``[g0, g1)`` of ``buf``."""
    return buf.view(g0, g1)  # type: ignore[return-value]


class Track:
    """The positions of one semantics (sample points and gaps, or timed-run entries), in time order (ns).

    ``ticks``: the observation times (every sample), to say when a window was complete; ``end_ns``: the end of
    observation (the last tick)."""

    def __init__(self) -> None:
        self.start = Buffer(np.int64)
        self.stop_ns = Buffer(np.int64)
        self.is_point = Buffer(np.bool_)
        self.ticks = Buffer(np.int64)
        self.end_ns: int | None = None
        self.first_ns: int | None = None  # start of the first position (where the formula is evaluated)

    @property
    def count(self) -> int:
        return self.start.stop

    def append(self, start_ns: IntArray, stop_ns: IntArray, is_point: npt.NDArray[np.bool_]) -> None:
        if self.first_ns is None and start_ns.shape[0]:
            self.first_ns = int(start_ns[0])
        self.start.extend(start_ns)
        self.stop_ns.extend(stop_ns)
        self.is_point.extend(is_point)

    def tick(self, times_ns: IntArray) -> None:
        if times_ns.shape[0]:
            self.ticks.extend(times_ns)
            self.end_ns = int(times_ns[-1])

    def positions(self, g0: int, g1: int, end_ns: int) -> Positions:
        return Positions(ints(self.start, g0, g1), ints(self.stop_ns, g0, g1),
                         self.is_point.view(g0, g1), end_ns)  # type: ignore[arg-type]

    def first_tick_at_or_after(self, times_ns: IntArray, closing: bool) -> IntArray:
        ticks = ints(self.ticks, self.ticks.base, self.ticks.stop)
        k = np.searchsorted(ticks, times_ns, side="left")
        out = np.where(k < ticks.shape[0], ticks[np.minimum(k, max(ticks.shape[0] - 1, 0))] if ticks.size else 0,
                       self.end_ns if closing and self.end_ns is not None else NEVER_NS)
        return out.astype(np.int64)

    def drop_before(self, g: int) -> None:
        """Drop positions before ``g`` and the ticks before them (the last tick is always kept)."""
        g = min(max(g, self.start.base), self.count)
        ticks = ints(self.ticks, self.ticks.base, self.ticks.stop)
        cut = int(np.searchsorted(ticks, int(self.start.at(g)))) - 1 if g < self.count else ticks.shape[0] - 1
        self.start.drop_before(g)
        self.stop_ns.drop_before(g)
        self.is_point.drop_before(g)
        self.ticks.drop_before(self.ticks.base + max(cut, 0))
