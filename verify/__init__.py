"""verify: certify robot logs (ROS1 .bag, ROS2 sqlite3/MCAP) against a scenario and an MITL formula.

It judges any log, whoever produced it; it shares only the MITL language and the scenario model with ``tubempc``.
The names below are imported on first use (PEP 562), so that importing one submodule (``verify.info``,
``verify.errors``) does not load the whole certifier.
"""

from __future__ import annotations

import importlib
from typing import TYPE_CHECKING, Any

if TYPE_CHECKING:
    from verify.certify import CertifyResult, certify_data, certify_log, write_certificate
    from verify.errors import (
        LogReadError,
        MissingTopicError,
        ScenarioInputError,
        SpecError,
        TruncatedLogError,
        UnusableInputError,
        VerifyError,
    )
    from verify.semantics.timed_run import TimedRunVerdict, check_timed_run

__all__ = [
    "CertifyResult",
    "LogReadError",
    "MissingTopicError",
    "ScenarioInputError",
    "SpecError",
    "TimedRunVerdict",
    "TruncatedLogError",
    "UnusableInputError",
    "VerifyError",
    "certify_data",
    "certify_log",
    "check_timed_run",
    "write_certificate",
]

_HOME = {
    "CertifyResult": "verify.certify", "certify_data": "verify.certify", "certify_log": "verify.certify",
    "write_certificate": "verify.certify", "TimedRunVerdict": "verify.semantics.timed_run",
    "check_timed_run": "verify.semantics.timed_run",
    **dict.fromkeys(("LogReadError", "MissingTopicError", "ScenarioInputError", "SpecError", "TruncatedLogError",
                     "UnusableInputError", "VerifyError"), "verify.errors"),
}


def __getattr__(name: str) -> Any:
    home = _HOME.get(name)
    if home is None:
        raise AttributeError(f"module 'verify' has no attribute {name!r}")
    value = getattr(importlib.import_module(home), name)
    globals()[name] = value
    return value
