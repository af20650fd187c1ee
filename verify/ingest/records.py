"""Message-level reads: the records an index points at inside an uncompressed chunk -> one compact byte buffer.

input: an open file descriptor, the file position where a chunk's records start, their length, and the offsets (from
the chunk's index) of the wanted records -> output: a compact ``uint8`` buffer holding just those records and each
record's position in it. The callers (``verify.ingest.ros1``, ``verify.ingest.mcap``) then parse the records from
the compact buffer exactly as from the whole chunk.

Offsets closer than ``gap_b`` are read together (one ``pread`` per cluster: the bytes between two wanted records of a
cluster are read too, the bytes of a camera frame between two clusters are not). Every record must end inside the
chunk and before the next wanted record begins (checked for all of them, vectorized); anything else raises
``SpanError`` and the caller falls back to reading the whole chunk. ``in_order`` runs the per-chunk reading (and
decompression) a few chunks ahead in threads, keeping the chunks' order and a bounded number of them in memory.
"""

from __future__ import annotations

import ctypes
import os
import struct
import threading
from collections import deque
from collections.abc import Callable, Iterable, Iterator
from concurrent.futures import Future, ThreadPoolExecutor
from itertools import pairwise
from typing import TypeVar

import numpy as np
import numpy.typing as npt

__all__ = ["MCAP", "ROS1", "WORKERS", "CutError", "MalformedError", "SpanError", "gather", "in_order", "lz4_decompress",
           "read_records", "read_scratch", "record_ends", "record_size_at", "retain_freed_memory",
           "ros1_records_back_to_back", "walk_chain"]

_T = TypeVar("_T")
_R = TypeVar("_R")
U8Array = npt.NDArray[np.uint8]
IntArray = npt.NDArray[np.int64]

ROS1 = "ros1"  # record: header length u32, header, data length u32, data
MCAP = "mcap"  # record: opcode u8, content length u64, content


# chunks read and decompressed ahead of the one being parsed (the decompressors release the GIL): at most
# WORKERS + 1 chunks are alive at once
WORKERS = max(1, min(4, os.cpu_count() or 1))


_SCRATCH = threading.local()
_SLACK_B = 4096  # read past a cluster's last record start, to learn its length in the same read
_GROUP_B = 2 << 20  # clusters read and checked together before their records are copied out


class SpanError(Exception):
    """The index points at something that is not a well-formed record of the chunk."""


class CutError(Exception):
    """The bytes end inside a record (a truncated file, or one still being written)."""


class MalformedError(Exception):
    """A record's fields contradict its lengths or the format (damaged bytes)."""


def lz4_decompress(data: bytes | memoryview) -> bytes:
    """An lz4 frame (ROS1 and MCAP chunks) -> its bytes; raises lz4's own error (RuntimeError) on damaged data."""
    from lz4.frame import decompress as lz4_frame  # type: ignore[import-untyped]  # a rosbags dependency

    # lz4 reads any contiguous byte buffer: a chunk read into the scratch buffer is not copied first (~1 GB of
    # copies for a 1 GB lz4 bag)
    src = data if isinstance(data, bytes) or (data.c_contiguous and data.itemsize == 1) else bytes(data)
    out: bytes = lz4_frame(src)
    return out


def _pread(fd: int, pos: int, n: int) -> bytes:
    data = os.pread(fd, n, pos)
    if len(data) != n:
        raise SpanError("short read")
    return data


def _record_size(fd: int, kind: str, pos: int, room: int) -> int:
    """Size of the record at file position ``pos`` that has at most ``room`` bytes before the chunk ends."""
    if kind == ROS1:
        if room < 8:
            raise SpanError("record header outside its chunk")
        (hlen,) = struct.unpack("<I", _pread(fd, pos, 4))
        if 8 + hlen > room:
            raise SpanError("record header outside its chunk")
        (dlen,) = struct.unpack("<I", _pread(fd, pos + 4 + hlen, 4))
        size = 8 + int(hlen) + int(dlen)
    else:
        if room < 9:
            raise SpanError("record header outside its chunk")
        (clen,) = struct.unpack("<Q", _pread(fd, pos + 1, 8))
        size = 9 + int(clen)
    if size > room:
        raise SpanError("record runs past the end of its chunk")
    return size


def _u32_at(u8: U8Array, at: IntArray) -> IntArray:
    return np.ascontiguousarray(u8[at[:, None] + np.arange(4)]).view("<u4").ravel().astype(np.int64)


