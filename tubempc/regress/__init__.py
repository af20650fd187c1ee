"""Regression checks of controller changes: a suite of closed-loop runs, certified and compared with a baseline.

``load_suite`` -> ``expand_suite`` -> ``run_cases`` (parallel) -> ``compare`` with ``read_baseline`` -> ``format_diff``;
``write_baseline`` stores a new baseline. ``tubempc regress`` is the command-line front.
"""

from tubempc.regress.compare import (
    BASELINE_FORMAT,
    BaselineError,
    Comparison,
    DiffRow,
    compare,
    comparison_junit,
    format_diff,
    read_baseline,
    write_baseline,
)
from tubempc.regress.runner import RunJob, RunOutcome, closed_loop_metrics, falsify_metrics, run_case, run_cases
from tubempc.regress.suite import (
    FalsifyCase,
    FalsifySpec,
    LoadedSuite,
    RunCase,
    Suite,
    SuiteError,
    Tolerance,
    Tolerances,
    default_suite_path,
    expand_falsify,
    expand_suite,
    load_suite,
)

__all__ = [
    "BASELINE_FORMAT",
    "BaselineError",
    "Comparison",
    "DiffRow",
    "FalsifyCase",
    "FalsifySpec",
    "LoadedSuite",
    "RunCase",
    "RunJob",
    "RunOutcome",
    "Suite",
    "SuiteError",
    "Tolerance",
    "Tolerances",
    "closed_loop_metrics",
    "compare",
    "comparison_junit",
    "default_baseline_path",
    "default_suite_path",
    "expand_falsify",
    "expand_suite",
    "falsify_metrics",
    "format_diff",
    "load_suite",
    "read_baseline",
    "run_case",
    "run_cases",
    "write_baseline",
]


def default_baseline_path() -> str:
    """The baseline of the default suite shipped with the package."""
    from importlib import resources

    return str(resources.files("tubempc.regress").joinpath("default-baseline.json"))
