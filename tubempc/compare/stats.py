"""Two sides' metrics + settings -> one ``MetricResult`` per metric: summaries, the difference, a status.

input: the ``Pairing`` of the runs, the metrics of every run (``certificate_metrics``) and the ``CompareSettings``
-> output: a tuple of frozen ``MetricResult`` (``compare_metrics``).

Every number is turned into its *badness* (``-value`` when larger is better), so that "worse" is always "larger".
Per numeric metric, with ``tol`` its tolerance and ``alpha = 1 - confidence``:

- paired (every run has its partner): the differences ``d = bad(after) - bad(before)`` per pair; the difference
  reported is their median. **regressed**: median ``d > tol`` and the Wilcoxon signed-rank test rejects "not
  worse" (one-sided, ``d > 0``) at ``alpha``; **within tolerance**: the same test rejects "worse by at least
  ``tol``" (on ``d - tol``, one-sided) at ``alpha``; **improved**: median ``d < -tol`` and the test rejects "not
  better"; anything else is **cannot tell**. Exact differences of zero with no tolerance are "no change".
- unpaired: the same three tests with Mann-Whitney U on the two samples (the difference reported is the
  Hodges-Lehmann shift, the median of all after - before differences).
- A test that could not reach ``alpha`` with any data (too few runs: a paired signed-rank test needs ``n`` pairs
  with ``2**-n < alpha``, five at 95 %; Mann-Whitney needs ``1 / C(n1 + n2, n1) < alpha``) makes the metric
  **too few runs** ("cannot tell"), never "within tolerance".

Verdicts (pass < inconclusive < fail): a pair whose after-run is worse than its before-run **regresses**, whatever
the statistics (pass -> fail or inconclusive; inconclusive -> fail). Unpaired, the share of runs that are not a pass
is compared with Fisher's exact test (one-sided) under the same minimum-runs rule.
Entry and transition times: a pair whose before-run reached the region and whose after-run did not regresses.
"""

from __future__ import annotations

import math
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, replace
from typing import Literal

import numpy as np
from scipy import stats

from tubempc.compare.metrics import VERDICT_RANK, MetricInfo, MetricValue, metric_info
from tubempc.compare.runs import Pairing
from tubempc.compare.settings import CompareSettings

__all__ = ["STATUS_ORDER", "MetricResult", "SideSummary", "Status", "compare_metrics", "min_pairs", "verdict_name"]

Status = Literal["regressed", "cannot_tell", "improved", "ok", "not_judged"]
#: the order of the readable diff: regressions first
STATUS_ORDER: tuple[Status, ...] = ("regressed", "cannot_tell", "improved", "ok", "not_judged")
_RANK_VERDICT = {v: k for k, v in VERDICT_RANK.items()}


@dataclass(frozen=True, slots=True)
class SideSummary:
    """One side of one metric: n, median, 5th/95th percentiles and the worst value (in the metric's own sign);
    for verdicts, the count per verdict and the worst verdict."""

    n: int
    median: float | None = None
    p05: float | None = None
    p95: float | None = None
    worst: float | None = None
    verdicts: tuple[tuple[str, int], ...] = ()
    worst_verdict: str | None = None


@dataclass(frozen=True, slots=True)
class MetricResult:
    name: str
    kind: str
    direction: str
    unit: str
    status: Status
    reason: str
    before: SideSummary
    after: SideSummary
    values_before: tuple[float, ...]  # the numbers (verdict ranks) per run, for the plots
    values_after: tuple[float, ...]
    paired: bool
    difference: float | None = None  # median after - before (paired) or Hodges-Lehmann shift, metric's own sign
    worse_by: float | None = None  # the same, positive when worse
    tolerance: float | None = None
    test: str | None = None
    p_worse: float | None = None  # one-sided p of "after is worse"
    p_within: float | None = None  # one-sided p of "after is worse by less than the tolerance"
    runs_worse: tuple[str, ...] = ()  # paired runs whose verdict got worse (or that no longer reach a region)


def min_pairs(alpha: float) -> int:
    """The fewest pairs with which a one-sided signed-rank test can reach ``p < alpha`` (``2**-n < alpha``)."""
    return math.floor(math.log2(1.0 / alpha)) + 1


