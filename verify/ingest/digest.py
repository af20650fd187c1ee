"""A log's identity: a path or the messages read from it -> a named digest.

input: a log path (a file, or a ROS2 bag directory) and a digest name, or the raw messages read (``RawLog``) ->
output: a ``LogDigest`` (algorithm, hex). The certificate names the algorithm beside the digest.

``blake3-messages`` (default): BLAKE3 over the messages the certificate was computed from: for each topic read (by
name), its name, type, message count, log times, payload lengths and payload bytes (``messages_digest``; the exact
byte layout is below). It hashes what was read and nothing else, so it adds no read of the file: on a lab recording
(cameras, lidars) the judged topics are a few percent of the bytes, and hashing the whole file would cost more than
reading the judged messages (measured in ``benchmarks/bench_bigbag.py``). It is independent of the container: the
same messages in a ROS2 bag stored as MCAP or sqlite3, compressed or not, have the same digest (a ROS1 bag's
payloads are serialized differently, so its digest differs). It identifies the data behind the verdict, not the file:
bytes of topics that were not read (a camera frame) can change without changing it, as they cannot change the
verdict. ``tubempc digest LOG --scenario S`` recomputes it.

``blake3`` / ``sha256``: the whole file's bytes, what ``b3sum FILE`` / ``sha256sum FILE`` print, for archives that
must bind the certificate to the exact file. BLAKE3 (a 256-bit cryptographic hash whose tree mode hashes on every
core) is read through read-only memory maps of 16 MiB; SHA-256 in 8 MiB blocks into one reused buffer. A bag
directory is digested as every file's relative name, a NUL byte and its bytes, in name order. ``start_digest``
runs a file digest in a daemon thread beside the reader (both hashers release the GIL on large buffers): the wall
time is about the longer of the two, not their sum, but the whole file is read once more. An error reading the file
is re-raised by ``result()``. (A file truncated by another program while it is being mapped ends the process with
SIGBUS, as for any reader that maps files; certify finished recordings.)

``messages_digest`` byte layout, all integers little-endian: ``b"tubempc-messages-v1\0"``; then per topic in
name order: the topic name, ``\0``, the message type, ``\0``, the count (u64), the log times (i64 each), the
payload lengths (u64 each), the payloads concatenated in reading order (rosbags' order).
"""

from __future__ import annotations

import hashlib
import mmap
import os
import struct
import threading
from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING, Protocol

import blake3
import numpy as np

from verify.ingest.ros1 import PayloadBuffer

if TYPE_CHECKING:
    from verify.ingest.raw import RawLog

__all__ = ["DEFAULT_DIGEST", "DIGESTS", "FILE_DIGESTS", "MESSAGES_DIGEST", "DigestJob", "LogDigest", "digest_path",
           "messages_digest", "start_digest"]

MESSAGES_DIGEST = "blake3-messages"
FILE_DIGESTS = ("blake3", "sha256")
DIGESTS = (MESSAGES_DIGEST, *FILE_DIGESTS)
DEFAULT_DIGEST = MESSAGES_DIGEST
_BLOCK_B = 8 << 20
_WINDOW_B = 16 << 20  # a multiple of mmap.ALLOCATIONGRANULARITY


class _Hasher(Protocol):
    def update(self, data: memoryview, /) -> object: ...

    def hexdigest(self) -> str: ...


@dataclass(frozen=True, slots=True)
class LogDigest:
    """The digest of a log's bytes: ``algorithm`` (one of ``DIGESTS``) and the lowercase hex value."""

    algorithm: str
    hex: str


