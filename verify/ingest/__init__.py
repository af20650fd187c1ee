"""Reading ROS logs (ROS1 .bag, ROS2 MCAP / sqlite3, bare files) with ``rosbags``; ``read_log`` is the entry point.

The data flow, one module a step:

- ``raw``: a path -> the raw payloads of the wanted topics (format detection by rosbags' dispatch); it uses our fast
  readers ``ros1``, ``mcap``, ``sqlite`` and ``records`` (message-level reads from the indexes) or plain rosbags
  (``TUBEMPC_FAST_INGEST=0``), and ``salvage`` for damaged files; ``readerrors`` turns library errors into words;
- ``decode`` (poses, twists, strings) and ``fields`` (signal atoms' message fields): payloads -> numpy columns;
- ``timebase`` (header or log time, duplicates, outlier stamps), ``clocks`` (offsets between topics), ``quality``
  (data-quality findings): columns -> the samples the certifier judges;
- ``log``: all of it -> ``LogData``, with ``digest`` hashing the file in a thread beside the reading.
"""

from verify.ingest.log import LogData, PoseStream, file_sha256, read_log
from verify.ingest.raw import RawLog, RawTopic, read_raw

__all__ = ["LogData", "PoseStream", "RawLog", "RawTopic", "file_sha256", "read_log", "read_raw"]