def _mw_can_decide(n1: int, n2: int, alpha: float) -> bool:
    return n1 > 0 and n2 > 0 and 1.0 / math.comb(n1 + n2, n1) < alpha


def _numeric_summary(values: Sequence[float], direction: str) -> SideSummary:
    if not values:
        return SideSummary(0)
    a = np.asarray(values, dtype=float)
    worst = float(a.min()) if direction == "higher_better" else float(a.max())
    return SideSummary(len(a), float(np.median(a)), float(np.percentile(a, 5)), float(np.percentile(a, 95)),
                       worst if direction != "neutral" else None)


def _verdict_summary(ranks: Sequence[int]) -> SideSummary:
    counts = tuple((_RANK_VERDICT[r].value, sum(1 for x in ranks if x == r)) for r in sorted(set(ranks)))
    return SideSummary(len(ranks), verdicts=counts,
                       worst_verdict=_RANK_VERDICT[max(ranks)].value if ranks else None)


def _wilcoxon(d: np.ndarray, alternative: Literal["greater", "less"]) -> float:
    if not np.any(d != 0):
        return 1.0
    return float(stats.wilcoxon(d, alternative=alternative, zero_method="wilcox").pvalue)


def _mannwhitney(x: np.ndarray, y: np.ndarray, alternative: Literal["greater", "less"]) -> float:
    if np.all(x == x[0]) and np.all(y == x[0]):
        return 1.0
    return float(stats.mannwhitneyu(x, y, alternative=alternative).pvalue)


def _fmt(v: float) -> str:
    return f"{v:.4g}"


@dataclass(frozen=True, slots=True)
class _Sample:
    before: dict[str, float]  # run key -> value (metric's own sign)
    after: dict[str, float]


