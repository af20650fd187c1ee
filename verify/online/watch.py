"""Watch a log while it is written: a growing log + scenario -> one line per decision, then certify's exit code.

input: a log path (MCAP file, ROS2 bag folder, ROS1 bag, sqlite3 storage) that a recorder may still be writing, a
scenario (and formula), ``follow``/``idle_timeout`` -> output: ``WatchResult`` (decisions, the monitor's final
result, whether the log was finished by its recorder). ``watch_log`` reads the records completed so far with a
``verify.online.follow`` follower (``_read``), decodes them with the certifier's decoders (the pose, nominal and
command topics and the topics of the signal atoms the formula uses) and pushes them into an ``OnlineMonitor``
(``_Feeder``), reports each decision through ``on_decision``, and closes the monitor (``_close``).

Reading rules: certify's (``verify.ingest.rules.ReadingRules``: the pose topic, the transform's child frame, each
stream's time base, ``TwistStamped`` commands, clock corrections: the scenario's ``clock_offsets`` and
``clock_offsets``, as ``--clock-offset`` gives them).

Time rule: one for every stream (pose, nominal, commands, every signal topic), applied as certify applies it: to
the whole stream, in certify's reading order (by log time for a ROS1 or MCAP log its recorder closed, else the file
order; a sqlite3 storage in its timestamp index's order, as the follower delivers it; ``verify.online.streamtimes``,
``_Reading.by_log_time``):
- without ``follow`` (a log read once, complete or not) the messages are held until the end of the reading and
  pushed at once, each stream in certify's order: the rule sees each whole stream as certify does (the same time
  base for the pose -- ``auto``: ``verify.ingest.timebase.choose_time_base`` on the whole pose stream -- and the
  same re-timed stamps on every stream), the same times by construction;
- with ``follow`` an ``auto`` base is chosen on the pose messages read when ``AUTO_PROBE`` of them are in (all of
  them, if the log ends first) and kept; each poll's samples are timed with the samples read before them as
  context. At the end the rule is applied again to every stream whole, in certify's order: if certify would choose
  the other base for the pose, or give a sample of any stream another time, the decisions were made on times
  certify would not use, and the run's verdict is inconclusive (a fail too), with a note that says so.

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
from verify.ingest.fields import FieldSamples, decode_field
from verify.ingest.log import wanted_topics
from verify.ingest.raw import RawTopic, check_log_path
from verify.ingest.readerrors import READ_ERRORS, in_words, one_type_per_topic
from verify.ingest.rules import ReadingRules
from verify.ingest.salvage import SalvagedMessage
from verify.ingest.timebase import TIME_BASES
from verify.online.fleet import FleetMonitor, FleetResult, RobotFeed
from verify.online.follow import Follower, log_bytes, open_follower
from verify.online.monitor import Decision, OnlineMonitor, OnlineResult
from verify.online.streamtimes import StreamTimes, TimeRule

__all__ = ["WatchResult", "watch_log"]

T = TypeVar("T")
IntArray = npt.NDArray[np.int64]
#: what makes an optional stream unused rather than the log unusable (as ``verify.ingest.log``)
_OPTIONAL_ERRORS: tuple[type[BaseException], ...] = (VerifyError, *READ_ERRORS)
#: ``--time-base auto`` with ``follow``: pose messages whose header stamps decide the time base
AUTO_PROBE = 50
_ALL_DECIDED = "every check and obligation is decided"


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


def _in_log_order(messages: list[SalvagedMessage]) -> list[SalvagedMessage]:
    """certify's reading order of a closed ROS1 or MCAP log: by log time; among equal ones by
    ``SalvagedMessage.tie`` (a ROS1 message's connection, as rosbags orders them), then the file order (a stable
    sort)."""
    # log times are u64 (a damaged one may be 2**63 or more: certify's reader then sorts as rosbags does, unsigned)
    log_ns = np.fromiter((m.log_ns for m in messages), dtype=np.uint64, count=len(messages))
    ties = np.fromiter((m.tie for m in messages), dtype=np.int64, count=len(messages))
    if bool(np.all(log_ns[1:] > log_ns[:-1])) or (bool(np.all(log_ns[1:] >= log_ns[:-1])) and not ties.any()):
        return messages  # a recorded log: already in that order
    return [messages[k] for k in np.lexsort((ties, log_ns)).tolist()]


class _Feeder:
    """Decodes the messages of one poll and pushes them, stream by stream in time order, into the monitor, under
    the reading rules certify applies (``verify.ingest.rules.ReadingRules``), each stream timed by one
    ``StreamTimes``."""

    def __init__(self, monitor: OnlineMonitor | RobotFeed, rules: ReadingRules, ros1: bool, path: Path, *,
                 probe: int | None) -> None:
        self.monitor = monitor
        self.rules = rules
        self.scenario = rules.scenario
        self.ros1 = ros1
        self.requested = rules.requested
        self.probe = probe  # follow: pose messages read before an auto base is chosen (None: hold the whole log)
        self.time_base: str | None = None if rules.requested == "auto" else rules.requested  # None: not chosen yet
        self.chosen_on: int | None = None  # auto: how many pose messages the base was chosen on
        self.base_note: str | None = None
        self.path = path
        self.pose_topic: str | None = None
        self.seen_topics: dict[str, str] = {}
        self._holding = True  # messages are held until the base is chosen (follow) or the reading ends (no follow)
        self._held: list[SalvagedMessage] = []
        self.times: dict[str, StreamTimes] = {}  # stream (pose, nominal, cmd_vel, a signal topic) -> its samples
        self.problems: dict[str, str] = {}  # stream -> why nothing judged on it can pass (as read_log's)
        self.unused: dict[str, str] = {}  # optional stream (nominal, cmd_vel) -> why its messages are not used
        self.pushed: dict[str, int] = {"nominal": 0, "cmd_vel": 0}
        # the signal atoms the formula uses: topic -> [(name, field)]
        self.signals: dict[str, list[tuple[str, str]]] = {}
        for name in monitor.signal_names:
            spec = self.scenario.signals[name]
            self.signals.setdefault(spec.topic, []).append((name, spec.field))

    # ---- reading ---------------------------------------------------------------------------------------------------
    def feed(self, messages: list[SalvagedMessage], *, final: bool = False, by_log_time: bool = False) -> None:
        """Push the messages of one poll (``final``: the log ends -- an auto time base is chosen now at the latest;
        ``by_log_time``: certify reads this log by log time -- ``_Reading.by_log_time``)."""
        if self._holding:
            self._held += messages
            for m in messages:
                self.seen_topics.setdefault(m.topic, m.msgtype)
            self._find_pose_topic()
            if not final and not self._probe_done():
                return
            messages, self._held, self._holding = self._held, [], False
            if final and by_log_time:
                messages = _in_log_order(messages)
            if self.time_base is None:
                self.time_base = self._choose([m for m in messages if m.topic == self.pose_topic])
        self._feed(messages)

    def declare(self, topics: Mapping[str, str]) -> None:
        """Topics the log declares (name -> type) beside the messages delivered (``Follower.declared_topics``: a
        sqlite3 storage's topics table, whose unwanted topics' rows are not read): the log's topics as certify's
        reader lists them, for choosing the pose topic and for naming the log's topics."""
        for name, typ in topics.items():
            self.seen_topics.setdefault(name, typ)

    def _probe_done(self) -> bool:
        """follow: an explicit base is known at once, auto once ``probe`` pose messages are in."""
        if self.probe is None:
            return False
        return self.time_base is not None or sum(m.topic == self.pose_topic for m in self._held) >= self.probe

    def _choose(self, pose: list[SalvagedMessage]) -> str:
        if not pose:
            return "header"
        cols = self._decoded(lambda: self._decode_pose(pose))
        base, _ = self.rules.pose_times(pose[0].topic, cols.stamp_ns, cols.log_ns)
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

    def _raw(self, msgs: list[SalvagedMessage]) -> RawTopic:
        m0 = msgs[0]
        one_type_per_topic([(m0.topic, self.seen_topics.get(m0.topic, m0.msgtype)),
                            *((m.topic, m.msgtype) for m in msgs)], str(self.path))
        return RawTopic(m0.topic, m0.msgtype, m0.has_definition, [m.log_ns for m in msgs], [m.payload for m in msgs])

    # ---- times -----------------------------------------------------------------------------------------------------
    @property
    def _pose_base(self) -> str:
        return self.time_base or "header"

    def _rule(self, stream: str, topic: str, pose_base: str | None) -> TimeRule:
        """The time rule of a stream: the pose's on ``pose_base`` (None: the base requested, chosen on the
        stamps given), every other stream's beside a pose on ``pose_base``."""
        if stream == "pose":
            return lambda s, log: self.rules.pose_times(topic, log if s is None else s, log, base=pose_base)
        return lambda s, log: self.rules.stream_times(topic, s, log, pose_base=pose_base or "header")

    def _times(self, stream: str, topic: str, stamps_ns: IntArray | None, log_ns: npt.ArrayLike) -> IntArray:
        """The times of one poll's samples of ``stream``, timed after the samples read before them."""
        clock = self.times.setdefault(stream, StreamTimes(topic))
        return clock.times(self._rule(stream, topic, self._pose_base), stamps_ns, np.asarray(log_ns, dtype=np.int64))

    def base_mismatch(self, *, by_log_time: bool = False) -> str | None:
        """auto, chosen before the whole pose stream was read: why certify, which decides on the whole stream (in its
        reading order: ``by_log_time`` or the file order), would judge this log on another time base (None: the
        same)."""
        pose = self.times.get("pose")
        if self.requested != "auto" or self.time_base is None or pose is None or not pose.count:
            return None
        whole, _ = pose.final(self._rule("pose", pose.topic, None), by_log_time=by_log_time)
        if whole.name == self.time_base:
            return None
        return (f"--time-base auto: the decisions were made on {self.time_base} time, chosen on the first "
                f"{self.chosen_on} pose messages, but on the whole stream ({pose.count} messages) certify chooses "
                f"{whole.name} time ({whole.note or 'the header stamps order the samples'}): the verdict is "
                f"undecided here; run certify, or watch without --follow on the complete log")

    def finish(self, *, by_log_time: bool) -> list[str]:
        """The end of the reading: the time rule applied to every whole stream in certify's order (``by_log_time``,
        else the file order). Sets each stream's problem (an explicit header base whose stamps cannot order it: no
        pass, as read_log) and returns why the decisions were made on times certify would not use (empty: none)."""
        why: list[str] = []
        if (mismatch := self.base_mismatch(by_log_time=by_log_time)) is not None:
            why.append(mismatch)
        pose = self.times.get("pose")
        pose_base = self._pose_base
        if pose is not None and pose.count:
            pose_base = pose.final(self._rule("pose", pose.topic, None), by_log_time=by_log_time)[0].name
        for stream, clock in self.times.items():
            if stream in self.unused:
                continue
            tb, differ = clock.final(self._rule(stream, clock.topic, pose_base if stream != "pose" else None),
                                     by_log_time=by_log_time)
            if not tb.usable and self.requested != "auto" and tb.note:
                for label in self._labels(stream):
                    self.problems.setdefault(label, tb.note)
            if differ and not (stream == "pose" and mismatch is not None):  # the base's note says it already
                why.append(f"{clock.topic}: {differ} of {clock.count} sample(s) were judged at other times than "
                           f"certify gives them (its time rule applied to the whole stream, in its reading order): "
                           f"the verdict is undecided here; run certify, or watch without --follow on the complete "
                           f"log")
        return why

    def _labels(self, stream: str) -> list[str]:
        """The names certify gives a stream's problem (a signal topic: one per signal atom read from it)."""
        if stream in ("pose", "nominal", "cmd_vel"):
            return [stream]
        return [f"signal {name}" for name, _ in self.signals.get(stream, [])]

    # ---- pushing ---------------------------------------------------------------------------------------------------
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
                self._optional("nominal", nominal, lambda: self._push_nominal(nominal))
            if self.pose_topic in by_topic:
                self._push_pose(by_topic[self.pose_topic])
            cmd = by_topic.get(t.cmd_vel) if t.cmd_vel is not None else None
            if cmd and "cmd_vel" not in self.unused:
                self._optional("cmd_vel", cmd, lambda: self._push_cmd(cmd))

        self._decoded(push_all)

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

    def _push_cmd(self, msgs: list[SalvagedMessage]) -> None:
        tw = decode_twist(self._raw(msgs), self.ros1)  # TwistStamped by its header, Twist on log time
        cst = self._times("cmd_vel", msgs[0].topic, tw.stamp_ns, tw.log_ns)
        for k in np.argsort(cst, kind="stable").tolist():
            self.monitor.push_cmd(int(cst[k]), *(float(v) for v in tw.u[k]))

    def _push_signals(self, msgs: list[SalvagedMessage], fields: list[tuple[str, str]]) -> None:
        """One signal topic's messages: timed once (its stream's rule, the topic's clock correction included), each
        field's values pushed to the atoms that read it."""
        raw = self._raw(msgs)
        decoded: dict[str, FieldSamples] = {}
        for _name, fld in fields:
            if fld not in decoded:
                decoded[fld] = decode_field(raw, self.ros1, fld)
        first = decoded[fields[0][1]]
        times = self._times(msgs[0].topic, msgs[0].topic, first.stamp_ns, first.log_ns)
        order = np.argsort(times, kind="stable").tolist()
        for name, fld in fields:
            values = decoded[fld].value
            for k in order:
                self.monitor.push_signal(name, int(times[k]), float(values[k]))

    def _push_nominal(self, msgs: list[SalvagedMessage]) -> None:
        cols = decode_pose(self._raw(msgs), self.ros1)
        self._push_positions(cols, self._times("nominal", msgs[0].topic, cols.stamp_ns, cols.log_ns),
                             self.monitor.push_nominal)

    def _push_pose(self, msgs: list[SalvagedMessage]) -> None:
        cols = self._decode_pose(msgs)  # on the base chosen, its stamps' outliers re-timed
        self._push_positions(cols, self._times("pose", msgs[0].topic, cols.stamp_ns, cols.log_ns),
                             self.monitor.push_pose)

    @staticmethod
    def _push_positions(cols: PoseColumns, times: IntArray, push: Callable[..., None]) -> None:
        for k in np.argsort(times, kind="stable").tolist():
            push(int(times[k]), float(cols.x_m[k]), float(cols.y_m[k]))