def record_ends(u8: U8Array, kind: str, rel: IntArray) -> IntArray:
    """End (exclusive) of each record starting at ``rel`` in ``u8``; -1 where its header is not in ``u8``."""
    n = u8.shape[0]
    ends = np.full(rel.shape[0], -1, dtype=np.int64)
    if kind == ROS1:
        ok = rel + 4 <= n
        hlen = np.zeros(rel.shape[0], dtype=np.int64)
        hlen[ok] = _u32_at(u8, rel[ok])
        ok &= rel + 8 + hlen <= n
        ends[ok] = rel[ok] + 8 + hlen[ok] + _u32_at(u8, rel[ok] + 4 + hlen[ok])
    else:
        ok = rel + 9 <= n
        at = rel[ok] + 1
        clen = np.ascontiguousarray(u8[at[:, None] + np.arange(8)]).view("<u8").ravel()
        if np.any(clen >= np.uint64(2**62)):
            raise SpanError("record length beyond the file")
        ends[ok] = rel[ok] + 9 + clen.astype(np.int64)
    return ends


def walk_chain(buf: bytes | memoryview, kind: str, hints: IntArray | None = None) -> tuple[IntArray, IntArray]:
    """The sequential walk of a chunk's records (``buf``: its records back to back, from 0 to its end) -> start and
    end of every record, in order; ``MalformedError`` when a record runs past the end. The format's walk, in one
    place for every reader of a chunk (indexed reading, the scan, salvage, following a growing file).

    ``hints``: candidate record starts (sorted, unique; e.g. from the chunk's index). Their lengths are read with
    numpy, and a run of candidates where each record ends exactly where the next candidate begins is taken in one
    step (by induction every candidate in the run is a true record start of the sequential walk). Records between
    runs (or every record, without hints) are stepped over one by one. A hint is only a hint: nothing is taken from
    it that the walk does not confirm."""
    view = memoryview(buf)
    size = len(view)
    u8 = np.frombuffer(view, dtype=np.uint8)
    cand = np.zeros(0, dtype=np.int64) if hints is None else hints[(hints >= 0) & (hints < size)]
    k = cand.shape[0]
    if k:
        try:
            c_end = record_ends(u8, kind, cand)
        except SpanError:
            c_end = np.full(k, -1, dtype=np.int64)
        c_end = np.where((c_end > cand) & (c_end <= size), c_end, -1)
        breaks = [*np.flatnonzero(c_end[:-1] != cand[1:]).tolist(), k - 1]  # runs end where a record misses the next
    else:
        c_end = np.zeros(0, dtype=np.int64)
        breaks = []
    cand_l = cand.tolist()
    seg_pos: list[IntArray] = []
    seg_end: list[IntArray] = []
    one_pos: list[int] = []
    one_end: list[int] = []
    pos = i = b = 0  # i: next candidate not behind pos; b: index into breaks
    while pos < size:
        while i < k and cand_l[i] < pos:
            i += 1
        if i < k and cand_l[i] == pos and c_end[i] >= 0:
            while breaks[b] < i:
                b += 1
            j = breaks[b]  # candidates i..j chain; j's record ends at c_end[j]
            if c_end[j] < 0:
                j -= 1  # j's length runs past the end: the run ends at j's start, where the walk steps on
            if one_pos:
                seg_pos.append(np.array(one_pos, dtype=np.int64))
                seg_end.append(np.array(one_end, dtype=np.int64))
                one_pos, one_end = [], []
            seg_pos.append(cand[i : j + 1])
            seg_end.append(c_end[i : j + 1])
            pos, i = int(c_end[j]), j + 1
            continue
        stop = i if i < k else None  # step up to the next candidate (or the end) without leaving this loop
        pos = _step(view, kind, pos, size, until=cand_l[stop] if stop is not None else size, starts=one_pos,
                    ends=one_end)
    seg_pos.append(np.array(one_pos, dtype=np.int64))
    seg_end.append(np.array(one_end, dtype=np.int64))
    return np.concatenate(seg_pos), np.concatenate(seg_end)


_U32 = struct.Struct("<I")
_U64 = struct.Struct("<Q")


def walk_steps(buf: bytes | memoryview, kind: str) -> tuple[list[int], list[int]]:
    """``walk_chain`` without hints, as Python lists (start and end of every record): for a chunk of a few dozen
    records, read on in plain Python."""
    view = memoryview(buf)
    starts: list[int] = []
    ends: list[int] = []
    if view:
        _step(view, kind, 0, len(view), until=len(view), starts=starts, ends=ends)
    return starts, ends


