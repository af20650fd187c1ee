"""Library errors met while reading a damaged log -> one line in words (the library's message is detail).

input: an exception raised by rosbags, sqlite3/apsw, the decompressors or our own readers on bad bytes -> output:
the problem in words (``in_words``), and ``read_errors()``, the exception classes the read boundary
(``verify.ingest.log.read_log``) turns into ``LogReadError`` (exit 3) instead of an internal error (exit 70).

``rosbags.rosbag2`` (and the YAML library it loads) is imported only for the logs that need it (ROS2 bags, MCAP,
sqlite3): its ``ReaderError`` joins ``read_errors()`` once that package is loaded, since nothing else raises it.
``READ_ERRORS``, the full tuple, imports it when first named.
"""

from __future__ import annotations

import sqlite3
import struct
import sys
import zlib
from collections.abc import Callable, Iterable, Mapping
from typing import Any, TypeGuard

import apsw  # rosbags' sqlite3 driver
from rosbags.rosbag1 import ReaderError as ReaderError1
from rosbags.serde import SerdeError

from verify.errors import LogReadError, TruncatedLogError
from verify.ingest.mcaprecords import zstd

__all__ = [
    "DECOMPRESS_ERRORS", "DESERIALIZE_ERRORS", "LibraryError", "check_declared_counts", "deserialize", "in_words",
    "one_type_per_topic", "read_errors", "rosbag2_errors"]

#: what the decompressors raise on a damaged chunk: zlib/bz2 (zlib.error, OSError), lz4 (RuntimeError), zstd
DECOMPRESS_ERRORS: tuple[type[Exception], ...] = (zlib.error, OSError, RuntimeError, zstd.ZstdError)

#: what rosbags' deserializers raise on bytes that are not a message of their type (an index or count past the
#: payload, a length field that asks for too much, text that is not UTF-8): caught only around the library's call
#: (``deserialize``), never around our own code
DESERIALIZE_ERRORS: tuple[type[Exception], ...] = (
    SerdeError, struct.error, IndexError, KeyError, ValueError, UnicodeDecodeError, AssertionError, TypeError,
    AttributeError, MemoryError, OverflowError, RecursionError, NotImplementedError)


class LibraryError(Exception):
    """A library's error on damaged input, caught where the library is called; ``original`` is that error (its
    type decides the words: ``in_words``)."""

    def __init__(self, original: BaseException) -> None:
        self.original = original
        super().__init__(str(original))


def deserialize(deser: Callable[[Any, str], Any], payload: Any, msgtype: str) -> Any:
    """``deser(payload, msgtype)`` (a rosbags typestore's ``deserialize_cdr`` / ``deserialize_ros1``) with its
    errors on damaged bytes raised as ``LibraryError``."""
    try:
        return deser(payload, msgtype)
    except DESERIALIZE_ERRORS as err:
        raise LibraryError(err) from err


#: what the read boundary (``read_log``, ``log_digest``) turns into exit 3: the readers' own errors on damaged
#: bytes, and library errors translated where the library is called (``LibraryError``). A ``TypeError``,
#: ``AttributeError``, ``KeyError``, ``IndexError`` or ``AssertionError`` is not here: raised by our code it is a bug
#: (exit 70); raised by a library on bad bytes it arrives as ``LibraryError``. Without rosbags.rosbag2's
#: ``ReaderError``: ``read_errors()`` adds it once that package is loaded.
_BASE_READ_ERRORS: tuple[type[BaseException], ...] = (
    ReaderError1, SerdeError, LibraryError, OverflowError, UnicodeDecodeError, ValueError,
    struct.error, EOFError, sqlite3.Error, apsw.Error, MemoryError, RecursionError, NotImplementedError,
    *DECOMPRESS_ERRORS)


def rosbag2_errors() -> tuple[type[Exception], ...]:
    """rosbags.rosbag2's ``ReaderError`` when that package is loaded, else nothing (only it raises that error, so
    a log read without it cannot meet one)."""
    errors = sys.modules.get("rosbags.rosbag2.errors")
    return () if errors is None else (errors.ReaderError,)


def read_errors() -> tuple[type[BaseException], ...]:
    """The exception classes the read boundary turns into exit 3 (see ``_BASE_READ_ERRORS``), with rosbags.rosbag2's
    ``ReaderError`` once that package is loaded: ``except read_errors()`` is evaluated when an error is met."""
    return (*_BASE_READ_ERRORS, *rosbag2_errors())


