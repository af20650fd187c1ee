"""Our ROS1 chunk reader returns exactly what rosbags' reader returns (order, times, payloads, types, definitions),
on uncompressed, bz2 and lz4 bags, and declines (falls back to rosbags) on anything unusual."""

from __future__ import annotations

import os
import tracemalloc
from pathlib import Path
from typing import Any

import numpy as np
import pytest
from rosbags.rosbag1 import Writer
from rosbags.typesys import Stores, get_typestore

from tubempc.scenario import Scenario
from verify.errors import TruncatedLogError
from verify.ingest import ros1
from verify.ingest.decode import decode_pose
from verify.ingest.raw import _read_indexed, read_raw
from verify.ingest.ros1 import _INDEX_HEADS, PayloadBuffer, read_ros1_fast
from verify.ingest.ros1records import MAGIC, Op, record_at

from .support import tied_publishers_bag

STORE = get_typestore(Stores.ROS1_NOETIC)
T = STORE.types
POSE = "geometry_msgs/msg/PoseStamped"
STRING = "std_msgs/msg/String"


def _pose(t_ns: int, x: float, frame: str) -> bytes:
    hdr = T["std_msgs/msg/Header"](seq=0, stamp=T["builtin_interfaces/msg/Time"](sec=t_ns // 10**9,
                                                                                  nanosec=t_ns % 10**9),
                                   frame_id=frame)
    msg = T[POSE](header=hdr, pose=T["geometry_msgs/msg/Pose"](
        position=T["geometry_msgs/msg/Point"](x=x, y=-x, z=0.0),
        orientation=T["geometry_msgs/msg/Quaternion"](x=0.0, y=0.0, z=0.0, w=1.0)))
    return bytes(STORE.serialize_ros1(msg, POSE))


def _write(path: Path, compression: str | None, *, chunk_bytes: int = 4096, shuffle: bool = False,
           frames: tuple[str, ...] = ("world",), no_definition: bool = False) -> Path:
    """Pose on /pose (two connections: two callers), strings on /status, a Twist-free /other; many chunks."""
    rng = np.random.default_rng(5)
    times = 1_700_000_000 * 10**9 + np.arange(600, dtype=np.int64) * 10_000_000
    if shuffle:  # log times out of order within and across chunks, with ties
        times = times[rng.permutation(times.size)]
        times[10] = times[11]
    writer = Writer(path)
    if compression == "bz2":
        writer.set_compression(Writer.CompressionFormat.BZ2)
    elif compression == "lz4":
        writer.set_compression(Writer.CompressionFormat.LZ4)
    writer.chunk_threshold = chunk_bytes
    with writer as w:
        kw: dict[str, Any] = {"msgdef": "", "md5sum": "0" * 32} if no_definition else {"typestore": STORE}
        pose_a = w.add_connection("/pose", POSE, callerid="/a", **kw)
        pose_b = w.add_connection("/pose", POSE, callerid="/b", typestore=STORE)
        status = w.add_connection("/status", STRING, typestore=STORE)
        other = w.add_connection("/other", STRING, typestore=STORE)
        for k, t in enumerate(times.tolist()):
            frame = frames[k % len(frames)]
            w.write(pose_a if k % 3 else pose_b, t, _pose(t, 0.001 * k, frame))
            if k % 7 == 0:
                text = T[STRING](data="x" * (k % 13))
                w.write(status, t + 1, bytes(STORE.serialize_ros1(text, STRING)))
            if k % 50 == 0:
                w.write(other, t, bytes(STORE.serialize_ros1(T[STRING](data="o"), STRING)))
    return path


def _same_as_rosbags(path: Path, wanted: set[str]) -> None:
    fast = read_ros1_fast(path, wanted)
    assert fast is not None
    ref = _read_indexed(path, "ros1", wanted, [])
    assert fast.available == ref.available
    assert set(fast.topics) == set(ref.topics)
    for topic, (msgtype, has_def, log_ns, payloads) in fast.topics.items():
        want = ref.topics[topic]
        assert isinstance(payloads, PayloadBuffer)
        assert (msgtype, has_def) == (want.msgtype, want.has_definition)
        assert log_ns.tolist() == list(want.log_ns)
        assert list(payloads) == list(want.payloads)


