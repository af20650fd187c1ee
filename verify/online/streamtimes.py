"""One stream's times in watch, under certify's time rule: a stream's header stamps and log times, poll by poll ->
the times its samples are pushed at, and at the end whether certify, applying the rule once to the whole stream,
gives every sample the same time.

input: per poll, a stream's header stamps (None: its messages have no header) and log times, in the order the
follower read them (file order), and a rule (``verify.ingest.rules.ReadingRules.pose_times`` or ``stream_times``
with the pose's base) -> output: the times of the poll's samples, and at the end (``StreamTimes.final``) the
certify-side ``TimeBase`` of the whole stream and the number of samples whose pushed time differs from it.

certify applies the rule (stamp outliers re-timed, the header judged able or not to order the samples) to the whole
stream in its reading order: by log time (stable, the file order breaking ties) for a ROS1 or MCAP log its recorder
closed (its indexed reader's order), else the order the follower delivers (the file order; a sqlite3 storage's
timestamp index walk) (``verify.online.watch`` says which). The rule looks at each
stamp's neighbours in that order, so a poll read alone may get other times: each poll is timed with the samples read
before it as context (the last ``CONTEXT``), and ``final`` re-applies the rule to every sample in certify's order. A
log read once (``watch`` without ``--follow``) is pushed in one poll, in certify's order: the same times by
construction.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass, field

import numpy as np
import numpy.typing as npt

from verify.ingest.timebase import TimeBase

__all__ = ["CONTEXT", "StreamTimes", "TimeRule", "reading_order"]

IntArray = npt.NDArray[np.int64]
#: the rule of one stream: (header stamps or None, log times) -> its time base and the samples' times
TimeRule = Callable[[IntArray | None, IntArray], tuple[TimeBase, IntArray]]
#: samples read before a poll that the rule sees with it (the outlier rule's neighbourhood is 31 samples)
CONTEXT = 1024
_PARTS = 64


def reading_order(log_ns: IntArray, *, by_log_time: bool) -> IntArray:
    """The order in which certify reads a stream whose samples were read (by the follower) in file order: by log
    time, stable (``by_log_time``: the indexed reader of a closed ROS1 or MCAP log), or the delivery order itself."""
    if not by_log_time:
        return np.arange(log_ns.shape[0], dtype=np.int64)
    return np.argsort(log_ns, kind="stable").astype(np.int64)


def _cat(parts: list[IntArray]) -> IntArray:
    return np.concatenate(parts) if parts else np.zeros(0, dtype=np.int64)


@dataclass(slots=True)
class StreamTimes:
    """The samples of one stream read so far (stamps, log times, the times they were pushed at)."""

    topic: str
    header: bool | None = None  # whether its messages carry a header stamp (None: no sample yet)
    _stamps: list[IntArray] = field(default_factory=list)
    _logs: list[IntArray] = field(default_factory=list)
    _pushed: list[IntArray] = field(default_factory=list)
    count: int = 0

    def times(self, rule: TimeRule, stamps_ns: IntArray | None, log_ns: IntArray) -> IntArray:
        """The times of one poll's samples: the rule applied to them after the last ``CONTEXT`` samples read."""
        logs = np.asarray(log_ns, dtype=np.int64)
        self.header = stamps_ns is not None if self.header is None else self.header
        stamps = np.asarray(stamps_ns, dtype=np.int64) if stamps_ns is not None else logs
        ctx = min(self.count, CONTEXT)
        before_s, before_l = self._tail(self._stamps, ctx), self._tail(self._logs, ctx)
        _, t = rule(np.concatenate((before_s, stamps)) if self.header else None, np.concatenate((before_l, logs)))
        new = np.asarray(t[ctx:], dtype=np.int64)
        for parts, part in ((self._stamps, stamps), (self._logs, logs), (self._pushed, new)):
            parts.append(part)
            if len(parts) > _PARTS:  # many small polls: one array again (the tail is then one slice)
                parts[:] = [_cat(parts)]
        self.count += int(logs.shape[0])
        return new

    @staticmethod
    def _tail(parts: list[IntArray], n: int) -> IntArray:
        out: list[IntArray] = []
        need = n
        for part in reversed(parts):
            if need <= 0:
                break
            out.append(part[-need:] if part.shape[0] > need else part)
            need -= int(out[-1].shape[0])
        return _cat(out[::-1])

    def final(self, rule: TimeRule, *, by_log_time: bool) -> tuple[TimeBase, int]:
        """certify's time base for the whole stream (in its reading order: ``by_log_time`` or the file order) and
        how many samples were pushed at another time than the one certify gives them."""
        stamps, logs, pushed = _cat(self._stamps), _cat(self._logs), _cat(self._pushed)
        order = reading_order(logs, by_log_time=by_log_time)
        base, t = rule(stamps[order] if self.header else None, logs[order])
        certify = np.empty_like(pushed)
        certify[order] = t
        return base, int(np.count_nonzero(certify != pushed))
