"""The record layer's rules, the same for every reader of a log (certify's two read paths, ``--salvage`` and
``watch``): a ROS1 chunk's index data must list exactly its message records, so a bag whose index contradicts its
records is never "closed by its recorder" for one reader and damaged for another."""

from __future__ import annotations

import struct
from pathlib import Path

import pytest

from verify.ingest.ros1records import MAGIC, Op, Record, Ros1Stream, record_at
from verify.ingest.salvage import walk_ros1

from .support import FUZZ, one_line_error, run

SPEC = "G[0,inf) !(obs_1 | obs_2 | obs_3 | obs_4)"


def _records(data: bytes) -> list[tuple[int, Record]]:
    out, pos = [], len(MAGIC)
    while pos < len(data):
        rec = record_at(data, pos, len(data))
        out.append((pos, rec))
        pos = rec.end
    return out


def _index_entry_flipped(path: Path) -> int:
    """Flip a bit of the offset of the first entry of the first non-empty index data record (as the fault
    campaign's byte flip did: seed 61, case 1922) -> that record's position."""
    data = bytearray(path.read_bytes())
    for pos, rec in _records(bytes(data)):
        if rec.op == Op.INDEX_DATA and rec.data_len:
            data[rec.data_start + 8] ^= 0x04
            path.write_bytes(bytes(data))
            return pos
    raise AssertionError("no index data record")


@pytest.fixture(params=["bag", "bag-lz4"])
def damaged_index(request: pytest.FixtureRequest, tmp_path: Path) -> tuple[Path, int]:
    path = FUZZ.write_run(FUZZ.base_run(violating=False), tmp_path / "run.bag", request.param)
    return path, _index_entry_flipped(path)


def test_the_stream_refuses_an_index_that_disagrees_with_its_records(damaged_index: tuple[Path, int]) -> None:
    path, at = damaged_index
    stream = Ros1Stream()
    with pytest.raises(Exception, match="disagrees with its message records"):
        stream.feed(path.read_bytes(), 0, [])
    assert not stream.closed
    assert stream.pos == at
    walk = walk_ros1(path)
    assert list(walk.messages)
    assert walk.stopped_at == at
    assert "damaged record" in walk.reason


@pytest.mark.usefixtures("ingest_path")
def test_certify_salvage_and_watch_agree_the_bag_is_damaged(damaged_index: tuple[Path, int],
                                                            capsys: pytest.CaptureFixture[str]) -> None:
    """One rule (the record layer's): ``certify``, ``certify --salvage`` and ``watch`` all refuse the bag as
    damaged, naming the index record (before, ``--salvage`` read it as partial, exit 2, or refused it, as rosbags'
    error happened to read, and ``watch`` found it closed by its recorder and passed it, exit 0)."""
    path, at = damaged_index
    base = [str(path), "--scenario", "nexus-sml", "--spec", SPEC]
    for argv in (["certify", *base], ["certify", *base, "--salvage"]):
        code, _, err = run(argv, capsys)
        assert code == 3, err
        one_line_error(err, "damaged ros1 log", "disagrees with its message records", f"byte {at}")
    code, _, err = run(["watch", *base, "--time-base", "auto"], capsys)
    assert code == 3
    one_line_error(err, f"malformed ROS1 record at byte {at}", "disagrees with its message records")


def test_a_missing_index_data_record_is_damage(tmp_path: Path) -> None:
    """A chunk followed by index data for some of its connections only: the stream stops at the next chunk."""
    path = FUZZ.write_run(FUZZ.base_run(violating=False), tmp_path / "run.bag", "bag-lz4")
    data = path.read_bytes()
    records = _records(data)
    first = next(k for k, (_pos, rec) in enumerate(records) if rec.op == Op.INDEX_DATA)
    pos, rec = records[first]
    header = bytearray(data[pos : rec.data_start])
    at = header.find(b"op=") + 3
    header[at] = Op.CONNECTION  # no longer an index record: its connection's messages are not indexed
    with pytest.raises(Exception, match="connection record|no index data record"):
        Ros1Stream().feed(data[:pos] + bytes(header) + data[rec.data_start :], 0, [])


def test_a_whole_bag_is_closed_with_every_index_checked(tmp_path: Path) -> None:
    for fmt in ("bag", "bag-lz4", "bag-cam"):
        path = FUZZ.write_run(FUZZ.base_run(violating=False), tmp_path / f"{fmt}.bag", fmt)
        stream, got = Ros1Stream(), []
        stream.feed(path.read_bytes(), 0, got)
        assert stream.closed
        n_index = sum(1 for _pos, rec in _records(path.read_bytes()) if rec.op == Op.INDEX_DATA)
        assert n_index > 0
        assert len(got) == sum(struct.unpack("<I", rec.header["count"])[0]
                               for _pos, rec in _records(path.read_bytes()) if rec.op == Op.INDEX_DATA)
