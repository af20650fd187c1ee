"""Time bases and judged samples: header stamps + log times -> the time each sample is judged at, no sample dropped.

input: a stream's header stamps and log times (ns, reading order) and the requested base (``auto``, ``header``,
``log``) -> output: a ``TimeBase`` (the base used, one time per sample, the samples re-timed, the reasons the header
stamps could not order the samples). input: times and values -> output: ``JudgedSamples`` (sorted; duplicates that
agree merged, duplicates that disagree kept for the per-sample checks and unknown (NaN) for the formula).

Rules (the certificate states which applied):
- a header stamp is an *outlier* when it is zero or negative, near 1970 in a stream whose stamps are not, or far
  (more than ``max(1 s, 20 periods)``) from the median of its 31 neighbours in reading order. Outliers are re-timed
  from their log time (interpolated between the good samples' stamps), so one bad stamp never moves time 0;
- the header stamps *cannot order the samples* when more than 5 % of them are outliers, repeat an earlier stamp, or
  go backwards in reading order. ``auto`` then uses log time (with a data-quality finding); an explicit ``header``
  keeps them but the certificate cannot pass;
- every stream is under these rules (``stream_time_base``): the pose, the nominal, the commands and every signal
  topic. A stream beside the pose uses its header stamps (outliers re-timed) when its messages have a header and the
  pose is judged on header time, with the base requested for the pose (``auto``: log time for that stream when its
  own stamps cannot order its samples); else log time. A stream whose stamps are all unset is on log time.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import numpy.typing as npt
from numpy.lib.stride_tricks import sliding_window_view

from verify.ingest.quality import NEAR_1970_NS
from verify.ingest.stats import median

__all__ = ["TIME_BASES", "UNORDERABLE_FRACTION", "JudgedSamples", "TimeBase", "choose_time_base", "header_outliers",
           "judged_samples", "stream_time_base"]

FloatArray = npt.NDArray[np.float64]
IntArray = npt.NDArray[np.int64]
BoolArray = npt.NDArray[np.bool_]

TIME_BASES = ("auto", "header", "log")
#: more than this fraction of zero / outlier, repeated or backwards stamps: the header cannot order the samples
UNORDERABLE_FRACTION = 0.05
#: a stamp this far from the median of its neighbours (or OUTLIER_PERIODS typical periods, if more) is an outlier
OUTLIER_MIN_NS = 10**9
OUTLIER_PERIODS = 20
OUTLIER_WINDOW = 31
#: duplicates closer than this (m, rad) are the same sample sent twice
AGREE_TOL = 1e-9


@dataclass(frozen=True, slots=True)
class TimeBase:
    """The base used (``header`` or ``log``), the time of every sample (reading order) and how it was chosen."""

    name: str
    requested: str
    t_ns: IntArray
    retimed: int  # header stamps that were outliers, re-timed from their log time
    problems: tuple[str, ...]  # why the header stamps cannot order the samples (empty: they can)
    usable: bool  # False: an explicit header base whose stamps cannot order the samples (never a pass)

    @property
    def note(self) -> str | None:
        if not self.problems:
            return None
        what = "; ".join(self.problems)
        if self.name == "log":
            return f"header stamps cannot order the samples ({what}): judged on log (receive) time"
        return f"header stamps cannot order the samples ({what}): no pass is possible on this time base"


def header_outliers(stamps_ns: IntArray) -> BoolArray:
    """Stamps that are zero/negative, near 1970 among modern stamps, or far from their neighbours (reading order)."""
    bad = stamps_ns <= 0
    if bool(np.all(bad)):
        return bad
    typical = int(median(stamps_ns[~bad]))
    if typical >= NEAR_1970_NS:
        bad |= stamps_ns < NEAR_1970_NS
    good_idx = np.flatnonzero(~bad)
    s = stamps_ns[good_idx]
    if s.size < 3:
        return bad
    d = np.abs(np.diff(s))
    period = float(median(d))
    tol = max(float(OUTLIER_MIN_NS), OUTLIER_PERIODS * period)
    big = np.flatnonzero(d > tol)
    if big.size == 0:
        return bad
    cand = np.unique(np.concatenate([big, big + 1]))
    half = min(OUTLIER_WINDOW // 2, s.size - 1)
    padded = np.pad(s, half, mode="reflect")
    windows = sliding_window_view(padded, 2 * half + 1)[cand]
    med = median(windows, axis=1)
    far = np.abs(s[cand].astype(np.float64) - med) > tol
    bad[good_idx[cand[far]]] = True
    return bad


def _retime(stamps_ns: IntArray, log_ns: IntArray, out: BoolArray) -> IntArray:
    """Outliers' times: their log time plus the header-minus-log offset interpolated between the good samples (by
    log time; beyond them, the nearest good sample's offset). Integer offsets relative to the first good one keep
    nanoseconds exact in float64."""
    t = stamps_ns.copy()
    good = np.flatnonzero(~out)
    if good.size == 0:
        return log_ns.copy()  # no stamp to interpolate between: the messages' log times
    if not out.any():
        return t
    order = good[np.argsort(log_ns[good], kind="stable")]
    offset = stamps_ns - log_ns
    ref_off = int(offset[order[0]])
    ref_log = int(log_ns[order[0]])
    xp = (log_ns[order] - ref_log).astype(np.float64)
    fp = (offset[order] - ref_off).astype(np.float64)
    est = np.interp((log_ns[out] - ref_log).astype(np.float64), xp, fp)
    t[out] = log_ns[out] + ref_off + np.rint(est).astype(np.int64)
    return t


def choose_time_base(stamps_ns: IntArray, log_ns: IntArray, requested: str) -> TimeBase:
    """The time base for a stream (see the module docstring)."""
    if requested not in TIME_BASES:
        raise ValueError(f"time_base={requested!r} must be one of {', '.join(TIME_BASES)}")
    stamps_ns = np.asarray(stamps_ns, dtype=np.int64)
    log_ns = np.asarray(log_ns, dtype=np.int64)
    if requested == "log":
        return TimeBase("log", requested, log_ns, 0, (), True)
    n = int(stamps_ns.shape[0])
    out = header_outliers(stamps_ns) if n else np.zeros(0, dtype=bool)
    limit = UNORDERABLE_FRACTION * n
    problems: list[str] = []
    n_out = int(np.count_nonzero(out))
    if n_out > limit:
        problems.append(f"{n_out} of {n} stamps are zero, negative or far from their neighbours")
    good = stamps_ns[~out]
    step = np.diff(good)
    backwards = int(np.count_nonzero(step < 0))
    # repeated stamps: on sorted stamps (the usual case) the zero steps; else after sorting (np.unique is slower)
    repeats = int(np.count_nonzero((step if backwards == 0 else np.diff(np.sort(good))) == 0))
    if repeats > limit:
        problems.append(f"{repeats} of {n} stamps repeat an earlier stamp")
    if backwards > limit:
        problems.append(f"{backwards} of {n} stamps go backwards in reading order")
    if problems and requested == "auto":
        return TimeBase("log", requested, log_ns, 0, tuple(problems), True)
    return TimeBase("header", requested, _retime(stamps_ns, log_ns, out), n_out, tuple(problems), not problems)


def stream_time_base(stamps_ns: IntArray | None, log_ns: IntArray, *, requested: str, pose_base: str) -> TimeBase:
    """The times of a stream beside the pose (nominal, commands, a signal topic): see the module docstring.
    ``stamps_ns``: its header stamps (None: its messages have no header); ``requested``: the base asked for the
    pose; ``pose_base``: the base the pose uses."""
    log_ns = np.asarray(log_ns, dtype=np.int64)
    if stamps_ns is None or pose_base == "log" or requested == "log":
        return TimeBase("log", requested, log_ns, 0, (), True)
    return choose_time_base(stamps_ns, log_ns, requested)


@dataclass(frozen=True, slots=True)
class JudgedSamples:
    """A stream sorted by time with every sample accounted for.

    ``index``/``t_ns``: one entry per distinct time (the first sample read at that time); ``conflict``: True where
    samples sharing that time disagree (their values are unknown to the formula checks). ``all_index``: every
    sample, sorted by time (stable), for per-sample checks that judge all of them (worst case)."""

    index: IntArray
    t_ns: IntArray
    conflict: BoolArray
    all_index: IntArray
    read: int
    merged: int  # duplicates equal to the first sample at their time (the same message sent twice)
    conflicting: int  # samples at a time shared with a different value

    def counts(self) -> dict[str, int]:
        return {"read": self.read, "judged": self.read - self.merged, "merged_duplicates": self.merged,
                "conflicting_duplicates": self.conflicting}


def judged_samples(t_ns: IntArray, values: FloatArray, *, agree_tol: float = AGREE_TOL) -> JudgedSamples:
    """Sort by time; duplicates whose ``values`` rows agree within ``agree_tol`` (NaN equal to NaN) are merged,
    others are conflicts (signal values: exactly equal, as the online feed merges them)."""
    n = int(t_ns.shape[0])
    if n < 2 or bool(np.all(t_ns[1:] > t_ns[:-1])):  # strictly increasing (the usual case): nothing to sort or merge
        every = np.arange(n, dtype=np.int64)
        return JudgedSamples(every, np.asarray(t_ns, dtype=np.int64), np.zeros(n, dtype=bool), every, n, 0, 0)
    order = np.argsort(t_ns, kind="stable").astype(np.int64)
    ts = t_ns[order]
    first = np.ones(n, dtype=bool)
    first[1:] = np.diff(ts) != 0
    starts = np.flatnonzero(first)
    group = np.cumsum(first) - 1
    vals = np.asarray(values, dtype=np.float64).reshape(n, -1)[order]
    head = vals[starts][group]
    same = np.all((vals == head) | (np.abs(vals - head) <= agree_tol) | (np.isnan(vals) & np.isnan(head)), axis=1)
    dup = ~first
    conflict_rows = dup & ~same
    conflict_group = np.zeros(starts.shape[0], dtype=bool)
    conflict_group[group[conflict_rows]] = True
    keep_all = first | conflict_rows
    conflicting = int(np.count_nonzero(conflict_group[group]))
    return JudgedSamples(order[starts], ts[starts], conflict_group, order[keep_all], n,
                         int(np.count_nonzero(dup & same)), conflicting)
