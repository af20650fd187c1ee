"""Timed runs (paper, Definition 3) and their pointwise MITL check.

input: a trajectory's region indices per sample (``geometry.containing_region``) -> output: the timed run
``[(region, time_s), ...]`` (``timed_run_of``); input: formula text + timed run + labels -> output: a
``TimedRunVerdict`` (``check_timed_run``), evaluated with the pointwise semantics of ``verify.monitor.engine``.
"""

from __future__ import annotations

import math
from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np
import numpy.typing as npt

from tubempc.mitl import Eventually, Formula, SpecSyntaxError, atoms, parse
from verify.errors import SpecError
from verify.monitor.engine import Positions, Truth, evaluate, explain, truth_from_bool, verdict_of

__all__ = [
    "UNKNOWN_ENTRY", "TimedRunVerdict", "check_timed_run", "entry_exits", "parse_spec", "timed_run_of",
    "timed_run_of_sets"]

#: the name of a timed-run entry whose regions are unknown (a NaN position, duplicates that disagree): every region
#: label is unknown there, so the run's verdict is undecided unless a violation is shown elsewhere
UNKNOWN_ENTRY = "?"


def parse_spec(text: str) -> Formula:
    """MITL text -> formula; a malformed formula raises ``SpecError`` (exit 3) naming the column."""
    try:
        return parse(text)
    except SpecSyntaxError as err:
        raise SpecError(f"malformed formula: {err}") from err


@dataclass(frozen=True, slots=True)
class TimedRunVerdict:
    """Verdict of a formula on a timed run, with the first violation (or the undecided sub-formula) when not pass."""

    verdict: str
    formula: str
    subformula: str | None = None
    time_s: float | None = None
    reason: str | None = None
    margin_s: float | None = None  # a fail's margin in seconds (< 0; see ``_time_margin_s``)
    margin_reason: str | None = None  # a fail without a margin: why

    @property
    def first_violation_time(self) -> float | None:
        return self.time_s if self.verdict == "fail" else None


def _to_ns(t: float) -> int:
    if not math.isfinite(t):
        raise ValueError(f"time={t!r} is not finite")
    return round(t * 1e9)


def check_timed_run(formula: str, run: Sequence[tuple[str, float]], labels: Mapping[str, Sequence[str]],
                    end: float | None = None,
                    atom_values: Mapping[str, tuple[npt.NDArray[np.float64], npt.NDArray[np.float64]]] | None = None,
                    *, exits: Sequence[float] | None = None) -> TimedRunVerdict:
    """Pointwise 3-valued verdict of ``formula`` at the first entry of the timed ``run``.

    ``run``: ``(region, time_s)`` entries with non-decreasing times; ``labels``: region -> its atomic propositions
    (a region missing from ``labels`` has none); ``end``: when observation stopped (default: the last time).
    Times are compared in integer nanoseconds (``round(t * 1e9)``). ``atom_values``: robustness bounds
    ``(lo, hi)`` per run entry for atoms that are not region labels (signal atoms, sampled at the entry times).
    ``exits``: when the robot left each entry's regions (``entry_exits``; default: at the next entry), which bounds
    how long a false sub-formula stayed false (the margin of a fail).
    """
    f = parse_spec(formula)
    external = atom_values
    if not run:
        return TimedRunVerdict("inconclusive", str(f), str(f), None, "the timed run is empty")
    times = np.array([_to_ns(float(t)) for _, t in run], dtype=np.int64)
    if np.any(np.diff(times) < 0):
        raise ValueError(f"run times must be non-decreasing, got {[t for _, t in run]}")
    end_ns = int(times[-1]) if end is None else _to_ns(float(end))
    if end_ns < int(times[-1]):
        raise ValueError(f"end={end} is before the last run time {run[-1][1]}")
    pos = Positions.points(times, end_ns)  # equal times are allowed: distinct positions at the same instant
    inputs: dict[str, Truth] = {}
    for name in atoms(f):
        if external is not None and name in external:
            lo, hi = external[name]
            inputs[name] = Truth(np.asarray(lo, dtype=np.float64), np.asarray(hi, dtype=np.float64))
            continue
        holds = np.array([name in labels.get(region, ()) for region, _ in run], dtype=bool)
        truth = truth_from_bool(holds)
        unknown = np.array([region == UNKNOWN_ENTRY for region, _ in run], dtype=bool)
        if unknown.any():
            truth = Truth(np.where(unknown, -np.inf, truth.lo), np.where(unknown, np.inf, truth.hi))
        inputs[name] = truth
    values = evaluate(f, pos, inputs)
    root = values[f]
    verdict = verdict_of(float(root.lo[0]), float(root.hi[0]))
    if verdict == "pass":
        return TimedRunVerdict("pass", str(f))
    why = explain(f, 0, pos, values)
    exit_ns = None if exits is None else np.array([_to_ns(float(t)) for t in exits], dtype=np.int64)
    margin = (_time_margin_s(values, why.subformula, why.time_ns, times, end_ns, exits=exit_ns) if verdict == "fail"
              else None)
    margin_reason = None
    if verdict == "fail" and (margin is None or margin >= 0):
        margin = None
        margin_reason = ("no time stretch to measure: the violation is decided by constants or at the end of the log "
                         "(e.g. a window that opens after the log ends)")
    return TimedRunVerdict(verdict, str(f), why.subformula, why.time_ns / 1e9, why.reason, margin, margin_reason)


