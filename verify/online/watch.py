"""Watch a log while it is written: a growing log + scenario -> one line per decision, then certify's exit code.

input: a log path (MCAP file, ROS2 bag folder, ROS1 bag, sqlite3 storage) that a recorder may still be writing, a
scenario (and formula), ``follow``/``idle_timeout`` -> output: ``WatchResult`` (decisions, the monitor's final
result, whether the log was finished by its recorder). ``watch_log`` reads the records completed so far with a
``verify.online.follow`` follower, decodes them with the certifier's decoders (the pose, nominal and command
topics and the topics of the signal atoms the formula uses), pushes them into an ``OnlineMonitor`` and reports each
decision through ``on_decision``.

Time base: ``header`` or ``log`` as given; ``auto`` is certify's rule (``verify.ingest.timebase.choose_time_base``:
header stamps unless they cannot order the samples) applied to the first ``AUTO_PROBE`` pose messages (or all of
them, if the log ends first): the messages are held until then, and the base chosen is kept for the rest of the
log. Certify applies the rule to the whole stream; if the stamps read after the choice repeat, go backwards or are
zero in more than ``UNORDERABLE_FRACTION`` of the stream, a note says that certify would choose log time.

It stops when every check and obligation is decided, when the recorder has closed the log, when the log has not
grown for ``idle_timeout`` seconds (its bytes: ``verify.online.follow.log_bytes``; ``follow``), or after one read
(no ``follow``). A log its recorder did not close is judged as ``--salvage`` judges it: its complete records,
partial, never a pass.
"""

from __future__ import annotations

import time
from collections.abc import Callable
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np
import numpy.typing as npt

from tubempc.scenario import Scenario
from verify.errors import LogReadError, MissingTopicError, VerifyError
from verify.ingest.clocks import clock_offsets_ns
from verify.ingest.decode import TF, TRANSFORM_STAMPED, PoseColumns, decode_pose, decode_twist
from verify.ingest.fields import decode_field
from verify.ingest.raw import RawTopic, check_log_path
from verify.ingest.readerrors import READ_ERRORS, in_words, one_type_per_topic
from verify.ingest.salvage import SalvagedMessage
from verify.ingest.timebase import TIME_BASES, UNORDERABLE_FRACTION, choose_time_base, stream_time_base
from verify.online.fleet import FleetMonitor, FleetResult, RobotFeed
from verify.online.follow import log_bytes, open_follower
from verify.online.monitor import Decision, OnlineMonitor, OnlineResult

__all__ = ["WatchResult", "watch_log"]

