"""Current run metrics + stored baseline + tolerances -> a diff with regressions, improvements and a verdict.

input: ``RunOutcome`` values, a baseline JSON (``read_baseline``) and the suite's ``Tolerances``
-> output: a frozen ``Comparison`` (one ``DiffRow`` per metric that moved, plus missing/new runs); ``format_diff``
renders it as text; ``Comparison.regressed`` decides the exit code. ``write_baseline`` stores the current metrics.

Direction of "worse" per metric: verdicts pass < inconclusive < fail (no tolerance); larger is worse for transition
times, tube ratio/error, solver failures/backups and solve times; smaller is worse for clearances and margins.
A transition that is no longer reached (t_ij None), a run that errors, or a run without a baseline regresses; so does
a falsification case that finds a counterexample (``falsify.violation``) where the baseline found none (its margin
and simulation counts are reported only through the verdict: a search's lowest margin is not a tolerance metric).
"""

from __future__ import annotations

import json
import math
from collections.abc import Iterable, Mapping
from dataclasses import dataclass
from datetime import UTC, datetime
from pathlib import Path
from typing import TYPE_CHECKING, Any, Literal

from tubempc.errors import BaselineError
from tubempc.regress.runner import RunOutcome
from tubempc.regress.suite import Suite, Tolerance, Tolerances

if TYPE_CHECKING:
    from verify.junit import JUnitSuite

__all__ = [
    "BASELINE_FORMAT",
    "BaselineError",
    "Comparison",
    "DiffRow",
    "compare",
    "comparison_junit",
    "format_diff",
    "read_baseline",
    "write_baseline",
]

BASELINE_FORMAT = "tubempc-regress-baseline/1"
_VERDICT_RANK = {"pass": 0, "inconclusive": 1, "fail": 2}
Status = Literal["regressed", "improved", "new", "missing", "error"]


@dataclass(frozen=True, slots=True)
class DiffRow:
    run_id: str
    metric: str
    status: Status
    baseline: Any
    current: Any
    allowed: float | None  # the tolerance that applied (None for verdicts and missing values)

    def describe(self) -> str:
        if self.metric == "*":
            return f"{self.run_id}: {self.current}"
        delta = ""
        if isinstance(self.baseline, int | float) and isinstance(self.current, int | float) \
                and not isinstance(self.baseline, bool):
            delta = f" ({self.current - self.baseline:+.4g}"
            delta += f", tolerance {self.allowed:.4g})" if self.allowed is not None else ")"
        return f"{self.run_id}  {self.metric}: {_show(self.baseline)} -> {_show(self.current)}{delta}"


def _show(value: Any) -> str:
    if isinstance(value, float):
        return f"{value:.6g}"
    return "none" if value is None else str(value)


@dataclass(frozen=True, slots=True)
class Comparison:
    rows: tuple[DiffRow, ...]
    runs: int
    metrics: int

    @property
    def regressed(self) -> bool:
        return any(r.status in ("regressed", "new", "error") for r in self.rows)

    def by_status(self, *statuses: Status) -> list[DiffRow]:
        return [r for r in self.rows if r.status in statuses]


# ---- per-metric rules ---------------------------------------------------------------------------------------------
def _rule(metric: str, tol: Tolerances) -> tuple[str, Tolerance | None]:
    """(direction, tolerance): direction ``verdict``, ``flag`` / ``flag_bad``, ``higher_worse`` or ``lower_worse``."""
    if metric == "verdict" or metric.endswith(".verdict"):
        return "verdict", None
    if metric == "arrived":
        return "flag", None
    if metric == "falsify.violation":
        return "flag_bad", None
    if metric.startswith("t_ij_s."):
        return "higher_worse", tol.t_ij_s
    if metric.startswith("check.") and metric.endswith(".margin"):
        return "lower_worse", tol.check_margin
    table: dict[str, tuple[str, Tolerance]] = {
        "tube_ratio": ("higher_worse", tol.tube_ratio),
        "max_tube_error_m": ("higher_worse", tol.max_tube_error_m),
        "min_clearance_m": ("lower_worse", tol.min_clearance_m),
        "workspace_margin_m": ("lower_worse", tol.workspace_margin_m),
        "input_margin": ("lower_worse", tol.input_margin),
        "solver_failures": ("higher_worse", tol.solver_failures),
        "solver_backups": ("higher_worse", tol.solver_backups),
        "solve_time_p50_ms": ("higher_worse", tol.solve_time_p50_ms),
        "solve_time_p95_ms": ("higher_worse", tol.solve_time_p95_ms),
    }
    if metric in table:
        direction, tolerance = table[metric]
        return direction, tolerance
    return "unknown", None


