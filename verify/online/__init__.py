"""Online certification: an incremental monitor fed sample by sample, and readers of logs that are still growing.

``OnlineMonitor`` judges pose / nominal / command samples and signal-atom messages as they arrive and reports each
check and each top-level obligation of the formula as soon as it is decided; ``close`` gives the verdicts
``certify_log`` gives offline.
"""

from verify.online.monitor import (
    CheckState,
    Decision,
    MonitorClosedError,
    MonitorState,
    OnlineMonitor,
    OnlineResult,
    feed_log_data,
)

__all__ = [
    "CheckState",
    "Decision",
    "MonitorClosedError",
    "MonitorState",
    "OnlineMonitor",
    "OnlineResult",
    "feed_log_data",
]
