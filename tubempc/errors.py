"""Exceptions of the tubempc package: one root, semantic leaves that also subclass the natural builtin.

Input problems (a malformed formula or scenario) are ``ValueError``s; a controller that cannot be designed for a
scenario is a ``DesignError``; a specification the planner proves unsatisfiable is ``NoAcceptingRunError``, one it
could not decide within its state limit ``SearchLimitError``.
Failed *checks* are never exceptions: they are values (see ``verify``).
"""

from __future__ import annotations

__all__ = [
    "AbstractionError",
    "BaselineError",
    "CompareInputError",
    "ControllerError",
    "DesignError",
    "FalsifyError",
    "InvalidArgumentError",
    "LogWriteError",
    "NoAcceptingRunError",
    "NoGuidePathError",
    "NotAvailableError",
    "OverrideError",
    "ScenarioError",
    "SearchLimitError",
    "SolverError",
    "SpecSyntaxError",
    "SuiteError",
    "TubeMPCError",
]


class TubeMPCError(Exception):
    """Root of every error raised on purpose by ``tubempc``."""


class SpecSyntaxError(TubeMPCError, ValueError):
    """Malformed MITL text. ``column`` is 1-based; ``text`` is the whole input."""

    def __init__(self, message: str, *, text: str, column: int) -> None:
        self.text = text
        self.column = column
        self.reason = message
        shown = repr(text) if len(text) <= 120 else f"{text[:80]!r}... ({len(text)} characters)"
        super().__init__(f"column {column}: {message} (in {shown})")


class ScenarioError(TubeMPCError, ValueError):
    """A scenario file or value is malformed; the message names the file and the field."""

    def __init__(self, message: str, *, source: str = "<scenario>", field: str | None = None) -> None:
        self.source = source
        self.field = field
        self.reason = message
        where = f"{source}: {field}" if field else source
        super().__init__(f"{where}: {message}")


class DesignError(TubeMPCError, ValueError):
    """The tube/MPC design is impossible for a scenario (empty tightened set, region too small, ...)."""


class SolverError(TubeMPCError, RuntimeError):
    """A numerical solver failed in a way that cannot be recovered by the documented backup."""


class NoAcceptingRunError(TubeMPCError, ValueError):
    """The planner proved that no timed run of the abstraction satisfies the formula.

    ``obligation`` names the sub-formula that cannot be met when the planner can tell.
    """

    def __init__(self, message: str, *, obligation: str | None = None) -> None:
        self.obligation = obligation
        super().__init__(message)


class SearchLimitError(TubeMPCError, RuntimeError):
    """The planner's search reached its state limit before it found a run or proved that none exists (undecided,
    exit 2). ``limit`` is the limit that was reached; the message says how to raise it."""

    def __init__(self, message: str, *, limit: int) -> None:
        self.limit = limit
        super().__init__(message)


class LogWriteError(TubeMPCError, OSError):
    """A ROS log could not be written."""


class NotAvailableError(TubeMPCError, NotImplementedError):
    """A subcommand whose feature has not landed yet (exit code 4)."""


class CompareInputError(TubeMPCError, ValueError):
    """``compare`` cannot use its input (no runs, an unusable log or certificate, bad tolerances); the message names
    the file or option (exit 3)."""


class ControllerError(TubeMPCError, ValueError):
    """A ``--controller`` that cannot be loaded or that breaks the controller protocol (exit 3, the message names
    it)."""


class InvalidArgumentError(TubeMPCError, ValueError):
    """An argument of a control function is out of its domain; the message names it and its value."""


class AbstractionError(TubeMPCError, RuntimeError):
    """The abstraction could not be built (an oracle crashed or returned a malformed result)."""


class FalsifyError(TubeMPCError, ValueError):
    """The falsification cannot start (the unperturbed run fails to simulate, an unknown check, ...)."""


class OverrideError(TubeMPCError, ValueError):
    """A ``--set`` override is malformed or names no scenario field; the message quotes it."""


class BaselineError(TubeMPCError, ValueError):
    """The baseline file is missing or malformed (the message names the file)."""


class SuiteError(TubeMPCError, ValueError):
    """A suite file is malformed; the message names the file and the field."""

    def __init__(self, message: str, *, source: str, field: str | None = None) -> None:
        self.source = source
        self.field = field
        super().__init__(f"{source}: {field}: {message}" if field else f"{source}: {message}")


class NoGuidePathError(DesignError):
    """No collision-free polyline connects the start to the goal."""
