"""Online certification: an incremental monitor fed sample by sample, and readers of logs that are still growing.

``OnlineMonitor`` judges pose / nominal / command samples and signal-atom messages as they arrive and reports each
check and each top-level obligation of the formula as soon as it is decided; ``close`` gives the verdicts
``certify_log`` gives offline.
"""

from verify.errors import MonitorClosedError
from verify.online.monitor import OnlineMonitor, feed_log_data
from verify.online.states import CheckState, Decision, MonitorState, OnlineResult

__all__ = [
    "CheckState",
    "Decision",
    "MonitorClosedError",
    "MonitorState",
    "OnlineMonitor",
    "OnlineResult",
    "feed_log_data",
]
