"""Two sides + settings -> a ``CompareOutcome`` (the judged metrics and the exit code), its JSON model, text and JUnit.

input: the before and after ``Side`` (``runs.load_side``), the ``Pairing`` and the ``CompareSettings`` -> output:
``CompareOutcome`` (``judge``); ``format_diff`` (regressions first), ``outcome_json`` (the typed ``CompareReport``,
``--json`` and ``compare.json``), ``outcome_junit`` (one test case per metric).

Exit codes: 1 when any metric regressed; else 2 when any judged metric cannot be told (too few runs, or a change the
runs cannot decide); else 0. "Cannot tell" is never reported as "no regression".
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import TYPE_CHECKING, Literal

from pydantic import BaseModel, ConfigDict

from tubempc.compare.metrics import MetricValue, certificate_metrics
from tubempc.compare.runs import Pairing, Side
from tubempc.compare.settings import CompareSettings
from tubempc.compare.stats import STATUS_ORDER, MetricResult, SideSummary, Status, compare_metrics

if TYPE_CHECKING:
    from verify.junit import JUnitSuite

__all__ = ["COMPARE_FORMAT", "CompareOutcome", "CompareReport", "format_diff", "judge", "outcome_json",
           "outcome_junit"]

COMPARE_FORMAT = "tubempc-compare/1"
EXIT_OK, EXIT_REGRESSED, EXIT_CANNOT_TELL = 0, 1, 2
_TITLES: dict[Status, str] = {"regressed": "REGRESSED", "cannot_tell": "CANNOT TELL",
                              "improved": "IMPROVED", "ok": "WITHIN TOLERANCE", "not_judged": "NOT JUDGED"}


@dataclass(frozen=True, slots=True)
class CompareOutcome:
    before: Side
    after: Side
    pairing: Pairing
    settings: CompareSettings
    metrics: tuple[MetricResult, ...]

    def by_status(self, *statuses: Status) -> list[MetricResult]:
        return [m for m in self.metrics if m.status in statuses]

    @property
    def exit_code(self) -> int:
        if self.by_status("regressed"):
            return EXIT_REGRESSED
        if self.by_status("cannot_tell"):
            return EXIT_CANNOT_TELL
        return EXIT_OK

    @property
    def verdict(self) -> Literal["regression", "cannot tell", "no regression"]:
        return ("regression", "cannot tell", "no regression")[(EXIT_REGRESSED, EXIT_CANNOT_TELL,
                                                                EXIT_OK).index(self.exit_code)]


def _ids(side: Side) -> dict[str, dict[str, MetricValue]]:
    """Run id -> metrics; a key that repeats on a side gets ``#2``, ``#3`` (it is then in no pair)."""
    out: dict[str, dict[str, MetricValue]] = {}
    for run in side.runs:
        key, k = run.key, 2
        while key in out:
            key, k = f"{run.key}#{k}", k + 1
        out[key] = certificate_metrics(run.certificate)
    return out


def judge(before: Side, after: Side, pairing: Pairing, settings: CompareSettings) -> CompareOutcome:
    """Every metric of every run of both sides, judged (``stats.compare_metrics``)."""
    metrics = compare_metrics(pairing, _ids(before), _ids(after), settings)
    return CompareOutcome(before, after, pairing, settings, metrics)


# ---- text ---------------------------------------------------------------------------------------------------------
def _num(value: float | None) -> str:
    return "-" if value is None else f"{value:.4g}"


def _side_text(s: SideSummary, kind: str) -> str:
    if kind == "verdict":
        return f"n={s.n}: " + ", ".join(f"{n} {v}" for v, n in s.verdicts) if s.n else "n=0"
    if not s.n:
        return "n=0"
    return f"median {_num(s.median)} (p05 {_num(s.p05)}, p95 {_num(s.p95)}, worst {_num(s.worst)}; n={s.n})"


def describe(m: MetricResult) -> list[str]:
    """Two lines for one metric: name, status reason; before -> after."""
    unit = f" [{m.unit}]" if m.unit else ""
    diff = f", difference {m.difference:+.4g}" if m.difference is not None else ""
    return [f"{m.name}{unit}: {m.reason}",
            f"    before {_side_text(m.before, m.kind)} -> after {_side_text(m.after, m.kind)}{diff}"]