def _number(value: Any) -> float | None:
    if isinstance(value, bool) or not isinstance(value, int | float):
        return None
    return float(value) if math.isfinite(float(value)) else None


def _compare_metric(run_id: str, metric: str, base: Any, cur: Any, tol: Tolerances) -> DiffRow | None:
    direction, tolerance = _rule(metric, tol)
    if direction == "verdict":
        b, c = _VERDICT_RANK.get(str(base), 3), _VERDICT_RANK.get(str(cur), 3)
        if c > b or (c == b == 3 and base != cur):
            return DiffRow(run_id, metric, "regressed", base, cur, None)
        return DiffRow(run_id, metric, "improved", base, cur, None) if c < b else None
    if direction == "flag_bad":  # true is the bad state: a counterexample found
        if bool(cur) and not bool(base):
            return DiffRow(run_id, metric, "regressed", base, cur, None)
        return DiffRow(run_id, metric, "improved", base, cur, None) if bool(base) and not bool(cur) else None
    if direction == "flag":
        if bool(base) and not bool(cur):
            return DiffRow(run_id, metric, "regressed", base, cur, None)
        return DiffRow(run_id, metric, "improved", base, cur, None) if bool(cur) and not bool(base) else None
    b_num, c_num = _number(base), _number(cur)
    if b_num is None and c_num is None:
        return None
    if c_num is None:  # e.g. a transition no longer reached
        return DiffRow(run_id, metric, "regressed", base, cur, None)
    if b_num is None:
        return DiffRow(run_id, metric, "improved", base, cur, None)
    if tolerance is None:  # a metric this version does not know: report changes without judging them
        return None
    allowed = tolerance.allowed(b_num)
    worse = c_num - b_num if direction == "higher_worse" else b_num - c_num
    if worse > allowed + 1e-12:
        return DiffRow(run_id, metric, "regressed", base, cur, allowed)
    if -worse > allowed + 1e-12:
        return DiffRow(run_id, metric, "improved", base, cur, allowed)
    return None


def compare(baseline: Mapping[str, Any], outcomes: Iterable[RunOutcome], tolerances: Tolerances) -> Comparison:
    """Compare every run's metrics with the baseline's ``runs`` mapping."""
    base_runs: Mapping[str, Any] = baseline.get("runs", {})
    rows: list[DiffRow] = []
    seen: set[str] = set()
    n_metrics = 0
    for out in outcomes:
        seen.add(out.run_id)
        if out.error is not None:
            rows.append(DiffRow(out.run_id, "*", "error", None, out.error, None))
            continue
        base = base_runs.get(out.run_id)
        if base is None:
            rows.append(DiffRow(out.run_id, "*", "new", None, "no baseline for this run (run with --update-baseline)",
                                None))
            continue
        base_metrics: Mapping[str, Any] = base.get("metrics", {})
        for metric in sorted(set(base_metrics) | set(out.metrics)):
            n_metrics += 1
            row = _compare_metric(out.run_id, metric, base_metrics.get(metric), out.metrics.get(metric), tolerances)
            if row is not None:
                rows.append(row)
    for run_id in sorted(set(base_runs) - seen):
        rows.append(DiffRow(run_id, "*", "missing", None, "in the baseline but not in the suite", None))
    return Comparison(tuple(rows), len(seen), n_metrics)


