"""Watch a log while it is written: a growing log + scenario -> one line per decision, then certify's exit code.

input: a log path (MCAP file, ROS2 bag folder, ROS1 bag, sqlite3 storage) that a recorder may still be writing, a
scenario (and formula), ``follow``/``idle_timeout`` -> output: ``WatchResult`` (decisions, the monitor's final
result, whether the log was finished by its recorder). ``watch_log`` reads the records completed so far with a
``verify.online.follow`` follower, decodes them with the certifier's decoders (the pose, nominal and command
topics and the topics of the signal atoms the formula uses), pushes them into an ``OnlineMonitor`` and reports each
decision through ``on_decision``.

Reading rules: certify's (``verify.ingest.rules.ReadingRules``: the pose topic, the transform's child frame, each
stream's time base, ``TwistStamped`` commands, clock corrections: the scenario's ``clock_offsets`` and
``clock_offsets``, as ``--clock-offset`` gives them).

Time base: ``header`` or ``log`` as given. ``auto`` is certify's rule (``verify.ingest.timebase.choose_time_base``:
header stamps unless they cannot order the samples), which certify applies to the whole pose stream:
- without ``follow`` (a log read once, complete or not) the messages are held until the end of the reading and the
  rule is applied to the whole pose stream, as certify does: the same base by construction;
- with ``follow`` the rule is applied to the pose messages read when ``AUTO_PROBE`` of them are in (all of them, if
  the log ends first) and the base chosen is kept. At the end the rule is applied again to every pose stamp read;
  if certify would choose the other base, the decisions were made on a base certify would not use, and the run's
  verdict is inconclusive (a fail too), with a note that says so.

It stops when every check and obligation is decided, when the recorder has closed the log, when the log has not
grown for ``idle_timeout`` seconds (its bytes: ``verify.online.follow.log_bytes``; ``follow``), or after one read
(no ``follow``). A log its recorder did not close is judged as ``--salvage`` judges it: its complete records,
partial, never a pass.
"""

from __future__ import annotations

import time
from collections.abc import Callable, Mapping
from dataclasses import dataclass, field, replace
from pathlib import Path
from typing import TypeVar

import numpy as np
import numpy.typing as npt

from verify.errors import LogReadError, MissingTopicError, UnusableInputError, VerifyError
from verify.ingest.decode import PoseColumns, decode_pose, decode_twist
from verify.ingest.fields import decode_field
from verify.ingest.raw import RawTopic, check_log_path
from verify.ingest.readerrors import READ_ERRORS, in_words, one_type_per_topic
from verify.ingest.rules import ReadingRules
from verify.ingest.salvage import SalvagedMessage
from verify.ingest.timebase import TIME_BASES, TimeBase, choose_time_base
from verify.online.fleet import FleetMonitor, FleetResult, RobotFeed
from verify.online.follow import log_bytes, open_follower
from verify.online.monitor import Decision, OnlineMonitor, OnlineResult

__all__ = ["WatchResult", "watch_log"]

T = TypeVar("T")
#: what makes an optional stream unused rather than the log unusable (as ``verify.ingest.log``)
_OPTIONAL_ERRORS: tuple[type[BaseException], ...] = (VerifyError, *READ_ERRORS)
#: ``--time-base auto`` with ``follow``: pose messages whose header stamps decide the time base
AUTO_PROBE = 50


@dataclass(slots=True)
class WatchResult:
    result: OnlineResult | FleetResult
    decisions: list[Decision]
    finished: bool  # the recorder closed the log
    stop_reason: str
    messages: int
    notes: list[str] = field(default_factory=list)

    @property
    def partial(self) -> bool:
        return not self.finished