def messages_digest(raw: RawLog) -> LogDigest:
    """The ``blake3-messages`` digest of the messages read (layout: the module docstring)."""
    h = blake3.blake3(b"tubempc-messages-v1\0")
    for name in sorted(raw.topics):
        topic = raw.topics[name]
        times = np.asarray(topic.log_ns, dtype="<i8")
        h.update(name.encode() + b"\0" + topic.msgtype.encode() + b"\0" + struct.pack("<Q", times.shape[0]))
        h.update(np.ascontiguousarray(times).view(np.uint8).data)
        payloads = topic.payloads
        if isinstance(payloads, PayloadBuffer):  # packed in order: payload i at the running sum of the lengths
            lengths = np.asarray(payloads.lengths, dtype="<u8")
            h.update(np.ascontiguousarray(lengths).view(np.uint8).data)
            h.update(np.ascontiguousarray(payloads.data[: int(lengths.sum())], dtype=np.uint8).data)
        else:
            h.update(np.fromiter(map(len, payloads), dtype="<u8", count=len(payloads)).view(np.uint8).data)
            for payload in payloads:
                h.update(payload)
    return LogDigest(MESSAGES_DIGEST, h.hexdigest())


def _hasher(algorithm: str) -> _Hasher:
    if algorithm == MESSAGES_DIGEST:
        raise ValueError(f"digest={algorithm!r} is computed from the messages read, not from the file")
    if algorithm == "blake3":
        return blake3.blake3(max_threads=blake3.blake3.AUTO)
    if algorithm == "sha256":
        return hashlib.sha256()
    raise ValueError(f"digest={algorithm!r}: expected one of {', '.join(DIGESTS)}")


def digest_path(path: str | Path, algorithm: str = "blake3", *, stop: threading.Event | None = None
                ) -> LogDigest | None:
    """The digest of the file (or bag directory) at ``path``, computed here; None when ``stop`` is set first."""
    p = Path(path)
    h = _hasher(algorithm)
    files = sorted(f for f in p.rglob("*") if f.is_file()) if p.is_dir() else [p]
    buf = bytearray(0 if isinstance(h, blake3.blake3) else _BLOCK_B)
    view = memoryview(buf)
    for f in files:
        if p.is_dir():
            h.update(memoryview(str(f.relative_to(p)).encode() + b"\0"))
        if isinstance(h, blake3.blake3):
            if not _hash_mapped(h, f, stop):
                return None
            continue
        with f.open("rb", buffering=0) as fh:
            while n := fh.readinto(buf):
                if stop is not None and stop.is_set():
                    return None
                h.update(view[:n])
    return LogDigest(algorithm, h.hexdigest())


def _hash_mapped(h: blake3.blake3, path: Path, stop: threading.Event | None) -> bool:
    """Feed ``path`` to ``h`` through read-only memory maps of ``_WINDOW_B`` bytes, one at a time (no copy of the
    bytes: a third less CPU than reading them into a buffer; one window resident at a time, so the process's RSS
    does not grow with the file). False when ``stop`` is set first."""
    with path.open("rb") as fh:
        size = os.fstat(fh.fileno()).st_size
        pos = 0
        while pos < size:
            if stop is not None and stop.is_set():
                return False
            n = min(_WINDOW_B, size - pos)
            with mmap.mmap(fh.fileno(), n, access=mmap.ACCESS_READ, offset=pos) as window:
                h.update(window)
            pos += n
    return True


class DigestJob:
    """A digest being computed in a daemon thread; ``result()`` waits for it (and re-raises its error),
    ``cancel()`` stops it at the next block (when the log turned out unusable)."""

    def __init__(self, path: Path, algorithm: str) -> None:
        _hasher(algorithm)  # an unknown name fails here, in the caller's thread
        self._path = path
        self._algorithm = algorithm
        self._out: LogDigest | None = None
        self._err: BaseException | None = None
        self._stop = threading.Event()
        self._thread = threading.Thread(target=self._run, name=f"digest {path.name}", daemon=True)
        self._thread.start()

    def _run(self) -> None:
        try:
            self._out = digest_path(self._path, self._algorithm, stop=self._stop)
        except BaseException as err:  # re-raised in the caller's thread by result()
            self._err = err

    def cancel(self) -> None:
        self._stop.set()

    def result(self) -> LogDigest:
        self._thread.join()
        if self._err is not None:
            raise self._err
        if self._out is None:
            raise RuntimeError(f"digest of {self._path} was cancelled")
        return self._out


def start_digest(path: str | Path, algorithm: str = "blake3") -> DigestJob:
    """Start digesting ``path`` in a background thread (see the module docstring)."""
    return DigestJob(Path(path), algorithm)