def _step(view: memoryview, kind: str, pos: int, size: int, *, until: int, starts: list[int], ends: list[int]) -> int:
    """Records stepped over one by one from ``pos`` (appended to ``starts``/``ends``) until one ends at or past
    ``until`` -> the position after the last; ``MalformedError`` when a record does not end by ``size``."""
    u32, u64 = _U32.unpack_from, _U64.unpack_from
    while True:
        if kind == ROS1:
            if pos + 8 > size or pos + 8 + u32(view, pos)[0] > size:
                raise MalformedError(f"a chunk ends inside the record at byte {pos}")
            hlen = u32(view, pos)[0]
            nxt = pos + 8 + hlen + u32(view, pos + 4 + hlen)[0]
        else:
            if pos + 9 > size:
                raise MalformedError(f"a chunk ends inside the record at byte {pos}")
            nxt = pos + 9 + u64(view, pos + 1)[0]
        if nxt > size:
            raise MalformedError(f"the record at byte {pos} of a chunk runs past its end")
        starts.append(pos)
        ends.append(nxt)
        pos = nxt
        if pos >= until:
            return pos


def read_records(fd: int, base: int, limit: int, offsets: IntArray, kind: str, *, gap_b: int = 1 << 16,
                 limits: IntArray | None = None) -> tuple[U8Array, IntArray]:
    """The records at ``offsets`` (relative to file position ``base``; sorted, unique, each < ``limit``, the length
    of the chunk's records) -> (compact buffer holding just those records, back to back, and each record's position
    in it). ``limits`` (same shape as ``offsets``, relative to ``base``): each record's own end bound instead of
    ``limit``, for records of many chunks read in one call (``base`` 0, offsets and limits file positions: a record
    must end inside its chunk).

    Clusters are read into a group of at most ``_GROUP_B`` bytes, checked together (vectorized), and only their
    records are copied out: the bytes between two records of a cluster (another topic's messages) are never kept,
    so the memory held is the wanted records plus one group, whatever the file's size."""
    k = offsets.shape[0]
    if k == 0:
        return np.zeros(0, dtype=np.uint8), np.zeros(0, dtype=np.int64)
    lim = np.full(k, limit, dtype=np.int64) if limits is None else limits.astype(np.int64, copy=False)
    if lim.shape != offsets.shape:
        raise ValueError("limits and offsets must have the same shape")
    if np.any(np.diff(offsets) <= 0) or int(offsets[0]) < 0 or np.any(offsets >= lim):
        raise SpanError("index offsets not sorted or outside their chunk")
    cuts = [0, *(np.flatnonzero(np.diff(offsets) > gap_b) + 1).tolist(), k]
    out: list[U8Array] = []
    out_len: list[IntArray] = []
    group: list[bytes] = []
    group_b = 0
    first = 0  # the group's first cluster
    for c, (a, b) in enumerate(pairwise(cuts)):
        lo, last = int(offsets[a]), int(offsets[b - 1])
        room = int(lim[b - 1]) - last
        # the cluster and a little beyond: the last record's length is then usually known without a second read
        piece = _pread(fd, base + lo, last - lo + min(room, _SLACK_B))
        size = record_size_at(piece, kind, last - lo, room)
        if size is None:
            size = _record_size(fd, kind, base + last, room)
        n = last - lo + size
        if n > len(piece):
            piece += _pread(fd, base + lo + len(piece), n - len(piece))
        elif n < len(piece):
            piece = piece[:n]
        group.append(piece)
        group_b += n
        if group_b >= _GROUP_B or c == len(cuts) - 2:
            data, lengths = _group_records(group, cuts[first : c + 2], offsets, lim, kind)
            out.append(data)
            out_len.append(lengths)
            group, group_b, first = [], 0, c + 1
    lengths_all = np.concatenate(out_len)
    pos = np.zeros(k, dtype=np.int64)
    np.cumsum(lengths_all[:-1], out=pos[1:])
    return (out[0] if len(out) == 1 else np.concatenate(out)), pos


