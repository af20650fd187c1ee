"""Online certification: samples pushed in time order -> the state of every check and obligation as soon as decided.

input: a scenario (and formula), then pose / nominal / command samples in time order per stream (absolute integer
ns) and the messages of the signal atoms the formula uses (any order; ``verify.online.signalfeed``) -> output:
``Decision`` events (``update``), the current ``MonitorState`` (``state``) and, at ``close``, the same checks and
overall verdict as ``verify.certify.certify_log`` on a log holding the same samples.

Verdicts are final once given: a check that fails never passes later, and a formula obligation is reported decided
only when no continuation of the run can change its verdict. The obligations are the top-level conjuncts of the
formula under the trajectory semantics; ``spec_trajectory`` and ``spec_timed_run`` are the whole formula under each
semantics. Until ``close`` a check that can only pass at the end of the run (``G`` over the whole run, the
workspace, the tube) is "inconclusive so far".

``push_*`` only buffers (O(1)); the buffered samples are judged together (vectorised, with the offline code) when
``update``/``state`` is called or when ``max_pending`` samples wait. The time a verdict is reported with is the time
of the sample that decided it, whatever the batching. With signal atoms a pose sample is judged once every used
signal has a message after it, or once it is ``max_signal_lag_s`` older than the newest sample.
"""

from __future__ import annotations

import math
from bisect import bisect_left, bisect_right
from collections.abc import Callable, Mapping, Sequence
from dataclasses import replace
from functools import partial
from pathlib import Path

import numpy as np
import numpy.typing as npt

from tubempc.mitl import Formula, atoms
from tubempc.scenario import Scenario
from verify.certify import resolve_scenario
from verify.checks import CheckResult
from verify.errors import MonitorClosedError
from verify.geometry import step_bound_m
from verify.ingest import LogData
from verify.judging import formula_of, overall_verdict, split_obligations
from verify.online.accumulate import SampleChecks
from verify.online.heads import BoolHead, Evaluation, Head, build_head
from verify.online.inputs import StreamInput
from verify.online.quiet import EVERY_STREAM, POSE_RUN, POSE_TRAJECTORY, Quiet
from verify.online.regions import RegionGeometry, RunLog, point_and_gap_bounds, positions_after, prepend
from verify.online.signalfeed import SignalFeed
from verify.online.states import CheckState, Decision, MonitorState, OnlineResult, rel_s
from verify.online.stream import AtomNode
from verify.online.track import Track
from verify.selection import select_checks
from verify.semantics.timed_run import UNKNOWN_ENTRY
from verify.semantics.trajectory import reported_margin

__all__ = ["CheckState", "Decision", "MonitorClosedError", "MonitorState", "OnlineMonitor", "OnlineResult",
           "feed_log_data"]

FloatArray = npt.NDArray[np.float64]
IntArray = npt.NDArray[np.int64]
#: how long (s) a pose sample waits for a message of every signal the formula uses before the silence is judged
DEFAULT_SIGNAL_LAG_S = 3.0


class _Semantics:
    """One semantics of the formula: its track, atom nodes, heads and evaluation."""

    def __init__(self, formula: Formula) -> None:
        self.track = Track()
        self.atoms: dict[str, AtomNode] = {}
        atom = lambda name: self.atoms.setdefault(name, AtomNode())  # noqa: E731
        self.head = build_head(formula, atom)
        # the obligations are the certificate's (verify.judging.split_obligations): one per top-level conjunct
        conjuncts = split_obligations(formula)
        own: list[Head] = []
        if len(conjuncts) == 1:
            self.obligations: list[Head] = [self.head]
        elif isinstance(self.head, BoolHead) and self.head.kind == "and":
            self.obligations = list(self.head.children())
        else:  # a conjunction judged as one stream node or at close (no window, or U / X): a head per conjunct
            own = [build_head(c, atom) for c in conjuncts]
            self.obligations = own
        self.evaluation = Evaluation(self.track, [self.head, *own])
        for name in atoms(formula):
            self.atoms.setdefault(name, AtomNode())


