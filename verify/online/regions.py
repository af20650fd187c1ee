"""Pose batches in the online monitor's two semantics: pose samples -> the regions' and atoms' margins, the positions
of the trajectory semantics with the atoms' bounds there, and the timed run's entries.

input: a batch of pose samples (the sample judged before it in front) -> output: every region's and atom's margin
(``RegionGeometry``, bit for bit ``verify.geometry``), each sample's and each gap's bounds and the positions after
the previous sample (``point_and_gap_bounds``, ``positions_after``: ``verify.semantics.trajectory``), and the
timed run's entries where the set of containing regions changes (``RunLog``: ``verify.semantics.timed_run``), kept
for the failed timed run's temporal margin at the end.
"""

from __future__ import annotations

from collections.abc import Mapping

import numpy as np
import numpy.typing as npt

from tubempc.scenario import Scenario
from verify.geometry import containment, label_margins, region_margins
from verify.semantics.timed_run import UNKNOWN_ENTRY, check_timed_run

__all__ = ["RegionGeometry", "RunLog", "point_and_gap_bounds", "positions_after", "prepend"]

FloatArray = npt.NDArray[np.float64]
IntArray = npt.NDArray[np.int64]
BoolArray = npt.NDArray[np.bool_]


def prepend(prev: tuple[int, float, float], t: IntArray, x: FloatArray, y: FloatArray
            ) -> tuple[IntArray, FloatArray, FloatArray]:
    """A batch with the sample before it in front."""
    return np.concatenate(([prev[0]], t)), np.concatenate(([prev[1]], x)), np.concatenate(([prev[2]], y))


class RegionGeometry:
    """The scenario's regions for the formula's atoms (``names``; those in ``signals`` are not regions). With disc
    regions only, every margin comes from one broadcast pass; otherwise from ``verify.geometry`` per batch."""

    def __init__(self, sc: Scenario, names: list[str], signals: Mapping[str, object]) -> None:
        self.scenario = sc
        self.names = names
        self.region_names = [n for n in names if n not in signals]
        eta = sc.robot.radius
        discs = [r for r in sc.regions if getattr(r, "polygon", None) is None]
        self.discs = len(discs) == len(sc.regions)
        self.cx = np.array([r.center[0] for r in discs], dtype=np.float64)
        self.cy = np.array([r.center[1] for r in discs], dtype=np.float64)
        self.radius = np.array([r.radius for r in discs], dtype=np.float64)
        self.offset = np.array([(r.radius + eta) if r.unsafe else (r.radius - eta) for r in discs])
        self.atom_rows = [[k for k, r in enumerate(sc.regions) if name in r.labels and name not in signals]
                          for name in names]
        self.unsafe = [k for k, r in enumerate(sc.regions) if r.unsafe]

    def margins(self, x: FloatArray, y: FloatArray) -> tuple[FloatArray | None, FloatArray, FloatArray]:
        """The distance of every disc region's centre (None: a polygon region; rows in scenario order), every
        region's margin and every atom's (rows in name order), as ``verify.geometry.region_margins`` /
        ``label_margins`` give them (bit for bit)."""
        if not self.discs:
            atom = label_margins(x, y, self.scenario, frozenset(self.region_names))
            atom_m = np.array([atom[n] if n in atom else np.full(x.shape[0], -np.inf) for n in self.names]
                              ).reshape(-1, x.shape[0])
            return None, region_margins(x, y, self.scenario), atom_m
        dist = np.hypot(x[None, :] - self.cx[:, None], y[None, :] - self.cy[:, None])
        region_m = self.offset[:, None] - dist
        atom_m = np.empty((len(self.names), x.shape[0]))
        for k, rows in enumerate(self.atom_rows):
            if len(rows) == 1:
                atom_m[k] = region_m[rows[0]]
            else:
                atom_m[k] = region_m[rows].max(axis=0) if rows else -np.inf
        return dist, region_m, atom_m

    def containment(self, x: FloatArray, y: FloatArray, dist: FloatArray | None) -> BoolArray:
        """``verify.geometry.containment``: (regions, samples), whether the region contains the robot's disc
        (``dist``: the discs' centre distances, from ``margins``)."""
        if dist is None:
            return containment(x, y, self.scenario)
        return dist + self.scenario.robot.radius <= self.radius[:, None]


