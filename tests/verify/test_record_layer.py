"""The record layer's rules, the same for every reader of a log (certify's two read paths, ``--salvage`` and
``watch``): a ROS1 chunk's index data must list exactly its message records, so a bag whose index contradicts its
records is never "closed by its recorder" for one reader and damaged for another; a chunk that holds no wanted
topic is checked structurally but not decompressed, by both read paths."""

from __future__ import annotations

import os
import random
import string
import struct
from pathlib import Path

import pytest
from rosbags.typesys import Stores, get_typestore

from verify.errors import LogReadError
from verify.ingest.mcaprecords import MAGIC as MCAP_MAGIC
from verify.ingest.mcaprecords import Op as McapOp
from verify.ingest.raw import FAST_INGEST_ENV, read_raw
from verify.ingest.ros1records import MAGIC, MalformedError, Op, Record, Ros1Stream, record_at
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
    with pytest.raises(MalformedError, match="disagrees with its message records"):
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
    with pytest.raises(MalformedError, match="has no index data record for connection"):
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


# ---- a damaged chunk that holds no wanted topic --------------------------------------------------------------------
# The rule, for both read paths (``TUBEMPC_FAST_INGEST=1`` and ``=0``): a chunk that holds no wanted topic (by the
# log's index) is checked structurally -- its record and fields within their lengths, a compression the format
# defines, its index records -- but it is not decompressed. So damage inside it is not seen, damage to its
# structure is refused, the same way on both paths.
CDR_TWIST = "geometry_msgs/msg/Twist"
CDR_STRING = "std_msgs/msg/String"
WANTED = {"/cmd"}


def _noise() -> str:
    """8000 letters that do not compress much (a camera frame's stand-in)."""
    return "".join(random.Random(7).choices(string.ascii_letters, k=8000))


def _payloads(*, ros1: bool) -> tuple[bytes, bytes]:
    """A Twist command and a camera frame's stand-in (a String of 8000 letters), serialized for the format."""
    store = get_typestore(Stores.ROS1_NOETIC if ros1 else Stores.ROS2_HUMBLE)
    ser = store.serialize_ros1 if ros1 else store.serialize_cdr
    lin = store.types["geometry_msgs/msg/Vector3"](x=1.0, y=0.0, z=0.0)
    return (bytes(ser(store.types[CDR_TWIST](linear=lin, angular=lin), CDR_TWIST)),
            bytes(ser(store.types[CDR_STRING](data=_noise()), CDR_STRING)))


def _mcap_with_camera_chunks(path: Path) -> tuple[Path, list[tuple[int, int]]]:
    """An MCAP file (zstd chunks, statistics, the writer's indexes): 40 /cmd messages in the first chunks, then 4
    "camera" frames of 8 KB, each alone in its chunk -> the file and each camera chunk's (record position, length)."""
    import mcap.writer as mcap_writer

    twist, frame = _payloads(ros1=False)
    t0 = 1_700_000_000 * 10**9
    with path.open("wb") as fh:
        w = mcap_writer.Writer(fh, chunk_size=2048, compression=mcap_writer.CompressionType.ZSTD)
        w.start(profile="ros2", library="test")
        s_twist = w.register_schema(name=CDR_TWIST, encoding="ros2msg",
                                    data=b"geometry_msgs/Vector3 linear\ngeometry_msgs/Vector3 angular\n")
        s_string = w.register_schema(name=CDR_STRING, encoding="ros2msg", data=b"string data\n")
        cmd = w.register_channel("/cmd", "cdr", s_twist)
        cam = w.register_channel("/camera", "cdr", s_string)
        for i in range(40):
            w.add_message(cmd, log_time=t0 + i * 10**7, data=twist, publish_time=t0 + i * 10**7)
        for i in range(4):
            w.add_message(cam, log_time=t0 + i * 10**8, data=frame, publish_time=t0 + i * 10**8)
        w.finish()
    data = path.read_bytes()
    chunks, pos = [], len(MCAP_MAGIC)
    while data[pos] != McapOp.FOOTER:
        (length,) = struct.unpack_from("<Q", data, pos + 1)
        if data[pos] == McapOp.CHUNK and length > 4000:
            chunks.append((pos, length))
        pos += 9 + length
    assert len(chunks) == 4
    return path, chunks


