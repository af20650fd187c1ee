"""Message-level reads (``verify.ingest.records``): the records an index points at, and nothing that is not one;
chunks processed ahead in threads come back in order, a bounded number at a time, errors where they are due."""

from __future__ import annotations

import os
import struct
import threading
import tracemalloc
from pathlib import Path

import numpy as np
import pytest

from verify.ingest import records as records_mod
from verify.ingest.records import MCAP, ROS1, SpanError, gather, in_order, read_records


def _ros1_record(data: bytes) -> bytes:
    header = b"\x03\x00\x00\x00op=\x02"
    return struct.pack("<I", len(header)) + header + struct.pack("<I", len(data)) + data


def _mcap_record(content: bytes) -> bytes:
    return b"\x05" + struct.pack("<Q", len(content)) + content


def _file(tmp_path: Path, body: bytes) -> tuple[int, int]:
    path = tmp_path / "chunk.bin"
    path.write_bytes(b"HEAD" + body + b"TAIL")
    return os.open(path, os.O_RDONLY), len(body)


@pytest.mark.parametrize("kind", [ROS1, MCAP])
def test_reads_exactly_the_indexed_records(tmp_path: Path, kind: str) -> None:
    make = _ros1_record if kind == ROS1 else _mcap_record
    records = [make(bytes([k]) * (10 + 7 * k)) for k in range(6)]
    filler = make(b"\xff" * 200_000)  # a camera frame between the wanted records: far apart, not read
    body = records[0] + records[1] + filler + records[2] + filler + records[3] + records[4] + records[5]
    starts = [body.index(r) for r in records]
    fd, size = _file(tmp_path, body)
    try:
        wanted = np.array([starts[0], starts[2], starts[3], starts[5]], dtype=np.int64)
        u8, pos = read_records(fd, 4, size, wanted, kind, gap_b=1 << 16)
        got = [u8[int(p) : int(p) + len(records[k])].tobytes() for p, k in zip(pos, (0, 2, 3, 5), strict=True)]
        assert got == [records[k] for k in (0, 2, 3, 5)]
        assert u8.shape[0] == sum(len(records[k]) for k in (0, 2, 3, 5))  # just the records, back to back
    finally:
        os.close(fd)


@pytest.mark.parametrize("kind", [ROS1, MCAP])
def test_groups_of_clusters_give_the_same_records(tmp_path: Path, monkeypatch: pytest.MonkeyPatch, kind: str) -> None:
    """Clusters are checked and compacted a group at a time (bounded memory): any group size gives the same
    records; a record running into the next one is refused inside any group."""
    make = _ros1_record if kind == ROS1 else _mcap_record
    records = [make(bytes([k]) * (5 + 3 * k)) for k in range(40)]
    body = b"".join(r + (make(b"\xee" * 70_000) if k % 5 == 4 else b"") for k, r in enumerate(records))
    starts = np.array([body.index(r) for r in records], dtype=np.int64)
    fd, size = _file(tmp_path, body)
    try:
        wanted = starts[::2]
        ref = read_records(fd, 4, size, wanted, kind)
        for group_b in (1, 64, 1 << 12):
            monkeypatch.setattr(records_mod, "_GROUP_B", group_b)
            u8, pos = read_records(fd, 4, size, wanted, kind)
            assert u8.tobytes() == ref[0].tobytes() and pos.tolist() == ref[1].tolist()
            assert u8.tobytes() == b"".join(records[::2])
            with pytest.raises(SpanError):
                read_records(fd, 4, size, np.sort(np.append(wanted, starts[3] + 2)), kind)
    finally:
        os.close(fd)