def point_and_gap_bounds(atom_m: FloatArray, step: FloatArray) -> tuple[FloatArray, FloatArray, FloatArray, FloatArray]:
    """Every atom's bounds at each sample (a NaN margin: unknown) and over each gap between consecutive samples
    (``verify.geometry.gap_bounds`` on every atom at once)."""
    nan = np.isnan(atom_m)
    p_lo, p_hi = (np.where(nan, -np.inf, atom_m), np.where(nan, np.inf, atom_m)) if nan.any() else (atom_m, atom_m)
    with np.errstate(invalid="ignore"):  # inf - inf (an unknown atom over an unbounded gap): NaN, then unknown
        mid = 0.5 * (atom_m[:, :-1] + atom_m[:, 1:])
        half = 0.5 * step
        g_lo, g_hi = mid - half, mid + half
    g_lo[np.isnan(g_lo)] = -np.inf
    g_hi[np.isnan(g_hi)] = np.inf
    return p_lo, p_hi, g_lo, g_hi


def positions_after(t_rel: IntArray, p_lo: FloatArray, p_hi: FloatArray, g_lo: FloatArray, g_hi: FloatArray,
                    *, first: bool) -> tuple[IntArray, IntArray, BoolArray, FloatArray, FloatArray]:
    """The positions of ``verify.semantics.trajectory.trajectory_positions`` after the first sample of ``t_rel``:
    each later sample's preceding gap ``[t_(i-1) + 1, t_i - 1]`` (when it holds an instant) then the sample itself
    (``first``: the first sample too, a point with no gap before it). Returns their spans, whether each is a point,
    and every atom's bounds there (rows as ``p_lo``)."""
    m = t_rel.shape[0] - 1
    o = 1 if first else 0
    start = np.empty(2 * m + o, dtype=np.int64)
    stop = np.empty_like(start)
    is_point = np.zeros(start.shape[0], dtype=bool)
    lo = np.empty((p_lo.shape[0], start.shape[0]))
    hi = np.empty_like(lo)
    if first:
        start[0] = stop[0] = t_rel[0]
        is_point[0] = True
        lo[:, 0], hi[:, 0] = p_lo[:, 0], p_hi[:, 0]
    start[o::2], stop[o::2] = t_rel[:-1] + 1, t_rel[1:] - 1
    start[o + 1 :: 2] = stop[o + 1 :: 2] = t_rel[1:]
    is_point[o + 1 :: 2] = True
    lo[:, o::2], hi[:, o::2] = g_lo, g_hi
    lo[:, o + 1 :: 2], hi[:, o + 1 :: 2] = p_lo[:, 1:], p_hi[:, 1:]
    keep = is_point | (stop >= start)  # two samples 1 ns apart leave no gap
    if not keep.all():
        start, stop, is_point, lo, hi = start[keep], stop[keep], is_point[keep], lo[:, keep], hi[:, keep]
    return start, stop, is_point, lo, hi