def _group_records(pieces: list[bytes], cuts: list[int], offsets: IntArray, lim: IntArray, kind: str
                   ) -> tuple[U8Array, IntArray]:
    """Check the records of a group of clusters (``pieces``: each cluster's bytes; ``cuts``: their record index
    bounds) and copy them out back to back -> (bytes, record lengths)."""
    u8 = np.frombuffer(b"".join(pieces), dtype=np.uint8)
    a0, a1 = cuts[0], cuts[-1]
    sizes = np.array([len(p) for p in pieces], dtype=np.int64)
    stops = np.cumsum(sizes)
    starts = stops - sizes
    counts: IntArray = np.diff(np.array(cuts, dtype=np.int64)).astype(np.int64)
    cluster_lo = offsets[np.array(cuts[:-1], dtype=np.int64)]
    offs = offsets[a0:a1]
    pos = offs - np.repeat(cluster_lo, counts) + np.repeat(starts, counts)
    ends = record_ends(u8, kind, pos)
    # each record ends before the next one of its cluster starts (the last at the cluster's end), inside its chunk
    last_of = np.zeros(a1 - a0, dtype=bool)
    last_of[np.cumsum(counts) - 1] = True
    nxt = np.append(pos[1:], 0)
    bound = np.minimum(np.where(last_of, np.repeat(stops, counts), nxt), lim[a0:a1] - offs + pos)
    if np.any(ends < 0) or np.any(ends > bound) or np.any(ends[last_of] != stops):
        raise SpanError("records overlap or run past their chunk")
    lengths = ends - pos
    if int(lengths.sum()) == u8.shape[0]:  # nothing between the records: the group is the compact buffer
        return u8, lengths
    return gather(u8, pos, lengths), lengths


def record_size_at(piece: bytes | memoryview, kind: str, rel: int, room: int) -> int | None:
    """Size of the record at ``rel`` in ``piece`` when its length fields are inside ``piece`` (else None);
    ``SpanError`` when it would not fit in ``room``."""
    if kind == ROS1:
        if rel + 4 > len(piece):
            return None
        (hlen,) = struct.unpack_from("<I", piece, rel)
        if 8 + hlen > room:
            raise SpanError("record header outside its chunk")
        if rel + 8 + hlen > len(piece):
            return None
        (dlen,) = struct.unpack_from("<I", piece, rel + 4 + hlen)
        size = 8 + int(hlen) + int(dlen)
    else:
        if rel + 9 > len(piece):
            return None
        (clen,) = struct.unpack_from("<Q", piece, rel + 1)
        size = 9 + int(clen)
    if size > room:
        raise SpanError("record runs past the end of its chunk")
    return size


def ros1_records_back_to_back(piece: bytes | memoryview, starts: list[int]) -> list[int]:
    """The sizes of the ROS1 records at ``starts`` (increasing) in ``piece``: each must end by the next start (the
    last by the end of ``piece``), the rule of ``record_size_at`` for a run of records in one call (a chunk's few
    dozen wanted records: one call instead of one per record); ``SpanError`` where one does not."""
    sizes: list[int] = []
    ends = [*starts[1:], len(piece)]
    unpack = struct.unpack_from
    try:
        for rel, room_end in zip(starts, ends, strict=True):
            (hlen,) = unpack("<I", piece, rel)
            (dlen,) = unpack("<I", piece, rel + 4 + hlen)
            size = 8 + hlen + dlen
            if rel + size > room_end:
                raise SpanError("record runs past the next record or the end of its chunk")
            sizes.append(size)
    except struct.error:
        raise SpanError("record header outside its chunk") from None
    return sizes


def in_order(fn: Callable[[_T], _R], items: Iterable[_T], *, workers: int = WORKERS) -> Iterator[_R]:
    """``map(fn, items)`` with up to ``workers`` calls running ahead in threads; results in the order of ``items``,
    at most ``workers + 1`` of them alive at once; an exception of ``fn`` is raised where its result is due."""
    if workers <= 1:
        yield from map(fn, items)
        return
    with ThreadPoolExecutor(workers, thread_name_prefix="chunk") as pool:
        pending: deque[Future[_R]] = deque()
        try:
            for item in items:
                pending.append(pool.submit(fn, item))
                if len(pending) > workers:
                    yield pending.popleft().result()
            while pending:
                yield pending.popleft().result()
        finally:
            for fut in pending:
                fut.cancel()


_RETAINED = False
_M_TRIM_THRESHOLD, _M_MMAP_THRESHOLD = -1, -3  # glibc's mallopt parameters (malloc.h)