def format_diff(outcome: CompareOutcome, *, verbose: bool = False) -> str:
    """Regressions first, then what cannot be told, improvements; metrics within tolerance are counted (listed with
    ``verbose``); the last line states the outcome and the exit code."""
    o = outcome
    lines = [f"compare: before {o.before.label} ({len(o.before.runs)} {o.before.kind}), after {o.after.label} "
             f"({len(o.after.runs)} {o.after.kind}); {o.pairing.note}; confidence {o.settings.confidence:g}, "
             f"tolerances: {o.settings.source}"]
    for status in STATUS_ORDER:
        rows = o.by_status(status)
        if not rows:
            continue
        if status in ("ok", "not_judged") and not verbose:
            lines.append(f"{_TITLES[status]} ({len(rows)}): {', '.join(m.name for m in rows)}")
            continue
        lines.append(f"{_TITLES[status]} ({len(rows)}):")
        for m in rows:
            lines += [f"  {text}" for text in describe(m)]
    counts = ", ".join(f"{len(o.by_status(s))} {_TITLES[s].lower()}" for s in STATUS_ORDER if o.by_status(s))
    lines.append(f"{o.verdict.upper()}: {len(o.metrics)} metrics ({counts}); exit code {o.exit_code}")
    return "\n".join(lines)


# ---- JSON ---------------------------------------------------------------------------------------------------------
class _Frozen(BaseModel):
    model_config = ConfigDict(frozen=True, extra="forbid")


class SideJson(_Frozen):
    n: int
    median: float | None
    p05: float | None
    p95: float | None
    worst: float | None
    verdicts: dict[str, int] | None
    worst_verdict: str | None


class MetricJson(_Frozen):
    name: str
    kind: str
    direction: str
    unit: str
    status: Status
    reason: str
    before: SideJson
    after: SideJson
    difference: float | None
    worse_by: float | None
    tolerance: float | None
    test: str | None
    p_worse: float | None
    p_within: float | None
    runs_worse: list[str]


class SideInput(_Frozen):
    input: str
    kind: str
    runs: list[str]


class CompareReport(_Frozen):
    """``tubempc compare --json`` and ``compare.json``."""

    format: Literal["tubempc-compare/1"]
    verdict: Literal["regression", "cannot tell", "no regression"]
    exit_code: int
    confidence: float
    tolerances_source: str
    paired: bool
    pairing: str
    before: SideInput
    after: SideInput
    metrics: list[MetricJson]


def _side_json(s: SideSummary) -> SideJson:
    return SideJson(n=s.n, median=s.median, p05=s.p05, p95=s.p95, worst=s.worst,
                    verdicts=dict(s.verdicts) if s.verdicts else None, worst_verdict=s.worst_verdict)


def outcome_json(outcome: CompareOutcome) -> CompareReport:
    o = outcome
    return CompareReport(
        format=COMPARE_FORMAT, verdict=o.verdict, exit_code=o.exit_code, confidence=o.settings.confidence,
        tolerances_source=o.settings.source, paired=o.pairing.paired, pairing=o.pairing.note,
        before=SideInput(input=o.before.label, kind=o.before.kind, runs=[r.source for r in o.before.runs]),
        after=SideInput(input=o.after.label, kind=o.after.kind, runs=[r.source for r in o.after.runs]),
        metrics=[MetricJson(name=m.name, kind=m.kind, direction=m.direction, unit=m.unit, status=m.status,
                            reason=m.reason, before=_side_json(m.before), after=_side_json(m.after),
                            difference=m.difference, worse_by=m.worse_by, tolerance=m.tolerance, test=m.test,
                            p_worse=m.p_worse, p_within=m.p_within, runs_worse=list(m.runs_worse))
                 for m in o.metrics])


# ---- JUnit --------------------------------------------------------------------------------------------------------
def outcome_junit(outcome: CompareOutcome, *, suite_name: str = "compare") -> JUnitSuite:
    """One test case per metric: ``failure`` of type ``regression`` or ``cannot-tell`` (not a pass: CI turns red),
    ``skipped`` for metrics reported but not judged, passed otherwise."""
    from verify.junit import JUnitCase, JUnitSuite

    cases = []
    for m in outcome.metrics:
        text = "\n".join(describe(m))
        if m.status == "regressed":
            cases.append(JUnitCase(m.name, suite_name, "failure", "regression", m.reason, text))
        elif m.status == "cannot_tell":
            cases.append(JUnitCase(m.name, suite_name, "failure", "cannot-tell",
                                   f"{m.reason} (not a pass: the runs cannot decide)", text))
        elif m.status == "not_judged":
            cases.append(JUnitCase(m.name, suite_name, "skipped", message=m.reason))
        else:
            cases.append(JUnitCase(m.name, suite_name))
    props = (("verdict", outcome.verdict), ("confidence", f"{outcome.settings.confidence:g}"),
             ("before", outcome.before.label), ("after", outcome.after.label), ("pairing", outcome.pairing.note))
    return JUnitSuite(suite_name, tuple(cases), props)
