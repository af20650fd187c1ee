"""One certificate -> the metrics ``compare`` judges, each with its unit, its family and which way is worse.

input: a ``verify.certificate.Certificate`` -> output: ``{metric name: MetricValue}``; ``metric_info(name)`` gives the
metric's ``MetricInfo`` (kind, direction, unit, tolerance family).

The metrics (a metric a certificate lacks is absent, never invented):
- ``verdict`` and ``check.<name>.verdict``, ``obligation.<formula>.verdict``: pass < inconclusive < fail;
- ``check.<name>.margin``, ``obligation.<formula>.margin``: the certificate's worst margin (smaller is worse);
- ``min_clearance_m``: the smallest sampled clearance of the robot disc from an unsafe region (``obstacle_clearance``;
  the check's margin also bounds the motion between samples), ``workspace_margin_m`` likewise (``workspace``);
- ``tube_ratio``: largest deviation from the nominal / tube radius (``tube``; larger is worse);
- ``input_usage``: largest ``|u_i| / max_abs_i`` over the logged commands (``input_box``; larger is worse);
- ``entry_s.<region>``: first time the robot disc was inside ``region`` (timed run; later is worse);
  ``transition_s.<from>-><to>``: time from entering ``from`` to entering ``to`` the first time the timed run goes
  from one to the other (longer is worse); a paired run that no longer gets there is worse (``compare.stats``);
- ``duration_s``: the log's span; reported, never judged (a recording's length is the operator's choice).
"""

from __future__ import annotations

import itertools
import math
from collections.abc import Mapping
from dataclasses import dataclass
from typing import Any, Literal

from verify.certificate import Certificate, Verdict

__all__ = ["VERDICT_RANK", "MetricInfo", "MetricValue", "certificate_metrics", "metric_info"]

Direction = Literal["higher_better", "lower_better", "neutral"]
Kind = Literal["verdict", "number"]

#: pass < inconclusive < fail: a larger rank is a worse verdict
VERDICT_RANK = {Verdict.PASS: 0, Verdict.INCONCLUSIVE: 1, Verdict.FAIL: 2}


@dataclass(frozen=True, slots=True)
class MetricInfo:
    """How a metric is judged: ``kind``, which ``direction`` is better, its ``unit`` and tolerance ``family``.
    ``absent_is_worse``: a run of a pair that lacks the metric while its partner has it got worse (a region no
    longer entered)."""

    kind: Kind
    direction: Direction
    unit: str
    family: str
    absent_is_worse: bool = False


@dataclass(frozen=True, slots=True)
class MetricValue:
    """One run's value of one metric: a verdict or a finite number, with the unit the certificate states."""

    verdict: Verdict | None = None
    number: float | None = None
    unit: str = ""


_FIXED: dict[str, MetricInfo] = {
    "verdict": MetricInfo("verdict", "lower_better", "", "verdict"),
    "min_clearance_m": MetricInfo("number", "higher_better", "m", "min_clearance_m"),
    "workspace_margin_m": MetricInfo("number", "higher_better", "m", "workspace_margin_m"),
    "tube_ratio": MetricInfo("number", "lower_better", "", "tube_ratio"),
    "input_usage": MetricInfo("number", "lower_better", "", "input_usage"),
    "duration_s": MetricInfo("number", "neutral", "s", "duration_s"),
}


def metric_info(name: str, unit: str = "") -> MetricInfo:
    """The rule for ``name`` (``unit``: the unit a certificate states for a margin)."""
    if name in _FIXED:
        return _FIXED[name]
    if name.endswith(".verdict"):
        return MetricInfo("verdict", "lower_better", "", "verdict")
    if name.endswith(".margin"):
        return MetricInfo("number", "higher_better", unit, "check_margin")
    if name.startswith("entry_s."):
        return MetricInfo("number", "lower_better", "s", "entry_s", absent_is_worse=True)
    if name.startswith("transition_s."):
        return MetricInfo("number", "lower_better", "s", "transition_s", absent_is_worse=True)
    return MetricInfo("number", "neutral", unit, "other")


def _finite(value: Any) -> float | None:
    if isinstance(value, bool) or not isinstance(value, int | float):
        return None
    return float(value) if math.isfinite(float(value)) else None