class _Feeder:
    """Decodes the messages of one poll and pushes them, stream by stream in stamp order, into the monitor, under
    the reading rules certify applies (``verify.ingest.rules.ReadingRules``)."""

    def __init__(self, monitor: OnlineMonitor | RobotFeed, rules: ReadingRules, ros1: bool, path: Path, *,
                 probe: int | None) -> None:
        self.monitor = monitor
        self.rules = rules
        self.scenario = rules.scenario
        self.ros1 = ros1
        self.requested = rules.requested
        self.probe = probe  # auto: pose messages read before the base is chosen (None: the whole stream)
        self.time_base: str | None = None if rules.requested == "auto" else rules.requested  # None: not chosen yet
        self.chosen_on: int | None = None  # auto: how many pose messages the base was chosen on
        self.base_note: str | None = None
        self.path = path
        self.pose_topic: str | None = None
        self.seen_topics: dict[str, str] = {}
        self._held: list[SalvagedMessage] = []  # auto: the messages read before the base is chosen
        self._stamps: list[npt.NDArray[np.int64]] = []  # auto: every pose header stamp and log time read
        self._logs: list[npt.NDArray[np.int64]] = []
        self.problems: dict[str, str] = {}  # stream -> why nothing judged on it can pass (as read_log's)
        self.unused: dict[str, str] = {}  # optional stream (nominal, cmd_vel) -> why its messages are not used
        self.pushed: dict[str, int] = {"nominal": 0, "cmd_vel": 0}
        # the signal atoms the formula uses: topic -> [(name, field)]
        self.signals: dict[str, list[tuple[str, str]]] = {}
        for name in monitor.signal_names:
            spec = self.scenario.signals[name]
            self.signals.setdefault(spec.topic, []).append((name, spec.field))

    def feed(self, messages: list[SalvagedMessage], *, final: bool = False) -> None:
        """Push the messages of one poll (``final``: the log ends; an auto time base is chosen now at the latest)."""
        if self.time_base is None:
            self._held += messages
            for m in messages:
                self.seen_topics.setdefault(m.topic, m.msgtype)
            self._find_pose_topic()
            pose = [m for m in self._held if m.topic == self.pose_topic]
            if not final and (self.probe is None or len(pose) < self.probe):
                return
            self.time_base = self._choose(pose)
            messages, self._held = self._held, []
        self._feed(messages)

    def _choose(self, pose: list[SalvagedMessage]) -> str:
        if not pose:
            return "header"
        cols = self._decoded(lambda: self._decode_pose(pose))
        base = choose_time_base(cols.stamp_ns, np.asarray(cols.log_ns, dtype=np.int64), "auto")
        self.chosen_on = len(pose)
        on = "the whole pose stream" if self.probe is None else "the first"
        self.base_note = (f"--time-base auto: {base.name} time, chosen on {on} {len(pose)} pose messages"
                          + (" as certify chooses" if self.probe is None else "")
                          + (f" ({base.note})" if base.note else ""))
        return base.name

    def _decoded(self, decode: Callable[[], T]) -> T:
        try:
            return decode()
        except LogReadError as err:
            raise LogReadError(err.reason, path=str(self.path)) from err
        except READ_ERRORS as err:  # a decoder's error on damaged bytes: one line, as read_log words it
            if isinstance(err, VerifyError):
                raise
            raise LogReadError(f"messages cannot be decoded: {in_words(err)}", path=str(self.path)) from err

    def _find_pose_topic(self) -> None:
        if self.pose_topic is None:
            self.pose_topic = self.rules.pose_topic(self.seen_topics)

    def _decode_pose(self, msgs: list[SalvagedMessage]) -> PoseColumns:
        return decode_pose(self._raw(msgs), self.ros1, child_frame=self.rules.child_frame(msgs[0].msgtype))

    def base_mismatch(self) -> str | None:
        """auto, chosen before the whole pose stream was read: why certify, which decides on the whole stream, would
        judge this log on another time base (None: it would choose the same)."""
        if self.requested != "auto" or self.time_base is None or not self._stamps:
            return None
        whole = choose_time_base(np.concatenate(self._stamps), np.concatenate(self._logs), "auto")
        if whole.name == self.time_base:
            return None
        count = sum(len(s) for s in self._stamps)
        return (f"--time-base auto: the decisions were made on {self.time_base} time, chosen on the first "
                f"{self.chosen_on} pose messages, but on the whole stream ({count} messages) certify chooses "
                f"{whole.name} time ({whole.note or 'the header stamps order the samples'}): the verdict is "
                f"undecided here; run certify, or watch without --follow on the complete log")

    def _raw(self, msgs: list[SalvagedMessage]) -> RawTopic:
        m0 = msgs[0]
        one_type_per_topic([(m0.topic, self.seen_topics.get(m0.topic, m0.msgtype)),
                            *((m.topic, m.msgtype) for m in msgs)], str(self.path))
        return RawTopic(m0.topic, m0.msgtype, m0.has_definition, [m.log_ns for m in msgs], [m.payload for m in msgs])

    def _feed(self, messages: list[SalvagedMessage]) -> None:
        t = self.scenario.topics
        by_topic: dict[str, list[SalvagedMessage]] = {}
        for m in messages:
            self.seen_topics.setdefault(m.topic, m.msgtype)
            by_topic.setdefault(m.topic, []).append(m)
        self._find_pose_topic()

        def push_all() -> None:
            # the signals first: a pose sample is judged once they reach its time (or the lag bound) -- a message
            # pushed after the pose samples of its poll could arrive for a time judged already (late)
            for topic, fields in self.signals.items():
                if topic in by_topic:
                    self._push_signals(by_topic[topic], fields)
            nominal = by_topic.get(t.nominal) if t.nominal is not None else None
            if nominal and "nominal" not in self.unused:
                self._optional("nominal", nominal, lambda: self._push_pose(nominal, self.monitor.push_nominal,
                                                                           pose=False))
            if self.pose_topic in by_topic:
                self._push_pose(by_topic[self.pose_topic], self.monitor.push_pose, pose=True)
            cmd = by_topic.get(t.cmd_vel) if t.cmd_vel is not None else None
            if cmd and "cmd_vel" not in self.unused:
                self._optional("cmd_vel", cmd, lambda: self._push_cmd(cmd))

        self._decoded(push_all)

    def _push_cmd(self, msgs: list[SalvagedMessage]) -> None:
        tw = decode_twist(self._raw(msgs), self.ros1)
        tb, cst = self.rules.stream_times(msgs[0].topic, tw.stamp_ns, tw.log_ns, pose_base=self._pose_base)
        self._problem("cmd_vel", tb)
        for k in np.argsort(cst, kind="stable").tolist():
            self.monitor.push_cmd(int(cst[k]), *(float(v) for v in tw.u[k]))

    def _optional(self, stream: str, msgs: list[SalvagedMessage], push: Callable[[], None]) -> None:
        """An optional stream whose messages cannot be decoded is not used, as ``read_log`` does not use it (a
        finding, not an error; one topic with two types stays an error, as in ``read_log``); if some of its
        messages were judged already (following a growing log), the run cannot pass."""
        topic = msgs[0].topic
        self._raw(msgs)  # one topic, one type: exit 3 as read_log's reader
        try:
            push()
        except _OPTIONAL_ERRORS as err:
            words = err.reason if isinstance(err, UnusableInputError) else in_words(err)
            self.unused[stream] = f"{topic}: messages cannot be decoded ({words}); the {stream} stream is not used"
            if self.pushed[stream]:
                self.problems[stream] = f"messages of {topic} were judged before one that cannot be decoded"
            return
        self.pushed[stream] += 1

    def _problem(self, stream: str, tb: TimeBase) -> None:
        """An explicit header base whose stamps cannot order a stream's samples: no pass (as read_log)."""
        if not tb.usable and self.requested != "auto" and tb.note:
            self.problems.setdefault(stream, tb.note)

    @property
    def _pose_base(self) -> str:
        return self.time_base or "header"

    def _push_signals(self, msgs: list[SalvagedMessage], fields: list[tuple[str, str]]) -> None:
        """Times under the rules of every stream, the topic's clock correction included."""
        raw = self._raw(msgs)
        decoded: dict[str, tuple[np.ndarray, np.ndarray]] = {}
        for name, fld in fields:
            if fld not in decoded:
                cols = decode_field(raw, self.ros1, fld)
                tb, times = self.rules.stream_times(msgs[0].topic, cols.stamp_ns, cols.log_ns,
                                                    pose_base=self._pose_base)
                decoded[fld] = (times, cols.value)
                self._problem(f"signal {name}", tb)
            stamps, values = decoded[fld]
            for k in np.argsort(stamps, kind="stable").tolist():
                self.monitor.push_signal(name, int(stamps[k]), float(values[k]))

    def _push_pose(self, msgs: list[SalvagedMessage], push: Callable[..., None], *, pose: bool) -> None:
        topic = msgs[0].topic
        if pose:  # the pose: on the base chosen, its stamps' outliers re-timed
            cols = self._decode_pose(msgs)
            tb, stamps = self.rules.pose_times(topic, cols.stamp_ns, cols.log_ns, base=self._pose_base)
            self._problem("pose", tb)
            if self.requested == "auto":
                self._stamps.append(np.asarray(cols.stamp_ns, dtype=np.int64))
                self._logs.append(np.asarray(cols.log_ns, dtype=np.int64))
        else:
            cols = decode_pose(self._raw(msgs), self.ros1)
            tb, stamps = self.rules.stream_times(topic, cols.stamp_ns, cols.log_ns, pose_base=self._pose_base)
            self._problem("nominal", tb)
        for k in np.argsort(stamps, kind="stable").tolist():
            push(int(stamps[k]), float(cols.x_m[k]), float(cols.y_m[k]))


