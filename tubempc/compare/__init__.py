"""Regression checks of any controller change from recorded logs: two sets of runs, certified, compared per metric.

``load_side`` (logs certified with ``verify``, or certificates) -> ``pair_runs`` -> ``judge`` (per metric: summaries,
difference, one-sided tests against a tolerance) -> ``format_diff`` / ``write_page`` / ``outcome_junit`` /
``outcome_json``. ``tubempc compare`` is the command-line front (``tubempc.cli.compare``).
"""

from tubempc.compare.metrics import MetricInfo, MetricValue, certificate_metrics, metric_info
from tubempc.compare.outcome import CompareOutcome, CompareReport, format_diff, judge, outcome_json, outcome_junit
from tubempc.compare.runs import Pairing, Run, Side, load_side, pair_runs
from tubempc.compare.settings import CompareSettings, Tolerance, load_settings, settings_path_for
from tubempc.compare.stats import MetricResult, SideSummary, compare_metrics, min_pairs

__all__ = [
    "CompareOutcome",
    "CompareReport",
    "CompareSettings",
    "MetricInfo",
    "MetricResult",
    "MetricValue",
    "Pairing",
    "Run",
    "Side",
    "SideSummary",
    "Tolerance",
    "certificate_metrics",
    "compare_metrics",
    "format_diff",
    "judge",
    "load_settings",
    "load_side",
    "metric_info",
    "min_pairs",
    "outcome_json",
    "outcome_junit",
    "pair_runs",
    "settings_path_for",
]
