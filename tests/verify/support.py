"""Helpers shared by the tests of damaged and adversarial input (``test_no_false_pass.py``,
``test_damaged_input.py``, the reading rules): the fault campaign's log kit (``benchmarks/fuzz_certify.py``, imported
as a module of the repository) and the CLI run in this process."""

from __future__ import annotations

from pathlib import Path

import pytest

from benchmarks import fuzz_certify as FUZZ  # noqa: N812  (the fault campaign: seed logs, runs, writers)
from tubempc.cli import main

__all__ = ["FUZZ", "one_line_error", "run", "tied_publishers_bag"]


def run(argv: list[str], capsys: pytest.CaptureFixture[str]) -> tuple[int, str, str]:
    """``tubempc`` with ``argv`` in this process: (exit code, stdout, stderr)."""
    with pytest.raises(SystemExit) as exc:
        main(argv)
    out, err = capsys.readouterr()
    code = exc.value.code
    return (code if isinstance(code, int) else 0), out, err


def one_line_error(err: str, *needles: str) -> None:
    """stderr is one ``tubempc: error:`` line holding every needle."""
    lines = [ln for ln in err.splitlines() if ln.strip()]
    assert len(lines) == 1, err
    assert lines[0].startswith("tubempc: error: "), err
    for needle in needles:
        assert needle in lines[0], (needle, err)


def tied_publishers_bag(path: Path, compression: str | None) -> Path:
    """A ROS1 bag (``compression`` None or "lz4", chunks of ~2 KB) of 900 PoseStamped on ``/pose`` from two
    connections (caller ids ``/b`` then ``/a``, written alternately), 60 messages per log time (a simulation's clock):
    message k is at x = k / 1000 m."""
    from rosbags.rosbag1 import Writer
    from rosbags.typesys import Stores, get_typestore

    store = get_typestore(Stores.ROS1_NOETIC)
    ty = store.types
    pose = "geometry_msgs/msg/PoseStamped"
    writer = Writer(path)
    if compression == "lz4":
        writer.set_compression(Writer.CompressionFormat.LZ4)
    writer.chunk_threshold = 2048
    with writer as w:
        conns = [w.add_connection("/pose", pose, callerid=c, typestore=store) for c in ("/b", "/a")]
        for k in range(900):
            t = FUZZ.TIME0_NS + (k // 60) * 10_000_000
            stamp = ty["builtin_interfaces/msg/Time"](sec=t // 10**9, nanosec=t % 10**9)
            msg = ty[pose](header=ty["std_msgs/msg/Header"](seq=k, stamp=stamp, frame_id="world"),
                           pose=ty["geometry_msgs/msg/Pose"](
                               position=ty["geometry_msgs/msg/Point"](x=k / 1000, y=0.0, z=0.0),
                               orientation=ty["geometry_msgs/msg/Quaternion"](x=0.0, y=0.0, z=0.0, w=1.0)))
            w.write(conns[k % 2], t, bytes(store.serialize_ros1(msg, pose)))
    return path
