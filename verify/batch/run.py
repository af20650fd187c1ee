"""Many logs -> one ``BatchItem`` each (discovery, the per-log job, ``certify_many``) and the ``BatchResult``."""

from __future__ import annotations

import re
import time
from collections.abc import Callable, Iterable, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING, Any, Literal

from runkit.executor import parallel_map
from tubempc.mitl import parse
from tubempc.scenario import Scenario
from verify.certificate import Certificate, Verdict
from verify.errors import VerifyError
from verify.ingest.digest import DEFAULT_DIGEST
from verify.selection import select_checks

if TYPE_CHECKING:  # verify.report imports matplotlib (the 'report' extra): only when reports are written
    from verify.report import CertifyResultLike

__all__ = ["EXIT_INTERNAL", "EXIT_UNUSABLE", "LOG_SUFFIXES", "BatchItem", "BatchResult", "certify_many",
           "discover_logs", "summary_lines", "worst_exit_code"]

LOG_SUFFIXES = (".bag", ".mcap", ".db3")
EXIT_UNUSABLE = 3
EXIT_INTERNAL = 70
_SEVERITY = {0: 0, 2: 1, 1: 2, 3: 3, 70: 4}
_VERDICT_OF_CODE = {0: "pass", 1: "fail", 2: "inconclusive", 3: "unusable", 70: "error"}

# the process server imports the certifier and builds its first-call caches once for all workers
_PRELOAD = ("verify.batch", "verify.batch.warm")


def worst_exit_code(codes: Iterable[int]) -> int:
    """The most severe code: 0 < 2 (inconclusive) < 1 (violation) < 3 (unusable) < 70 (internal); 0 if empty."""
    worst = 0
    for code in codes:
        if _SEVERITY.get(code, 5) > _SEVERITY.get(worst, 5):
            worst = code
    return worst


# ---- finding logs -------------------------------------------------------------------------------------------------
def _is_ros2_bag_dir(path: Path) -> bool:
    return (path / "metadata.yaml").is_file()


def _scan(folder: Path, seen: set[Path] | None = None) -> list[Path]:
    """Logs under ``folder``; a folder reached again (symlinks to itself or to an ancestor) is scanned once."""
    seen = set() if seen is None else seen
    try:
        key = folder.resolve()
    except (OSError, RuntimeError):  # a symlink loop that cannot be resolved
        return []
    if key in seen:
        return []
    seen.add(key)
    found: list[Path] = []
    for entry in sorted(folder.iterdir(), key=lambda p: p.name):
        if entry.is_dir():
            found.extend([entry] if _is_ros2_bag_dir(entry) else _scan(entry, seen))
        elif entry.is_file() and entry.suffix.lower() in LOG_SUFFIXES:
            found.append(entry)
    return found


def discover_logs(paths: Iterable[str | Path]) -> tuple[list[Path], list[tuple[str, str]]]:
    """Expand folders into logs; return (logs in a stable order without duplicates, [(path, problem), ...]).

    A folder holding ``metadata.yaml`` is one ROS2 bag; any other folder is scanned recursively for ``.bag``,
    ``.mcap``, ``.db3`` files and ROS2 bag folders. A missing path or a folder without logs is a problem, not an
    exception, so that the batch can report it as an unusable row.
    """
    logs: list[Path] = []
    problems: list[tuple[str, str]] = []
    seen: set[Path] = set()
    for raw in paths:
        path = Path(raw)
        if not path.exists():
            problems.append((str(path), "file not found"))
            continue
        if path.is_dir() and not _is_ros2_bag_dir(path):
            found = _scan(path)
            if not found:
                problems.append((str(path), "folder holds no .bag, .mcap or .db3 log and no ROS2 bag folder"))
        else:
            found = [path]
        for log in found:
            key = log.resolve()
            if key not in seen:
                seen.add(key)
                logs.append(log)
    return logs, problems


