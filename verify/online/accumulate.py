"""Per-sample checks accumulated over batches: margins / batch results -> the ``CheckResult`` of the whole run.

input: per batch, the margins of new samples with the previous one (workspace, obstacle clearance), or the offline
check's result on the batch (tube, input box) -> output: the first violation as soon as it is seen, and at the end
the ``CheckResult`` ``verify.checks`` gives for all the samples at once (same verdict, margin, first violation).
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import Any

import numpy as np
import numpy.typing as npt

from verify.checks import CheckResult
from verify.geometry import gap_bounds

__all__ = ["MarginRun", "MergedRun"]

FloatArray = npt.NDArray[np.float64]
IntArray = npt.NDArray[np.int64]


def _finite_min(a: FloatArray) -> float | None:
    finite = a[np.isfinite(a)]
    return float(finite.min()) if finite.size else None


def _min(a: float | None, b: float | None) -> float | None:
    return b if a is None else (a if b is None else min(a, b))


@dataclass(slots=True)
class MarginRun:
    """``verify.checks.margin_check`` accumulated over batches (workspace, obstacle clearance)."""

    name: str
    samples: int = 0
    fail_ns: int | None = None
    fail_detail: dict[str, Any] = field(default_factory=dict)
    sample_min: float | None = None
    least: float = math.inf  # the least margin, -inf included (a failed check's margin: verify.checks._least)
    nan: int = 0
    worst_gap: float = math.inf
    worst_gap_at: tuple[int, int] | None = None

    def feed(self, t_ns: IntArray, margin: FloatArray, step_m: FloatArray, new_from: int) -> int | None:
        """``t_ns``/``margin``: the previous sample (if ``new_from`` = 1) and the new ones; returns the index of a
        first violation found in this batch."""
        new = margin[new_from:]
        self.samples += new.shape[0]
        least = float(new.min()) if new.size else math.inf  # NaN if any sample is NaN
        if math.isfinite(least):  # no NaN and no -inf: the least margin is also the least finite one
            self.sample_min = _min(self.sample_min, least)
            self.least = min(self.least, least)
        elif new.size:
            self.sample_min = _min(self.sample_min, _finite_min(new))
            with np.errstate(all="ignore"):
                if not np.isnan(new).all():
                    self.least = min(self.least, float(np.nanmin(new)))
            self.nan += int(np.isnan(new).sum())
        hit = None
        if self.fail_ns is None and not least >= 0:
            bad = np.flatnonzero(new < 0)
            if bad.size:
                hit = int(bad[0]) + new_from
                self.fail_ns = int(t_ns[hit])
        if margin.shape[0] >= 2:
            lo = gap_bounds(margin, step_m).lo
            k = int(np.argmin(lo))
            if lo[k] < self.worst_gap:
                self.worst_gap, self.worst_gap_at = float(lo[k]), (int(t_ns[k]), int(t_ns[k + 1]))
        return hit

    def result(self) -> CheckResult:
        if self.samples == 0:
            return CheckResult(self.name, "inconclusive", None, None, {"reason": "no samples"})
        if self.fail_ns is not None:
            return CheckResult(self.name, "fail", self.least, self.fail_ns, dict(self.fail_detail))
        if self.nan or self.worst_gap < 0:
            why = []
            if self.nan:
                why.append(f"{self.nan} NaN sample(s)")
            if self.worst_gap < 0 and self.worst_gap_at is not None:
                a, b = self.worst_gap_at
                why.append(f"the robot may have crossed the limit between samples at {a} ns and {b} ns "
                           f"(bound {self.worst_gap:.4f} m)")
            return CheckResult(self.name, "inconclusive", self.sample_min, None,
                               {"reason": "; ".join(why), "guaranteed_margin_m": None})
        guaranteed = min(self.sample_min if self.sample_min is not None else -math.inf, self.worst_gap)
        return CheckResult(self.name, "pass", guaranteed, None, {"sample_margin_m": self.sample_min})


@dataclass(slots=True)
class MergedRun:
    """Batch results of an offline check (tube, input box) merged: first failure, smallest margin, any undecided."""

    name: str
    samples: int = 0
    fail: CheckResult | None = None
    margin: float | None = None
    undecided: list[str] = field(default_factory=list)
    counts: dict[str, int] = field(default_factory=dict)
    max_dev: float | None = None
    missing_reason: str = "no samples"
    unit: str | None = None  # the unit of the smallest margin (the input box: its tightest component's)

    def feed(self, res: CheckResult, n: int) -> bool:
        self.samples += n
        if res.margin is not None and (self.margin is None or res.margin < self.margin):
            self.unit = res.details.get("margin_unit", self.unit)
        self.margin = _min(self.margin, res.margin)
        for key in ("matched_samples", "unmatched_samples"):
            if key in res.details:
                self.counts[key] = self.counts.get(key, 0) + int(res.details[key])
        dev = res.details.get("max_deviation_m")
        if dev is not None and math.isfinite(dev):
            self.max_dev = dev if self.max_dev is None else max(self.max_dev, dev)
        if res.verdict == "fail" and self.fail is None:
            self.fail = res
            return True
        if res.verdict == "inconclusive":
            self.undecided.append(str(res.details.get("reason", "undecided samples")))
        return False

    def result(self, details: dict[str, Any]) -> CheckResult:
        d = {**details, **self.counts, **({"margin_unit": self.unit} if self.unit else {})}
        if self.max_dev is not None:
            d["max_deviation_m"] = self.max_dev
        if self.fail is not None:
            extra = {k: v for k, v in self.fail.details.items() if k == "component"}
            return CheckResult(self.name, "fail", self.margin, self.fail.first_violation_ns, {**d, **extra})
        if self.samples == 0:
            return CheckResult(self.name, "inconclusive", None, None, {**d, "reason": self.missing_reason})
        if self.undecided:
            return CheckResult(self.name, "inconclusive", self.margin, None, {**d, "reason": "; ".join(self.undecided)})
        return CheckResult(self.name, "pass", self.margin, None, d)
