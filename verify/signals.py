"""Signal atoms: a field's samples (sample-and-hold) -> robustness bounds at the monitor's positions.

input: a ``SignalStream`` (sorted times in ns, values, the expected period) and the atom's predicate
``value op threshold`` -> output: the atom's margin in the field's unit (``value - threshold`` for ``>``/``>=``,
``threshold - value`` for ``<``/``<=``; positive = holds, exactly 0 = undecided, as for regions) at the pose samples
and over the open gaps between them, and at the entries of a timed run.

Sample-and-hold with gaps: at time t the atom has the value of the last message at or before t, for at most
``DROPOUT_FACTOR`` (1.5) expected periods after that message; before the first message, and in any stretch longer
than that without a message, the atom is unknown (``[-inf, inf]``), exactly as a gap in the pose stream. Over a gap
between two pose samples the bounds are the least and largest margin held anywhere in it (unknown if any part of it
is unknown), so a signal that dips between two pose samples is never missed.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

import numpy as np
import numpy.typing as npt

from verify.ingest.fields import SignalStream, signal_margin

__all__ = ["SignalBounds", "signal_bounds", "signal_margin", "signal_summary", "values_at"]

FloatArray = npt.NDArray[np.float64]
IntArray = npt.NDArray[np.int64]


@dataclass(frozen=True, slots=True)
class SignalBounds:
    point_lo: FloatArray
    point_hi: FloatArray
    gap_lo: FloatArray
    gap_hi: FloatArray


def values_at(stream: SignalStream, t_ns: IntArray) -> tuple[FloatArray, FloatArray]:
    """Margin bounds at instants ``t_ns`` (absolute ns): the held value's margin, or ``[-inf, inf]`` if unknown."""
    if stream.t_ns.size == 0:  # no message: unknown everywhere
        return np.full(t_ns.shape[0], -np.inf), np.full(t_ns.shape[0], np.inf)
    m = signal_margin(stream.spec, stream.value)
    j = np.searchsorted(stream.t_ns, t_ns, side="right") - 1
    known = (j >= 0) & (t_ns - stream.t_ns[np.maximum(j, 0)] <= stream.hold_ns)
    held = m[np.maximum(j, 0)] if m.size else np.zeros(t_ns.shape[0])
    lo = np.where(known, held, -np.inf)
    hi = np.where(known, held, np.inf)
    nan = np.isnan(held)
    lo[nan] = -np.inf
    hi[nan] = np.inf
    return lo, hi


def signal_bounds(stream: SignalStream, t_ns: IntArray) -> SignalBounds:
    """Bounds at the pose samples ``t_ns`` (absolute ns, strictly increasing) and over each open gap between two."""
    point_lo, point_hi = values_at(stream, t_ns)
    n = t_ns.shape[0]
    if n < 2 or stream.t_ns.size == 0:
        empty = np.full(max(n - 1, 0), -np.inf)
        return SignalBounds(point_lo, point_hi, empty, -empty)
    st, m = stream.t_ns, signal_margin(stream.spec, stream.value)
    a = np.searchsorted(st, t_ns[:-1], side="right") - 1  # the message held at the gap's start
    b = np.searchsorted(st, t_ns[1:] - 1, side="right") - 1  # the last message before the gap's end
    # a stretch after message j (to the next message) longer than the hold time has an unknown part
    nxt = np.append(st[1:], np.iinfo(np.int64).max)
    expired = (nxt - st) > stream.hold_ns
    cs = np.concatenate(([0], np.cumsum(expired)))
    ac = np.maximum(a, 0)
    inner_expired = (cs[np.maximum(b, 0)] - cs[ac]) > 0  # some j in [a, b) leaves a hole inside the gap
    tail_expired = (t_ns[1:] - st[np.maximum(b, 0)]) > stream.hold_ns  # after message b, before the gap's end
    unknown = (a < 0) | inner_expired | tail_expired
    ext = np.append(m, 0.0)
    idx = np.empty(2 * (n - 1), dtype=np.int64)
    idx[0::2] = ac
    idx[1::2] = np.maximum(b, 0) + 1
    lo = np.minimum.reduceat(ext, idx)[0::2]
    hi = np.maximum.reduceat(ext, idx)[0::2]
    nan = np.isnan(lo) | np.isnan(hi)
    gap_lo = np.where(unknown | nan, -np.inf, lo)
    gap_hi = np.where(unknown | nan, np.inf, hi)
    return SignalBounds(point_lo, point_hi, gap_lo, gap_hi)


def signal_summary(stream: SignalStream, t0_ns: int, end_ns: int) -> dict[str, Any]:
    """The certificate's entry for one atom: its data, its worst and best margin over the messages (field unit),
    that margin relative to the threshold (unit-free; None when the threshold is 0) and where the atom is unknown."""
    spec = stream.spec
    m = signal_margin(spec, stream.value)
    finite = m[np.isfinite(m)]
    worst = float(finite.min()) if finite.size else None
    st = stream.t_ns
    holes: list[dict[str, float]] = []
    if st.size == 0 or st[0] > t0_ns:
        holes.append({"from_s": 0.0, "to_s": round(((st[0] if st.size else end_ns) - t0_ns) * 1e-9, 9)})
    if st.size:
        ends = np.append(st[1:], max(end_ns, int(st[-1])))
        gap = np.flatnonzero(ends - st > stream.hold_ns)
        holes += [{"from_s": round((int(st[g]) + stream.hold_ns - t0_ns) * 1e-9, 9),
                   "to_s": round((int(ends[g]) - t0_ns) * 1e-9, 9)} for g in gap[:10]
                  if int(st[g]) + stream.hold_ns < int(ends[g])]
    return {"topic": spec.topic, "field": spec.field, "predicate": f"{spec.field} {spec.op} {spec.value}",
            "unit": spec.unit, "messages": int(st.size), "time_base": stream.time_base,
            "expected_period_s": round(stream.period_ns * 1e-9, 9),
            "hold_s": round(stream.hold_ns * 1e-9, 9),
            "min_value": float(np.nanmin(stream.value)) if stream.value.size and not np.isnan(stream.value).all()
            else None,
            "max_value": float(np.nanmax(stream.value)) if stream.value.size and not np.isnan(stream.value).all()
            else None,
            "worst_margin": worst,
            "relative_worst_margin": (worst / abs(spec.value)) if worst is not None and spec.value != 0 else None,
            "unknown_stretches": holes}
