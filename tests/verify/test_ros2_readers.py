"""Our fast MCAP and sqlite3 message readers return exactly what the plain path returns (MCAP: the record scan,
``verify.ingest.mcapfile``; sqlite3: rosbags' reader) -- order, log times, payloads -- on bag directories and bare
files, uncompressed / zstd / lz4 MCAP chunks, out-of-order log times with ties, frame ids of different lengths,
several topics; and they decline (the plain path reads the file and reports the damage) on damaged files."""

from __future__ import annotations

import os
import shutil
import sqlite3
from pathlib import Path

import numpy as np
import pytest
from lz4.frame import compress as lz4_compress  # type: ignore[import-untyped]  # a rosbags dependency
from rosbags.rosbag2 import CompressionFormat, CompressionMode, Reader, StoragePlugin, Writer
from rosbags.typesys import Stores, get_typestore

from verify.errors import LogReadError, TruncatedLogError, UnusableInputError
from verify.ingest import raw as raw_mod
from verify.ingest.decode import decode_pose
from verify.ingest.mcap import read_mcap_storage
from verify.ingest.raw import read_raw
from verify.ingest.ros1 import PayloadBuffer

STORE = get_typestore(Stores.ROS2_HUMBLE)
T = STORE.types
POSE = "geometry_msgs/msg/PoseStamped"
STRING = "std_msgs/msg/String"
TWIST = "geometry_msgs/msg/Twist"
TOPICS = ("/pose", "/status", "/cmd")


