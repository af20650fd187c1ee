"""Watch a log while it is written: a growing log + scenario -> one line per decision, then certify's exit code.

input: a log path (MCAP file, ROS2 bag folder, ROS1 bag, sqlite3 storage) that a recorder may still be writing, a
scenario (and formula), ``follow``/``idle_timeout`` -> output: ``WatchResult`` (decisions, the monitor's final
result, whether the log was finished by its recorder). ``watch_log`` reads the records completed so far with a
``verify.online.follow`` follower, decodes them with the certifier's decoders, pushes them into an
``OnlineMonitor`` and reports each decision through ``on_decision``.

It stops when every check and obligation is decided, when the recorder has closed the log, when the log has not
grown for ``idle_timeout`` seconds (``follow``), or after one read (no ``follow``). A log its recorder did not close
is judged as ``--salvage`` judges it: its complete records, partial, never a pass.
"""

from __future__ import annotations

import time
from collections.abc import Callable
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from tubempc.scenario import Scenario
from verify.errors import LogReadError, MissingTopicError
from verify.ingest.decode import TF, TRANSFORM_STAMPED, decode_pose, decode_twist
from verify.ingest.raw import RawTopic
from verify.ingest.salvage import SalvagedMessage
from verify.online.follow import open_follower
from verify.online.monitor import Decision, OnlineMonitor, OnlineResult

__all__ = ["WatchResult", "watch_log"]

TF_TOPIC = "/tf"


@dataclass(slots=True)
class WatchResult:
    result: OnlineResult
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

    def __init__(self, monitor: OnlineMonitor, scenario: Scenario, ros1: bool, time_base: str, path: Path) -> None:
        self.monitor = monitor
        self.scenario = scenario
        self.ros1 = ros1
        self.time_base = time_base
        self.path = path
        self.pose_topic: str | None = None
        self.seen_topics: dict[str, str] = {}

    def _raw(self, msgs: list[SalvagedMessage]) -> RawTopic:
        m0 = msgs[0]
        return RawTopic(m0.topic, m0.msgtype, m0.has_definition, [m.log_ns for m in msgs], [m.payload for m in msgs])

    def feed(self, messages: list[SalvagedMessage]) -> None:
        t = self.scenario.topics
        by_topic: dict[str, list[SalvagedMessage]] = {}
        for m in messages:
            self.seen_topics.setdefault(m.topic, m.msgtype)
            by_topic.setdefault(m.topic, []).append(m)
        if self.pose_topic is None:
            if t.pose in self.seen_topics:
                self.pose_topic = t.pose
            elif TF_TOPIC in self.seen_topics and t.tf_child_frame:
                self.pose_topic = TF_TOPIC
        try:
            if t.nominal in by_topic:
                self._push_pose(by_topic[t.nominal], self.monitor.push_nominal, None)
            if self.pose_topic in by_topic:
                msgs = by_topic[self.pose_topic]
                child = t.tf_child_frame if msgs[0].msgtype in (TF, TRANSFORM_STAMPED) else None
                self._push_pose(msgs, self.monitor.push_pose, child)
            if t.cmd_vel in by_topic:
                tw = decode_twist(self._raw(by_topic[t.cmd_vel]), self.ros1)
                for k in np.argsort(tw.log_ns, kind="stable").tolist():
                    self.monitor.push_cmd(int(tw.log_ns[k]), *(float(v) for v in tw.u[k]))
        except LogReadError as err:
            raise LogReadError(err.reason, path=str(self.path)) from err

    def _push_pose(self, msgs: list[SalvagedMessage], push: Callable[..., None], child: str | None) -> None:
        cols = decode_pose(self._raw(msgs), self.ros1, child_frame=child)
        stamps = cols.stamp_ns if self.time_base == "header" else cols.log_ns
        for k in np.argsort(stamps, kind="stable").tolist():
            push(int(stamps[k]), float(cols.x_m[k]), float(cols.y_m[k]))


def watch_log(path: str | Path, monitor: OnlineMonitor, *, follow: bool = False, idle_timeout_s: float = 10.0,
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
    if time_base not in ("header", "log"):
        raise LogReadError(f"time_base={time_base!r} must be 'header' or 'log'", path=str(p))
    follower = open_follower(p)
    feeder = _Feeder(monitor, monitor.scenario, follower.format == "ros1", time_base, p)
    decisions: list[Decision] = []
    count = 0

    def report(new: list[Decision]) -> None:
        for d in new:
            decisions.append(d)
            if on_decision is not None:
                on_decision(d)

    last_growth = time.monotonic()
    while True:
        msgs = follower.poll()
        if msgs:
            count += len(msgs)
            feeder.feed(msgs)
            report(monitor.update())
            last_growth = time.monotonic()
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
        extra = follower.rest()  # what --salvage reads beyond the complete chunks (a cut uncompressed chunk)
        if extra:
            count += len(extra)
            feeder.feed(extra)
        notes.append("the log was not closed by its recorder: judged as --salvage judges it (partial)")
    if feeder.pose_topic is None or monitor.counts["pose"] == 0:
        have = ", ".join(sorted(feeder.seen_topics)) or "no topics"
        raise MissingTopicError(f"pose topic {monitor.scenario.topics.pose} is absent; the log has: {have}",
                                path=str(p))
    result = monitor.close(partial=not follower.finished)
    report(monitor.final_decisions)
    return WatchResult(result, decisions, follower.finished, reason, count, notes)