@pytest.mark.parametrize("kind", [ROS1, MCAP])
def test_offsets_that_are_not_records_are_refused(tmp_path: Path, kind: str) -> None:
    make = _ros1_record if kind == ROS1 else _mcap_record
    a, b = make(b"a" * 40), make(b"b" * 40)
    body = a + b
    fd, size = _file(tmp_path, body)
    try:
        with pytest.raises(SpanError):  # the second offset points inside the first record
            read_records(fd, 4, size, np.array([0, 5], dtype=np.int64), kind)
        with pytest.raises(SpanError):  # a record that runs past the chunk's end
            read_records(fd, 4, size - 3, np.array([0, len(a)], dtype=np.int64), kind)
        with pytest.raises(SpanError):  # unsorted
            read_records(fd, 4, size, np.array([len(a), 0], dtype=np.int64), kind)
        u8, pos = read_records(fd, 4, size, np.array([0, len(a)], dtype=np.int64), kind)
        assert u8.tobytes() == body and pos.tolist() == [0, len(a)]
    finally:
        os.close(fd)


def test_in_order_keeps_order_bounds_work_ahead_and_raises_where_due() -> None:
    alive = [0]
    most = [0]
    lock = threading.Lock()

    def work(k: int) -> int:
        with lock:
            alive[0] += 1
            most[0] = max(most[0], alive[0])
        if k == 7:
            raise ValueError("chunk 7 is damaged")
        return k

    got: list[int] = []

    def consume() -> None:
        for k in in_order(work, range(20), workers=3):
            got.append(k)
            with lock:
                alive[0] -= 1

    with pytest.raises(ValueError, match="chunk 7"):
        consume()
    assert got == list(range(7))
    assert most[0] <= 3 + 1
    assert list(in_order(lambda k: k * k, range(50), workers=4)) == [k * k for k in range(50)]
    assert list(in_order(lambda k: k, range(5), workers=1)) == list(range(5))


@pytest.mark.parametrize("seed", range(3))
def test_gather_packs_the_pieces_in_order(seed: int) -> None:
    """``gather``: pieces in the given order (sorted or not, of one length or several, adjacent, empty), as slicing
    and joining gives them."""
    rng = np.random.default_rng(seed)
    for trial in range(400):
        u8 = rng.integers(0, 256, int(rng.integers(50, 2000)), dtype=np.uint8)
        n = int(rng.integers(1, 30))
        lengths = rng.integers(0 if trial % 5 == 0 else 1, 25, n).astype(np.int64)
        if trial % 2:  # back to back, or with small gaps, in increasing order: records read from a file
            gaps = rng.integers(0, 4, n) * (rng.random(n) < 0.5)
            starts = np.cumsum(np.concatenate(([int(rng.integers(0, 10))], (lengths + gaps)[:-1]))).astype(np.int64)
        else:
            starts = rng.integers(0, u8.shape[0], n).astype(np.int64)
        if int((starts + lengths).max()) > u8.shape[0]:
            continue
        want = b"".join(u8[a : a + b].tobytes() for a, b in zip(starts.tolist(), lengths.tolist(), strict=True))
        got = gather(u8, starts, lengths)
        assert got.dtype == np.uint8 and got.tobytes() == want


def test_gather_of_records_read_back_to_back_needs_no_index_per_byte() -> None:
    """Records of several lengths read back to back (the wanted records of a bag: ~2 MB per GB) are copied out
    with a mask of their span, not with an int64 index per byte copied (24 bytes of temporaries per byte)."""
    rng = np.random.default_rng(3)
    lengths = rng.integers(90, 400, 8000).astype(np.int64)
    starts = np.concatenate(([0], np.cumsum(lengths + 8)[:-1])).astype(np.int64)  # 8 bytes between records
    u8 = rng.integers(0, 256, int(starts[-1] + lengths[-1]), dtype=np.uint8)
    tracemalloc.start()
    try:
        got = gather(u8, starts, lengths)
        _, peak = tracemalloc.get_traced_memory()
    finally:
        tracemalloc.stop()
    assert got.shape[0] == int(lengths.sum())
    assert peak < 4 * u8.shape[0], f"peak {peak} B for {u8.shape[0]} B"