TF_TOPIC = "/tf"
#: ``--time-base auto``: pose messages whose header stamps decide the time base
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
    """Decodes the messages of one poll and pushes them, stream by stream in stamp order, into the monitor."""

    def __init__(self, monitor: OnlineMonitor | RobotFeed, scenario: Scenario, ros1: bool, time_base: str,
                 path: Path) -> None:
        self.monitor = monitor
        self.scenario = scenario
        self.ros1 = ros1
        self.requested = time_base
        self.time_base: str | None = None if time_base == "auto" else time_base  # None: not chosen yet (auto)
        self.base_note: str | None = None
        self.path = path
        # as read_log: the scenario's clock_offsets (topic -> s) added to that topic's times
        self.offsets_ns = clock_offsets_ns(scenario.clock_offsets, None)  # range-checked as read_log's
        self.pose_topic: str | None = None
        self.seen_topics: dict[str, str] = {}
        self._held: list[SalvagedMessage] = []  # auto: the messages read before the base is chosen
        self._last_stamp: int | None = None  # auto with header chosen: the stamps' order over the whole stream
        self._stamps = self._bad_stamps = 0
        # the signal atoms the formula uses: topic -> [(name, field)]
        self.signals: dict[str, list[tuple[str, str]]] = {}
        for name in monitor.signal_names:
            spec = scenario.signals[name]
            self.signals.setdefault(spec.topic, []).append((name, spec.field))

    def feed(self, messages: list[SalvagedMessage], *, final: bool = False) -> None:
        """Push the messages of one poll (``final``: the log ends; an auto time base is chosen now at the latest)."""
        if self.time_base is None:
            self._held += messages
            for m in messages:
                self.seen_topics.setdefault(m.topic, m.msgtype)
            self._find_pose_topic()
            pose = [m for m in self._held if m.topic == self.pose_topic]
            if len(pose) < AUTO_PROBE and not final:
                return
            self.time_base = self._choose(pose)
            messages, self._held = self._held, []
        self._feed(messages)

    def _choose(self, pose: list[SalvagedMessage]) -> str:
        if not pose:
            return "header"
        try:
            cols = self._decode_pose(pose)
        except LogReadError as err:
            raise LogReadError(err.reason, path=str(self.path)) from err
        except READ_ERRORS as err:  # a decoder's error on damaged bytes: one line, as read_log words it
            if isinstance(err, VerifyError):
                raise
            raise LogReadError(f"messages cannot be decoded: {in_words(err)}", path=str(self.path)) from err
        base = choose_time_base(cols.stamp_ns, np.asarray(cols.log_ns, dtype=np.int64), "auto")
        self.base_note = (f"--time-base auto: {base.name} time, chosen on the first {len(pose)} pose messages"
                          + (f" ({base.note})" if base.note else ""))
        return base.name

    def _find_pose_topic(self) -> None:
        t = self.scenario.topics
        if self.pose_topic is None:
            if t.pose in self.seen_topics:
                self.pose_topic = t.pose
            elif TF_TOPIC in self.seen_topics and t.tf_child_frame:
                self.pose_topic = TF_TOPIC

    def _decode_pose(self, msgs: list[SalvagedMessage]) -> PoseColumns:
        child = self.scenario.topics.tf_child_frame if msgs[0].msgtype in (TF, TRANSFORM_STAMPED) else None
        return decode_pose(self._raw(msgs), self.ros1, child_frame=child)

    def auto_findings(self) -> str | None:
        """auto, header chosen: whether the whole stream's stamps would make certify choose log time."""
        if self.requested != "auto" or self.time_base != "header" or not self._stamps:
            return None
        if self._bad_stamps > UNORDERABLE_FRACTION * self._stamps:
            return (f"{self._bad_stamps} of {self._stamps} pose stamps are zero, repeat or go backwards: certify "
                    f"--time-base auto would judge this log on log time")
        return None

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
        try:
            # the signals first: a pose sample is judged once they reach its time (or the lag bound) -- a message
            # pushed after the pose samples of its poll could arrive for a time judged already (late)
            for topic, fields in self.signals.items():
                if topic in by_topic:
                    self._push_signals(by_topic[topic], fields)
            if t.nominal in by_topic:
                self._push_pose(by_topic[t.nominal], self.monitor.push_nominal, None)
            if self.pose_topic in by_topic:
                msgs = by_topic[self.pose_topic]
                child = t.tf_child_frame if msgs[0].msgtype in (TF, TRANSFORM_STAMPED) else None
                self._push_pose(msgs, self.monitor.push_pose, child)
            if t.cmd_vel in by_topic:
                tw = decode_twist(self._raw(by_topic[t.cmd_vel]), self.ros1)
                cst = self._times(tw.stamp_ns, tw.log_ns) + self.offsets_ns.get(t.cmd_vel, 0)
                for k in np.argsort(cst, kind="stable").tolist():
                    self.monitor.push_cmd(int(cst[k]), *(float(v) for v in tw.u[k]))
        except LogReadError as err:
            raise LogReadError(err.reason, path=str(self.path)) from err
        except READ_ERRORS as err:  # a decoder's error on damaged bytes: one line, as read_log words it
            if isinstance(err, VerifyError):
                raise
            raise LogReadError(f"messages cannot be decoded: {in_words(err)}", path=str(self.path)) from err

    def _push_signals(self, msgs: list[SalvagedMessage], fields: list[tuple[str, str]]) -> None:
        """Times under the rules of every stream (``_times``), plus the topic's clock offset."""
        raw = self._raw(msgs)
        decoded: dict[str, tuple[np.ndarray, np.ndarray]] = {}
        for name, fld in fields:
            if fld not in decoded:
                cols = decode_field(raw, self.ros1, fld)
                offset = self.offsets_ns.get(msgs[0].topic, 0)
                decoded[fld] = (self._times(cols.stamp_ns, cols.log_ns) + offset, cols.value)
            stamps, values = decoded[fld]
            for k in np.argsort(stamps, kind="stable").tolist():
                self.monitor.push_signal(name, int(stamps[k]), float(values[k]))

    def _push_pose(self, msgs: list[SalvagedMessage], push: Callable[..., None], child: str | None) -> None:
        cols = decode_pose(self._raw(msgs), self.ros1, child_frame=child)
        log_ns = np.asarray(cols.log_ns, dtype=np.int64)
        if push == self.monitor.push_pose:  # the pose: its stamps' outliers re-timed on the base chosen
            times = choose_time_base(cols.stamp_ns, log_ns, self.time_base or "header").t_ns
        else:
            times = self._times(cols.stamp_ns, log_ns)
        stamps = times + self.offsets_ns.get(msgs[0].topic, 0)
        if self.requested == "auto" and self.time_base == "header" and push == self.monitor.push_pose:
            self._count_stamps(np.asarray(cols.stamp_ns, dtype=np.int64))
        for k in np.argsort(stamps, kind="stable").tolist():
            push(int(stamps[k]), float(cols.x_m[k]), float(cols.y_m[k]))


    def _times(self, stamps_ns: npt.NDArray[np.int64] | None, log_ns: npt.ArrayLike) -> npt.NDArray[np.int64]:
        """A stream beside the pose, under the rules of every stream (``verify.ingest.timebase.stream_time_base``),
        applied to the messages of one poll (all of them when the log is read once)."""
        base = stream_time_base(stamps_ns, np.asarray(log_ns, dtype=np.int64),
                                requested="log" if self.time_base == "log" else self.requested,
                                pose_base=self.time_base or "header")
        return base.t_ns

    def _count_stamps(self, stamps: npt.NDArray[np.int64]) -> None:
        """Stamps that are zero or negative, repeat the previous one or go back (reading order)."""
        prev = np.concatenate(([self._last_stamp], stamps[:-1])) if self._last_stamp is not None else None
        bad = stamps <= 0
        if prev is not None:
            bad |= stamps <= prev
        elif stamps.size > 1:
            bad[1:] |= stamps[1:] <= stamps[:-1]
        self._stamps += int(stamps.size)
        self._bad_stamps += int(np.count_nonzero(bad))
        if stamps.size:
            self._last_stamp = int(stamps[-1])


