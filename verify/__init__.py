"""verify: certify robot logs (ROS1 .bag, ROS2 sqlite3/MCAP) against a scenario and an MITL formula.

It judges any log, whoever produced it; it shares only the MITL language and the scenario model with ``tubempc``.
"""

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