@pytest.mark.parametrize("compression", [None, "bz2", "lz4"])
def test_reader_equals_rosbags(tmp_path: Path, compression: str | None) -> None:
    path = _write(tmp_path / "run.bag", compression)
    _same_as_rosbags(path, {"/pose", "/status", "/absent"})


@pytest.mark.parametrize("compression", [None, "lz4"])
def test_reader_equals_rosbags_out_of_order_and_variable_sizes(tmp_path: Path, compression: str | None) -> None:
    """Shuffled times with ties across chunks, two connections on /pose, records of several lengths: the order
    (time, chunk position, offset) and the payloads are rosbags' (uncompressed: all chunks' records read in one
    pass; lz4: chunk by chunk)."""
    path = _write(tmp_path / "run.bag", compression, shuffle=True, frames=("world", "map", "mocap_frame"))
    for wanted in ({"/pose", "/status"}, {"/pose"}, {"/status", "/other"}):
        _same_as_rosbags(path, wanted)
    path2 = _write(tmp_path / "run2.bag", None, chunk_bytes=1 << 20, no_definition=True)  # one chunk
    _same_as_rosbags(path2, {"/pose"})


def test_read_raw_uses_fast_reader_and_decodes(tmp_path: Path) -> None:
    path = _write(tmp_path / "run.bag", "bz2")
    raw = read_raw(path, ["/pose"])
    pose = raw.topics["/pose"]
    assert isinstance(pose.payloads, PayloadBuffer)
    cols = decode_pose(pose, True)
    assert cols.fast
    slow = decode_pose(pose, True, fast=False)  # per-message deserialize over the same buffer
    np.testing.assert_array_equal(cols.x_m, slow.x_m)
    np.testing.assert_array_equal(cols.stamp_ns, slow.stamp_ns)