def _pose(t_ns: int, x: float, frame: str) -> bytes:
    hdr = T["std_msgs/msg/Header"](stamp=T["builtin_interfaces/msg/Time"](sec=t_ns // 10**9, nanosec=t_ns % 10**9),
                                   frame_id=frame)
    msg = T[POSE](header=hdr, pose=T["geometry_msgs/msg/Pose"](
        position=T["geometry_msgs/msg/Point"](x=x, y=-x, z=0.0),
        orientation=T["geometry_msgs/msg/Quaternion"](x=0.0, y=0.0, z=0.0, w=1.0)))
    return bytes(STORE.serialize_cdr(msg, POSE))


def _write(path: Path, plugin: StoragePlugin, compression: str = "", *, chunk_every: int = 97,
           frames: tuple[str, ...] = ("world",)) -> Path:
    """Three topics; log times shuffled with many ties; MCAP chunks closed every ``chunk_every`` messages."""
    rng = np.random.default_rng(11)
    n = 700
    times = 1_700_000_000 * 10**9 + rng.integers(0, 150, n) * 10_000_000  # ~5 messages per distinct time
    topics = rng.integers(0, 3, n)
    w = Writer(path, version=9, storage_plugin=plugin)
    if compression == "zstd":
        w.set_compression(CompressionMode.STORAGE, CompressionFormat.ZSTD)
    with w:
        if compression == "lz4":
            storage = w.storage
            storage.compression, storage.compressor = "lz4", lz4_compress  # type: ignore[union-attr]
        conns = [w.add_connection("/pose", POSE, typestore=STORE), w.add_connection("/status", STRING, typestore=STORE),
                 w.add_connection("/cmd", TWIST, typestore=STORE)]
        for i, (t, k) in enumerate(zip(times.tolist(), topics.tolist(), strict=True)):
            if k == 0:
                data = _pose(t, float(i), frames[i % len(frames)])
            elif k == 1:
                data = bytes(STORE.serialize_cdr(T[STRING](data="x" * (i % 7)), STRING))
            else:
                lin = T["geometry_msgs/msg/Vector3"](x=float(i), y=0.0, z=0.0)
                data = bytes(STORE.serialize_cdr(T[TWIST](linear=lin, angular=lin), TWIST))
            w.write(conns[k], t, data)
            if plugin == StoragePlugin.MCAP and (i + 1) % chunk_every == 0:
                w.storage.close_chunk()  # type: ignore[union-attr]
    return path


def _reference(path: Path, topics: tuple[str, ...], monkeypatch: pytest.MonkeyPatch) -> raw_mod.RawLog:
    with monkeypatch.context() as m:
        m.setenv(raw_mod.FAST_INGEST_ENV, "0")  # MCAP: the record scan; sqlite3: rosbags' reader
        return read_raw(path, topics)


def _assert_same(path: Path, topics: tuple[str, ...], monkeypatch: pytest.MonkeyPatch) -> None:
    fast = read_raw(path, topics)
    ref = _reference(path, topics, monkeypatch)
    assert fast.available == ref.available
    assert set(fast.topics) == set(ref.topics) == set(topics)
    for topic in topics:
        a, b = fast.topics[topic], ref.topics[topic]
        assert isinstance(a.payloads, PayloadBuffer), "the fast reader must have read this log"
        assert (a.msgtype, a.has_definition) == (b.msgtype, b.has_definition)
        assert np.array_equal(np.asarray(a.log_ns, dtype=np.int64), np.asarray(b.log_ns, dtype=np.int64))
        assert list(a.payloads) == list(b.payloads)
    if "/pose" in topics:
        pa, pb = decode_pose(fast.topics["/pose"], False), decode_pose(ref.topics["/pose"], False)
        assert np.array_equal(pa.stamp_ns, pb.stamp_ns) and np.array_equal(pa.x_m, pb.x_m)


@pytest.mark.parametrize("compression", ["", "zstd", "lz4"])
@pytest.mark.parametrize("bare", [False, True])
def test_mcap_reader_matches_rosbags(tmp_path: Path, monkeypatch: pytest.MonkeyPatch, compression: str,
                                     bare: bool) -> None:
    bag = _write(tmp_path / "bag", StoragePlugin.MCAP, compression, frames=("world", "map", "mocap_frame_long"))
    path = next(bag.glob("*.mcap")) if bare else bag
    for topics in (("/pose",), ("/pose", "/status"), TOPICS):
        _assert_same(path, topics, monkeypatch)


def test_mcap_reader_one_chunk_and_many_small_chunks(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    for every in (10_000, 3):
        bag = _write(tmp_path / f"bag{every}", StoragePlugin.MCAP, chunk_every=every)
        _assert_same(bag, TOPICS, monkeypatch)


@pytest.mark.parametrize("bare", [False, True])
def test_sqlite_reader_matches_rosbags(tmp_path: Path, monkeypatch: pytest.MonkeyPatch, bare: bool) -> None:
    bag = _write(tmp_path / "bag", StoragePlugin.SQLITE3, frames=("w", "world_frame"))
    path = next(bag.glob("*.db3")) if bare else bag
    for topics in (("/pose",), ("/status", "/pose"), TOPICS):
        assert raw_mod._read_sqlite_quick(path, set(topics), []) is not None, "our open must have read this log"
        _assert_same(path, topics, monkeypatch)


@pytest.mark.parametrize("bare", [False, True])
def test_sqlite_quick_open_without_message_definitions(tmp_path: Path, monkeypatch: pytest.MonkeyPatch,
                                                      bare: bool) -> None:
    """A schema-2 database (no ``schema`` / ``message_definitions`` tables, as older rosbag2 wrote them): our open
    finds the same topics, types and (absent) definitions as rosbags."""
    bag = _write(tmp_path / "bag", StoragePlugin.SQLITE3)
    db = next(bag.glob("*.db3"))
    with sqlite3.connect(db) as con:
        con.execute("DROP TABLE message_definitions")
        con.execute("DROP TABLE schema")
    con.close()
    path = db if bare else bag
    quick = raw_mod._read_sqlite_quick(path, set(TOPICS), [])
    assert quick is not None
    assert not any(t.has_definition for t in quick.topics.values())
    _assert_same(path, TOPICS, monkeypatch)


def test_sqlite_quick_open_declines_on_damage(tmp_path: Path) -> None:
    """Our open declines (rosbags then opens the file) on a truncated file and on a file that grew past its header's
    page count; and when no wanted topic is present (rosbags' counting scans still vet the whole database)."""
    bag = _write(tmp_path / "bag", StoragePlugin.SQLITE3)
    db = next(bag.glob("*.db3"))
    assert raw_mod._read_sqlite_quick(db, {"/absent"}, []) is None
    grown = tmp_path / "grown.db3"
    grown.write_bytes(db.read_bytes() + bytes(4096))
    assert raw_mod._read_sqlite_quick(grown, {"/pose"}, []) is None
    cut = tmp_path / "cut.db3"
    cut.write_bytes(db.read_bytes()[: db.stat().st_size - 4096])
    assert raw_mod._read_sqlite_quick(cut, {"/pose"}, []) is None


def test_mcap_damaged_chunk_record_falls_back(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    """A message record's length field is made huge inside an uncompressed chunk: our walk declines and rosbags
    reports the damage exactly as without the fast path. Every topic is read, so the damaged record is one the
    reader reads (records of unwanted topics in an uncompressed chunk are not read at all: message-level reads)."""
    bag = _write(tmp_path / "bag", StoragePlugin.MCAP)
    mcap = next(bag.glob("*.mcap"))
    raw = bytearray(mcap.read_bytes())
    with Reader(mcap) as r:
        chunk = r.storage.chunks[1]  # type: ignore[attr-defined]
        start = chunk.chunk_start_offset + 9 + 40 + len(chunk.compression)
        conns = list(r.connections)
        assert read_mcap_storage(r.storage, conns) is not None  # type: ignore[arg-type]
    assert raw[start] == 0x05  # the chunk starts with a message record
    raw[start + 1 : start + 9] = (2**40).to_bytes(8, "little")
    mcap.write_bytes(bytes(raw))
    with Reader(mcap) as r:
        assert read_mcap_storage(r.storage, list(r.connections)) is None  # type: ignore[arg-type]
    with pytest.raises(LogReadError) as fast_err:
        read_raw(bag, TOPICS)
    with pytest.raises(LogReadError) as ref_err:
        _reference(bag, TOPICS, monkeypatch)
    assert (type(fast_err.value), str(fast_err.value)) == (type(ref_err.value), str(ref_err.value))


def test_mcap_message_level_reads_decline_on_a_damaged_wanted_record(tmp_path: Path,
                                                                     monkeypatch: pytest.MonkeyPatch) -> None:
    """Only /pose is wanted, so its records are read one by one; one of them is damaged (huge length): the
    message-level read declines, the chunk is walked whole, and rosbags' error is reported as before."""
    bag = _write(tmp_path / "bag", StoragePlugin.MCAP)
    mcap = next(bag.glob("*.mcap"))
    raw = bytearray(mcap.read_bytes())
    with Reader(mcap) as r:
        chunk = r.storage.chunks[1]  # type: ignore[attr-defined]
        pose_id = next(c.id for c in r.connections if c.topic == "/pose")
        index_at = chunk.message_index_offsets[pose_id]
    first = int.from_bytes(raw[index_at + 15 + 8 : index_at + 15 + 16], "little")  # offset of the first entry
    start = chunk.chunk_start_offset + 9 + 40 + first
    assert raw[start] == 0x05
    raw[start + 1 : start + 9] = (2**40).to_bytes(8, "little")
    mcap.write_bytes(bytes(raw))
    with pytest.raises(LogReadError) as fast_err:
        read_raw(bag, ["/pose"])
    with pytest.raises(LogReadError) as ref_err:
        _reference(bag, ("/pose",), monkeypatch)
    assert (type(fast_err.value), str(fast_err.value)) == (type(ref_err.value), str(ref_err.value))


@pytest.mark.parametrize("plugin", [StoragePlugin.MCAP, StoragePlugin.SQLITE3])
def test_truncated_files_behave_as_before(tmp_path: Path, monkeypatch: pytest.MonkeyPatch,
                                          plugin: StoragePlugin) -> None:
    bag = _write(tmp_path / "bag", plugin)
    bare = tmp_path / f"cut{'.mcap' if plugin == StoragePlugin.MCAP else '.db3'}"
    src = next(bag.glob("*.mcap" if plugin == StoragePlugin.MCAP else "*.db3"))
    shutil.copyfile(src, bare)
    with bare.open("r+b") as fh:
        fh.truncate(bare.stat().st_size * 2 // 3)
    with pytest.raises(LogReadError) as fast_err:
        read_raw(bare, ["/pose"])
    with pytest.raises(LogReadError) as ref_err:
        _reference(bare, ("/pose",), monkeypatch)
    assert (type(fast_err.value), str(fast_err.value)) == (type(ref_err.value), str(ref_err.value))
    assert isinstance(fast_err.value, UnusableInputError)  # exit code 3
    if plugin == StoragePlugin.MCAP:
        assert isinstance(fast_err.value, TruncatedLogError)
        salvaged = read_raw(bare, ["/pose"], salvage=True)
        assert salvaged.partial and len(salvaged.topics["/pose"].payloads) > 0


def test_mcap_uncompressed_chunks_are_read_message_by_message(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    """/pose is a few hundred bytes of every ~1 MiB chunk (a camera-like topic fills the rest): only its records and
    index are read from the uncompressed chunks, and the result is rosbags'."""
    filler = bytes(STORE.serialize_cdr(T[STRING](data="z" * (1 << 18)), STRING))
    bag = tmp_path / "bag"
    t0 = 1_700_000_000 * 10**9
    with Writer(bag, version=9, storage_plugin=StoragePlugin.MCAP) as w:
        pose = w.add_connection("/pose", POSE, typestore=STORE)
        camera = w.add_connection("/camera", STRING, typestore=STORE)
        for k in range(20):
            t = t0 + k * 10**8
            w.write(pose, t, _pose(t, float(k), "world"))
            for j in range(4):
                w.write(camera, t + j + 1, filler)
    real_pread = os.pread
    read_b = [0]

    def counting(fd: int, n: int, pos: int) -> bytes:
        read_b[0] += n
        return real_pread(fd, n, pos)

    mcap = next(bag.glob("*.mcap"))
    with Reader(mcap) as r, monkeypatch.context() as m:
        m.setattr(os, "pread", counting)
        got = read_mcap_storage(r.storage, [c for c in r.connections if c.topic == "/pose"])  # type: ignore[arg-type]
    assert got is not None and got["/pose"].log_ns.shape[0] == 20
    assert read_b[0] < mcap.stat().st_size // 50, f"read {read_b[0]} of {mcap.stat().st_size} bytes"
    _assert_same(bag, ("/pose",), monkeypatch)


def test_mcap_chunks_of_few_records_read_as_the_vectorized_walk_reads_them(tmp_path: Path) -> None:
    """A chunk of few records is walked and read in plain Python (``_few_messages``), one of many with numpy
    (``_walked_messages``): one rule either way. The records of a chunk (schema and channel records among its
    messages), each byte of 250 places changed to two values: both give the same messages (channel, log time,
    payload, in the same order) or both decline."""
    from rosbags.rosbag2.storage_mcap import McapReader

    from verify.ingest import mcap as fast_mcap

    bag = _write(tmp_path / "bag", StoragePlugin.MCAP, chunk_every=40)
    storage = McapReader(next(bag.glob("*.mcap")))
    storage.open()
    try:
        known = {int(cid): str(ch.topic) for cid, ch in storage.channels.items()}
        chunk = storage.chunks[0]
    finally:
        storage.close()
    at = int(chunk.chunk_start_offset) + fast_mcap._CHUNK_DATA_AT + len(chunk.compression)
    records = next(bag.glob("*.mcap")).read_bytes()[at : at + int(chunk.uncompressed_size)]
    wanted = {cid for cid, topic in known.items() if topic in ("/pose", "/cmd")}
    tables = {"is_known": fast_mcap._channel_table(known), "is_wanted": fast_mcap._channel_table(wanted)}

    def outcome(fn: object, raw: bytes) -> object:
        try:
            channel, log_ns, data, lens = fast_mcap._copied_out(fn(raw))  # type: ignore[operator]
        except (fast_mcap._UnusualError, fast_mcap.MalformedError) as err:
            return type(err).__name__
        return channel.tolist(), log_ns.tolist(), data.tobytes(), lens.tolist()

    def few(raw: bytes) -> object:
        return fast_mcap._few_messages(raw, known, wanted)

    def walked(raw: bytes) -> object:
        return fast_mcap._walked_messages(raw, None, known, **tables)

    intact = outcome(few, records)
    assert intact == outcome(walked, records) and isinstance(intact, tuple) and len(intact[0]) > 10
    rng = np.random.default_rng(3)
    declined = 0
    for pos in rng.choice(len(records), size=250, replace=False).tolist():
        for value in (records[pos] ^ 0x01, records[pos] ^ 0xF0):
            damaged = records[:pos] + bytes([value]) + records[pos + 1 :]
            got = outcome(few, damaged)
            assert got == outcome(walked, damaged), f"byte {pos} -> {value:#x}"
            declined += isinstance(got, str)
    assert declined > 20  # the test has teeth: record heads and fixed fields are hit
    # a message record too short for its fixed fields (channel, sequence, log and publish times), walked all the same
    for n in (0, 2, 21):
        short = records + bytes([5]) + n.to_bytes(8, "little") + bytes(n)
        assert outcome(few, short) == outcome(walked, short) == "FastPathError"