def watch_log(path: str | Path, monitor: OnlineMonitor | FleetMonitor, *, follow: bool = False,
              idle_timeout_s: float = 10.0,
              poll_s: float = 0.2, time_base: str = "header",
              on_decision: Callable[[Decision], None] | None = None) -> WatchResult:
    """Judge the log at ``path`` as it grows (see the module docstring); never modifies it."""
    p = Path(path)
    waited = time.monotonic()
    while follow and not p.exists() and time.monotonic() - waited < idle_timeout_s:
        time.sleep(poll_s)  # the recorder may not have created the log yet
    if not p.exists():
        raise LogReadError("no such file or directory" + (f" (waited {idle_timeout_s:g} s)" if follow else ""),
                           path=str(p))
    if time_base not in TIME_BASES:
        raise LogReadError(f"time_base={time_base!r} must be one of {', '.join(TIME_BASES)}", path=str(p))
    check_log_path(p)
    follower = open_follower(p)
    ros1 = follower.format == "ros1"
    # several robots: one feeder per robot (its topics, under its one-robot scenario), all into the fleet monitor
    if isinstance(monitor, FleetMonitor):
        robots = [monitor.robot_feed(name) for name in monitor.scenario.robot_names]
        feeders = [_Feeder(f, f.scenario, ros1, time_base, p) for f in robots]
    else:
        feeders = [_Feeder(monitor, monitor.scenario, ros1, time_base, p)]
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
                feeder.feed(msgs)
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
    for feeder in feeders:
        notes += [n for n in (feeder.base_note, feeder.auto_findings()) if n and n not in notes]
        if feeder.pose_topic is None or feeder.monitor.counts["pose"] == 0:
            have = ", ".join(sorted(feeder.seen_topics)) or "no topics"
            raise MissingTopicError(f"pose topic {feeder.scenario.topics.pose} is absent; the log has: {have}",
                                    path=str(p))
        for topic, fields in feeder.signals.items():
            if topic not in feeder.seen_topics:
                have = ", ".join(sorted(feeder.seen_topics)) or "no topics"
                raise MissingTopicError(f"signal {fields[0][0]}: topic {topic} (field {fields[0][1]}) is absent "
                                        f"from the log; the log has: {have}", path=str(p))
    result = monitor.close(partial=not follower.finished)
    report(monitor.final_decisions)
    return WatchResult(result, decisions, follower.finished, reason, count, notes)
