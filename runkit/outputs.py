"""Output paths of every command: ``--out`` -> a ready folder (or log path), or one clear exit-3 error.

The policy, one for all commands (certify, regress, demo write a folder; simulate writes a log):
- nothing that exists is overwritten unless ``--force`` is given: a report folder must be new or empty, a log
  path must not exist (exit 3, one line, "exists already");
- with ``--force`` an existing output of the right kind is replaced: a report folder keeps its other files and gets
  its own files (``certificate.json``, ``report.*``, ``junit.xml``, per-log sub-folders) rewritten; an existing log
  file (``.bag``, ``.mcap``, ``.db3``) or ROS2 bag folder (it holds ``metadata.yaml``) is replaced once the new log
  is ready;
- an output of the wrong kind is always refused (``OutputError``, exit 3): a file (or ``/dev/null``, a
  device) where a folder is needed, a folder that is not a bag where a log is needed, a path below a file, an
  unwritable or read-only place, and a report folder that is (or is inside) a log being certified (inputs are never
  modified);
- a path that cannot be made at all (a symlink loop, a name longer than the file system allows, a path over
  PATH_MAX) is exit 3 naming ``--out``;
- every file a command writes into its output folder goes through ``write_output_file``: it never follows a symlink
  (nor writes into a sub-folder that is a symlink), never replaces an entry that is not a regular file (a symlink,
  a folder, a FIFO: not the command's own output), and replaces a regular file by renaming a new file over it, so
  a hard link to an input keeps the input's bytes.
"""

from __future__ import annotations

import errno
import os
import shutil
import stat
import tempfile
from collections.abc import Iterable
from pathlib import Path

from runkit.errors import OutputError

__all__ = ["LOG_SUFFIXES", "output_subdir", "prepare_output_dir", "prepare_output_log", "replace_output_log",
           "write_output_file"]

LOG_SUFFIXES = (".bag", ".mcap", ".db3")


def _os_words(err: OSError) -> str:
    if err.errno in (errno.EROFS,):
        return "the file system is read-only"
    if err.errno in (errno.EACCES, errno.EPERM):
        return "permission denied"
    if err.errno == errno.ENOTDIR:
        return "a part of the path is a file, not a folder"
    if err.errno == errno.ENOSPC:
        return "no space left on the device"
    if err.errno == errno.ENOENT:
        return "a part of the path does not exist and cannot be created"
    if err.errno == errno.ELOOP:
        return "too many levels of symbolic links (a symlink loop)"
    if err.errno == errno.ENAMETOOLONG:
        return "the name or the path is longer than the file system allows"
    return err.strerror or err.__class__.__name__


def _below_a_file(path: Path) -> Path | None:
    for parent in path.absolute().parents:
        if parent.exists():
            return None if parent.is_dir() else parent
    return None


def prepare_output_dir(path: str | Path, *, force: bool = False, inputs: Iterable[str | Path] = ()) -> Path:
    """Create (or, with ``force``, reuse) the report folder ``path``; refuse what the policy above refuses."""
    try:
        return _prepare_output_dir(Path(path), force=force, inputs=inputs)
    except (OSError, RuntimeError) as err:  # RuntimeError: pathlib's resolve() on a symlink loop
        words = _os_words(err) if isinstance(err, OSError) else "too many levels of symbolic links (a symlink loop)"
        raise OutputError(f"--out cannot be made: {words}", path=str(path)) from None


def _prepare_output_dir(out: Path, *, force: bool, inputs: Iterable[str | Path]) -> Path:
    if out.exists() and not out.is_dir():
        raise OutputError("--out exists and is not a folder (reports need a folder)", path=str(out))
    if out.is_dir() and not force and any(out.iterdir()):
        raise OutputError("--out exists already and is not empty: pass --force to replace its reports",
                                 path=str(out))
    blocker = _below_a_file(out)
    if blocker is not None:
        raise OutputError(f"--out lies below {blocker}, which is a file, not a folder", path=str(out))
    resolved = out.resolve()
    for item in inputs:
        log = Path(item).resolve()
        if log.is_dir() and (resolved == log or log in resolved.parents):
            raise OutputError(f"--out is inside the log {item} being certified (inputs are never modified)",
                                     path=str(out))
    try:
        out.mkdir(parents=True, exist_ok=True)
    except OSError as err:
        raise OutputError(f"cannot create the output folder: {_os_words(err)}", path=str(out)) from None
    if not os.access(out, os.W_OK | os.X_OK):
        raise OutputError("the output folder is not writable: permission denied", path=str(out))
    return out


