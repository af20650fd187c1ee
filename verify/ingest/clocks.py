"""Clock offsets between topics: each stream's times vs the recorder's clock -> findings and corrections.

input: per stream, the times it is judged on (header stamps or log times) and its log (receive) times, plus the
corrections the user gave (``clock_offsets: {topic: seconds}`` in the scenario, ``--clock-offset TOPIC=SECONDS``)
-> output: a JSON-ready ``clocks`` section and one finding per topic whose clock differs from the pose topic's by
more than ``CLOCK_OFFSET_THRESHOLD_S``.

Every message's log time comes from one clock (the recorder's), so the median of ``time used - log time`` of a
stream is its clock's offset from the recorder plus its transport latency (milliseconds on a lab network). Two
streams whose medians differ by more than the threshold come from clocks that disagree: a command stamped on
another computer (or judged on log time while the pose is judged on its MoCap header clock) lands at the wrong time
on the pose's time axis. A correction is *added* to the topic's times: the finding's ``suggested_correction_s``
moves the topic onto the pose's clock. Corrections of the pose topic move the whole log (time 0 moves with it).
"""

from __future__ import annotations

import math
from collections.abc import Iterable, Mapping
from typing import Any

import numpy as np
import numpy.typing as npt

from verify.errors import ScenarioInputError
from verify.ingest.stats import median

__all__ = [
    "CLOCK_OFFSET_LIMIT_S",
    "CLOCK_OFFSET_THRESHOLD_S",
    "check_offset_topics",
    "clock_offsets_ns",
    "clock_report",
    "median_offset_s",
    "parse_clock_offsets",
]

IntArray = npt.NDArray[np.int64]

#: two topics whose clocks differ by more than this (seconds, after corrections) are reported
CLOCK_OFFSET_THRESHOLD_S = 0.1
#: a correction larger than this (s, about 127 years: a simulated clock moved onto wall time fits) is refused; with
#: ROS times (at most 2**32 s) the corrected times stay inside int64 nanoseconds
CLOCK_OFFSET_LIMIT_S = 4e9


def clock_offsets_ns(scenario_s: Mapping[str, float], option_s: Mapping[str, float] | None) -> dict[str, int]:
    """The corrections in ns (``--clock-offset`` over ``clock_offsets:``), each checked for range: a value that is
    not finite or larger than ``CLOCK_OFFSET_LIMIT_S`` is exit 3 naming where it was given."""
    out: dict[str, int] = {}
    for where, given in (("clock_offsets:", scenario_s), ("--clock-offset", option_s or {})):
        for topic, sec in given.items():
            if not (isinstance(sec, int | float) and math.isfinite(sec) and abs(sec) <= CLOCK_OFFSET_LIMIT_S):
                raise ScenarioInputError(f"{where} {topic}={sec!r} s is out of range: a clock offset is finite and "
                                         f"at most {CLOCK_OFFSET_LIMIT_S:g} s in size")
            out[topic] = round(sec * 1e9)
    return out


def parse_clock_offsets(items: Iterable[str]) -> dict[str, float]:
    """``--clock-offset TOPIC=SECONDS`` items (certify, watch) -> topic -> seconds; a malformed item is exit 3 naming
    the option (the range is ``clock_offsets_ns``'s)."""
    out: dict[str, float] = {}
    for item in items:
        topic, sep, value = item.partition("=")
        try:
            seconds = float(value)
        except ValueError:
            seconds = float("nan")
        if not sep or not topic.startswith("/") or not math.isfinite(seconds):
            raise ScenarioInputError(f"--clock-offset {item!r}: expected TOPIC=SECONDS, e.g. /cmd_vel=2.0")
        out[topic] = seconds
    return out


def check_offset_topics(scenario_s: Iterable[str], option_s: Iterable[str], log_topics: Iterable[str],
                        path: str) -> None:
    """A correction for a topic the log does not hold (a typo) is exit 3 listing the log's topics."""
    known = set(log_topics)
    for where, topics in (("--clock-offset", option_s), ("clock_offsets:", scenario_s)):
        unknown = sorted(set(topics) - known)
        if unknown:
            raise ScenarioInputError(f"{where} names {', '.join(unknown)}, which the log does not hold; its topics: "
                                     f"{', '.join(sorted(known)) or 'none'}", path=path)


def median_offset_s(t_used_ns: IntArray, log_ns: IntArray) -> float | None:
    """Median of ``time used - log time`` (s); None without samples."""
    if t_used_ns.shape[0] == 0 or t_used_ns.shape != log_ns.shape:
        return None
    return round(float(median((t_used_ns - log_ns).astype(np.float64))) * 1e-9, 9)


def clock_report(pose_topic: str, streams: dict[str, tuple[str, float | None]], applied_s: dict[str, float],
                 ) -> dict[str, Any]:
    """``streams``: topic -> (time base used, median offset vs the log clock in s, corrections included).
    Returns the certificate's ``clocks`` section (``findings``: one line per topic off the pose clock)."""
    pose_base, pose_off = streams.get(pose_topic, ("header", None))
    out: dict[str, Any] = {
        "threshold_s": CLOCK_OFFSET_THRESHOLD_S,
        "convention": "offset = median(time used - log time) of the stream, corrections included; a correction "
                      "(clock_offsets / --clock-offset) is added to the topic's times",
        "pose_topic": pose_topic, "streams": {}, "findings": [],
        "applied_s": dict(sorted(applied_s.items())),
    }
    for topic, (base, off) in sorted(streams.items()):
        entry: dict[str, Any] = {"time_base": base, "offset_vs_log_s": off}
        if off is not None and pose_off is not None:
            diff = round(off - pose_off, 9)
            entry["offset_vs_pose_s"] = diff
            if topic != pose_topic and abs(diff) > CLOCK_OFFSET_THRESHOLD_S:
                fix = round(applied_s.get(topic, 0.0) - diff, 6)
                entry["suggested_correction_s"] = fix
                ahead = "ahead of" if diff > 0 else "behind"
                out["findings"].append(
                    f"{topic}: its times ({base} time base) run {abs(diff):.3f} s {ahead} the pose topic "
                    f"{pose_topic} ({pose_base} time base); events on it are placed {abs(diff):.3f} s "
                    f"{'late' if diff > 0 else 'early'} on the pose's time axis. If the clocks differ, correct with "
                    f"clock_offsets: {{{topic}: {fix}}} or --clock-offset {topic}={fix}")
        out["streams"][topic] = entry
    unused = sorted(set(applied_s) - set(streams))
    if unused:
        out["findings"].append(f"clock_offsets names {', '.join(unused)}, which no judged stream uses")
    return out
