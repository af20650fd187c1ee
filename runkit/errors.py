"""Exceptions of the run-time pieces (``tubempc.runtime``).

``OutputError``: an output path or a ``--dask`` address that cannot be used (exit 3; the message names it).
``MissingExtraError``: a feature needs an optional dependency that is not installed (exit 4; the message names the
extra that installs it, ``tubempc.runtime.extras``).
"""

from __future__ import annotations

from tubempc.errors import TubeMPCError

__all__ = ["MissingExtraError", "OutputError"]


class OutputError(TubeMPCError, ValueError):
    """An output folder or file, or an executor address, that cannot be used: the message names it (exit 3)."""

    def __init__(self, message: str, *, path: str | None = None) -> None:
        self.path = path
        self.reason = message
        super().__init__(f"{path}: {message}" if path else message)


class MissingExtraError(TubeMPCError, ImportError):
    """A feature needs an optional dependency that is not installed (exit code 4: feature not available); the
    message names the extra that installs it (``tubempc.runtime.extras``)."""