# ---- results ------------------------------------------------------------------------------------------------------
@dataclass(frozen=True, slots=True)
class BatchItem:
    """One log's outcome. ``result`` is the ``CertifyResult`` (None when the log was unusable or crashed)."""

    path: str
    name: str
    exit_code: int
    verdict: Literal["pass", "fail", "inconclusive", "unusable", "error"]
    error: str | None
    elapsed_s: float
    result: CertifyResultLike | None

    @property
    def typed(self) -> Certificate | None:
        """The certificate as the typed model (None for a log that was unusable or crashed)."""
        return None if self.result is None else Certificate.model_validate(self.result.certificate)

    def __post_init__(self) -> None:
        if self.exit_code not in _VERDICT_OF_CODE:
            raise ValueError(f"exit_code={self.exit_code!r} is not one of {sorted(_VERDICT_OF_CODE)}")
        if (self.result is None) != (self.exit_code in (EXIT_UNUSABLE, EXIT_INTERNAL)):
            raise ValueError(f"{self.path}: a result is required exactly when the log was certified")


@dataclass(frozen=True, slots=True)
class BatchResult:
    """All logs of a batch in input order; ``exit_code`` is the worst code (see the module docstring)."""

    items: tuple[BatchItem, ...]
    scenario: Scenario
    spec: str | None

    @property
    def exit_code(self) -> int:
        return worst_exit_code(item.exit_code for item in self.items)

    def counts(self) -> dict[str, int]:
        out = dict.fromkeys(("pass", "fail", "inconclusive", "unusable", "error"), 0)
        for item in self.items:
            out[item.verdict] += 1
        return out

    def rows(self) -> list[dict[str, Any]]:
        """One summary row per log (the content of ``summary.csv``)."""
        rows = []
        for item in self.items:
            cert = item.typed
            checks = cert.checks if cert is not None else []
            failed = [c.name for c in checks if c.verdict == Verdict.FAIL]
            unknown = [c.name for c in checks if c.verdict not in (Verdict.PASS, Verdict.FAIL)]
            # a failed log's worst margin is its most negative failed check's, never a passing check's;
            # metres only: seconds and m/s do not compare
            judged = [c for c in checks if c.verdict == Verdict.FAIL] or checks
            margins = [c.margin for c in judged if c.margin is not None and c.margin_unit == "m"]
            first = [c.first_violation_time for c in checks
                     if c.verdict == Verdict.FAIL and c.first_violation_time is not None]
            rows.append({
                "log": item.path, "folder": item.name, "verdict": item.verdict, "exit_code": item.exit_code,
                "checks": len(checks), "failed_checks": " ".join(failed), "inconclusive_checks": " ".join(unknown),
                "worst_margin_m": min(margins) if margins else None,
                "first_violation_s": min(first) if first else None,
                "error": item.error or "", "elapsed_s": round(item.elapsed_s, 3),
            })
        return rows


# ---- the per-log job (module level: picklable for processes and Dask) -----------------------------------------------
@dataclass(frozen=True, slots=True)
class _Job:
    path: str
    name: str
    scenario: Scenario
    spec: str | None
    time_base: str
    salvage: bool
    checks: tuple[str, ...] | None = None
    digest: str = DEFAULT_DIGEST
    clock_offsets: tuple[tuple[str, float], ...] = ()


def _certify_function() -> Callable[..., CertifyResultLike]:
    from verify import certify_log  # type: ignore[attr-defined,unused-ignore]

    fn: Callable[..., CertifyResultLike] = certify_log
    return fn


def _certify_one(job: _Job) -> BatchItem:
    start = time.perf_counter()
    try:
        result = _certify_function()(job.path, job.scenario, spec=job.spec, time_base=job.time_base,
                                     salvage=job.salvage, checks=job.checks, digest=job.digest,
                                     clock_offsets=dict(job.clock_offsets) or None)
    except VerifyError as err:
        return BatchItem(job.path, job.name, EXIT_UNUSABLE, "unusable", str(err), time.perf_counter() - start, None)
    except Exception as err:  # a bug in one log's certification must not take the other logs down
        message = f"internal error: {err.__class__.__name__}: {err}"
        return BatchItem(job.path, job.name, EXIT_INTERNAL, "error", message, time.perf_counter() - start, None)
    code = int(result.exit_code)
    verdict = _VERDICT_OF_CODE.get(code, "error")
    if code not in (0, 1, 2):
        message = f"internal error: certifier returned exit code {code} with a result"
        return BatchItem(job.path, job.name, EXIT_INTERNAL, "error", message, time.perf_counter() - start, None)
    return BatchItem(job.path, job.name, code, verdict,  # type: ignore[arg-type]
                     None, time.perf_counter() - start, result)