def prepare_output_log(path: str | Path, *, force: bool = False) -> Path:
    """Check a log output path before the work starts (nothing is removed here)."""
    try:
        return _prepare_output_log(Path(path), force=force)
    except (OSError, RuntimeError) as err:
        words = _os_words(err) if isinstance(err, OSError) else "too many levels of symbolic links (a symlink loop)"
        raise OutputError(f"--out cannot be made: {words}", path=str(path)) from None


def _prepare_output_log(out: Path, *, force: bool) -> Path:
    if out.exists() and not force:
        raise OutputError("--out exists already: pass --force to replace it", path=str(out))
    if out.exists():
        if out.is_dir():
            if not (out / "metadata.yaml").is_file():
                raise OutputError("--out is a folder that is not a ROS2 bag (no metadata.yaml): not replaced",
                                         path=str(out))
        elif not out.is_file() or out.suffix.lower() not in LOG_SUFFIXES:
            raise OutputError(f"--out exists and is not a log file ({', '.join(LOG_SUFFIXES)}): not "
                                     f"replaced", path=str(out))
    blocker = _below_a_file(out)
    if blocker is not None:
        raise OutputError(f"--out lies below {blocker}, which is a file, not a folder", path=str(out))
    parent = out.absolute().parent
    if not parent.is_dir():
        raise OutputError(f"the folder {parent} does not exist", path=str(out))
    if not os.access(parent, os.W_OK | os.X_OK):
        raise OutputError(f"cannot write into {parent}: permission denied", path=str(out))
    return out


def replace_output_log(path: str | Path) -> Path:
    """Remove an existing log at ``path`` (after ``prepare_output_log`` accepted it), so the new one takes its place."""
    out = prepare_output_log(path, force=True)
    try:
        if out.is_dir():
            shutil.rmtree(out)
        elif out.exists():
            out.unlink()
    except OSError as err:
        raise OutputError(f"cannot replace the existing log: {_os_words(err)}", path=str(out)) from None
    return out


def _not_own(entry: Path) -> str | None:
    """Why an existing entry is not one the command may replace (None: absent or a regular file)."""
    try:
        mode = os.lstat(entry).st_mode
    except FileNotFoundError:
        return None
    if stat.S_ISREG(mode):
        return None
    return ("a symbolic link" if stat.S_ISLNK(mode) else "a folder" if stat.S_ISDIR(mode)
            else "a FIFO (named pipe)" if stat.S_ISFIFO(mode) else "not a regular file")


def output_subdir(folder: Path, name: str) -> Path:
    """``folder/name`` as a real folder (created); a symlink or a file there is refused, never followed."""
    sub = folder / name
    try:
        mode = os.lstat(sub).st_mode
    except FileNotFoundError:
        try:
            sub.mkdir()
        except OSError as err:
            raise OutputError(f"cannot create {name}/ in the output folder: {_os_words(err)}",
                                     path=str(sub)) from None
        return sub
    if not stat.S_ISDIR(mode):
        what = "a symbolic link" if stat.S_ISLNK(mode) else "not a folder"
        raise OutputError(f"{name} in the output folder is {what}: not written through", path=str(sub))
    return sub


def write_output_file(path: str | Path, data: bytes | str) -> Path:
    """Write one output file (see the module doc): a new file renamed over ``path``; a symlink, folder or special
    file at ``path`` is refused (exit 3), never followed or replaced."""
    target = Path(path)
    why = _not_own(target)
    if why is not None:
        raise OutputError(f"{target.name} in the output folder is {why}, not a file this command wrote: "
                                 "not replaced", path=str(target))
    raw = data.encode("utf-8") if isinstance(data, str) else data
    try:
        fd, tmp = tempfile.mkstemp(prefix=f".{target.name}.", dir=target.parent)
    except OSError as err:
        raise OutputError(f"cannot write {target.name}: {_os_words(err)}", path=str(target)) from None
    try:
        with os.fdopen(fd, "wb") as fh:
            fh.write(raw)
        os.chmod(tmp, 0o644)  # mkstemp makes 0o600; a report is for reading
        os.replace(tmp, target)
    except OSError as err:
        Path(tmp).unlink(missing_ok=True)
        raise OutputError(f"cannot write {target.name}: {_os_words(err)}", path=str(target)) from None
    return target

