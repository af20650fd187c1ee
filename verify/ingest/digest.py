"""A log's identity: a path -> the content digest of its bytes, computed in a thread while the log is read.

input: a log path (a file, or a ROS2 bag directory) and a digest name -> output: a ``LogDigest`` (algorithm, hex).

The certificate names the algorithm beside the digest. ``blake3`` (default): BLAKE3, a 256-bit cryptographic hash
whose tree mode hashes on every core (4-8 GB/s here, against 1.7 GB/s for SHA-256 with the CPU's SHA extensions);
for a single file it is what ``b3sum FILE`` prints. ``sha256``: SHA-256, what ``sha256sum FILE`` prints. A bag
directory is digested as every file's relative name, a NUL byte and its bytes, in name order.

``start_digest`` starts the digest in a daemon thread and returns at once; ``LogDigest`` comes from ``result()``.
Both hashers release the GIL on large buffers, so the digest runs beside the reader (on another core when there is
one) instead of before it: the wall time is about the longer of the two, not their sum. BLAKE3 hashes the file
through read-only memory maps of 16 MiB, one at a time (the page cache's pages, nothing copied); SHA-256 reads it in
8 MiB blocks into one reused buffer: the memory used is bounded either way. An error reading the file is re-raised
by ``result()``. (A file truncated by another program while it is being mapped ends the process with SIGBUS, as
for any reader that maps files; certify finished recordings.)
"""

from __future__ import annotations

import hashlib
import mmap
import os
import threading
from dataclasses import dataclass
from pathlib import Path
from typing import Protocol

import blake3

__all__ = ["DEFAULT_DIGEST", "DIGESTS", "DigestJob", "LogDigest", "digest_path", "start_digest"]

DIGESTS = ("blake3", "sha256")
DEFAULT_DIGEST = "blake3"
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


def _hasher(algorithm: str) -> _Hasher:
    if algorithm == "blake3":
        return blake3.blake3(max_threads=blake3.blake3.AUTO)
    if algorithm == "sha256":
        return hashlib.sha256()
    raise ValueError(f"digest={algorithm!r}: expected one of {', '.join(DIGESTS)}")


def digest_path(path: str | Path, algorithm: str = DEFAULT_DIGEST, *, stop: threading.Event | None = None
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


def start_digest(path: str | Path, algorithm: str = DEFAULT_DIGEST) -> DigestJob:
    """Start digesting ``path`` in a background thread (see the module docstring)."""
    return DigestJob(Path(path), algorithm)