def _judge_numeric(name: str, info: MetricInfo, unit: str, sample: _Sample, *, pairing: Pairing,
                   settings: CompareSettings) -> MetricResult:
    sign = -1.0 if info.direction == "higher_better" else 1.0
    common = [(b.key, a.key) for b, a in pairing.pairs if b.key in sample.before and a.key in sample.after]
    if pairing.paired and len(common) == len(sample.before) == len(sample.after):  # pair order (for the plots)
        b_vals, a_vals = [sample.before[k] for k, _ in common], [sample.after[k] for _, k in common]
    else:
        b_vals, a_vals = list(sample.before.values()), list(sample.after.values())
    base = MetricResult(name, info.kind, info.direction, unit, "not_judged", "",
                        _numeric_summary(b_vals, info.direction), _numeric_summary(a_vals, info.direction),
                        tuple(b_vals), tuple(a_vals), pairing.paired)
    lost: tuple[str, ...] = ()
    if info.absent_is_worse:
        lost = tuple(b.key for b, a in pairing.pairs if b.key in sample.before and a.key not in sample.after)
    if info.direction == "neutral":
        diff = (float(np.median([sample.after[k2] - sample.before[k1] for k1, k2 in common])) if pairing.paired
                and common else (float(np.median(a_vals) - np.median(b_vals)) if a_vals and b_vals else None))
        return replace(base, reason="reported, not judged", difference=diff)
    if not b_vals or not a_vals:
        side = "after" if not a_vals else "before"
        status: Status = "regressed" if lost else "cannot_tell"
        why = (f"no longer reached in {len(lost)} paired run(s): {', '.join(lost[:5])}" if lost
               else f"no value {side}: nothing to compare")
        return replace(base, status=status, reason=why, runs_worse=lost)
    tol = settings.tolerance(name, info.family).allowed(float(np.median(b_vals)))
    alpha = settings.alpha
    if pairing.paired:
        d = np.array([sign * (sample.after[k2] - sample.before[k1]) for k1, k2 in common], dtype=float)
        n = d.size
        test = "Wilcoxon signed-rank, paired, one-sided"
        can_decide = n >= min_pairs(alpha)
        need = f"a paired test needs at least {min_pairs(alpha)} pairs"
        worse_by = float(np.median(d)) if n else 0.0
        p_worse = _wilcoxon(d, "greater") if n else 1.0
        p_within = _wilcoxon(d - tol, "less") if n else 1.0
        p_better = _wilcoxon(d, "less") if n else 1.0
        exact_same = n > 0 and tol == 0 and not np.any(d != 0)
    else:
        a = sign * np.asarray(a_vals, dtype=float)
        b = sign * np.asarray(b_vals, dtype=float)
        n = min(a.size, b.size)
        test = "Mann-Whitney U, two samples, one-sided"
        can_decide = _mw_can_decide(a.size, b.size, alpha)
        need = "two samples need 1 / C(n1 + n2, n1) < alpha (4 runs a side at 95 %)"
        worse_by = float(np.median(np.subtract.outer(a, b)))
        p_worse = _mannwhitney(a, b, "greater")
        p_within = _mannwhitney(a - tol, b, "less")
        p_better = _mannwhitney(a, b, "less")
        exact_same = tol == 0 and bool(np.all(a == b[0]) and np.all(b == b[0]))
    worse_by += 0.0  # no "-0" in the output
    base = replace(base, difference=sign * worse_by + 0.0, worse_by=worse_by, tolerance=tol, test=test, p_worse=p_worse,
                   p_within=p_within, runs_worse=lost)
    conf = f"{settings.confidence:g}"
    shift = (f"worse by {_fmt(worse_by)}" if worse_by > 0 else f"better by {_fmt(-worse_by)}" if worse_by < 0
             else "no change of the median")
    if lost:
        return replace(base, status="regressed",
                            reason=f"no longer reached in {len(lost)} paired run(s): {', '.join(lost[:5])}")
    if exact_same:
        return replace(base, status="ok", reason="no change in any run")
    if not can_decide:
        return replace(base, status="cannot_tell",
                            reason=f"too few runs to tell: n={n}; at confidence {conf} {need} ({shift}, "
                                   f"tolerance {_fmt(tol)})")
    if worse_by > tol and p_worse < alpha:
        return replace(base, status="regressed",
                            reason=f"{shift} (tolerance {_fmt(tol)}); p = {p_worse:.3g} < {alpha:.3g}")
    if worse_by < -tol and p_better < alpha:
        return replace(base, status="improved",
                            reason=f"{shift} (tolerance {_fmt(tol)}); p = {p_better:.3g} < {alpha:.3g}")
    if p_within < alpha:
        return replace(base, status="ok",
                            reason=f"within tolerance {_fmt(tol)} at confidence {conf} ({shift}; "
                                   f"p = {p_within:.3g})")
    if worse_by > tol:
        why = f"{shift}, beyond the tolerance {_fmt(tol)}, but not significant at {conf} (p = {p_worse:.3g})"
    else:
        why = (f"{shift}, but the runs cannot show it stays within the tolerance {_fmt(tol)} at {conf} "
               f"(p = {p_within:.3g}): more runs, or a larger tolerance")
    return replace(base, status="cannot_tell", reason=why)