class OnlineMonitor:
    """Incremental certifier of one run. ``push_pose`` / ``push_nominal`` / ``push_cmd`` in time order (per stream),
    ``update`` for the new decisions, ``state`` for everything so far, ``close`` for the final verdicts."""

    def __init__(self, scenario: Scenario | str | Path, *, spec: str | None = None, max_pending: int = 100,
                 checks: Sequence[str] | None = None, max_signal_lag_s: float = DEFAULT_SIGNAL_LAG_S) -> None:
        if max_pending < 1:
            raise ValueError(f"max_pending={max_pending!r} must be >= 1")
        if not max_signal_lag_s >= 0.0 or not math.isfinite(max_signal_lag_s):
            raise ValueError(f"max_signal_lag_s={max_signal_lag_s!r} must be a finite number >= 0")
        sc = resolve_scenario(scenario)
        self.scenario = sc
        self.selection = select_checks(sc, checks)  # as certify: --checks, else the scenario's, else what it names
        self._selected = {n for c in self.selection.selected
                          for n in (("spec_trajectory", "spec_timed_run") if c == "spec" else (c,))}
        self.formula = formula_of(sc, spec)  # the rule certify applies (verify.judging)
        self.max_pending = max_pending
        self._names = sorted(atoms(self.formula))
        # a name that is both a label and a signal is the signal (as verify.certify)
        self._feeds = {n: SignalFeed(n, sc.signals[n], pose_topic=sc.topics.pose) for n in self._names
                       if n in sc.signals}
        self._signal_rows = [k for k, n in enumerate(self._names) if n in self._feeds]
        self.max_signal_lag_ns = round(max_signal_lag_s * 1e9)
        self._newest_ns = -(2**63)  # the newest time pushed on the pose or a signal stream (the monitor's clock)
        self._pose_trigger = max_pending  # pending pose samples that make a push judge the buffer
        self.signal_ignored = 0  # messages of scenario signals the formula does not use
        self._traj = _Semantics(self.formula)
        self._run = _Semantics(self.formula)
        self._obligation_names = [str(h.formula) for h in self._traj.obligations]
        # a formula's margin is its deciding atom's: metres for regions, the field's unit for a signal
        self._units: dict[str, str | None] = {"spec_trajectory": self._unit_of(self.formula), "spec_timed_run": "s",
                                              "tube": "m", "workspace": "m", "obstacle_clearance": "m"}
        self._units.update({str(h.formula): self._unit_of(h.formula) for h in self._traj.obligations})
        self._geometry = RegionGeometry(sc, self._names, self._feeds)
        self._max_speed_mps = sc.max_speed_mps
        # input: the samples buffered until judged, per stream
        self._pose = StreamInput.of("pose", 2)  # x, y
        self._nom = StreamInput.of("nominal", 2)  # x, y
        self._cmd = StreamInput.of("cmd", 3)  # u1, u2, u3
        self._conflict: set[int] = set()  # pending pose times whose duplicates disagree (unknown to the formula)
        self._extra: list[tuple[int, float, float]] = []  # the disagreeing duplicates (judged by per-sample checks)
        self._late: list[tuple[int, float, float]] = []  # ... of a sample the formula had judged already
        self._formula_late_conflicts = 0
        # judged state
        self.t0_ns: int | None = None
        self._prev: tuple[int, float, float] | None = None  # the last sample judged by the formula
        self._run_log = RunLog(sc, list(self._feeds))
        self._checks = SampleChecks(sc, self._geometry, tube="tube" in self._selected)
        self._reported: set[str] = set()
        self._closed = False
        self._result: OnlineResult | None = None
        self._final: list[CheckResult] | None = None
        self._unreturned: list[Decision] = []
        # the second half of a judged pose batch (timed run and per-sample checks, or the checks) left for the next
        # update
        self._second_half: Callable[[], None] | None = None
        self._quiet = Quiet(self)  # whether an update can leave the buffered samples buffered (nothing to decide)

    def _unit_of(self, formula: Formula) -> str | None:
        units = {self.scenario.signals[n].unit if n in self._feeds else "m" for n in atoms(formula)}
        return units.pop() if len(units) == 1 else None

    # ---- input ----------------------------------------------------------------------------------------------------
    @property
    def _streams(self) -> tuple[StreamInput, StreamInput, StreamInput]:
        return self._pose, self._nom, self._cmd

    @property
    def counts(self) -> dict[str, int]:
        """Samples accepted per stream."""
        return {s.name: s.count for s in self._streams}

    @property
    def merged(self) -> dict[str, int]:
        """Per stream: samples at the time of the one before them with the same values (merged with it)."""
        return {s.name: s.merged for s in self._streams}

    @property
    def conflicting(self) -> dict[str, int]:
        """Per stream: samples at the time of the one before them with other values."""
        return {s.name: s.conflicting for s in self._streams}

    @property
    def duplicates(self) -> dict[str, int]:
        """Per stream: samples at the time of the one before them (merged or conflicting)."""
        return {s.name: s.duplicates for s in self._streams}

    @property
    def out_of_order(self) -> dict[str, int]:
        """Per stream: samples before the time of the one before them (never judged)."""
        return {s.name: s.out_of_order for s in self._streams}

    def _reject(self, stream: StreamInput, t_ns: int, values: tuple[float, ...]) -> bool:
        """A sample at or before the stream's last time (``StreamInput.repeat``; True: a conflict)."""
        if self._closed:
            raise MonitorClosedError(f"a {stream.name} sample at t_ns={t_ns} was pushed after close()")
        return stream.repeat(t_ns, values)

    def push_pose(self, t_ns: int, x_m: float, y_m: float, yaw_rad: float = 0.0) -> None:
        """A pose sample (absolute ns). A sample is judged once the next one (or ``close``) arrives, so that a
        sample repeating its time can still be merged with it or make it unknown."""
        pose = self._pose
        if t_ns > pose.last_ns and not self._closed:
            pose.last_ns = t_ns
            pose.last_values = (x_m, y_m, yaw_rad)
            pose.t.append(t_ns)
            xs, ys = pose.cols
            xs.append(x_m)
            ys.append(y_m)
            self._newest_ns = max(self._newest_ns, t_ns)
            if len(pose.t) > self._pose_trigger:
                self._process()
        elif self._reject(pose, t_ns, (x_m, y_m, yaw_rad)):
            if pose.t and pose.t[-1] == t_ns:  # not judged yet: unknown to the formula
                self._conflict.add(t_ns)
                self._extra.append((t_ns, x_m, y_m))
            else:  # the formula has judged the first sample at this time already: it cannot pass any more
                self._late.append((t_ns, x_m, y_m))
                self._formula_late_conflicts += 1

    def push_nominal(self, t_ns: int, x_m: float, y_m: float, yaw_rad: float = 0.0) -> None:
        """A sample of the MPC's nominal state (absolute ns)."""
        nom = self._nom
        if t_ns > nom.last_ns and not self._closed:
            nom.last_ns = t_ns
            nom.last_values = (x_m, y_m, yaw_rad)
            nom.t.append(t_ns)
            xs, ys = nom.cols
            xs.append(x_m)
            ys.append(y_m)
            if len(nom.t) >= self.max_pending:
                self._process()
        elif self._reject(nom, t_ns, (x_m, y_m, yaw_rad)):
            self._unknown_nominal(t_ns)

    def _unknown_nominal(self, t_ns: int) -> None:
        """Nominal samples that disagree at one time: the nominal state there is unknown."""
        self._quiet.block = True
        if self._nom.t and self._nom.t[-1] == t_ns:
            for c in self._nom.cols:
                c[-1] = math.nan
            return
        self._checks.nominal_unknown(t_ns)

    def push_signal(self, name: str, t_ns: int, value: float) -> None:
        """A message of the scenario's signal ``name`` (absolute ns on the pose's time base; the field's value).
        Any order: a message is placed among the others by time, unless a pose sample at or after its time was
        judged already (then it is counted late and the formula cannot pass). A pose sample is judged once every
        signal the formula uses has a message after it, or once it is ``max_signal_lag_s`` older than the newest
        sample (the silence is then unknown after each message's hold, as offline)."""
        if self._closed:
            raise MonitorClosedError(f"a sample of signal {name} at t_ns={t_ns} was pushed after close()")
        feed = self._feeds.get(name)
        if feed is None:
            if name not in self.scenario.signals:
                raise KeyError(f"signal {name!r} is not a signal of scenario {self.scenario.name!r} "
                               f"(it has: {', '.join(sorted(self.scenario.signals)) or 'none'})")
            self.signal_ignored += 1  # a signal of the scenario the formula does not use
            return
        feed.push(t_ns, value)
        self._newest_ns = max(self._newest_ns, t_ns)

    @property
    def signal_names(self) -> tuple[str, ...]:
        """The scenario signals the formula uses (the ones ``push_signal`` judges)."""
        return tuple(self._feeds)

    @property
    def signal_counts(self) -> dict[str, dict[str, int]]:
        """Per signal the formula uses: messages accepted (distinct instants), merged and conflicting duplicates,
        and late messages (for an instant already judged)."""
        return {n: {"messages": f.messages, "merged": f.merged, "conflicting": f.conflicting, "late": f.late}
                for n, f in self._feeds.items()}

    def _judgeable(self, closing: bool) -> int:
        """How many pending pose samples every used signal is known for (a message after them), or that are older
        than the lag bound."""
        pt = self._pose.t
        n = len(pt)
        if closing or not self._feeds or not n:
            return n
        cover = min(f.newest_ns for f in self._feeds.values())
        k = bisect_left(pt, cover)  # samples strictly before the newest message of every signal
        if k < n and pt[k] <= self._newest_ns - self.max_signal_lag_ns:
            k = bisect_right(pt, self._newest_ns - self.max_signal_lag_ns)
        return k

    def push_cmd(self, t_ns: int, u1: float, u2: float, u3: float) -> None:
        """An applied input (absolute ns; body frame as logged: vx, vy, wz). Every command is judged, also one
        that repeats a time with other values."""
        cmd = self._cmd
        if (t_ns > cmd.last_ns and not self._closed) or self._reject(cmd, t_ns, (u1, u2, u3)):
            if t_ns > cmd.last_ns:
                cmd.last_ns = t_ns
                cmd.last_values = (u1, u2, u3)
            cmd.t.append(t_ns)
            c1, c2, c3 = cmd.cols
            c1.append(u1)
            c2.append(u2)
            c3.append(u3)
            if len(cmd.t) >= self.max_pending:
                self._process()

    # ---- judging --------------------------------------------------------------------------------------------------
    def update(self) -> list[Decision]:
        """Judge the buffered samples; the checks and obligations decided since the last call (including those
        decided when ``max_pending`` samples made a push judge the buffer). Samples that cannot decide anything
        (``verify.online.quiet``) may stay buffered until one can: the same decisions, at the same call, with the
        same times, as judging at every call. Those are judged one stream at a time, one stream per update, once
        ``QUIET_BATCH`` of them wait, so that no update pays for judging every stream at once; and when only a
        semantics of the formula can decide, the rest waits for the next update in the same way."""
        loud = self._quiet.loud()
        if loud:
            self._process(loud)
        else:
            self._judge_quiet_stream()
        if not self._unreturned:
            return []
        out, self._unreturned = self._unreturned, []
        return out

    def _judge_quiet_stream(self) -> None:
        """Judge the buffered samples of the stream ``Quiet.due`` names (all tested quiet: nothing is decided, so
        neither decisions nor the quiet test's state change)."""
        if self._second_half is not None:  # the second half of the last pose batch
            self._finish_pose()
            return
        stream = self._quiet.due()
        if stream == "pose":
            self._judge_poses(closing=False, defer="run")
        elif stream == "cmd":
            self._judge_cmd()
        elif stream == "nominal":
            self._judge_nominal()
            self._checks.resolve_tube(closing=False)
        else:
            return
        self._quiet.judged(stream)

    @staticmethod
    def _with_extras(t: IntArray, x: FloatArray, y: FloatArray, extra: list[tuple[int, float, float]]
                     ) -> tuple[IntArray, FloatArray, FloatArray]:
        """Every sample for the per-sample checks: each disagreeing duplicate right after the samples at its time
        (a duplicate of a sample judged in an earlier batch goes first)."""
        et = np.array([e[0] for e in extra], dtype=np.int64)
        at = np.searchsorted(t, et, side="right")
        return (np.insert(t, at, et), np.insert(x, at, [e[1] for e in extra]), np.insert(y, at, [e[2] for e in extra]))

    def _process(self, streams: frozenset[str] = EVERY_STREAM, closing: bool = False) -> None:
        """Judge the buffered samples of ``streams`` (those of the others cannot decide anything now), then collect
        the new decisions."""
        self._finish_pose()
        if "nominal" in streams:
            self._judge_nominal()
        if "pose" in streams:
            self._judge_poses(closing)
        elif POSE_RUN in streams or POSE_TRAJECTORY in streams:  # the rest cannot decide anything now
            self._judge_poses(closing, defer="checks" if POSE_RUN in streams else "run")
        if "cmd" in streams:
            self._judge_cmd()
        if "nominal" in streams:
            self._checks.resolve_tube(closing=False)
        self._unreturned.extend(self._new_decisions())
        self._quiet.refresh(keep_tube="nominal" not in streams and (POSE_RUN in streams or POSE_TRAJECTORY in streams))

    def _judge_nominal(self) -> None:
        if self._nom.t:
            t, (x, y) = self._nom.take()
            self._checks.feed_nominal(t, x, y)

    def _judge_cmd(self) -> None:
        if self._cmd.t:
            t, cols = self._cmd.take()
            self._checks.feed_cmd(t, np.column_stack(cols))

    def _judge_poses(self, closing: bool, *, defer: str | None = None) -> None:
        """The pose samples every used signal is known for, with their duplicates that disagree and the late ones
        (``defer``: what of their judging may wait for the next update, ``_feed_pose``)."""
        self._finish_pose()
        late, self._late = self._late, []
        k = self._judgeable(closing)
        self._pose_trigger = len(self._pose.t) - k + self.max_pending
        if k:
            t, (x, y) = self._pose.take(k)
            every = None
            if self._conflict:
                done = int(t[-1])
                extra = [e for e in self._extra if e[0] <= done]
                self._extra = [e for e in self._extra if e[0] > done]
                every = self._with_extras(t, x, y, extra)
                bad = np.isin(t, np.array(sorted(self._conflict), dtype=np.int64))
                self._conflict = {c for c in self._conflict if c > done}
                x, y = np.where(bad, np.nan, x), np.where(bad, np.nan, y)
            if late:
                every = self._with_extras(*(every if every is not None else (t, x, y)), late)
            self._feed_pose(t, x, y, every, defer=defer)
        elif late:
            self._feed_every(np.array([e[0] for e in late], dtype=np.int64), np.array([e[1] for e in late]),
                             np.array([e[2] for e in late]))

    def _feed_pose(self, t_abs: IntArray, x: FloatArray, y: FloatArray,
                   every: tuple[IntArray, FloatArray, FloatArray] | None, *, defer: str | None = None) -> None:
        """``x``, ``y``: one sample per time for the formula (NaN where duplicates disagree); ``every``: all the
        samples for the per-sample checks (None: the same samples). The batch is judged with the sample before it
        (``k0`` = 1), whose gap to the first new sample it closes: the trajectory semantics, then the timed run and
        the per-sample checks (``defer`` "run": those two, "checks": the checks, left to ``_finish_pose``, at the
        next update or any judging before it; without signal atoms only: with them the timed run's entries come
        first, the signals' bounds there being computed with the trajectory's)."""
        if self.t0_ns is None:
            self.t0_ns = int(t_abs[0])
        t0 = self.t0_ns
        prev = self._prev
        k0 = 0 if prev is None else 1
        if prev is not None:
            t_abs, x, y = prepend(prev, t_abs, x, y)
        self._prev = (int(t_abs[-1]), float(x[-1]), float(y[-1]))
        t_rel = t_abs - t0
        step = step_bound_m(t_rel, x, y, self._max_speed_mps)
        dist, region_m, atom_m = self._geometry.margins(x, y)
        bounds = point_and_gap_bounds(atom_m, step)
        if every is None and self._checks.prev == prev:  # the per-sample checks reuse the steps and margins
            checks: tuple[IntArray, FloatArray, FloatArray, tuple[FloatArray, FloatArray, int] | None] = (
                t_abs, x, y, (step, region_m, k0))
        else:
            checks = (*(every if every is not None else (t_abs[k0:], x[k0:], y[k0:])), None)
        entry_dist = None if dist is None else dist[:, k0:]
        if not self._feeds:
            self._push_trajectory(t_rel, bounds, k0)
            if defer == "run":
                self._second_half = partial(self._run_and_checks, t_rel[k0:], x[k0:], y[k0:], entry_dist, checks)
            else:
                self._push_run(*self._run_changes(t_rel[k0:], x[k0:], y[k0:], entry_dist), {})
                self._second_half = partial(self._feed_every, *checks)
            if defer is None:
                self._finish_pose()
            return
        conv, entry, members = self._run_changes(t_rel[k0:], x[k0:], y[k0:], entry_dist)
        entry_values: dict[str, tuple[FloatArray, FloatArray]] = {}
        bounds = (bounds[0].copy(), bounds[1].copy(), bounds[2], bounds[3])
        for row in self._signal_rows:  # signal atoms: verify.signals on the messages held around this batch
            name = self._names[row]
            b, entry_values[name] = self._feeds[name].bounds(t_abs, t0 + conv[entry])
            for rows, values in zip(bounds, (b.point_lo, b.point_hi, b.gap_lo, b.gap_hi), strict=True):
                rows[row] = values
        self._push_trajectory(t_rel, bounds, k0)
        self._push_run(conv, entry, members, entry_values)
        self._feed_every(*checks)

    def _run_and_checks(self, t_rel: IntArray, x: FloatArray, y: FloatArray, dist: FloatArray | None,
                        checks: tuple[IntArray, FloatArray, FloatArray, tuple[FloatArray, FloatArray, int] | None]
                        ) -> None:
        """The second half of a pose batch without signal atoms: the timed run, then the per-sample checks."""
        self._push_run(*self._run_changes(t_rel, x, y, dist), {})
        self._feed_every(*checks)

    def _finish_pose(self) -> None:
        """The second half of the last pose batch, if it was left for later."""
        if self._second_half is not None:
            second, self._second_half = self._second_half, None
            second()

    def _push_trajectory(self, t_rel: IntArray, bounds: tuple[FloatArray, FloatArray, FloatArray, FloatArray],
                         k0: int) -> None:
        """Trajectory semantics: the positions after the previous sample (its gap to each new sample, then the
        sample) with every atom's bounds there, then one evaluation step."""
        tr = self._traj
        start, stop, is_point, lo, hi = positions_after(t_rel, *bounds, first=k0 == 0)
        known = np.where(is_point, start, stop + 1)
        for k, name in enumerate(self._names):
            tr.atoms[name].push(lo[k], hi[k], known)
        tr.track.append(start, stop, is_point)
        tr.track.tick(t_rel[k0:])
        tr.evaluation.step()

    def _run_changes(self, t_rel: IntArray, x: FloatArray, y: FloatArray, dist: FloatArray | None
                     ) -> tuple[IntArray, IntArray, list[str]]:
        """The timed run's new entries (``RunLog.changes``): the converted times, the entries among them, and the
        regions containing the robot at each."""
        entry, members, conv = self._run_log.changes(t_rel, x, y, self._geometry.containment(x, y, dist))
        return conv, entry, members

    def _push_run(self, conv: IntArray, entry: IntArray, members: list[str],
                  entry_values: dict[str, tuple[FloatArray, FloatArray]]) -> None:
        """Timed-run semantics: the new entries with every atom's value there, the new ticks, one evaluation step."""
        run = self._run
        if entry.size:
            t_e = conv[entry]
            self._run_log.record(members, t_e, entry_values)
            run.track.append(t_e, t_e, np.ones(entry.size, dtype=bool))
            unknown_entry = np.array([m == UNKNOWN_ENTRY for m in members], dtype=bool)
            some_unknown = bool(unknown_entry.any())
            labels = self._run_log.entry_labels
            for name in self._names:
                if name in entry_values:
                    e_lo, e_hi = entry_values[name]
                    run.atoms[name].push(e_lo, e_hi, t_e)
                    continue
                v1 = np.array([1.0 if name in labels[m] else -1.0 for m in members])
                if some_unknown:  # every label unknown there
                    run.atoms[name].push(np.where(unknown_entry, -np.inf, v1), np.where(unknown_entry, np.inf, v1),
                                         t_e)
                else:
                    run.atoms[name].push(v1, v1, t_e)
        run.track.tick(conv)
        run.evaluation.step()

    def _feed_every(self, et: IntArray, ex: FloatArray, ey: FloatArray,
                    reuse: tuple[FloatArray, FloatArray, int] | None = None) -> None:
        """The per-sample checks on pose samples (``SampleChecks.feed_poses``)."""
        self._checks.feed_poses(et, ex, ey, self.t0_ns or 0, reuse)

    # ---- state -------------------------------------------------------------------------------------------------------
    def _head_state(self, name: str, h: Head, *, margin: bool) -> CheckState:
        """Margin so far, by the certificate's rule (``reported_margin``): the guaranteed robustness on a pass, the
        optimistic one on a fail (how far from being satisfied it is at best), none while undecided."""
        verdict = h.verdict
        t0 = self.t0_ns or 0
        m: float | None = None
        if margin:
            m = reported_margin(verdict, h.lo, h.hi)
            m = m if m is not None and math.isfinite(m) else None
        decided_at = rel_s(h.decided_ns + t0, t0) if h.decided and h.decided_ns is not None else None
        first = rel_s(h.witness_ns + t0, t0) if verdict == "fail" and h.witness_ns is not None else None
        final_at = rel_s(h.final_ns + t0, t0) if h.final_ns is not None else None
        return CheckState(name, verdict, h.decided, decided_at, m, first, h.margin_final,
                          self._units.get(name) if margin else None, final_at)

    def _check_states(self) -> list[CheckState]:
        t0 = self.t0_ns
        if self._final is not None:
            end = self._traj.track.end_ns
            end_s = None if end is None else round(end * 1e-9, 9)
            return [CheckState(c.name, c.verdict, True, end_s,
                               c.margin if c.margin is None or math.isfinite(c.margin) else None,
                               rel_s(c.first_violation_ns, t0), True,
                               c.details.get("margin_unit", self._units.get(c.name)), end_s) for c in self._final]
        return [c for c in self._running_states() if c.name in self._selected]

    @property
    def _time0_ns(self) -> int | None:
        """Time 0: the first pose sample, judged or still buffered (None before any)."""
        if self.t0_ns is not None:
            return self.t0_ns
        return self._pose.t[0] if self._pose.t else None

    def _running_states(self) -> list[CheckState]:
        return [self._head_state("spec_trajectory", self._traj.head, margin=True),
                self._head_state("spec_timed_run", self._run.head, margin=False), *self._sample_states()]

    def _sample_states(self) -> list[CheckState]:
        """The per-sample checks before ``close``: decided only by failing (obstacle clearance: also with no unsafe
        region to touch)."""
        t0 = self._time0_ns
        out: list[CheckState] = []
        for name, failed, when, m in self._checks.running():
            if name == "obstacle_clearance" and not self._checks.unsafe:
                out.append(CheckState(name, "pass", True, 0.0, None, None))
                continue
            out.append(CheckState(name, "fail" if failed else "inconclusive", failed, rel_s(when, t0), m,
                                  rel_s(when, t0)))
        return out

    def state(self) -> MonitorState:
        """The current state of every check and obligation (judges the buffered samples first)."""
        if not self._closed:
            self._process()
        if self._result is not None:
            return self._result.state
        return self._state(closed=False)

    def _state(self, closed: bool) -> MonitorState:
        checks = self._check_states()
        obligations = [self._head_state(name, h, margin=True)
                       for name, h in zip(self._obligation_names, self._traj.obligations, strict=True)
                       if "spec" in self.selection]
        if closed and obligations and self._formula_doubt():  # as spec_trajectory: what passed cannot pass
            obligations = [replace(o, verdict="inconclusive", margin=None, margin_final=True) if o.verdict == "pass"
                           else o for o in obligations]
        verdict = "fail" if any(c.verdict == "fail" and c.decided for c in checks) else "inconclusive"
        return MonitorState(verdict, tuple(checks), tuple(obligations), dict(self.counts), closed)

    def _newly_decided(self) -> list[CheckState]:
        """Before ``close``: the states ``_state`` gives, in its order, of the selected obligations and checks
        decided but not reported yet (the others' are not built: this runs at every judging)."""
        rep, sel = self._reported, self._selected
        out: list[CheckState] = []
        if "spec" in self.selection:
            out += [self._head_state(n, h, margin=True)
                    for n, h in zip(self._obligation_names, self._traj.obligations, strict=True)
                    if h.decided and n not in rep]
        out += [self._head_state(n, h, margin=n == "spec_trajectory")
                for n, h in (("spec_trajectory", self._traj.head), ("spec_timed_run", self._run.head))
                if h.decided and n in sel and n not in rep]
        if any((failed or (name == "obstacle_clearance" and not self._checks.unsafe)) and name in sel
               and name not in rep for name, failed, _, _ in self._checks.running()):
            out += [c for c in self._sample_states() if c.decided and c.name in sel and c.name not in rep]
        return out

    def _new_decisions(self) -> list[Decision]:
        if self._time0_ns is None:  # a command decided before any pose sample: told once time 0 is known
            return []
        if self._closed:
            st = self._state(closed=True)
            states = [c for c in (*st.obligations, *st.checks) if c.decided and c.name not in self._reported]
        else:
            states = self._newly_decided()
        out: list[Decision] = []
        for c in states:
            self._reported.add(c.name)
            out.append(c.decision())
        out.sort(key=lambda d: d.time_s)
        return out

    @property
    def retained_positions(self) -> int:
        """Positions and values held by the formula's evaluation (bounded by the windows times the rate)."""
        return self._traj.evaluation.retained() + self._run.evaluation.retained()

    # ---- end of the run --------------------------------------------------------------------------------------------
    def close(self, *, partial: bool = False, problems: Mapping[str, str] | None = None) -> OnlineResult:
        """End of observation at the last pose sample: the final verdict of every check, as ``certify_log`` gives
        for a log with the same samples (``partial``: the log was salvaged, never a pass; ``problems``: stream ->
        why nothing judged on it can pass, as ``LogData.stream_problems``)."""
        if self._result is not None:
            return self._result
        self._process(closing=True)
        self._closed = True
        for sem in (self._traj, self._run):
            sem.evaluation.step(closing=True)
        self._checks.resolve_tube(closing=True)
        checks = self._final_checks()
        self._final = checks
        self._final_decisions = self._unreturned + self._new_decisions()
        self._unreturned = []
        problems = dict(problems or {})
        if self.out_of_order["pose"]:
            problems["pose"] = (f"{self.out_of_order['pose']} pose sample(s) arrived out of time order and were not "
                                f"judged")
        for name, feed in sorted(self._feeds.items()):  # as certify: the run is the pose's span, and cannot pass
            if self.t0_ns is not None and feed.violates_outside(self.t0_ns, self._pose.last_ns):
                problems[f"signal {name}"] = ("messages outside the pose's span violate its predicate: the run is "
                                              "the pose's span, so they are not judged and the run cannot pass")
        verdict, why = overall_verdict([(c.name, c.verdict) for c in checks], partial=partial, problems=problems)
        self._result = OnlineResult(verdict, why, tuple(checks), self._state(closed=True))
        return self._result

    @property
    def final_decisions(self) -> list[Decision]:
        """The decisions made by ``close`` (every check still open at the end)."""
        return list(getattr(self, "_final_decisions", []))

    def _formula_doubt(self) -> str | None:
        """Why the formula, as judged online, cannot pass: pose or signal samples that arrived for an instant
        already judged, or (signals without ``rate_hz``) a hold that the whole stream's median spacing changes."""
        why: list[str] = []
        if self._formula_late_conflicts:
            why.append(f"{self._formula_late_conflicts} pose sample(s) judged before a sample at the same time with "
                       f"other values arrived")
        for name, feed in self._feeds.items():
            if feed.late:
                why.append(f"{feed.late} message(s) of signal {name} arrived after the pose samples at or after "
                           f"their time were judged (more than the lag bound late, or out of order)")
            if feed.hold_mismatch():
                why.append(f"signal {name} has no rate_hz: it was judged with the median spacing seen so far, and "
                           f"the whole stream's median (hold {feed.final_hold_ns() * 1e-9:g} s) would judge a "
                           f"stretch differently")
        return "; ".join(why) or None

    def _final_checks(self) -> list[CheckResult]:
        t0 = self.t0_ns
        traj, run = self._traj.head, self._run.head
        if t0 is None:
            spec_traj = CheckResult("spec_trajectory", "inconclusive", None, None, {"reason": "no pose samples"})
            spec_run = CheckResult("spec_timed_run", "inconclusive", None, None, {"reason": "no pose samples"})
        else:
            v = traj.verdict
            spec_traj = CheckResult("spec_trajectory", v, reported_margin(v, traj.lo, traj.hi),
                                    traj.witness_ns + t0 if v == "fail" and traj.witness_ns is not None else None,
                                    {"guaranteed_margin_m": traj.lo, "optimistic_margin_m": traj.hi})
            rv = run.verdict if self._run.track.count else "inconclusive"
            run_margin, run_reason = (self._run_log.margin_s(str(self.formula), self._pose.last_ns - t0)
                                      if rv == "fail" else (None, None))
            spec_run = CheckResult("spec_timed_run", rv, run_margin,
                                   run.witness_ns + t0 if rv == "fail" and run.witness_ns is not None else None,
                                   ({} if self._run.track.count else {"reason": "the timed run is empty"})
                                   | ({"margin_reason": run_reason} if run_reason else {}))
        why = self._formula_doubt()
        if why:  # a judged sample turned out unknown (or may have been judged otherwise): the formula cannot pass
            spec_traj, spec_run = (CheckResult(c.name, "inconclusive", None, None, {**c.details, "reason": why})
                                   if c.verdict == "pass" else c for c in (spec_traj, spec_run))
        every = [spec_traj, spec_run, *self._checks.results()]
        return [c for c in every if c.name in self._selected]


