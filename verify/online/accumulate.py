"""Per-sample checks accumulated over batches: margins / batch results -> the ``CheckResult`` of the whole run.

input: per batch, the new pose samples with the previous one (workspace, obstacle clearance: their margins), the
pose samples whose nearest nominal sample is known (tube) and the commands (input box), judged by the offline
checks (``verify.checks``) -> output: the first violation as soon as it is seen, and at the end the
``CheckResult`` ``verify.checks`` gives for all the samples at once (same verdict, margin, first violation).
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import Any

import numpy as np
import numpy.typing as npt

from tubempc.scenario import Scenario
from verify.checks import CheckResult, check_input_box, check_tube
from verify.geometry import gap_bounds, step_bound_m, workspace_margin
from verify.judging import tube_tolerance_m
from verify.online.regions import RegionGeometry, prepend

__all__ = ["MarginRun", "MergedRun", "SampleChecks"]

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


class SampleChecks:
    """The per-sample checks of one run, accumulated over batches: workspace and obstacle clearance on every pose
    sample, the tube on every pose sample once a nominal sample at or after it is known (the nearest nominal sample
    is then known), the input box on every command."""

    def __init__(self, sc: Scenario, geometry: RegionGeometry, *, tube: bool) -> None:
        self.scenario = sc
        self.geometry = geometry
        self.unsafe = geometry.unsafe
        self.max_speed_mps = sc.max_speed_mps
        self.period_ns = round(1e9 / sc.mocap.rate_hz)
        self.tol_m = tube_tolerance_m(sc)
        self.tube_radius_m = sc.tube_radius_m if tube else math.nan
        self.tube_on = tube
        self.ws = MarginRun("workspace")
        self.clear = MarginRun("obstacle_clearance")
        self.tube = MergedRun("tube", missing_reason="no nominal state logged: tube containment cannot be checked")
        self.input = MergedRun("input_box", missing_reason="no cmd_vel logged")
        self.prev: tuple[int, float, float] | None = None  # the last pose sample judged
        self.tube_pending: list[tuple[IntArray, FloatArray, FloatArray]] = []  # judged, not matched yet
        self.tube_last_t = -(2**63)  # the last pose sample handed to the tube check
        self.nominal: tuple[IntArray, FloatArray, FloatArray] = (np.zeros(0, np.int64), np.zeros(0), np.zeros(0))
        self.nominal_seen = 0

    def feed_poses(self, t_ns: IntArray, x: FloatArray, y: FloatArray, t0: int,
                   reuse: tuple[FloatArray, FloatArray, int] | None = None) -> None:
        """New pose samples (``reuse``: with the previous one in front, its step bounds, region margins and 1)."""
        if reuse is not None:
            step, margin, k1 = reuse
        else:
            k1 = 0 if self.prev is None else 1
            if self.prev is not None:
                t_ns, x, y = prepend(self.prev, t_ns, x, y)
            step = step_bound_m(t_ns - t0, x, y, self.max_speed_mps)
            margin = self.geometry.margins(x, y)[1]
        self.prev = (int(t_ns[-1]), float(x[-1]), float(y[-1]))
        self.ws.feed(t_ns, workspace_margin(x, y, self.scenario), step, k1)
        if self.unsafe:
            margins = margin[self.unsafe]
            hit = self.clear.feed(t_ns, -np.max(margins, axis=0), step, k1)
            if hit is not None:
                region = self.unsafe[int(np.argmax(margins[:, hit]))]
                self.clear.fail_detail["region"] = self.scenario.regions[region].name
        if self.tube_on:
            self.tube_pending.append((t_ns[k1:], x[k1:], y[k1:]))
        self.tube_last_t = int(t_ns[-1])

    def feed_nominal(self, t: IntArray, x: FloatArray, y: FloatArray) -> None:
        nt, nx, ny = self.nominal
        self.nominal = (np.concatenate((nt, t)), np.concatenate((nx, x)), np.concatenate((ny, y)))
        self.nominal_seen += t.shape[0]

    def nominal_unknown(self, t_ns: int) -> None:
        """The nominal sample judged at ``t_ns`` (the last one) had a duplicate with other values: unknown."""
        nt, nx, ny = self.nominal
        if nt.size and int(nt[-1]) == t_ns:
            nx, ny = nx.copy(), ny.copy()
            nx[-1] = ny[-1] = math.nan
            self.nominal = (nt, nx, ny)

    def feed_cmd(self, t: IntArray, u: FloatArray) -> None:
        self.input.feed(check_input_box(t, u, self.scenario.inputs), t.shape[0])

    def resolve_tube(self, closing: bool) -> None:
        """Judge the pose samples whose nearest nominal sample is known (a nominal sample at or after them)."""
        if not self.tube_pending:
            return
        t = np.concatenate([p[0] for p in self.tube_pending])
        x = np.concatenate([p[1] for p in self.tube_pending])
        y = np.concatenate([p[2] for p in self.tube_pending])
        nt, nx, ny = self.nominal
        if nt.size == 0:
            self.tube_pending = [(t, x, y)] if not closing else []
            return
        k = t.shape[0] if closing else int(np.searchsorted(t, nt[-1], side="right"))
        if k:
            res = check_tube(t[:k], x[:k], y[:k], self.nominal, radius_m=self.tube_radius_m,
                             tolerance_m=self.tol_m, match_ns=self.period_ns // 2)
            self.tube.feed(res, k)
        self.tube_pending = [(t[k:], x[k:], y[k:])] if k < t.shape[0] else []
        # keep the nominal samples a later pose sample can still match: from the last one before it
        keep_from = int(t[k]) if k < t.shape[0] else self.tube_last_t + 1
        j = max(int(np.searchsorted(nt, keep_from, side="left")) - 1, 0)
        self.nominal = (nt[j:], nx[j:], ny[j:])

    def running(self) -> list[tuple[str, bool, int | None, float | None]]:
        """Per check (tube, input box, workspace, obstacle clearance): whether it failed, its first violation and
        its margin so far."""
        out: list[tuple[str, bool, int | None, float | None]] = []
        for run in (self.tube, self.input):
            when = run.fail.first_violation_ns if run.fail is not None else None
            out.append((run.name, run.fail is not None, when, run.margin))
        for margin_run in (self.ws, self.clear):
            out.append((margin_run.name, margin_run.fail_ns is not None, margin_run.fail_ns, margin_run.sample_min))
        return out

    def results(self) -> list[CheckResult]:
        """The ``CheckResult`` of each check at the end (tube, input box, workspace, obstacle clearance)."""
        tube = self.tube.result({"radius_m": self.tube_radius_m, "noise_tolerance_m": self.tol_m})
        if self.nominal_seen == 0:
            tube = CheckResult("tube", "inconclusive", None, None,
                               {"reason": "no nominal state logged: tube containment cannot be checked"})
        clear = self.clear.result() if self.unsafe else CheckResult(
            "obstacle_clearance", "pass", None, None, {"reason": "no unsafe regions"})
        return [tube, self.input.result({"max_abs": list(self.scenario.inputs.max_abs)}), self.ws.result(), clear]
