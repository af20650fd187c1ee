"""Exceptions of the certifier, one root (``VerifyError``): raised when a log cannot be judged at all, or its reports
cannot be written (exit code 3). (A feature whose optional dependency is not installed raises
``runkit.errors.MissingExtraError``, exit code 4.) Two more are internal and never reach the user: a fast reader
declines a record (``FastPathError``), the regular-grid monitor declines a formula (``UnsupportedFormulaError``).
The readers' record-level signals stay private to ``verify.ingest``.

A failed *check* is never an exception; it is a verdict value with its witness.
"""

from __future__ import annotations

__all__ = [
    "FastPathError",
    "LogReadError",
    "MissingTopicError",
    "MonitorClosedError",
    "ReportWriteError",
    "ScenarioInputError",
    "SpecError",
    "TruncatedLogError",
    "UnsupportedFormulaError",
    "UnusableInputError",
    "VerifyError",
]


class VerifyError(Exception):
    """Root of every error raised on purpose by ``verify``."""


class UnusableInputError(VerifyError, ValueError):
    """The input cannot be judged: the message names the file and the problem."""

    def __init__(self, message: str, *, path: str | None = None) -> None:
        self.path = path
        self.reason = message
        super().__init__(f"{path}: {message}" if path else message)


class LogReadError(UnusableInputError):
    """The log file is unreadable (not a bag, corrupt, unsupported format)."""


class TruncatedLogError(LogReadError):
    """The log ends mid-record or lacks its index; ``--salvage`` may read the complete part."""


class MissingTopicError(UnusableInputError):
    """A topic the scenario names is absent from the log."""


class SpecError(UnusableInputError):
    """The MITL formula given to the certifier is malformed or names unknown propositions."""


class ScenarioInputError(UnusableInputError):
    """The scenario given to the certifier cannot be loaded."""


class MonitorClosedError(VerifyError, RuntimeError):
    """A sample was pushed to ``verify.online.OnlineMonitor`` after its ``close`` (a programming error of the
    caller, not bad input)."""


class ReportWriteError(VerifyError, OSError):
    """The report files could not be written (the message names the folder)."""


class FastPathError(Exception):
    """Internal to the readers: a fast reader (``verify.ingest.ros1``, ``verify.ingest.mcap``) met a record it does not
    reproduce exactly; the caller falls back to rosbags. Never reaches the user."""


class UnsupportedFormulaError(Exception):
    """Internal to the monitors: the regular-grid evaluator (``verify.monitor.grid``) met an operator it does not
    handle (``Until``); the caller uses the general engine. Never reaches the user."""