def _worker_died(job: _Job) -> BatchItem:
    return BatchItem(job.path, job.name, EXIT_INTERNAL, "error",
                     "internal error: the certifier's worker process died twice on this log, alone (a crash or an "
                     "out-of-memory kill in native code)", 0.0, None)


# ---- the batch ----------------------------------------------------------------------------------------------------
def _folder_names(paths: Sequence[str]) -> list[str]:
    names: list[str] = []
    used: set[str] = set()
    for path in paths:
        base = re.sub(r"[^A-Za-z0-9._-]+", "_", Path(path).name).strip("._") or "log"
        name, k = base, 2
        while name in used:
            name, k = f"{base}-{k}", k + 1
        used.add(name)
        names.append(name)
    return names


def certify_many(paths: Iterable[str | Path], scenario: Scenario, *, spec: str | None = None,
                 time_base: Literal["auto", "header", "log"] = "auto", salvage: bool = False,
                 workers: int | None = None, dask: str | None = None, progress: bool | None = None,
                 checks: Sequence[str] | None = None, digest: str = DEFAULT_DIGEST,
                 clock_offsets: dict[str, float] | None = None) -> BatchResult:
    """Certify every log in ``paths`` (files, ROS2 bag folders, or folders to scan) with ``verify.certify_log``.

    Same arguments as ``certify_log`` plus the executor's (see ``parallel_map``). Returns the items in input
    order; unusable logs (and missing paths, empty folders) are items with exit code 3, never exceptions.
    Raises ``SpecSyntaxError`` for a malformed ``spec`` (it concerns every log) and ``UnusableInputError`` for
    an unreachable Dask scheduler.
    """
    if spec is not None:
        parse(spec)
    if time_base not in ("auto", "header", "log"):
        raise ValueError(f"time_base={time_base!r} must be 'auto', 'header' or 'log'")
    raw = list(paths)
    logs, problems = discover_logs(raw)
    ordered = [str(p) for p in logs] + [p for p, _ in problems]
    names = dict(zip(ordered, _folder_names(ordered), strict=True))
    if checks is not None:
        select_checks(scenario, checks)  # unknown or unsupported checks concern every log: raise before the jobs
    chosen = tuple(checks) if checks is not None else None
    offsets = tuple(sorted((clock_offsets or {}).items()))
    jobs = [_Job(str(p), names[str(p)], scenario, spec, time_base, salvage, chosen, digest, offsets) for p in logs]
    done = parallel_map(_certify_one, jobs, workers=workers, dask=dask, progress=progress, desc="certify",
                        preload=_PRELOAD, on_crash=_worker_died)
    bad = [BatchItem(p, names[p], EXIT_UNUSABLE, "unusable", f"{p}: {why}", 0.0, None) for p, why in problems]
    return BatchResult(tuple(done) + tuple(bad), scenario, spec)


def summary_lines(batch: BatchResult) -> list[str]:
    """One line per log for a terminal: ``path: verdict (failed checks with first violation times)``; an unusable
    log is ``path: unusable``: its error is printed once, as the ``tubempc: error:`` line on stderr."""
    from verify.certify import verdict_line

    lines = []
    for item in batch.items:
        if item.result is None:
            lines.append(f"{item.path}: {item.verdict}")
            continue
        lines.append(verdict_line(item.path, item.result.certificate))
    counts = ", ".join(f"{n} {k}" for k, n in batch.counts().items() if n)
    lines.append(f"{len(batch.items)} log(s): {counts}; exit code {batch.exit_code}")
    return lines