def format_diff(comparison: Comparison) -> str:
    """Readable text: regressions first, then errors/new runs, improvements, and a one-line summary."""
    lines: list[str] = []
    sections: tuple[tuple[str, tuple[Status, ...]], ...] = (
        ("REGRESSED", ("regressed",)), ("ERRORS", ("error",)), ("NOT IN BASELINE", ("new",)),
        ("IMPROVED (update the baseline to keep them)", ("improved",)), ("MISSING FROM THE SUITE", ("missing",)))
    for title, statuses in sections:
        rows = comparison.by_status(*statuses)
        if rows:
            lines.append(f"{title} ({len(rows)}):")
            lines += [f"  {r.describe()}" for r in rows]
    bad = len(comparison.by_status("regressed", "error", "new"))
    verdict = "REGRESSION" if comparison.regressed else "OK"
    lines.append(f"{verdict}: {comparison.runs} runs, {comparison.metrics} metrics compared; {bad} regressed or "
                 f"failing, {len(comparison.by_status('improved'))} improved, the rest within tolerance")
    return "\n".join(lines)


# ---- baseline files -----------------------------------------------------------------------------------------------
def read_baseline(path: str | Path) -> dict[str, Any]:
    p = Path(path)
    try:
        data = json.loads(p.read_text(encoding="utf-8"))
    except FileNotFoundError:
        raise BaselineError(f"{p}: baseline not found (create it with --update-baseline)") from None
    except (OSError, UnicodeDecodeError, json.JSONDecodeError) as err:
        raise BaselineError(f"{p}: unreadable baseline ({err.__class__.__name__}: {err})") from None
    if not isinstance(data, dict) or data.get("format") != BASELINE_FORMAT or not isinstance(data.get("runs"), dict):
        raise BaselineError(f"{p}: not a regress baseline (expected format {BASELINE_FORMAT!r} with a 'runs' map)")
    return data


def write_baseline(path: str | Path, suite: Suite, outcomes: Iterable[RunOutcome]) -> Path:
    """Store the metrics of every successful run; refuses when a run errored (its baseline would be empty)."""
    runs: dict[str, Any] = {}
    for out in outcomes:
        if out.error is not None:
            raise BaselineError(f"{path}: not written: run {out.run_id} failed ({out.error})")
        runs[out.run_id] = {"metrics": out.metrics}
    data = {"format": BASELINE_FORMAT, "suite": suite.name, "suite_sha256": suite.sha256(),
            "created": datetime.now(UTC).isoformat(timespec="seconds"), "runs": dict(sorted(runs.items()))}
    p = Path(path)
    p.parent.mkdir(parents=True, exist_ok=True)
    p.write_text(json.dumps(data, indent=1, sort_keys=False) + "\n", encoding="utf-8")
    return p


def comparison_junit(comparison: Comparison, outcomes: Iterable[RunOutcome], *, suite_name: str) -> JUnitSuite:
    """One test case per run (the shared writer ``verify.junit``): a regressed or new run carries a ``failure`` of
    type ``regression``, a run that could not be run an ``error``."""
    from verify.junit import JUnitCase, JUnitSuite

    problems: dict[str, list[DiffRow]] = {}
    for row in comparison.rows:
        if row.status in ("regressed", "new", "error"):
            problems.setdefault(row.run_id, []).append(row)
    name = f"regress.{suite_name}"
    cases = []
    for out in outcomes:
        rows = problems.get(out.run_id)
        text = "\n".join(r.describe() for r in rows or ())
        if out.error is not None:
            cases.append(JUnitCase(out.run_id, name, "error", "run", f"the run failed: {out.error}", text,
                                   out.elapsed_s))
        elif rows:
            cases.append(JUnitCase(out.run_id, name, "failure", "regression", f"{len(rows)} metric(s) regressed",
                                   text, out.elapsed_s))
        else:
            cases.append(JUnitCase(out.run_id, name, time_s=out.elapsed_s))
    return JUnitSuite(name, tuple(cases), time_s=sum(c.time_s for c in cases))