class RunLog:
    """The timed run so far: the set of regions containing the last sample, one entry per change of that set (its
    regions' names joined with ``+``, its labels their union), and every change's time (exits included) -- what
    the failed timed run's temporal margin is computed from at the end."""

    def __init__(self, sc: Scenario, signals: list[str]) -> None:
        self.scenario = sc
        self.region_labels = [frozenset(r.labels) for r in sc.regions]
        self.prev_set: BoolArray | None = None  # the regions containing the last sample (and "unknown"); None: none
        self.entry_labels: dict[str, frozenset[str]] = {}  # entry name -> labels
        self.entries: list[tuple[str, float]] = []  # (name, s from time 0): one per change
        self.changes_s: list[float] = []  # s from time 0 of every change of the containing set (exits included)
        self.entry_change: list[int] = []  # per entry: its index in changes_s
        self.signal_values: dict[str, tuple[list[float], list[float]]] = {n: ([], []) for n in signals}

    def changes(self, t_rel: IntArray, x: FloatArray, y: FloatArray, inside: BoolArray
                ) -> tuple[IntArray, list[str], IntArray]:
        """The entries (paper, Definition 3) among new samples: where the set of regions containing the robot
        (``inside``: regions x samples) changes (``verify.semantics.timed_run.timed_run_of_sets``), a sample of
        unknown position being an entry of its own. Returns the entries' indexes, their names and every new
        sample's time as the timed run rounds it (through seconds, ns)."""
        conv = np.round(t_rel.astype(np.float64) * 1e-9 * 1e9).astype(np.int64)
        unknown = ~(np.isfinite(x) & np.isfinite(y))  # an entry of its own, every label unknown
        inside = np.vstack((inside & ~unknown, unknown[None, :]))
        prev_set = self.prev_set
        self.prev_set = inside[:, -1:].copy()
        if prev_set is not None and (inside == prev_set).all():  # no change in this batch (the common case)
            return np.zeros(0, dtype=np.int64), [], conv
        before = np.concatenate((inside[:, :1] if prev_set is None else prev_set, inside[:, :-1]), axis=1)
        changed = np.any(inside != before, axis=0)
        if prev_set is None:
            changed[0] = True
        entry = np.flatnonzero(changed & inside.any(axis=0))
        ch = np.flatnonzero(changed)
        self.entry_change += (len(self.changes_s) + np.searchsorted(ch, entry)).tolist()
        self.changes_s += (t_rel[ch].astype(np.float64) * 1e-9).tolist()
        return entry, [self._entry_name(inside[:, int(e)]) for e in entry], conv

    def _entry_name(self, column: BoolArray) -> str:
        """An entry's name (its regions joined with ``+``); its labels (their union) are kept by name."""
        if column[-1]:  # the last row: the sample's position is unknown
            self.entry_labels.setdefault(UNKNOWN_ENTRY, frozenset())
            return UNKNOWN_ENTRY
        rows = np.flatnonzero(column[:-1])
        name = "+".join(self.scenario.regions[int(k)].name for k in rows)
        if name not in self.entry_labels:
            self.entry_labels[name] = frozenset(lab for k in rows for lab in self.region_labels[int(k)])
        return name

    def record(self, members: list[str], t_e: IntArray, signal_values: Mapping[str, tuple[FloatArray, FloatArray]]
               ) -> None:
        """New entries (names, ns from time 0 as the timed run rounds them) and the signal atoms' bounds there."""
        self.entries += [(m, float(t) * 1e-9) for m, t in zip(members, t_e, strict=True)]
        for name, (lo, hi) in signal_values.items():
            self.signal_values[name][0].extend(lo.tolist())
            self.signal_values[name][1].extend(hi.tolist())

    def margin_s(self, formula: str, last_ns: int) -> tuple[float | None, str | None]:
        """A failed timed run's temporal margin (or why it has none), as the certificate states it
        (``verify.semantics.timed_run``), on the entries kept; ``last_ns``: the last pose sample (from time 0)."""
        if not self.entries:
            return None, None
        end_s = max(last_ns * 1e-9, self.entries[-1][1])
        labels = {name: sorted(lab) for name, lab in self.entry_labels.items()}
        values = {n: (np.array(lo), np.array(hi)) for n, (lo, hi) in self.signal_values.items()}
        # an entry's exit: the next change of the containing set, or the last sample (timed_run.entry_exits)
        last_s = float(np.float64(last_ns) * 1e-9)
        exits = [self.changes_s[j + 1] if j + 1 < len(self.changes_s) else last_s for j in self.entry_change]
        tr = check_timed_run(formula, self.entries, labels, end=end_s, atom_values=values, exits=exits)
        return tr.margin_s, tr.margin_reason
