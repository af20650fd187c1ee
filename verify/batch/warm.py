"""Imported once by the batch's process server (``forkserver`` preload) before any worker forks from it.

input: nothing -> output: the per-process caches every certification builds on its first call, built once here
and inherited by every worker: the MITL parser's tables (``tubempc.mitl.parse``) and the ROS1 and ROS2 type stores
of the readers (``verify.ingest.decode.typestore``, which imports rosbags' generated message modules). Without it
each worker's first log paid about 0.8 s of CPU for them.
"""

from tubempc.mitl import parse
from verify.ingest.decode import typestore

__all__: list[str] = []

parse("F[0,1] true")
typestore(True)
typestore(False)