# ---- watch_log: open, follow, close ---------------------------------------------------------------------------------
def _wait_for(p: Path, *, follow: bool, idle_timeout_s: float, poll_s: float, time_base: str) -> None:
    """The log at ``p`` exists (``follow``: waiting up to ``idle_timeout_s`` for the recorder to create it) and the
    time base is known."""
    waited = time.monotonic()
    while follow and not p.exists() and time.monotonic() - waited < idle_timeout_s:
        time.sleep(poll_s)  # the recorder may not have created the log yet
    if not p.exists():
        raise LogReadError("no such file or directory" + (f" (waited {idle_timeout_s:g} s)" if follow else ""),
                           path=str(p))
    if time_base not in TIME_BASES:
        raise LogReadError(f"time_base={time_base!r} must be one of {', '.join(TIME_BASES)}", path=str(p))


def _feeders(monitor: OnlineMonitor | FleetMonitor, rules: ReadingRules, follower: Follower, p: Path, *,
             follow: bool, time_base: str, clock_offsets: Mapping[str, float] | None) -> list[_Feeder]:
    """One feeder per robot (several robots: its topics, under its one-robot scenario's reading rules, all into the
    fleet monitor)."""
    ros1, probe = follower.format == "ros1", AUTO_PROBE if follow else None
    if isinstance(monitor, FleetMonitor):
        robots = [monitor.robot_feed(name) for name in monitor.scenario.robot_names]
        return [_Feeder(f, ReadingRules.of(f.scenario, time_base, clock_offsets), ros1, p, probe=probe)
                for f in robots]
    return [_Feeder(monitor, rules, ros1, p, probe=probe)]


