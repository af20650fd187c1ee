"""verify: certify robot logs (ROS1 .bag, ROS2 sqlite3/MCAP) against a scenario and an MITL formula.

It judges any log, whoever produced it; it shares only the MITL language and the scenario model with ``tubempc``.
"""

from verify.errors import LogReadError, MissingTopicError, TruncatedLogError, UnusableInputError, VerifyError

__all__ = ["LogReadError", "MissingTopicError", "TruncatedLogError", "UnusableInputError", "VerifyError"]