def _time_margin_s(values: Mapping[Formula, Any], subformula: str | None, time_ns: int, times: npt.NDArray[np.int64],
                   end_ns: int, *, exits: npt.NDArray[np.int64] | None = None) -> float | None:
    """How far in time the run is from satisfying the witnessed sub-formula (seconds, <= 0).

    The pointwise semantics are boolean, so the margin is temporal: for ``F[a,b] phi`` never met, minus the time
    from the window to the nearest entry at which ``phi`` held (the log's end when it never did: at least that
    late); for any other false sub-formula, minus how long it stayed false from the witness on: until the robot left
    the regions of the last entry of the unbroken stretch of entries at which it is false (``exits``; without them,
    until the next entry at which it is not false, or the log's end).
    """
    g = next((h for h in values if str(h) == subformula), None)
    if g is None:
        return None
    if isinstance(g, Eventually) and g.interval.bounded:
        hi_ns, lo_ns = time_ns, time_ns - round((g.interval.hi_s - g.interval.lo_s) * 1e9)
        held = times[np.asarray(values[g.arg].lo) > 0]
        if held.size == 0:
            return -max(end_ns - hi_ns, 0) / 1e9
        gap = np.where(held > hi_ns, held - hi_ns, np.where(held < lo_ns, lo_ns - held, 0))
        return -float(gap.min()) / 1e9
    false = np.asarray(values[g].hi) < 0
    k = int(np.searchsorted(times, time_ns))
    if exits is not None and k < times.shape[0]:
        j = k
        while j + 1 < times.shape[0] and false[j + 1] and int(times[j + 1]) <= int(exits[j]):
            j += 1  # the next entry starts where this one was left: the sub-formula stays false across
        return -max(min(int(exits[j]), end_ns) - time_ns, 0) / 1e9
    after = np.flatnonzero(~false[k:])
    stop = int(times[k + int(after[0])]) if after.size else end_ns
    return -max(stop - time_ns, 0) / 1e9


def timed_run_of(region_index: npt.NDArray[np.int64], times_s: npt.NDArray[np.float64],
                 names: Sequence[str]) -> list[tuple[str, float]]:
    """Definition 3: each maximal stretch of samples whose disc lies in region r starts an entry ``(r, t)``.

    ``region_index[i]`` is the containing region of sample i or -1 (none, or unknown because of NaN).
    A stretch outside every region separates entries (leaving R1 and re-entering it gives two entries).
    """
    if region_index.size == 0:
        return []
    change = np.flatnonzero(np.diff(region_index) != 0) + 1
    starts = np.concatenate(([0], change))
    return [(names[int(region_index[s])], float(times_s[s])) for s in starts if region_index[s] >= 0]


def entry_exits(contains: npt.NDArray[np.bool_], times_s: npt.NDArray[np.float64],
                known: npt.NDArray[np.bool_] | None = None) -> list[float]:
    """For each entry of ``timed_run_of_sets(contains, times_s, ..., known=known)``: the time the robot left its
    regions (the first sample at which the set of containing regions, or whether it is known, changes), or the last
    sample's time."""
    n = contains.shape[1] if contains.ndim == 2 else 0
    if n == 0:
        return []
    unknown = np.zeros(n, dtype=bool) if known is None else ~np.asarray(known, dtype=bool)
    changed = np.any(contains[:, 1:] != contains[:, :-1], axis=0) | (unknown[1:] != unknown[:-1])
    change = np.flatnonzero(changed) + 1
    starts = np.concatenate(([0], change))
    ends = np.concatenate((change, [n - 1]))
    return [float(times_s[e]) for s, e in zip(starts, ends, strict=True) if unknown[s] or contains[:, s].any()]


def timed_run_of_sets(contains: npt.NDArray[np.bool_], times_s: npt.NDArray[np.float64], names: Sequence[str],
                      labels: Mapping[str, Sequence[str]], known: npt.NDArray[np.bool_] | None = None,
                      ) -> tuple[list[tuple[str, float]], dict[str, list[str]]]:
    """Definition 3 when regions may overlap or nest: ``contains`` is ``(n_regions, n)`` (``geometry.containment``).

    Each maximal stretch of samples contained in the same non-empty *set* of regions starts an entry; the entry is
    named by its regions joined with ``+`` in scenario order (``room+table``) and carries the union of their
    labels (a table inside a room: both labels hold). ``known``: False where a sample's position is unknown; each
    stretch of such samples is an entry ``UNKNOWN_ENTRY`` (its regions, hence its labels, unknown), never dropped.
    Returns the run and the labels of every entry name."""
    n = contains.shape[1] if contains.ndim == 2 else 0
    if n == 0:
        return [], {}
    unknown = np.zeros(n, dtype=bool) if known is None else ~np.asarray(known, dtype=bool)
    changed = np.any(contains[:, 1:] != contains[:, :-1], axis=0) | (unknown[1:] != unknown[:-1])
    change = np.flatnonzero(changed) + 1  # the set of regions (or whether it is known) changes
    starts = np.concatenate(([0], change))
    run: list[tuple[str, float]] = []
    entry_labels: dict[str, list[str]] = {}
    for s in starts:
        if unknown[s]:
            run.append((UNKNOWN_ENTRY, float(times_s[s])))
            entry_labels.setdefault(UNKNOWN_ENTRY, [])
            continue
        members = [names[int(k)] for k in np.flatnonzero(contains[:, s])]
        if not members:
            continue
        name = "+".join(members)
        run.append((name, float(times_s[s])))
        if name not in entry_labels:
            entry_labels[name] = sorted({lab for m in members for lab in labels.get(m, ())})
    return run, entry_labels