def _read(p: Path, step: Callable[[], list[SalvagedMessage]]) -> list[SalvagedMessage]:
    try:
        return step()
    except READ_ERRORS as err:  # the follower's reader or decompressor on damaged bytes
        if isinstance(err, VerifyError):
            raise
        raise LogReadError(f"unreadable log: {in_words(err)}", path=str(p)) from err


@dataclass(slots=True)
class _Reading:
    """The polls of one watch: messages read, decisions reported, why it stopped."""

    p: Path
    follower: Follower
    feeders: list[_Feeder]
    monitor: OnlineMonitor | FleetMonitor
    on_decision: Callable[[Decision], None] | None
    decisions: list[Decision] = field(default_factory=list)
    count: int = 0
    reason: str = ""

    @property
    def by_log_time(self) -> bool:
        """Whether certify reads this log's streams by log time, unlike the follower: a closed ROS1 or MCAP log.
        Their indexed readers yield messages by log time, not in file order: an MCAP log's sorts each chunk's
        message records by the log time they hold and merges the chunks; a ROS1 bag's sorts each connection's index
        entries by time (the time each message record holds: the readers check they agree) and merges the
        connections. A message recorded with a log time out of its file place (a tool that rewrote a bag, a clock
        that jumped) is read there. Among equal log times the file order stands (MCAP: chunk position, then record;
        ROS1: rosbags breaks such ties by connection first -- ``SalvagedMessage.tie``). A ROS1 or MCAP log not
        closed is read in file order, by certify's ``--salvage`` walk as here. A sqlite3 storage, closed or not, is
        delivered by the follower in certify's order already: its query's, the timestamp index walked
        (``verify.online.follow.SqliteFollower``)."""
        return self.follower.finished and self.follower.format != "sqlite3"

    def report(self, new: list[Decision]) -> None:
        for d in new:
            self.decisions.append(d)
            if self.on_decision is not None:
                self.on_decision(d)

    def run(self, *, follow: bool, idle_timeout_s: float, poll_s: float) -> None:
        """Poll until the log is closed, every check is decided, one read (no ``follow``) or the idle timeout."""
        follower, p = self.follower, self.p
        last_growth, last_bytes = time.monotonic(), log_bytes(p)
        while True:
            msgs = _read(p, follower.poll)
            for feeder in self.feeders:
                feeder.declare(follower.declared_topics)
            if msgs:
                self.count += len(msgs)
                for feeder in self.feeders:
                    feeder.feed(msgs, final=follower.finished, by_log_time=self.by_log_time)
                self.report(self.monitor.update())
            if (now_bytes := log_bytes(p)) != last_bytes or msgs:  # the idle timer measures the log's bytes, mtime
                last_bytes, last_growth = now_bytes, time.monotonic()
            if follower.finished:
                self.reason = "the recorder closed the log"
                return
            if self.monitor.state().all_decided:
                self.reason = _ALL_DECIDED
                return
            if not follow:
                self.reason = "read once (no --follow)"
                return
            if time.monotonic() - last_growth >= idle_timeout_s:
                self.reason = f"the log did not grow for {idle_timeout_s:g} s"
                return
            time.sleep(poll_s)

    def end(self) -> list[str]:
        """The last reading: what --salvage reads beyond the complete records of a log not closed."""
        if self.follower.finished:
            for feeder in self.feeders:
                feeder.feed([], final=True, by_log_time=self.by_log_time)
            return []
        extra = _read(self.p, self.follower.rest)  # a cut uncompressed chunk's complete records
        self.count += len(extra)
        for feeder in self.feeders:
            feeder.feed(extra, final=True, by_log_time=self.by_log_time)
        return ["the log was not closed by its recorder: judged as --salvage judges it (partial)"]