def _judge_verdict(name: str, info: MetricInfo, ranks_b: dict[str, int], ranks_a: dict[str, int], *,
                   pairing: Pairing, settings: CompareSettings) -> MetricResult:
    base = MetricResult(name, info.kind, info.direction, "", "not_judged", "",
                        _verdict_summary(list(ranks_b.values())), _verdict_summary(list(ranks_a.values())),
                        tuple(float(v) for v in ranks_b.values()), tuple(float(v) for v in ranks_a.values()),
                        pairing.paired)
    pairs = [(b.key, a.key) for b, a in pairing.pairs if b.key in ranks_b and a.key in ranks_a]
    worse = tuple(k1 for k1, k2 in pairs if ranks_a[k2] > ranks_b[k1])
    better = [k1 for k1, k2 in pairs if ranks_a[k2] < ranks_b[k1]]

    def moves(keys: Sequence[str]) -> str:
        by_key = dict(pairs)
        shown = [f"{k}: {_RANK_VERDICT[ranks_b[k]].value} -> {_RANK_VERDICT[ranks_a[by_key[k]]].value}"
                 for k in keys[:5]]
        return "; ".join(shown) + (f"; and {len(keys) - 5} more" if len(keys) > 5 else "")

    if worse:
        return replace(base, status="regressed", runs_worse=worse,
                            reason=f"{len(worse)} paired run(s) got a worse verdict: {moves(worse)}")
    if not ranks_b or not ranks_a:
        side = "after" if not ranks_a else "before"
        return replace(base, status="cannot_tell", reason=f"no value {side}: nothing to compare")
    if pairing.paired:
        if better:
            return replace(base, status="improved",
                                reason=f"{len(better)} paired run(s) got a better verdict: {moves(better)}")
        return replace(base, status="ok", reason="no paired run got a worse verdict")
    alpha = settings.alpha
    bad_b = sum(1 for r in ranks_b.values() if r > 0)
    bad_a = sum(1 for r in ranks_a.values() if r > 0)
    n_b, n_a = len(ranks_b), len(ranks_a)
    table = [[bad_a, n_a - bad_a], [bad_b, n_b - bad_b]]
    p_worse = float(stats.fisher_exact(table, alternative="greater").pvalue)
    p_better = float(stats.fisher_exact(table, alternative="less").pvalue)
    share = f"not a pass: {bad_b} of {n_b} before, {bad_a} of {n_a} after"
    test = "Fisher exact, two samples, one-sided"
    base = replace(base, test=test, p_worse=p_worse)
    if bad_a == bad_b == 0:
        return replace(base, status="ok", reason="every run passes on both sides")
    if not _mw_can_decide(n_b, n_a, alpha):
        return replace(base, status="cannot_tell",
                            reason=f"too few runs to tell ({share})")
    if p_worse < alpha:
        return replace(base, status="regressed",
                            reason=f"{share}; p = {p_worse:.3g} < {alpha:.3g}")
    if p_better < alpha:
        return replace(base, status="improved",
                            reason=f"{share}; p = {p_better:.3g} < {alpha:.3g}")
    if bad_a / n_a <= bad_b / n_b:
        return replace(base, status="ok", reason=f"no more runs fail or are undecided ({share})")
    return replace(base, status="cannot_tell",
                        reason=f"more runs are not a pass, but not significantly ({share}; p = {p_worse:.3g})")


def compare_metrics(pairing: Pairing, before: Mapping[str, Mapping[str, MetricValue]],
                    after: Mapping[str, Mapping[str, MetricValue]], settings: CompareSettings
                    ) -> tuple[MetricResult, ...]:
    """``before``/``after``: run key -> that run's metrics. Paired tests use ``pairing.pairs`` when
    ``pairing.paired``; otherwise every run of a side is one sample."""
    names = sorted({m for runs in (before, after) for metrics in runs.values() for m in metrics})
    out = []
    for name in names:
        unit = next((v.unit for runs in (before, after) for metrics in runs.values()
                     if (v := metrics.get(name)) is not None and v.unit), "")
        info = metric_info(name, unit)
        if info.kind == "verdict":
            rb = {k: VERDICT_RANK[v.verdict] for k, m in before.items() if (v := m.get(name)) and v.verdict}
            ra = {k: VERDICT_RANK[v.verdict] for k, m in after.items() if (v := m.get(name)) and v.verdict}
            out.append(_judge_verdict(name, info, rb, ra, pairing=pairing, settings=settings))
            continue
        sample = _Sample({k: v.number for k, m in before.items() if (v := m.get(name)) and v.number is not None},
                         {k: v.number for k, m in after.items() if (v := m.get(name)) and v.number is not None})
        out.append(_judge_numeric(name, info, info.unit or unit, sample, pairing=pairing, settings=settings))
    return tuple(sorted(out, key=lambda r: (STATUS_ORDER.index(r.status), not _beyond(r), r.name)))


def _beyond(r: MetricResult) -> bool:
    """Changed by more than the tolerance (listed first within its status)."""
    return r.worse_by is not None and r.tolerance is not None and abs(r.worse_by) > r.tolerance


def verdict_name(rank: float) -> str:
    """The verdict of a rank (for plots and tables)."""
    return _RANK_VERDICT[int(rank)].value if int(rank) in _RANK_VERDICT else "?"