def watch_log(path: str | Path, monitor: OnlineMonitor | FleetMonitor, *, follow: bool = False,
              idle_timeout_s: float = 10.0,
              poll_s: float = 0.2, time_base: str = "header", clock_offsets: Mapping[str, float] | None = None,
              on_decision: Callable[[Decision], None] | None = None) -> WatchResult:
    """Judge the log at ``path`` as it grows (see the module docstring); never modifies it. ``clock_offsets``
    (topic -> seconds added to that topic's times) extends and overrides the scenario's, as certify's
    ``--clock-offset`` does."""
    p = Path(path)
    waited = time.monotonic()
    while follow and not p.exists() and time.monotonic() - waited < idle_timeout_s:
        time.sleep(poll_s)  # the recorder may not have created the log yet
    if not p.exists():
        raise LogReadError("no such file or directory" + (f" (waited {idle_timeout_s:g} s)" if follow else ""),
                           path=str(p))
    if time_base not in TIME_BASES:
        raise LogReadError(f"time_base={time_base!r} must be one of {', '.join(TIME_BASES)}", path=str(p))
    rules = ReadingRules.of(monitor.scenario, time_base, clock_offsets)  # the offsets' ranges, before reading
    check_log_path(p)
    follower = open_follower(p)
    ros1, probe = follower.format == "ros1", AUTO_PROBE if follow else None
    # several robots: one feeder per robot (its topics, under its one-robot scenario's reading rules), all into the
    # fleet monitor
    if isinstance(monitor, FleetMonitor):
        robots = [monitor.robot_feed(name) for name in monitor.scenario.robot_names]
        feeders = [_Feeder(f, ReadingRules.of(f.scenario, time_base, clock_offsets), ros1, p, probe=probe)
                   for f in robots]
    else:
        feeders = [_Feeder(monitor, rules, ros1, p, probe=probe)]
    decisions: list[Decision] = []
    count = 0

    def report(new: list[Decision]) -> None:
        for d in new:
            decisions.append(d)
            if on_decision is not None:
                on_decision(d)

    def read(step: Callable[[], list[SalvagedMessage]]) -> list[SalvagedMessage]:
        try:
            return step()
        except READ_ERRORS as err:  # the follower's reader or decompressor on damaged bytes
            if isinstance(err, VerifyError):
                raise
            raise LogReadError(f"unreadable log: {in_words(err)}", path=str(p)) from err

    last_growth = time.monotonic()
    last_bytes = log_bytes(p)
    while True:
        msgs = read(follower.poll)
        if msgs:
            count += len(msgs)
            for feeder in feeders:
                feeder.feed(msgs, final=follower.finished)
            report(monitor.update())
        if (now_bytes := log_bytes(p)) != last_bytes or msgs:  # the idle timer measures the log's bytes (and mtime)
            last_bytes, last_growth = now_bytes, time.monotonic()
        if follower.finished:
            reason = "the recorder closed the log"
            break
        if monitor.state().all_decided:
            reason = "every check and obligation is decided"
            break
        if not follow:
            reason = "read once (no --follow)"
            break
        if time.monotonic() - last_growth >= idle_timeout_s:
            reason = f"the log did not grow for {idle_timeout_s:g} s"
            break
        time.sleep(poll_s)
    notes: list[str] = []
    if not follower.finished:
        extra = read(follower.rest)  # what --salvage reads beyond the complete chunks (a cut uncompressed chunk)
        count += len(extra)
        for feeder in feeders:
            feeder.feed(extra, final=True)
        notes.append("the log was not closed by its recorder: judged as --salvage judges it (partial)")
    else:
        for feeder in feeders:
            feeder.feed([], final=True)
    mismatches: list[str] = []
    for feeder in feeders:
        mismatch = feeder.base_mismatch()
        mismatches += [mismatch] if mismatch else []
        notes += [n for n in (feeder.base_note, mismatch, *feeder.unused.values()) if n and n not in notes]
        if feeder.pose_topic is None:
            raise feeder.rules.missing_pose(feeder.seen_topics, str(p))
        if feeder.monitor.counts["pose"] == 0:
            raise MissingTopicError(f"pose topic {feeder.pose_topic} has no messages", path=str(p))
        if reason != "every check and obligation is decided":  # every topic of the log seen: as certify, first
            feeder.rules.check_offset_topics(feeder.seen_topics, str(p))
        for topic, fields in feeder.signals.items():
            if topic not in feeder.seen_topics:
                have = ", ".join(sorted(feeder.seen_topics)) or "no topics"
                raise MissingTopicError(f"signal {fields[0][0]}: topic {topic} (field {fields[0][1]}) is absent "
                                        f"from the log; the log has: {have}", path=str(p))
    result: OnlineResult | FleetResult
    if isinstance(monitor, FleetMonitor):
        result = monitor.close(partial=not follower.finished,
                               stream_problems={f.monitor.robot: f.problems for f in feeders
                                         if isinstance(f.monitor, RobotFeed)})
    else:
        result = monitor.close(partial=not follower.finished, problems=feeders[0].problems)
    if mismatches and result.verdict != "inconclusive":
        result = replace(result, verdict="inconclusive", verdict_reason=mismatches[0])
    report(monitor.final_decisions)
    return WatchResult(result, decisions, follower.finished, reason, count, notes)
