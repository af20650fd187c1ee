"""Damage to a log (truncation, dropped or reordered samples, NaN, stamps, missing topic), applied to arrays."""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass
from typing import Literal

import numpy as np
import numpy.typing as npt

from tubempc.strategies._common import FloatArray, st

FaultKind = Literal["none", "truncate", "drop", "reorder", "nan", "zero_quaternion", "missing_topic",
                    "duplicate_stamp", "zero_stamps", "negative_stamp", "stamp_1970"]
FAULT_KINDS: tuple[FaultKind, ...] = ("none", "truncate", "drop", "reorder", "nan", "zero_quaternion",
                                      "missing_topic", "duplicate_stamp", "zero_stamps", "negative_stamp",
                                      "stamp_1970")
#: the header-stamp faults (the samples' positions are kept, except the moved duplicate)
STAMP_FAULTS: tuple[FaultKind, ...] = ("duplicate_stamp", "zero_stamps", "negative_stamp", "stamp_1970")


@dataclass(frozen=True, slots=True)
class LogFault:
    """Damage to a log, described, not applied.

    - ``truncate``: cut the file (or the storage file of a bag directory) to ``fraction`` of its bytes;
    - ``drop``: remove the pose samples with indices in [start, start + count);
    - ``reorder``: swap the *log order* of pose samples ``start`` and ``start + count`` (stamps unchanged);
    - ``nan``: set the position of pose samples [start, start + count) to NaN;
    - ``zero_quaternion``: set the orientation of pose samples [start, start + count) to (0, 0, 0, 0);
    - ``missing_topic``: omit ``topic`` (a role: ``pose``, ``cmd_vel`` or ``nominal``) from the log;
    - ``duplicate_stamp``: pose sample ``start + 1`` gets the header stamp of sample ``start`` and is moved to
      ``xy`` (when given): two different positions at one instant;
    - ``zero_stamps``: every header stamp is 0 (a publisher that never sets ``header.stamp``);
    - ``negative_stamp``: sample ``start``'s header stamp is -5 s (ROS2 only: ROS1 stamps are unsigned);
    - ``stamp_1970``: sample ``start``'s header stamp is 1 s after the epoch (a clock that was never set);
    - ``none``: an undamaged log.
    Indices are taken modulo the number of samples by ``apply_sample_fault``.
    """

    kind: FaultKind
    start: int = 0
    count: int = 1
    fraction: float = 1.0
    topic: Literal["pose", "cmd_vel", "nominal"] = "pose"
    xy: tuple[float, float] | None = None

    def __post_init__(self) -> None:
        if self.kind not in FAULT_KINDS:
            raise ValueError(f"kind={self.kind!r} is not one of {FAULT_KINDS}")
        if self.start < 0 or self.count < 1:
            raise ValueError(f"start={self.start!r} must be >= 0 and count={self.count!r} >= 1")
        if not 0 < self.fraction <= 1:
            raise ValueError(f"fraction={self.fraction!r} must lie in (0, 1]")

    @property
    def damages_samples(self) -> bool:
        return self.kind in ("drop", "reorder", "nan", "zero_quaternion", *STAMP_FAULTS)


@st.composite
def log_faults(draw: st.DrawFn, kinds: Sequence[FaultKind] = FAULT_KINDS, max_index: int = 400,
               places: Sequence[tuple[float, float]] = ()) -> LogFault:
    """Log faults of the given kinds with positions below ``max_index``; a ``duplicate_stamp`` moves its sample to
    one of ``places`` (e.g. obstacle centres) when given."""
    kind = draw(st.sampled_from(list(kinds)))
    xy = draw(st.sampled_from(list(places))) if places and kind == "duplicate_stamp" else None
    return LogFault(kind=kind, start=draw(st.integers(0, max_index - 1)), count=draw(st.integers(1, 50)),
                    fraction=draw(st.sampled_from([0.1, 0.3, 0.5, 0.7, 0.9, 0.99])),
                    topic=draw(st.sampled_from(["pose", "cmd_vel", "nominal"])), xy=xy)


def apply_sample_fault(fault: LogFault, stamps_ns: npt.NDArray[np.int64], xyz_m: FloatArray, quat_xyzw: FloatArray,
                       ) -> tuple[npt.NDArray[np.int64], FloatArray, FloatArray]:
    """Apply a sample-level fault (drop, reorder, nan, zero_quaternion, the stamp faults) to pose arrays, in log
    order.

    Returns new arrays (the inputs are not modified); other kinds return copies unchanged. ``reorder`` swaps two
    rows, stamps included, so the log order is no longer the stamp order.
    """
    n = len(stamps_ns)
    if not (xyz_m.shape == (n, 3) and quat_xyzw.shape == (n, 4)):
        raise ValueError(f"shapes stamps {stamps_ns.shape}, xyz {xyz_m.shape}, quat {quat_xyzw.shape} disagree")
    s, x, qt = stamps_ns.copy(), xyz_m.copy(), quat_xyzw.copy()
    if n == 0:
        return s, x, qt
    start = fault.start % n
    stop = min(start + fault.count, n)
    if fault.kind == "drop":
        keep = np.ones(n, dtype=bool)
        keep[start:stop] = False
        if not keep.any():
            keep[0] = True
        return s[keep], x[keep], qt[keep]
    if fault.kind == "reorder":
        other = (start + fault.count) % n
        if other == start:
            other = (start + 1) % n
        for arr in (s, x, qt):
            arr[[start, other]] = arr[[other, start]]
    elif fault.kind == "nan":
        x[start:stop, :2] = np.nan
    elif fault.kind == "zero_quaternion":
        qt[start:stop] = 0.0
    elif fault.kind == "duplicate_stamp" and n >= 2:
        k = min(start, n - 2)
        s[k + 1] = s[k]
        if fault.xy is not None:
            x[k + 1, :2] = fault.xy
    elif fault.kind == "zero_stamps":
        s[:] = 0
    elif fault.kind == "negative_stamp":
        s[start] = -5 * 10**9
    elif fault.kind == "stamp_1970":
        s[start] = 10**9
    return s, x, qt
