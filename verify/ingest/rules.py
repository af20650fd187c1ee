"""The reading rules of a log's streams, in one place: certify (``verify.ingest.log``) and watch
(``verify.online.watch``) both ask a ``ReadingRules`` for them.

input: the scenario, the requested time base (``auto``, ``header``, ``log``) and the ``--clock-offset`` corrections
-> output: which topic is the pose (the scenario's ``topics.pose``, else ``/tf`` when ``topics.tf_child_frame`` names
the robot's frame), which child frame a transform stream is read for, and the time of every sample of a stream:

- the pose: ``verify.ingest.timebase.choose_time_base`` on its header stamps and log times;
- the nominal, the commands and every signal topic: ``verify.ingest.timebase.stream_time_base`` with the pose's
  base. A ``TwistStamped`` command stream carries a header and is under these rules as every other stream is; a
  plain ``Twist`` has no header (``stamp_ns`` None) and is on log time;
- each topic's clock correction (``clock_offsets:`` of the scenario, overridden by ``--clock-offset``; range-checked
  by ``verify.ingest.clocks.clock_offsets_ns`` before any log is read) is added to that topic's times, after the
  time base is applied.
"""

from __future__ import annotations

from collections.abc import Collection, Mapping
from dataclasses import dataclass

import numpy as np
import numpy.typing as npt

from tubempc.scenario import Scenario
from verify.errors import MissingTopicError, UnusableInputError
from verify.ingest.clocks import check_offset_topics, clock_offsets_ns
from verify.ingest.decode import TF, TRANSFORM_STAMPED
from verify.ingest.timebase import TIME_BASES, TimeBase, choose_time_base, stream_time_base

__all__ = ["TF_TOPIC", "ReadingRules"]

IntArray = npt.NDArray[np.int64]
TF_TOPIC = "/tf"


@dataclass(frozen=True, slots=True)
class ReadingRules:
    """The rules one reading of a log applies (build with ``ReadingRules.of``)."""

    scenario: Scenario
    requested: str  # the time base asked for: auto, header or log
    offsets_s: dict[str, float]  # topic -> correction (s): the scenario's, overridden by the option's
    offsets_ns: dict[str, int]
    option_offsets_s: dict[str, float]

    @classmethod
    def of(cls, scenario: Scenario, time_base: str = "auto",
           clock_offsets: Mapping[str, float] | None = None) -> ReadingRules:
        """Checks the time base's name and every correction's range (exit 3 naming the option or the field)."""
        if time_base not in TIME_BASES:
            raise UnusableInputError(f"time_base={time_base!r} must be one of {', '.join(TIME_BASES)}")
        option = dict(clock_offsets or {})
        offsets_ns = clock_offsets_ns(scenario.clock_offsets, option)
        return cls(scenario, time_base, {**scenario.clock_offsets, **option}, offsets_ns, option)

    # ---- topics ----------------------------------------------------------------------------------------------------
    def pose_topic(self, available: Collection[str]) -> str | None:
        """The topic the pose is read from among ``available``, or None (not there, or not yet seen)."""
        t = self.scenario.topics
        if t.pose in available:
            return t.pose
        if TF_TOPIC in available and t.tf_child_frame:
            return TF_TOPIC
        return None

    def missing_pose(self, available: Collection[str], path: str) -> MissingTopicError:
        """The error for a log without the pose topic, listing the log's topics."""
        hint = "" if TF_TOPIC not in available else " (/tf is present: set topics.tf_child_frame in the scenario)"
        return MissingTopicError(f"pose topic {self.scenario.topics.pose} is absent{hint}; the log has: "
                                 f"{', '.join(sorted(available)) or 'no topics'}", path=path)

    def child_frame(self, msgtype: str) -> str | None:
        """The child frame a pose stream of ``msgtype`` is read for (transforms only)."""
        return self.scenario.topics.tf_child_frame if msgtype in (TF, TRANSFORM_STAMPED) else None

    def check_offset_topics(self, available: Collection[str], path: str) -> None:
        """A correction for a topic the log does not hold is exit 3 listing the log's topics."""
        check_offset_topics(self.scenario.clock_offsets, self.option_offsets_s, available, path)

    # ---- times -----------------------------------------------------------------------------------------------------
    def offset_ns(self, topic: str) -> int:
        return self.offsets_ns.get(topic, 0)

    def pose_times(self, topic: str, stamps_ns: IntArray, log_ns: npt.ArrayLike, *, base: str | None = None
                   ) -> tuple[TimeBase, IntArray]:
        """The pose stream's time base (``base``: one already chosen, else the requested one) and its times, the
        topic's correction included."""
        tb = choose_time_base(stamps_ns, np.asarray(log_ns, dtype=np.int64), base or self.requested)
        return tb, tb.t_ns + self.offset_ns(topic)

    def stream_times(self, topic: str, stamps_ns: IntArray | None, log_ns: npt.ArrayLike, *, pose_base: str
                     ) -> tuple[TimeBase, IntArray]:
        """A stream beside the pose (nominal, commands: ``TwistStamped`` by its header, ``Twist`` on log time; a
        signal topic): its time base and times, the topic's correction included."""
        tb = stream_time_base(stamps_ns, np.asarray(log_ns, dtype=np.int64), requested=self.requested,
                              pose_base=pose_base)
        return tb, tb.t_ns + self.offset_ns(topic)