def _check_streams(feeder: _Feeder, p: Path, reason: str) -> None:
    """A pose topic without messages, an absent signal topic, a correction for an absent topic: exit 3, as certify."""
    if feeder.pose_topic is None:
        raise feeder.rules.missing_pose(feeder.seen_topics, str(p))
    if feeder.monitor.counts["pose"] == 0:
        raise MissingTopicError(f"pose topic {feeder.pose_topic} has no messages", path=str(p))
    if reason != _ALL_DECIDED:  # every topic of the log seen: as certify, first
        feeder.rules.check_offset_topics(feeder.seen_topics, str(p))
    for topic, fields in feeder.signals.items():
        if topic not in feeder.seen_topics:
            have = ", ".join(sorted(feeder.seen_topics)) or "no topics"
            raise MissingTopicError(f"signal {fields[0][0]}: topic {topic} (field {fields[0][1]}) is absent "
                                    f"from the log; the log has: {have}", path=str(p))


def _close(reading: _Reading, notes: list[str]) -> WatchResult:
    """Every stream's times checked against certify's, the monitor closed, the verdict undecided where the
    decisions were made on times certify would not use."""
    finished, monitor, feeders = reading.follower.finished, reading.monitor, reading.feeders
    mismatches: list[str] = []
    for feeder in feeders:
        _check_streams(feeder, reading.p, reading.reason)
        why = feeder.finish(by_log_time=reading.by_log_time)
        mismatches += why
        notes += [n for n in (feeder.base_note, *why, *feeder.unused.values()) if n and n not in notes]
    result: OnlineResult | FleetResult
    if isinstance(monitor, FleetMonitor):
        result = monitor.close(partial=not finished,
                               stream_problems={f.monitor.robot: f.problems for f in feeders
                                                if isinstance(f.monitor, RobotFeed)})
    else:
        result = monitor.close(partial=not finished, problems=feeders[0].problems)
    if mismatches and result.verdict != "inconclusive":
        result = replace(result, verdict="inconclusive", verdict_reason=mismatches[0])
    reading.report(monitor.final_decisions)
    return WatchResult(result, reading.decisions, finished, reading.reason, reading.count, notes)