def test_damaged_bags_fall_back_to_rosbags(tmp_path: Path, scenario: Scenario) -> None:
    path = _write(tmp_path / "run.bag", None)
    data = path.read_bytes()
    cut = tmp_path / "cut.bag"
    cut.write_bytes(data[: len(data) * 2 // 3])
    assert read_ros1_fast(cut, {"/pose"}) is None
    with pytest.raises(TruncatedLogError):
        read_raw(cut, ["/pose"])
    salvaged = read_raw(cut, ["/pose"], salvage=True)
    assert salvaged.partial
    assert 0 < len(salvaged.topics["/pose"].payloads) < 600
    # a corrupted message record inside an uncompressed chunk: declined, rosbags decides
    broken = bytearray(data)
    first = data.index(b"op=\x02")
    broken[first + 3] = 0x09
    bad = tmp_path / "bad.bag"
    bad.write_bytes(bytes(broken))
    assert read_ros1_fast(bad, {"/pose", "/status", "/other"}) is None
    assert read_ros1_fast(tmp_path / "run.bag", {"/pose"}) is not None
    unindexed = bytearray(data)
    pos = data.index(b"index_pos=") + len(b"index_pos=")
    unindexed[pos : pos + 8] = bytes(8)
    un = tmp_path / "unindexed.bag"
    un.write_bytes(bytes(unindexed))
    assert read_ros1_fast(un, {"/pose"}) is None
    with pytest.raises(TruncatedLogError):
        read_raw(un, ["/pose"])


def _sparse_bag(path: Path, compression: str | None, chunks: int) -> Path:
    """A bag of ``chunks`` chunks of about 1 MiB (a 256 KiB camera-like filler) where /pose has one message per
    chunk: the shape of a lab recording whose slow topics are a tiny part of every chunk."""
    writer = Writer(path)
    if compression == "lz4":
        writer.set_compression(Writer.CompressionFormat.LZ4)
    writer.chunk_threshold = 1 << 20
    filler = bytes(STORE.serialize_ros1(T[STRING](data="z" * (1 << 18)), STRING))
    t0 = 1_700_000_000 * 10**9
    with writer as w:
        pose = w.add_connection("/pose", POSE, typestore=STORE)
        camera = w.add_connection("/camera", STRING, typestore=STORE)
        for k in range(chunks):
            t = t0 + k * 10**8
            w.write(pose, t, _pose(t, 0.01 * k, "world"))
            for j in range(4):
                w.write(camera, t + j + 1, filler)
    return path


@pytest.mark.parametrize("compression", [None, "lz4"])
def test_kept_payloads_do_not_hold_their_chunks(tmp_path: Path, compression: str | None) -> None:
    """One wanted message per ~1 MiB chunk: what the reader returns holds the payloads (~40 chunks x 200 bytes),
    not the chunks they came from (a view of a decompressed chunk keeps all of it alive: ~40 MiB here), and the
    reading works chunk by chunk (peak: a few chunks, not the file)."""
    chunks = 40
    path = _sparse_bag(tmp_path / "sparse.bag", compression, chunks)
    tracemalloc.start()
    try:
        fast = read_ros1_fast(path, {"/pose"})
        kept_b, peak_b = tracemalloc.get_traced_memory()
    finally:
        tracemalloc.stop()
    assert fast is not None
    assert len(fast.topics["/pose"][3]) == chunks
    # bounds: the returned arrays are ~10 KiB; a chunk is ~1 MiB and at most a few are alive at once
    assert kept_b < 1 << 20, f"the result holds {kept_b} bytes"
    assert peak_b < 8 << 20, f"peak {peak_b} bytes while reading"
    _same_as_rosbags(path, {"/pose"})


@pytest.mark.parametrize("compression", [None, "lz4"])
def test_uncompressed_chunks_are_read_message_by_message(tmp_path: Path, monkeypatch: pytest.MonkeyPatch,
                                                         compression: str | None) -> None:
    """/pose is ~200 bytes of every ~1 MiB chunk: from an uncompressed chunk only its records (and the index) are
    read; a compressed chunk has to be read whole."""
    path = _sparse_bag(tmp_path / "sparse.bag", compression, 20)
    real_pread, real_preadv = os.pread, os.preadv
    read_b = [0]

    def counting(fd: int, n: int, pos: int) -> bytes:
        read_b[0] += n
        return real_pread(fd, n, pos)

    def counting_v(fd: int, buffers: list[memoryview], pos: int) -> int:
        got = real_preadv(fd, buffers, pos)
        read_b[0] += got
        return got

    monkeypatch.setattr(os, "pread", counting)
    monkeypatch.setattr(os, "preadv", counting_v)
    fast = read_ros1_fast(path, {"/pose"})
    monkeypatch.undo()
    assert fast is not None and len(fast.topics["/pose"][3]) == 20
    size_b = path.stat().st_size
    if compression is None:
        assert read_b[0] < size_b // 50, f"read {read_b[0]} of {size_b} bytes"
    else:
        assert read_b[0] > size_b // 2
    _same_as_rosbags(path, {"/pose"})


def _last_index_records(data: bytes) -> list[tuple[int, int, int]]:
    """(record position, header length, data length) of each chunk's last index data record, in file order."""
    out: list[tuple[int, int, int]] = []
    pos, last = len(MAGIC), None
    while pos < len(data):
        rec = record_at(data, pos, len(data))
        if rec.op == Op.INDEX_DATA:
            last = (pos, rec.data_start - pos - 8, rec.data_len)
        elif last is not None:
            out.append(last)
            last = None
        pos = rec.end
    return out


@pytest.mark.parametrize("compression", [None, "lz4"])
def test_index_headers_seen_before_are_still_checked(tmp_path: Path, compression: str | None) -> None:
    """Index data record headers repeat from chunk to chunk, and a header seen before is not parsed again; what
    lies outside the header is checked for every record: the same bag read with the headers known (from a
    previous read) gives the same messages, and a record whose data length disagrees with its (known) header's
    count is declined as before."""
    path = _write(tmp_path / "run.bag", compression)
    _forget_shapes()
    cold = read_ros1_fast(path, {"/pose", "/status"})
    assert cold is not None and _INDEX_HEADS and ros1._INDEX_LAYOUTS  # the headers and layouts are known now
    warm = read_ros1_fast(path, {"/pose", "/status"})
    assert warm is not None
    for topic, (msgtype, has_def, log_ns, payloads) in cold.topics.items():
        assert (msgtype, has_def) == warm.topics[topic][:2]
        assert log_ns.tolist() == warm.topics[topic][2].tolist() and list(payloads) == list(warm.topics[topic][3])
    data = path.read_bytes()
    records = _last_index_records(data)
    headers = [data[p + 4 : p + 4 + h] for p, h, _n in records]
    # a chunk's last index record whose header an earlier chunk's repeats: its data length field says one entry
    # fewer than its count (nothing after it is read from that length: the next chunk's place is in the index)
    k = next(i for i in range(len(records)) if headers[i] in headers[:i])
    pos, hlen, dlen = records[k]
    at = pos + 4 + hlen
    damaged = bytearray(data)
    damaged[at : at + 4] = (dlen - 12).to_bytes(4, "little")
    bad = tmp_path / "bad.bag"
    bad.write_bytes(bytes(damaged))
    assert bytes(damaged[pos + 4 : pos + 4 + hlen]) in _INDEX_HEADS  # known: its data length is checked all the same
    assert read_ros1_fast(bad, {"/pose", "/status"}) is None


def _forget_shapes() -> None:
    """The fast reader's memory of record heads it has read in full (index headers, index layouts, chunk heads)."""
    _INDEX_HEADS.clear()
    ros1._INDEX_LAYOUTS.clear()
    ros1._LAYOUTS_SEEN.clear()
    ros1._LAYOUTS_COMPILED.clear()
    ros1._CHUNK_HEADS.clear()


class _Forgetful(dict[bytes, Any]):
    """A memory that keeps nothing."""

    def __setitem__(self, key: bytes, value: Any) -> None:
        pass


def _outcome(path: Path) -> Any:
    got = read_ros1_fast(path, {"/pose", "/status"})
    if got is None:
        return None
    return {t: (m, d, ns.tolist(), list(p)) for t, (m, d, ns, p) in got.topics.items()}, got.available


def _heads_and_index(data: bytes) -> list[int]:
    """Every byte position of the bag's record heads and index data records outside its chunks' data (chunk heads,
    index data records, connection and chunk info records)."""
    bag = record_at(data, len(MAGIC), len(data))
    out: list[int] = []
    pos = int.from_bytes(bag.header["index_pos"], "little")
    out += range(pos, len(data))
    pos = bag.end
    while pos < int.from_bytes(bag.header["index_pos"], "little"):
        rec = record_at(data, pos, len(data), head_only=True)
        out += range(pos, rec.data_start if rec.op == Op.CHUNK else rec.end)
        pos = rec.end
    return out


@pytest.mark.parametrize("compression", [None, "lz4"])
def test_record_heads_matched_as_they_are_parsed(tmp_path: Path, compression: str | None,
                                                 monkeypatch: pytest.MonkeyPatch) -> None:
    """Chunk heads, chunk info records and a chunk's index data records that repeat, but for their values, ones read
    in full before are matched (one compiled pattern), not parsed. One rule either way: a bag with one byte changed
    in any of them (300 places, each to two values) reads the same -- the same messages, or declined -- with every
    head known beforehand (from the undamaged bag) as with no head ever remembered (each parsed in full)."""
    path = _write(tmp_path / "run.bag", compression, chunk_bytes=2048)
    data = path.read_bytes()
    places = _heads_and_index(data)
    rng = np.random.default_rng(7)
    bad = tmp_path / "bad.bag"
    declined = 0
    for at in rng.choice(places, size=300, replace=False).tolist():
        for value in (data[at] ^ 0x01, data[at] ^ 0x80):
            bad.write_bytes(data[:at] + bytes([value]) + data[at + 1 :])
            _forget_shapes()
            assert _outcome(path) is not None  # every head known
            warm = _outcome(bad)
            with monkeypatch.context() as m:  # nothing remembered: every head parsed in full
                m.setattr(ros1._Shape, "learn", staticmethod(lambda *_a, **_k: None))
                m.setattr(ros1._Layout, "learn", staticmethod(lambda *_a, **_k: None))
                m.setattr(ros1, "_INDEX_HEADS", _Forgetful())
                _forget_shapes()
                cold = _outcome(bad)
            assert warm == cold, f"byte {at} -> {value:#x}"
            declined += cold is None
    assert declined > 100  # the test has teeth: most changed bytes are declined
    _forget_shapes()


def _chunk_infos_reversed(data: bytes) -> bytes:
    """The bag with its index's chunk info records in reverse order (a writer may list chunks in any order; readers
    order messages by (time, chunk position, offset) all the same)."""
    bag = record_at(data, len(MAGIC), len(data))
    pos = int.from_bytes(bag.header["index_pos"], "little")
    infos: list[bytes] = []
    start = None
    while pos < len(data):
        rec = record_at(data, pos, len(data))
        if rec.op == Op.CHUNK_INFO:
            start = pos if start is None else start
            infos.append(data[pos : rec.end])
        pos = rec.end
    assert start is not None and len(infos) > 3
    return data[:start] + b"".join(reversed(infos)) + data[start + sum(map(len, infos)) :]


@pytest.mark.parametrize("compression", [None, "lz4"])
def test_chunks_listed_out_of_file_order(tmp_path: Path, compression: str | None) -> None:
    """Two connections on one topic, log times tied across them and across chunks (60 messages per time, as a
    simulation's clock gives), the bag as written and with its index listing the chunks last to first: the messages
    come in rosbags' order (time; then connection, as the index lists them; then the chunk's place in the index's
    list; then the record's place in its index data record), whether the chunks are read in one pass (uncompressed)
    or one by one in threads (lz4). That order is not the writing order, nor file order among equal times."""
    path = tied_publishers_bag(tmp_path / "run.bag", compression)
    flipped = tmp_path / "flipped.bag"
    flipped.write_bytes(_chunk_infos_reversed(path.read_bytes()))
    fast = read_ros1_fast(flipped, {"/pose"})
    assert fast is not None
    xs = [STORE.deserialize_ros1(p, POSE).pose.position.x for p in fast.topics["/pose"][3]]
    assert xs != sorted(xs)  # the test has teeth: rosbags' order among ties is neither writing nor file order
    _same_as_rosbags(path, {"/pose"})
    _same_as_rosbags(flipped, {"/pose"})


def test_an_index_layout_is_remembered_once_it_repeats() -> None:
    """A chunk's run of index records is compiled into a pattern (~200 us, ten chunks' reading) only when a second
    chunk repeats it: a bag whose message counts never repeat from chunk to chunk compiles none."""
    _forget_shapes()
    ids = frozenset({1, 2})
    heads = [(b"\x04\x00\x00\x00head", 1, 12), (b"\x04\x00\x00\x00tail", 2, 24)]
    ros1._Layout.learn(ids, heads)
    assert not ros1._INDEX_LAYOUTS
    ros1._Layout.learn(ids, [(b"\x04\x00\x00\x00head", 1, 24), (b"\x04\x00\x00\x00tail", 2, 24)])
    assert not ros1._INDEX_LAYOUTS  # other heads: seen once each
    ros1._Layout.learn(ids, heads)
    (layout,) = ros1._INDEX_LAYOUTS[ids]
    assert layout.total == 3 and layout.size == 8 + 12 + 8 + 24
    _forget_shapes()
