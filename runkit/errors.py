"""Exceptions of the run-time kit (``runkit``): one root, ``RunkitError``, and two leaves that also subclass the
natural builtin.

``OutputError``: an output path or a ``--dask`` address that cannot be used (exit 3; the message names it).
``MissingExtraError``: a feature needs an optional dependency that is not installed (exit 4; the message names the
extra that installs it, ``runkit.extras``).

``runkit`` sits below both packages, so its root is its own: ``tubempc.cli.exits`` counts a ``RunkitError`` among
the errors raised on purpose (its message is for the user), like ``tubempc``'s and ``verify``'s.
"""

from __future__ import annotations

__all__ = ["MissingExtraError", "OutputError", "RunkitError"]


class RunkitError(Exception):
    """Root of every error raised on purpose by ``runkit``."""


class OutputError(RunkitError, ValueError):
    """An output folder or file, or an executor address, that cannot be used: the message names it (exit 3)."""

    def __init__(self, message: str, *, path: str | None = None) -> None:
        self.path = path
        self.reason = message
        super().__init__(f"{path}: {message}" if path else message)


class MissingExtraError(RunkitError, ImportError):
    """A feature needs an optional dependency that is not installed (exit code 4: feature not available); the
    message names the extra that installs it (``runkit.extras``)."""