def watch_log(path: str | Path, monitor: OnlineMonitor | FleetMonitor, *, follow: bool = False,
              idle_timeout_s: float = 10.0,
              poll_s: float = 0.2, time_base: str = "header", clock_offsets: Mapping[str, float] | None = None,
              on_decision: Callable[[Decision], None] | None = None) -> WatchResult:
    """Judge the log at ``path`` as it grows (see the module docstring); never modifies it. ``clock_offsets``
    (topic -> seconds added to that topic's times) extends and overrides the scenario's, as certify's
    ``--clock-offset`` does."""
    p = Path(path)
    _wait_for(p, follow=follow, idle_timeout_s=idle_timeout_s, poll_s=poll_s, time_base=time_base)
    rules = ReadingRules.of(monitor.scenario, time_base, clock_offsets)  # the offsets' ranges, before reading
    check_log_path(p)
    scenarios = ([monitor.robot_feed(name).scenario for name in monitor.scenario.robot_names]
                 if isinstance(monitor, FleetMonitor) else [monitor.scenario])
    follower = open_follower(p, set().union(*map(wanted_topics, scenarios)))  # the topics certify reads
    feeders = _feeders(monitor, rules, follower, p, follow=follow, time_base=time_base, clock_offsets=clock_offsets)
    reading = _Reading(p, follower, feeders, monitor, on_decision)
    reading.run(follow=follow, idle_timeout_s=idle_timeout_s, poll_s=poll_s)
    notes = reading.end()
    return _close(reading, notes)
