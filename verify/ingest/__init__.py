"""Reading ROS logs (ROS1 .bag, ROS2 MCAP / sqlite3, bare files) with ``rosbags``: raw access, bulk decoding,
data quality, salvage of damaged files. ``read_log`` is the entry point."""

from verify.ingest.log import LogData, PoseStream, file_sha256, read_log
from verify.ingest.raw import RawLog, RawTopic, read_raw

__all__ = ["LogData", "PoseStream", "RawLog", "RawTopic", "file_sha256", "read_log", "read_raw"]
