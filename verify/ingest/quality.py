"""Data quality of decoded streams: stamps and samples -> findings (plain JSON-ready dicts), never an exception.

input: stamps in reading order (ns), log times, positions/quaternions -> output: a findings dict per stream and
the order that sorts the stream by stamp with duplicates removed (``clean_order``).
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

import numpy as np
import numpy.typing as npt

from verify.ingest.stats import median

__all__ = ["NEAR_1970_NS", "CleanOrder", "clean_order", "pose_findings", "stream_findings", "yaw_from_quaternion"]

FloatArray = npt.NDArray[np.float64]
IntArray = npt.NDArray[np.int64]

#: stamps before 2000-01-01T00:00:00Z are taken as "near 1970" (a clock that was never set, or sim time)
NEAR_1970_NS = 946_684_800 * 10**9
#: a gap longer than this many nominal periods is a dropout
DROPOUT_FACTOR = 1.5


@dataclass(frozen=True, slots=True)
class CleanOrder:
    """Indices (into reading order) of the samples kept: sorted by stamp, first of each duplicate stamp."""

    index: IntArray
    out_of_order: int
    duplicates: int


def clean_order(stamps_ns: IntArray) -> CleanOrder:
    out_of_order = int(np.count_nonzero(np.diff(stamps_ns) < 0))
    order = np.argsort(stamps_ns, kind="stable")
    sorted_t = stamps_ns[order]
    keep = np.ones(order.shape[0], dtype=bool)
    keep[1:] = np.diff(sorted_t) != 0
    return CleanOrder(order[keep].astype(np.int64), out_of_order, int(np.count_nonzero(~keep)))


def _seconds(ns: float | int) -> float:
    return round(float(ns) * 1e-9, 9)


def stream_findings(stamps_ns: IntArray, log_ns: IntArray | None, order: CleanOrder, *,
                    expected_rate_hz: float | None, time0_ns: int) -> dict[str, Any]:
    """Count, rate, dropouts, duplicate / out-of-order stamps, stamps near 1970, header-vs-log-time offset."""
    t = stamps_ns[order.index]
    out: dict[str, Any] = {"count": int(stamps_ns.shape[0]), "duplicate_stamps": order.duplicates,
                           "out_of_order_stamps": order.out_of_order}
    if t.size >= 2:
        dt = np.diff(t)
        out["rate_hz"] = round(1e9 / float(median(dt)), 6) if median(dt) > 0 else None
        period_ns = float(median(dt))  # the stream's own rate; the expected rate is reported beside it
        out["expected_rate_hz"] = expected_rate_hz
        gaps = np.flatnonzero(dt > DROPOUT_FACTOR * period_ns)
        out["dropouts"] = {
            "count": int(gaps.size),
            "longest_gap_s": _seconds(int(dt.max())),
            "first": [{"after_s": _seconds(int(t[g]) - time0_ns), "gap_s": _seconds(int(dt[g]))} for g in gaps[:5]],
            "threshold_s": _seconds(DROPOUT_FACTOR * period_ns),
        }
    else:
        out["rate_hz"] = None
        out["dropouts"] = {"count": 0, "longest_gap_s": None, "first": [], "threshold_s": None}
    near = int(np.count_nonzero(stamps_ns < NEAR_1970_NS))
    out["stamps_near_1970"] = near
    if log_ns is not None and log_ns.shape == stamps_ns.shape and stamps_ns.size:
        # header stamp minus log (receive) time: negative when the header lags the recorder's clock (latency)
        off = (stamps_ns - log_ns).astype(np.float64) * 1e-9
        out["header_vs_log_offset_s"] = {"median": round(float(median(off)), 9),
                                         "max_abs": round(float(np.max(np.abs(off))), 9),
                                         "convention": "header stamp - log time"}
    return out


def yaw_from_quaternion(q_xyzw: FloatArray) -> tuple[FloatArray, npt.NDArray[np.bool_]]:
    """Yaw (rad) about z of unit-normalized quaternions; NaN where the quaternion is NaN or has zero norm."""
    x, y, z, w = q_xyzw[:, 0], q_xyzw[:, 1], q_xyzw[:, 2], q_xyzw[:, 3]
    norm = np.sqrt(x * x + y * y + z * z + w * w)
    bad = ~np.isfinite(norm) | (norm < 1e-9)
    yaw = np.arctan2(2.0 * (w * z + x * y), 1.0 - 2.0 * (y * y + z * z))
    yaw = np.where(bad, np.nan, yaw)
    return yaw, bad


def pose_findings(t_ns: IntArray, x_m: FloatArray, y_m: FloatArray, bad_quat: npt.NDArray[np.bool_], *,
                  max_speed_mps: float, jump_tolerance_m: float, time0_ns: int) -> dict[str, Any]:
    """NaN positions, zero-norm/NaN quaternions, and jumps faster than the robot can move (sorted samples)."""
    nan = ~np.isfinite(x_m) | ~np.isfinite(y_m)
    out: dict[str, Any] = {
        "nan_positions": int(np.count_nonzero(nan)),
        "first_nan_s": _seconds(int(t_ns[np.argmax(nan)]) - time0_ns) if nan.any() else None,
        "bad_quaternions": int(np.count_nonzero(bad_quat)),
    }
    if t_ns.size >= 2:
        dt_s = np.diff(t_ns) * 1e-9
        step = np.hypot(np.diff(x_m), np.diff(y_m))
        jump = step > max_speed_mps * dt_s + jump_tolerance_m
        speed = np.where(dt_s > 0, step / np.where(dt_s > 0, dt_s, 1.0), np.inf)
        out["jumps"] = {
            "count": int(np.count_nonzero(jump)),
            "max_speed_mps": round(float(np.nanmax(speed)), 6) if np.isfinite(speed).any() else None,
            "first_s": _seconds(int(t_ns[np.argmax(jump)]) - time0_ns) if jump.any() else None,
            "speed_bound_mps": max_speed_mps,
            "tolerance_m": jump_tolerance_m,
        }
    return out
