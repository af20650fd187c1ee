"""Library errors met while reading a damaged log -> one line in words (the library's message is detail).

input: an exception raised by rosbags, sqlite3/apsw, the decompressors or our own readers on bad bytes -> output:
the problem in words (``in_words``), and ``READ_ERRORS``, the exception classes the read boundary
(``verify.ingest.log.read_log``) turns into ``LogReadError`` (exit 3) instead of an internal error (exit 70).
"""

from __future__ import annotations

import sqlite3
import struct
import zlib
from collections.abc import Callable, Iterable
from typing import Any

import apsw  # rosbags' sqlite3 driver
from rosbags.rosbag1 import ReaderError as ReaderError1
from rosbags.rosbag2 import ReaderError as ReaderError2
from rosbags.serde import SerdeError

from verify.errors import LogReadError
from verify.ingest.mcaprecords import zstd

__all__ = [
    "DECOMPRESS_ERRORS", "DESERIALIZE_ERRORS", "READ_ERRORS", "LibraryError", "deserialize", "in_words",
    "one_type_per_topic"]

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
#: (exit 70); raised by a library on bad bytes it arrives as ``LibraryError``.
READ_ERRORS: tuple[type[BaseException], ...] = (
    ReaderError1, ReaderError2, SerdeError, LibraryError, OverflowError, UnicodeDecodeError, ValueError,
    struct.error, EOFError, sqlite3.Error, apsw.Error, MemoryError, RecursionError, NotImplementedError,
    *DECOMPRESS_ERRORS)

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
    elif isinstance(err, ReaderError1 | ReaderError2) and "YAML" in str(err):
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