def retain_freed_memory() -> None:
    """Have glibc's allocator reuse the memory of freed decompressed chunks instead of returning it to the system
    and faulting it in again for the next chunk (called before the first decompression; once per process).

    Decompressors return a new ``bytes`` per chunk (1-4 MB). glibc serves such sizes with a fresh ``mmap`` or
    trims them off the heap when freed, so every 4 KiB page of every chunk is faulted in anew: measured here, 200
    lz4 chunks of 1.8 MB decompressed in 0.79 s (0.62 s of it system time) against 0.11 s once the memory is
    reused. ``mallopt``: blocks below 32 MiB come from the heap (``M_MMAP_THRESHOLD``) and up to 16 MiB of free
    memory stays there (``M_TRIM_THRESHOLD``), so the process keeps at most that much more than it uses. Without
    glibc (musl, macOS) nothing is changed."""
    global _RETAINED  # noqa: PLW0603  # one process-wide setting, made once
    if _RETAINED:
        return
    _RETAINED = True
    try:
        libc = ctypes.CDLL(None)
        mallopt = libc.mallopt
    except (OSError, AttributeError):
        return
    mallopt(_M_MMAP_THRESHOLD, 32 << 20)
    mallopt(_M_TRIM_THRESHOLD, 16 << 20)


def read_scratch(fd: int, pos: int, n: int) -> memoryview:
    """``n`` bytes at ``pos`` read into this thread's reusable buffer (valid until this thread's next call): for
    compressed chunks, which are decompressed and dropped at once. A fresh buffer per chunk costs a page fault per
    4 KiB when the allocator hands the memory back to the system between chunks (3x the system time, measured)."""
    buf: bytearray | None = getattr(_SCRATCH, "buf", None)
    if buf is None or len(buf) < n:
        buf = bytearray(max(n, 1 << 20))
        _SCRATCH.buf = buf
    view = memoryview(buf)[:n]
    got = os.preadv(fd, [view], pos)
    if got != n:
        raise SpanError("short read")
    return view


def gather(u8: U8Array, starts: IntArray, lengths: IntArray) -> U8Array:
    """Bytes ``u8[starts[i] : starts[i] + lengths[i]]`` for all i, packed in order (strided view when evenly spaced,
    a fancy index per row when of one length, else index arrays built in blocks of about 4 MiB of output)."""
    n = starts.shape[0]
    if n == 0:
        return np.zeros(0, dtype=np.uint8)
    d = int(lengths[0])
    if np.all(lengths == d):
        if n > 1:
            step = int(starts[1] - starts[0])
            if step >= d and np.all(np.diff(starts) == step):
                view = np.lib.stride_tricks.as_strided(u8[int(starts[0]) :], shape=(n, d), strides=(step, 1),
                                                       writeable=False)
                packed = np.empty((n, d), dtype=np.uint8)  # a copy even when contiguous: never a view of the chunk
                packed[...] = view
                return packed.ravel()
        rows: U8Array = u8[starts[:, None] + np.arange(d)]
        return rows.ravel()
    out_off = np.zeros(n + 1, dtype=np.int64)
    np.cumsum(lengths, out=out_off[1:])
    if (kept := _gather_in_order(u8, starts, lengths, int(out_off[-1]))) is not None:
        return kept
    out = np.empty(int(out_off[-1]), dtype=np.uint8)
    block = 1 << 22
    i = 0
    while i < n:
        j = max(i + 1, int(np.searchsorted(out_off, out_off[i] + block, side="right")) - 1)
        j = min(j, n)
        o0, o1 = int(out_off[i]), int(out_off[j])
        idx = np.arange(o0, o1, dtype=np.int64) + np.repeat(starts[i:j] - out_off[i:j], lengths[i:j])
        out[o0:o1] = u8[idx]
        i = j
    return out


def _gather_in_order(u8: U8Array, starts: IntArray, lengths: IntArray, total: int) -> U8Array | None:
    """``gather`` of non-empty pieces in increasing order that do not overlap and cover most of their span (records
    read back to back with little between them): a mask of the span's bytes to keep (one byte per byte of the span,
    where the index arrays of the general path take 24 per byte copied). None when the pieces are not so."""
    lo, hi = int(starts[0]), int(starts[-1] + lengths[-1])
    if lo < 0 or hi > u8.shape[0] or hi - lo > 4 * total or not bool(np.all(lengths > 0)) or \
            not bool(np.all(starts[1:] >= starts[:-1] + lengths[:-1])):
        return None
    edge = np.zeros(hi - lo + 1, dtype=np.int8)  # +1 where a piece starts, -1 where it ends (distinct positions)
    edge[starts - lo] += 1
    edge[starts + lengths - lo] -= 1
    keep = np.cumsum(edge[:-1], dtype=np.int8).view(bool)  # 1 inside a piece, 0 between pieces
    kept: U8Array = u8[lo:hi][keep]
    return kept
