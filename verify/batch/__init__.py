"""Many logs -> one certificate each, in parallel (processes or Dask), plus a summary table.

input: log paths and/or folders (scanned for ``.bag``, ``.mcap``, ``.db3`` files and ROS2 bag folders), a scenario
-> output: a ``BatchResult`` (one ``BatchItem`` per log, in input order) whose ``exit_code`` is the worst of all;
``write_batch`` writes one sub-folder per log (``certificate.json`` + reports) and ``summary.md`` /
``summary.csv`` / ``junit.xml`` at the top.

An unusable log (unreadable, truncated, missing topic) becomes a row with exit code 3; it never stops the batch.
"Worst" orders the codes by severity, not by value: 0 pass < 2 inconclusive < 1 violation < 3 unusable < 70
internal error (an inconclusive log must not hide a violation in another one).

The logs run through ``runkit.executor.parallel_map``, the one executor of both packages (the abstraction,
batch certification, regress and the falsifier): inline for one job or ``workers=1``, a process pool by default, or Dask
distributed with ``dask="local"`` or ``dask="tcp://host:port"``.
"""

from runkit.executor import parallel_map  # re-exported: the batch's executor
from verify.batch.output import write_batch
from verify.batch.run import (
    EXIT_INTERNAL,
    EXIT_UNUSABLE,
    LOG_SUFFIXES,
    BatchItem,
    BatchResult,
    certify_many,
    discover_logs,
    summary_lines,
    worst_exit_code,
)

__all__ = [
    "EXIT_INTERNAL",
    "EXIT_UNUSABLE",
    "LOG_SUFFIXES",
    "BatchItem",
    "BatchResult",
    "certify_many",
    "discover_logs",
    "parallel_map",
    "summary_lines",
    "worst_exit_code",
    "write_batch",
]