def _read_cmd(path: Path, monkeypatch: pytest.MonkeyPatch, fast: bool) -> list[tuple[int, bytes]] | str:
    """The /cmd messages by one read path, or the error's words."""
    with monkeypatch.context() as m:
        m.setenv(FAST_INGEST_ENV, "1" if fast else "0")
        try:
            raw = read_raw(path, WANTED)
        except LogReadError as err:
            return err.reason
    t = raw.topics["/cmd"]
    return list(zip((int(x) for x in t.log_ns), list(t.payloads), strict=True))


def test_mcap_damage_inside_a_chunk_without_wanted_topics_is_not_read_on_either_path(
        tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    path, chunks = _mcap_with_camera_chunks(tmp_path / "cam.mcap")
    whole = _read_cmd(path, monkeypatch, True)
    assert isinstance(whole, list) and len(whole) == 40
    data = bytearray(path.read_bytes())
    pos, length = chunks[-1]
    for k in range(pos + length - 200, pos + length - 100):  # inside its compressed records
        data[k] ^= 0x5A
    path.write_bytes(bytes(data))
    assert _read_cmd(path, monkeypatch, True) == whole
    assert _read_cmd(path, monkeypatch, False) == whole  # before: the scan decompressed it and refused the file


@pytest.mark.parametrize("damage", ["compression", "stored size"])
def test_mcap_damage_to_the_structure_of_such_a_chunk_is_refused_on_both_paths(
        tmp_path: Path, monkeypatch: pytest.MonkeyPatch, damage: str) -> None:
    path, chunks = _mcap_with_camera_chunks(tmp_path / "cam.mcap")
    data = bytearray(path.read_bytes())
    pos, _length = chunks[-1]
    name_at = pos + 9 + 28 + 4
    assert data[name_at : name_at + 4] == b"zstd"
    if damage == "compression":
        data[name_at : name_at + 4] = b"zstx"  # no compression the format defines (the index still says zstd)
    else:
        data[name_at + 4 : name_at + 12] = struct.pack("<Q", 1 << 40)  # stored records past the record's end
    path.write_bytes(bytes(data))
    fast, plain = _read_cmd(path, monkeypatch, True), _read_cmd(path, monkeypatch, False)
    assert isinstance(fast, str), fast
    assert fast == plain
    assert "malformed" in fast


def _bag_with_camera_chunks(path: Path, compression: str | None) -> tuple[Path, list[Record], list[int]]:
    """A ROS1 bag: /cmd in the first chunk, then camera frames each alone in a chunk -> the file, the camera
    chunks' records and their positions."""
    from rosbags.rosbag1 import Writer

    store = get_typestore(Stores.ROS1_NOETIC)
    twist, frame = _payloads(ros1=True)
    t0 = 1_700_000_000 * 10**9
    w = Writer(path)
    if compression is not None:
        w.set_compression(getattr(Writer.CompressionFormat, compression.upper()))
    w.chunk_threshold = 4096
    with w:
        cmd = w.add_connection("/cmd", CDR_TWIST, typestore=store)
        cam = w.add_connection("/camera", CDR_STRING, typestore=store)
        for i in range(40):
            w.write(cmd, t0 + i * 10**7, twist)
        for i in range(4):
            w.write(cam, t0 + i * 10**8, frame)
    data = path.read_bytes()
    found = [(pos, rec) for pos, rec in _records(data) if rec.op == Op.CHUNK and rec.data_len > 4000]
    assert len(found) >= 3
    return path, [rec for _pos, rec in found], [pos for pos, _rec in found]


@pytest.mark.parametrize("compression", [None, "lz4"])
def test_ros1_damage_inside_a_chunk_without_wanted_topics_is_not_read_on_either_path(
        tmp_path: Path, monkeypatch: pytest.MonkeyPatch, compression: str | None) -> None:
    path, recs, _positions = _bag_with_camera_chunks(tmp_path / "cam.bag", compression)
    whole = _read_cmd(path, monkeypatch, True)
    assert isinstance(whole, list) and len(whole) == 40
    data = bytearray(path.read_bytes())
    rec = recs[-1]
    for k in range(rec.data_start + 50, rec.data_start + 150):  # the frame's record header and bytes / lz4 stream
        data[k] ^= 0x5A
    path.write_bytes(bytes(data))
    assert _read_cmd(path, monkeypatch, True) == whole
    assert _read_cmd(path, monkeypatch, False) == whole


def test_ros1_damage_to_the_structure_of_such_a_chunk_is_refused_on_both_paths(
        tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    path, _recs, positions = _bag_with_camera_chunks(tmp_path / "cam.bag", "lz4")
    data = bytearray(path.read_bytes())
    at = data.index(b"compression=lz4", positions[-1])
    data[at + len(b"compression=") : at + len(b"compression=lz4")] = b"lz5"
    path.write_bytes(bytes(data))
    fast, plain = _read_cmd(path, monkeypatch, True), _read_cmd(path, monkeypatch, False)
    assert isinstance(fast, str), fast
    assert fast == plain


# ---- the one walk over a chunk's records ---------------------------------------------------------------------------
def test_the_chunk_walk_takes_nothing_from_its_hints_that_the_walk_does_not_confirm() -> None:
    """``walk_chain`` with any hints (true record starts, positions inside records, past the end) gives the records
    of the plain sequential walk; a record that runs past the chunk's end is damage, whatever the hints."""
    import numpy as np

    from verify.ingest.records import MCAP, ROS1, walk_chain
    from verify.ingest.records import MalformedError as WalkError

    def ros1_record(n: int) -> bytes:
        header = struct.pack("<I", 4) + b"op=\x02"
        return struct.pack("<I", len(header)) + header + struct.pack("<I", n) + bytes(n)

    def mcap_record(n: int) -> bytes:
        return bytes([McapOp.MESSAGE]) + struct.pack("<Q", n) + bytes(n)

    rng = random.Random(3)
    for kind, make in ((ROS1, ros1_record), (MCAP, mcap_record)):
        sizes = [rng.choice([0, 1, 5, 30, 30, 30]) for _ in range(200)]
        buf = b"".join(make(n) for n in sizes)
        plain = walk_chain(buf, kind)
        starts = plain[0].tolist()
        assert len(starts) == 200 and plain[1][-1] == len(buf)
        for _ in range(20):
            hints = sorted(set(rng.sample(starts, rng.randrange(len(starts)))
                               + [rng.randrange(len(buf) + 50) for _ in range(rng.randrange(30))]))
            got = walk_chain(buf, kind, np.array(hints, dtype=np.int64))
            assert np.array_equal(got[0], plain[0]) and np.array_equal(got[1], plain[1])
        with pytest.raises(WalkError):
            walk_chain(buf[:-1], kind, plain[0])


@pytest.mark.parametrize("written", ["//battery//level/", "/battery/level", "battery/level"])
def test_every_ros1_reader_names_a_topic_as_rosbags_does(tmp_path: Path, monkeypatch: pytest.MonkeyPatch,
                                                         written: str) -> None:
    """A connection's topic with repeated or trailing slashes is one topic name for the fast indexed reader, the
    plain path (rosbags) and the record layer's walk (salvage and ``watch``): ``ros1records.topic_name``."""
    from rosbags.rosbag1 import Writer

    ts = get_typestore(Stores.ROS1_NOETIC)
    msg = ts.types["std_msgs/msg/Float64"]
    path = tmp_path / "odd.bag"
    with Writer(path) as w:
        conn = w.add_connection(written, msg.__msgtype__, typestore=ts)
        for i in range(5):
            w.write(conn, (i + 1) * 10**9, ts.serialize_ros1(msg(data=float(i)), msg.__msgtype__))
    want = "/battery/level" if written.startswith("/") else "battery/level"
    walked = walk_ros1(path)
    assert {m.topic for m in walked.messages} == {want}
    for fast in ("1", "0"):
        monkeypatch.setenv(FAST_INGEST_ENV, fast)
        raw = read_raw(path, [want])
        assert list(raw.topics) == [want], fast
        assert len(raw.topics[want].payloads) == 5, fast


def test_the_mcap_record_walk_reads_each_chunks_neighbourhood_once(tmp_path: Path, monkeypatch: pytest.MonkeyPatch
                                                                   ) -> None:
    """The indexed MCAP reader's check that the top-level records chain (``mcapfile._records_chain``) reads a
    chunk's head, its fixed fields and the message index records after it in one read, not one read each; and
    still accepts the file."""
    from rosbags.rosbag2.storage_mcap import McapReader

    from verify.ingest import mcapfile

    path, _camera = _mcap_with_camera_chunks(tmp_path / "run.mcap")
    storage = McapReader(path)
    storage.open()
    try:
        n_chunks = len(storage.chunks)
        real = os.pread
        reads = [0]

        def counting(fd: int, n: int, pos: int) -> bytes:
            reads[0] += 1
            return real(fd, n, pos)

        monkeypatch.setattr(os, "pread", counting)
        assert mcapfile._records_chain(path, storage)
    finally:
        storage.close()
    assert n_chunks >= 5
    assert reads[0] <= n_chunks + 2, f"{reads[0]} reads for {n_chunks} chunks"


@pytest.mark.usefixtures("ingest_path")
@pytest.mark.parametrize("fmt", ["bag", "bag-lz4"])
@pytest.mark.parametrize(("shift", "byte"), [(len(b"message_definition="), 0xFF), (6, 0x04)])
def test_a_connection_record_that_is_not_utf8_is_damage_for_every_reader(fmt: str, shift: int, byte: int,
                                                                          tmp_path: Path,
                                                                          capsys: pytest.CaptureFixture[str]) -> None:
    """In the bag index's last connection record, a byte of the message definition flipped to 0xff (fault campaign
    seed 68 case 183), or one of its field name (``messag\\x04_definition``: seed 70 case 1390): rosbags cannot read
    the field as text, or finds none, and refuses the bag; the fast reader accepted the first (exit 0), ``watch``
    passed both and ``--salvage`` judged the second (exit 2). Now every path refuses them, exit 3."""
    path = FUZZ.write_run(FUZZ.base_run(violating=False), tmp_path / "run.bag", fmt)
    data = bytearray(path.read_bytes())
    at = data.rindex(b"message_definition=") + shift
    data[at] = byte
    path.write_bytes(bytes(data))
    base = [str(path), "--scenario", "nexus-sml", "--spec", SPEC]
    for argv in (["certify", *base], ["certify", *base, "--salvage"], ["watch", *base, "--time-base", "auto"]):
        code, _, err = run(argv, capsys)
        assert code == 3, (argv, err)
        assert "message_definition" in err, err


def test_rows_of_a_topic_not_asked_for_are_damage(tmp_path: Path) -> None:
    """rosbags can yield a message of another connection from a damaged bag (fault campaign seed 68 case 68: exit 70
    with a KeyError in --salvage): the rows are checked against the topics asked for."""
    from rosbags.interfaces import Connection

    from verify.errors import LogReadError
    from verify.ingest.raw import _check_rows

    def conn(topic: str) -> Connection:
        return Connection(1, topic, "std_msgs/msg/Empty", "", "", 0, None, None)  # type: ignore[arg-type]

    _check_rows(tmp_path, "ros1", [(conn("/a"), 1, b""), (conn("/b"), 2, b"")], ["/a", "/b"])
    with pytest.raises(LogReadError, match="yields messages of /camera, which was not asked for"):
        _check_rows(tmp_path, "ros1", [(conn("/a"), 1, b""), (conn("/camera"), 2, b"")], ["/a", "/b"])


@pytest.mark.usefixtures("ingest_path")
@pytest.mark.parametrize("fmt", ["bag", "bag-lz4"])
def test_a_chunk_info_naming_no_chunk_is_damage_for_every_reader(fmt: str, tmp_path: Path,
                                                                 capsys: pytest.CaptureFixture[str]) -> None:
    """A bit of the last chunk info record's chunk position flipped (fault campaign seed 68 case 575): rosbags reads
    a record header there and refuses the bag; ``watch`` found the bag closed by its recorder and passed it (exit 0)
    and ``--salvage`` judged it (exit 2). Now every path refuses it, exit 3."""
    path = FUZZ.write_run(FUZZ.base_run(violating=False), tmp_path / "run.bag", fmt)
    data = bytearray(path.read_bytes())
    last = max(pos for pos, rec in _records(bytes(data)) if rec.op == Op.CHUNK_INFO)
    at = data.index(b"chunk_pos=", last) + len(b"chunk_pos=") + 2
    data[at] ^= 0x87
    path.write_bytes(bytes(data))
    base = [str(path), "--scenario", "nexus-sml", "--spec", SPEC]
    for argv in (["certify", *base], ["certify", *base, "--salvage"], ["watch", *base, "--time-base", "auto"]):
        code, _, err = run(argv, capsys)
        assert code == 3, (argv, err)
