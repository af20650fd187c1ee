"""Writing ROS1 / ROS2 logs of closed-loop runs (the log contract shared with ``verify``)."""

from tubempc.rosio.writer import POSE_FRAME, TIME0_NS, metadata_document, write_log

__all__ = ["POSE_FRAME", "TIME0_NS", "metadata_document", "write_log"]