def __getattr__(name: str) -> tuple[type[BaseException], ...]:
    """``READ_ERRORS``: the full tuple, rosbags.rosbag2's ``ReaderError`` included (importing that package)."""
    if name == "READ_ERRORS":
        import rosbags.rosbag2  # noqa: F401  # its ReaderError belongs in the tuple

        return read_errors()
    raise AttributeError(f"module {__name__!r} has no attribute {name!r}")


_DETAIL_CHARS = 160


def _detail(err: BaseException) -> str:
    text = " ".join(str(err).split()) or "no message"
    if len(text) > _DETAIL_CHARS:
        text = text[: _DETAIL_CHARS - 3] + "..."
    return f"{err.__class__.__name__}: {text}"


def in_words(err: BaseException) -> str:
    """What is wrong with the file, in words, with the library's message as detail in parentheses."""
    if isinstance(err, LibraryError):
        err = err.original
    name = err.__class__.__name__
    if isinstance(err, NotImplementedError):
        words = "it uses a feature this reader does not support"
    elif isinstance(err, AssertionError):
        words = "its index disagrees with its data (an internal consistency check of the file failed)"
    elif isinstance(err, SerdeError) or "Serde" in name:
        words = "a message cannot be decoded"
    elif isinstance(err, UnicodeDecodeError):
        words = "text that must be UTF-8 is not"
    elif isinstance(err, OverflowError):
        words = "a size, offset or time field is out of range"
    elif isinstance(err, KeyError | IndexError):
        words = "a record refers to a connection, schema or chunk that does not exist"
    elif isinstance(err, MemoryError):
        words = "a size field asks for more memory than is available"
    elif isinstance(err, RecursionError):
        words = "its structure is nested too deeply"
    elif isinstance(err, sqlite3.Error | apsw.Error):
        words = "the sqlite3 database is damaged or not a rosbag2 database"
    elif isinstance(err, zlib.error | RuntimeError | zstd.ZstdError) or "decompress" in str(err).lower():
        words = "a compressed chunk cannot be decompressed"
    elif isinstance(err, struct.error | EOFError):
        words = "it ends in the middle of a record (truncated)"
    elif isinstance(err, OSError):
        words = "it cannot be read from disk"
    elif isinstance(err, (ReaderError1, *rosbag2_errors())) and "YAML" in str(err):
        words = "its metadata.yaml is not valid YAML"
    else:
        words = "its records are malformed"
    return f"{words} ({_detail(err)})"


def one_type_per_topic(pairs: Iterable[tuple[str, str]], path: str | None = None) -> None:
    """One topic, one type: a topic carried by connections (or messages) of two message types is refused naming
    both (each reader calls this on the topics it reads, so the fast and the plain paths agree)."""
    seen: dict[str, str] = {}
    for topic, msgtype in pairs:
        first = seen.setdefault(topic, msgtype)
        if first != msgtype:
            raise LogReadError(f"topic {topic} is carried by connections of two message types, {first} and "
                               f"{msgtype}: one topic must have one type (the messages of one would be decoded as "
                               f"the other)", path=path)


def check_declared_counts(declared: Mapping[str, int], read: Mapping[str, int], want: Iterable[str], path: str, *,
                          fmt: str) -> None:
    """Each wanted topic holds the messages the log declares (MCAP Statistics summed over a folder's files, or a bag
    folder's metadata.yaml where that says more; the ROS1 index; per topic): fewer read is damage (a damaged index or
    chunk can make a reader stop early without an error, silently dropping samples), ``TruncatedLogError`` naming
    the topic. The rule of every reading: certify's readers and ``watch``'s followers."""
    for topic in sorted(want):
        want_n, got_n = declared.get(topic, 0), read.get(topic, 0)
        if want_n > got_n:
            raise TruncatedLogError(f"damaged {fmt} log: it declares {want_n} messages on {topic} but only {got_n} "
                                    f"can be read", path=path)


def sqlite_row_readable(stamp: object, payload: object) -> TypeGuard[int]:
    """Whether a sqlite3 message row's columns are what every reader of it needs: an integer log time that is not
    negative (nanoseconds since 1970; a damaged page can hold a row whose columns read as NULL -- NOT NULL is checked
    on writes only -- or a timestamp turned negative, 236 years before the others, which no time span of the run can
    hold) and a payload. The one rule of certify's readers and of watch's follower."""
    return isinstance(stamp, int) and stamp >= 0 and isinstance(payload, bytes | memoryview)


def unreadable_row(fmt: str, topic: str, path: str) -> LogReadError:
    """The error for a message row that ``sqlite_row_readable`` refuses."""
    return LogReadError(f"damaged {fmt} log: a message row on {topic} has no log time (NULL or negative) or no "
                        f"payload (a damaged database page)", path=path)