def _number(value: Any, unit: str) -> MetricValue | None:
    v = _finite(value)
    return None if v is None else MetricValue(number=v, unit=unit)


def _verdict_of(value: Any) -> Verdict | None:
    try:
        return Verdict(getattr(value, "value", value))
    except ValueError:
        return None


def _obligations(cert: Certificate) -> dict[str, MetricValue]:
    """Per-obligation verdict and margin, when the certificate carries them (read through the model's attributes:
    each entry names its formula, verdict and margin)."""
    out: dict[str, MetricValue] = {}
    for entry in getattr(cert, "obligations", None) or ():
        name = getattr(entry, "formula", None) or getattr(entry, "name", None)
        if not isinstance(name, str):
            continue
        verdict = _verdict_of(getattr(entry, "verdict", None))
        if verdict is not None:
            out[f"obligation.{name}.verdict"] = MetricValue(verdict=verdict)
        unit = getattr(entry, "margin_unit", None)
        margin = _number(getattr(entry, "margin", None), unit if isinstance(unit, str) else "")
        if margin is not None:
            out[f"obligation.{name}.margin"] = margin
    return out


def _check_derived(cert: Certificate) -> dict[str, MetricValue]:
    out: dict[str, MetricValue] = {}
    details: dict[str, Mapping[str, Any]] = {c.name: c.details for c in cert.checks}
    for check, metric in (("obstacle_clearance", "min_clearance_m"), ("workspace", "workspace_margin_m")):
        entry = cert.check(check)
        if entry is None:
            continue
        # a passing check states the sampled minimum beside its between-samples bound; otherwise the margin is it
        sampled = _finite(details[check].get("sample_margin_m"))
        value = _number(sampled if sampled is not None else entry.margin, "m")
        if value is not None:
            out[metric] = value
    tube = cert.check("tube")
    if tube is not None:
        dev, radius = _finite(details["tube"].get("max_deviation_m")), _finite(details["tube"].get("radius_m"))
        if dev is not None and radius is not None and radius > 0:
            out["tube_ratio"] = MetricValue(number=dev / radius)
    box = cert.check("input_box")
    if box is not None:
        bounds, margins = details["input_box"].get("bounds"), details["input_box"].get("component_margins")
        tolerance = _finite(details["input_box"].get("tolerance")) or 0.0
        if isinstance(bounds, Mapping) and isinstance(margins, Mapping):
            usage = []
            for name, bound in bounds.items():
                b, m = _finite(bound), _finite(margins.get(name))
                if b is not None and m is not None and b > 0:
                    usage.append((b + tolerance - m) / b)
            if usage:
                out["input_usage"] = MetricValue(number=max(usage))
    return out


def _timed_run(cert: Certificate) -> dict[str, MetricValue]:
    """Entry and transition times; several robots: each robot's own run (``entry_s.husky/dock``)."""
    out: dict[str, MetricValue] = {}
    robots = sorted({e.robot for e in cert.timed_run if e.robot is not None})
    runs = [(f"{r}/", [e for e in cert.timed_run if e.robot == r]) for r in robots] or [("", list(cert.timed_run))]
    for prefix, run in runs:
        for entry in run:
            out.setdefault(f"entry_s.{prefix}{entry.region}", MetricValue(number=entry.time, unit="s"))
        for prev, nxt in itertools.pairwise(run):
            if prev.region != nxt.region:
                out.setdefault(f"transition_s.{prefix}{prev.region}->{nxt.region}",
                               MetricValue(number=nxt.time - prev.time, unit="s"))
    return out


def certificate_metrics(cert: Certificate) -> dict[str, MetricValue]:
    """Every metric of one certificate (see the module docstring), sorted by name."""
    out: dict[str, MetricValue] = {"verdict": MetricValue(verdict=cert.verdict)}
    for check in cert.checks:
        out[f"check.{check.name}.verdict"] = MetricValue(verdict=check.verdict)
        margin = _number(check.margin, check.margin_unit or "")
        if margin is not None:
            out[f"check.{check.name}.margin"] = margin
    out |= _obligations(cert) | _check_derived(cert) | _timed_run(cert)
    duration = _number(cert.duration_s, "s")
    if duration is not None:
        out["duration_s"] = duration
    return dict(sorted(out.items()))
