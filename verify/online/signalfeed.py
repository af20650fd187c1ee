"""Signal atoms online: one signal's messages, pushed as they arrive -> its bounds at a batch of pose positions.

input: a scenario signal (``SignalSpec``) and its messages (absolute ns on the pose's time base, the field's value),
pushed in any order -> output: for a batch of pose samples the ``verify.signals.SignalBounds`` (samples and the gaps
between them) and the values at timed-run entries that ``verify.signals`` gives offline on the whole stream.

The offline rules, kept online: one value per instant (a second message at an instant with another value makes the
atom unknown there), sample-and-hold for ``hold_ns`` = 1.5 expected periods, unknown before the first message and in
longer silences. Messages are kept sorted from the one held at the last judged pose time on, so a message that
arrives out of order is placed where offline sorting puts it -- unless its time was judged already (``late``: the
formula can no longer pass).

The expected period is ``rate_hz`` when the scenario gives it (then online equals offline exactly). Without it the
offline period is the median spacing of the whole stream, unknown until the end: the feed judges with the median
spacing seen so far (re-estimated each time the message count doubles) and records, per hold used, the distances
it compared with it; ``hold_mismatch`` at the end says whether the final median would have classified one of them
(held or expired) differently -- then the formula cannot pass. Without ``rate_hz`` the feed keeps every message time
(8 bytes each) to compute that median.
"""

from __future__ import annotations

import math
from bisect import bisect_left, bisect_right

import numpy as np
import numpy.typing as npt

from tubempc.scenario import SignalSpec
from verify.ingest.fields import SignalStream, median_period_ns, signal_margin, signal_period_ns
from verify.ingest.quality import DROPOUT_FACTOR
from verify.online.track import Buffer
from verify.signals import SignalBounds, signal_bounds, values_at

__all__ = ["SignalFeed"]

FloatArray = npt.NDArray[np.float64]
IntArray = npt.NDArray[np.int64]
_NEVER = -(2**63)