def feed_log_data(monitor: OnlineMonitor, log: LogData, *, update_every: int = 0) -> list[Decision]:
    """Push every sample of a read log in time order (the streams and the signals merged), as a recorder would
    deliver them; ``update_every`` > 0: call ``update`` after that many pose samples. Returns the decisions made."""
    streams: list[tuple[str, IntArray, FloatArray]] = [
        ("pose", log.pose.t_ns, np.column_stack((log.pose.x_m, log.pose.y_m)))]
    if log.nominal is not None:
        streams.append(("nominal", log.nominal.t_ns, np.column_stack((log.nominal.x_m, log.nominal.y_m))))
    if log.cmd_t_ns is not None and log.cmd_u is not None:
        streams.append(("cmd", log.cmd_t_ns, log.cmd_u))
    push: dict[str, Callable[..., None]] = {"pose": monitor.push_pose, "nominal": monitor.push_nominal,
                                            "cmd": monitor.push_cmd}
    for name, sig in sorted(log.signals.items()):
        streams.append((f"signal:{name}", sig.t_ns, sig.value.reshape(-1, 1)))
        push[f"signal:{name}"] = partial(monitor.push_signal, name)
    kinds = np.concatenate([np.full(t.shape[0], k, dtype=np.int64) for k, (_, t, _) in enumerate(streams)])
    index = np.concatenate([np.arange(t.shape[0], dtype=np.int64) for _, t, _ in streams])
    order = np.argsort(np.concatenate([t for _, t, _ in streams]), kind="stable")
    columns = [(push[name], t.tolist(), values.tolist()) for name, t, values in streams]
    out: list[Decision] = []
    poses = 0
    for k, i in zip(kinds[order].tolist(), index[order].tolist(), strict=True):
        fn, t, values = columns[k]
        fn(t[i], *values[i])
        if k == 0:
            poses += 1
            if update_every and poses % update_every == 0:
                out.extend(monitor.update())
    out.extend(monitor.update())
    return out
