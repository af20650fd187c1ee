"""The exit codes of every ``tubempc`` command, and the one mapping from an error to its code.

0 success / all checks pass; 1 a violation was found (certify, watch, regress, compare, falsify) or no accepting run
exists (plan, proved); 2 inconclusive (certify, watch, compare) or undecided (plan: the search reached its state
limit, ``--max-states``); 3 unusable input (unreadable or truncated log, missing topic, malformed formula or
scenario, impossible controller design, an abstraction without any usable transition); 4 feature not available
(among others: an optional dependency is not installed; the line names the extra, ``runkit.extras``);
70 internal error; 130 interrupted.
"""

from __future__ import annotations

import sys
from typing import Any, NoReturn

from runkit.errors import MissingExtraError, RunkitError
from tubempc.errors import NoAcceptingRunError, NotAvailableError, SearchLimitError, TubeMPCError

__all__ = ["EXIT_FAIL", "EXIT_INCONCLUSIVE", "EXIT_INTERNAL", "EXIT_INTERRUPTED", "EXIT_NOT_AVAILABLE", "EXIT_OK",
           "EXIT_UNUSABLE", "exit_code", "is_ours", "leave"]

EXIT_OK = 0
EXIT_FAIL = 1
EXIT_INCONCLUSIVE = 2
EXIT_UNUSABLE = 3
EXIT_NOT_AVAILABLE = 4
EXIT_INTERNAL = 70
EXIT_INTERRUPTED = 130


def _verify_error() -> type[BaseException] | None:
    """``VerifyError`` when the certifier was imported (else no error can be one)."""
    mod: Any = sys.modules.get("verify.errors")
    return None if mod is None else mod.VerifyError


def is_ours(err: BaseException) -> bool:
    """An error raised on purpose by ``tubempc``, ``verify`` or ``runkit`` (its message is for the user)."""
    ve = _verify_error()
    return isinstance(err, TubeMPCError | RunkitError) or (ve is not None and isinstance(err, ve))


def exit_code(err: BaseException) -> int:
    """The exit code of an error that ends a command."""
    if isinstance(err, NotAvailableError | MissingExtraError):
        return EXIT_NOT_AVAILABLE
    if isinstance(err, NoAcceptingRunError):
        return EXIT_FAIL
    if isinstance(err, SearchLimitError):
        return EXIT_INCONCLUSIVE
    if is_ours(err):
        return EXIT_UNUSABLE
    return EXIT_INTERNAL


def leave(code: int) -> NoReturn:
    """End a command with ``code`` (stdout flushed first): the one way a command states its exit code.

    ``SystemExit``, not click's ``Exit``: under ``standalone_mode=False`` click returns an ``Exit``'s code instead of
    exiting, and a command called from ``cli.main`` directly must still end with its code."""
    sys.stdout.flush()
    sys.exit(code)