class SignalFeed:
    """One signal atom's messages between the last judged pose time and the newest message."""

    def __init__(self, name: str, spec: SignalSpec, *, pose_topic: str | None = None) -> None:
        self.name = name
        self.spec = spec
        self.follows_pose = pose_topic is not None and spec.topic == pose_topic  # shares the pose's samples
        self.t: list[int] = []  # retained messages: sorted, one per instant
        self.v: list[float] = []
        self.horizon = _NEVER  # the last pose time judged with this signal: messages at or before it are late
        self.messages = 0  # distinct instants accepted
        self.merged = 0  # a second message at an instant with the same value
        self.conflicting = 0  # ... with another value (the atom is unknown there)
        self.late = 0  # messages for an instant already judged (not used; the formula cannot pass)
        # the first and last message violating the predicate (verify.ingest.fields.outside_span at the end)
        self.first_violation_ns = 2**63 - 1
        self.last_violation_ns = _NEVER
        self.fixed_period_ns = signal_period_ns(name, spec, np.zeros(0, dtype=np.int64)) if (
            spec.rate_hz is not None or self.follows_pose) else None
        self._history = Buffer(np.int64)  # without rate_hz: the times of the messages dropped from ``t``
        self._period_ns = 0
        self._estimated_at = 0  # message count of the last estimate
        self._compared: dict[int, tuple[int, int]] = {}  # hold used -> (largest distance <= it, smallest > it)

    # ---- input ------------------------------------------------------------------------------------------------------
    def push(self, t_ns: int, value: float) -> None:
        if float(signal_margin(self.spec, np.asarray([value], dtype=np.float64))[0]) < 0:
            self.first_violation_ns = min(self.first_violation_ns, t_ns)
            self.last_violation_ns = max(self.last_violation_ns, t_ns)
        if t_ns <= self.horizon:
            self.late += 1
            return
        i = bisect_left(self.t, t_ns)
        if i < len(self.t) and self.t[i] == t_ns:  # verify.ingest.timebase.judged_samples with agree_tol=0
            if self.v[i] == value:
                self.merged += 1
            else:
                self.conflicting += 1
                self.v[i] = math.nan
            return
        self.t.insert(i, t_ns)
        self.v.insert(i, value)
        self.messages += 1

    @property
    def newest_ns(self) -> int:
        """The newest message time (pose times before it are known for this signal); very negative: none yet."""
        return self.t[-1] if self.t else _NEVER

    # ---- the hold ---------------------------------------------------------------------------------------------------
    def _all_times(self) -> IntArray:
        kept = np.asarray(self.t, dtype=np.int64)
        return np.concatenate((self._history.view(self._history.base, self._history.stop), kept))

    def period_ns(self, *, final: bool = False) -> int:
        """``rate_hz``'s period, else the median spacing so far (re-estimated when the count doubles, or ``final``)."""
        if self.fixed_period_ns is not None:
            return self.fixed_period_ns
        if final or self.messages >= 2 * max(self._estimated_at, 1):
            self._period_ns = median_period_ns(self._all_times())
            self._estimated_at = self.messages
        return self._period_ns

    def stream(self) -> SignalStream:
        """Every message kept, with the final hold (a feed never judged keeps them all: ``verify.online.fleet``)."""
        return self._stream(self.period_ns(final=True))

    def _stream(self, period_ns: int) -> SignalStream:
        return SignalStream(self.name, self.spec, np.asarray(self.t, dtype=np.int64),
                            np.asarray(self.v, dtype=np.float64), period_ns, "online", follows_pose=self.follows_pose)

    # ---- judging ----------------------------------------------------------------------------------------------------
    def bounds(self, t_ns: IntArray, entries_ns: IntArray) -> tuple[SignalBounds, tuple[FloatArray, FloatArray]]:
        """Bounds at the pose samples ``t_ns`` (the previously judged one first, if any) and the gaps between them,
        and at the timed-run entries ``entries_ns``; afterwards the messages before the one held at the last sample
        are dropped and later messages for those times are late."""
        if not self.t:  # no message yet: unknown everywhere (offline, a signal without messages is unusable input)
            self._judged(int(t_ns[-1]))
            n, e = t_ns.shape[0], entries_ns.shape[0]
            gap = np.full(max(n - 1, 0), -np.inf)
            return (SignalBounds(np.full(n, -np.inf), np.full(n, np.inf), gap, -gap),
                    (np.full(e, -np.inf), np.full(e, np.inf)))
        period = self.period_ns()
        stream = self._stream(period)
        out = signal_bounds(stream, t_ns), values_at(stream, entries_ns)
        if self.fixed_period_ns is None and stream.t_ns.size:
            self._record(stream, t_ns, entries_ns)
        self._judged(int(t_ns[-1]))
        return out

    def _record(self, stream: SignalStream, t_ns: IntArray, entries_ns: IntArray) -> None:
        """The distances compared with the hold in this batch (a superset): spacings of the messages up to the last
        sample, and from the message held at each sample, at each gap's end and at each entry."""
        st = stream.t_ns
        upto = int(np.searchsorted(st, t_ns[-1], side="right"))
        at = np.concatenate((t_ns, entries_ns))
        j = np.searchsorted(st, at, side="right") - 1
        ends = t_ns[1:]
        b = np.searchsorted(st, ends - 1, side="right") - 1
        d = np.concatenate((np.diff(st[: upto + 1]), at[j >= 0] - st[j[j >= 0]], ends[b >= 0] - st[b[b >= 0]]))
        if d.size == 0:
            return
        hold = stream.hold_ns
        below, above = d[d <= hold], d[d > hold]
        lo, hi = self._compared.get(hold, (_NEVER, 2**63 - 1))
        self._compared[hold] = (max(lo, int(below.max())) if below.size else lo,
                                min(hi, int(above.min())) if above.size else hi)

    def _judged(self, until_ns: int) -> None:
        self.horizon = max(self.horizon, until_ns)
        keep = bisect_right(self.t, until_ns) - 1  # the message held at that time stays
        if keep > 0:
            if self.fixed_period_ns is None:
                self._history.extend(np.asarray(self.t[:keep], dtype=np.int64))
            del self.t[:keep], self.v[:keep]

    def violates_outside(self, first_ns: int, last_ns: int) -> bool:
        """Whether a message violating the predicate lies outside the pose's span ``[first_ns, last_ns]``."""
        return self.first_violation_ns < first_ns or self.last_violation_ns > last_ns

    def hold_mismatch(self) -> bool:
        """Without ``rate_hz``: whether the whole stream's median spacing (offline's hold) would have judged one of
        the compared distances differently from the hold used (then online may differ from offline)."""
        if self.fixed_period_ns is not None or not self._compared:
            return False
        final = self.final_hold_ns()
        return any(below > final or above <= final for below, above in self._compared.values())

    def final_hold_ns(self) -> int:
        return int(DROPOUT_FACTOR * self.period_ns(final=True))
