"""Many logs -> one certificate each, in parallel (processes or Dask), plus a summary table.

input: log paths and/or folders (scanned for ``.bag``, ``.mcap``, ``.db3`` files and ROS2 bag folders), a scenario
-> output: a ``BatchResult`` (one ``BatchItem`` per log, in input order) whose ``exit_code`` is the worst of all;
``write_batch`` writes one sub-folder per log (``certificate.json`` + reports) and ``summary.md`` /
``summary.csv`` / ``junit.xml`` at the top.

An unusable log (unreadable, truncated, missing topic) becomes a row with exit code 3; it never stops the batch.
"Worst" orders the codes by severity, not by value: 0 pass < 2 inconclusive < 1 violation < 3 unusable < 70
internal error (an inconclusive log must not hide a violation in another one).

The logs run through ``verify.executor.parallel_map``, the one executor of both packages (the abstraction, batch
certification, regress and the falsifier): inline for one job or ``workers=1``, a process pool by default, or Dask
distributed with ``dask="local"`` or ``dask="tcp://host:port"``.
"""

from __future__ import annotations

import csv
import dataclasses
import re
import time
from collections.abc import Callable, Iterable, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING, Any, Literal

from tubempc.mitl import parse
from tubempc.scenario import Scenario
from verify.certificate import Certificate
from verify.errors import VerifyError
from verify.executor import parallel_map
from verify.junit import InconclusiveAs, JUnitCase, JUnitSuite, certificate_suite, write_junit
from verify.selection import select_checks

if TYPE_CHECKING:  # verify.report imports matplotlib (the 'report' extra): only when reports are written
    from verify.report import CertifyResultLike

__all__ = [
    "EXIT_INTERNAL",
    "EXIT_UNUSABLE",
    "LOG_SUFFIXES",
    "BatchItem",
    "BatchResult",
    "certify_many",
    "discover_logs",
    "parallel_map",  # verify.executor's, re-exported: the batch's executor
    "summary_lines",
    "worst_exit_code",
    "write_batch",
]

LOG_SUFFIXES = (".bag", ".mcap", ".db3")
EXIT_UNUSABLE = 3
EXIT_INTERNAL = 70
_SEVERITY = {0: 0, 2: 1, 1: 2, 3: 3, 70: 4}
_VERDICT_OF_CODE = {0: "pass", 1: "fail", 2: "inconclusive", 3: "unusable", 70: "error"}

_PRELOAD = ("verify.batch",)  # the process server imports the certifier once for all workers


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


def _scan(folder: Path) -> list[Path]:
    found: list[Path] = []
    for entry in sorted(folder.iterdir(), key=lambda p: p.name):
        if entry.is_dir():
            found.extend([entry] if _is_ros2_bag_dir(entry) else _scan(entry))
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
            checks = list(item.result.certificate.get("checks", []) or []) if item.result is not None else []
            failed = [str(c.get("name")) for c in checks if isinstance(c, dict) and c.get("verdict") == "fail"]
            unknown = [str(c.get("name")) for c in checks
                       if isinstance(c, dict) and c.get("verdict") not in ("pass", "fail")]
            # a failed log's worst margin is its most negative failed check's, never a passing check's;
            # metres only: seconds and m/s do not compare
            judged = [c for c in checks if isinstance(c, dict) and c.get("verdict") == "fail"] or checks
            margins = [float(c["margin"]) for c in judged
                       if isinstance(c, dict) and isinstance(c.get("margin"), int | float)
                       and c.get("margin_unit") == "m"]
            first = [float(c["first_violation_time"]) for c in checks if isinstance(c, dict)
                     and c.get("verdict") == "fail" and isinstance(c.get("first_violation_time"), int | float)]
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
    digest: str = "blake3"
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
                 checks: Sequence[str] | None = None, digest: str = "blake3",
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
    """One line per log for a terminal: ``path: verdict (failed checks with first violation times)``."""
    from verify.certify import verdict_line

    lines = []
    for item in batch.items:
        if item.result is None:
            lines.append(f"{item.path}: {item.verdict} ({item.error})")
            continue
        lines.append(verdict_line(item.path, item.result.certificate))
    counts = ", ".join(f"{n} {k}" for k, n in batch.counts().items() if n)
    lines.append(f"{len(batch.items)} log(s): {counts}; exit code {batch.exit_code}")
    return lines


# ---- writing ------------------------------------------------------------------------------------------------------
def _write_certificate(result: CertifyResultLike, out_dir: Path) -> Path:
    from verify import write_certificate  # type: ignore[attr-defined,unused-ignore]

    path: Path = write_certificate(result, out_dir)
    return path


def _md_cell(value: Any) -> str:
    import html

    text = "" if value is None else (f"{value:.6g}" if isinstance(value, float) else str(value))
    return re.sub(r"([\\`*_|\[\]])", r"\\\1", html.escape(text, quote=False)).replace("\n", " ")


@dataclass(frozen=True, slots=True)
class _WriteJob:
    item: BatchItem
    scenario: Scenario
    folder: str
    reports: bool
    junit_inconclusive: InconclusiveAs = "failure"


def _write_item(job: _WriteJob) -> JUnitSuite:
    """Write one log's folder; return its JUnit suite (a picklable value)."""
    item, sub = job.item, Path(job.folder)
    sub.mkdir(parents=True, exist_ok=True)
    if item.result is not None:
        _write_certificate(item.result, sub)
        if job.reports:
            from verify.report import write_reports

            write_reports(item.result, job.scenario, sub, suite_name=item.name,
                          junit_inconclusive=job.junit_inconclusive)
        suite = certificate_suite(Certificate.model_validate(item.result.certificate), suite_name=item.name,
                                  inconclusive=job.junit_inconclusive)
        return dataclasses.replace(suite, time_s=item.elapsed_s)
    (sub / "error.txt").write_text((item.error or "unknown error") + "\n", encoding="utf-8")
    case = JUnitCase("read log", item.name, "error", item.verdict, item.error or "")
    return JUnitSuite(item.name, (case,), time_s=item.elapsed_s)


def _summary_html(batch: BatchResult, rows: list[dict[str, Any]], reports: bool) -> str:
    """The summary as a self-contained page linking to each log's report (every log/scenario string escaped)."""
    import html

    def e(value: Any) -> str:
        text = "" if value is None else (f"{value:.6g}" if isinstance(value, float) else str(value))
        return html.escape(text, quote=True)

    colours = {"pass": "#2ca02c", "fail": "#d62728", "inconclusive": "#ff7f0e"}
    target = "report.html" if reports else "certificate.json"
    body = []
    for row in rows:
        name = e(row["log"])
        link = (f'<a href="{e(row["folder"])}/{target}">{name}</a>' if row["exit_code"] in (0, 1, 2) else name)
        colour = colours.get(row["verdict"], "#555")
        body.append(f'<tr><td>{link}</td><td style="color:{colour}">{e(row["verdict"])}</td>'
                    f"<td>{e(row['exit_code'])}</td><td>{e(row['failed_checks'])}</td>"
                    f"<td>{e(row['inconclusive_checks'])}</td><td>{e(row['worst_margin_m'])}</td>"
                    f"<td>{e(row['first_violation_s'])}</td><td>{e(row['error'])}</td></tr>")
    counts = ", ".join(f"{n} {k}" for k, n in batch.counts().items() if n)
    return ("<!DOCTYPE html>\n<html lang=\"en\"><head><meta charset=\"utf-8\"><title>Batch certification</title>"
            "<style>body{font-family:system-ui,sans-serif;margin:2em}table{border-collapse:collapse}"
            "td,th{border:1px solid #ccc;padding:3px 8px;text-align:left}</style></head><body>"
            f"<h1>Batch certification: exit code {batch.exit_code}</h1>"
            f"<p>Scenario {e(batch.scenario.name)}; {len(batch.items)} log(s): {e(counts)}.</p>"
            "<table><tr><th>log</th><th>verdict</th><th>exit</th><th>failed checks</th><th>inconclusive checks</th>"
            "<th>worst margin [m]</th><th>first violation [s]</th><th>error</th></tr>"
            + "".join(body) + "</table></body></html>\n")


def write_batch(batch: BatchResult, out_dir: str | Path, *, reports: bool = True, workers: int | None = None,
                dask: str | None = None, progress: bool | None = None,
                junit_inconclusive: InconclusiveAs = "failure") -> dict[str, Path]:
    """Write ``<out_dir>/<log>/`` (certificate.json + reports, or error.txt) and the summaries.

    The per-log folders are written in parallel like ``certify_many`` (figures take about 2 s per log).
    Returns the top-level files: ``summary.md``, ``summary.html`` (links to each ``report.html``),
    ``summary.csv``, ``junit.xml`` (one suite per log; an unusable log is a suite with one errored test case).
    """
    from verify.extras import require
    from verify.outputs import prepare_output_dir

    if reports:
        require("report", feature="report.html", alternative="write certificates only (reports=False, --no-report)")
    out = prepare_output_dir(out_dir, force=True, inputs=[item.path for item in batch.items])
    jobs = [_WriteJob(item, batch.scenario, str(out / item.name), reports, junit_inconclusive)
            for item in batch.items]
    suites = parallel_map(_write_item, jobs, workers=workers, dask=dask, progress=progress, desc="reports",
                          preload=_PRELOAD)
    rows = batch.rows()
    columns = list(rows[0]) if rows else ["log", "folder", "verdict", "exit_code"]
    with (out / "summary.csv").open("w", newline="", encoding="utf-8") as fh:
        writer = csv.DictWriter(fh, fieldnames=columns)
        writer.writeheader()
        writer.writerows(rows)
    counts = batch.counts()
    lines = [f"# Batch certification: exit code {batch.exit_code}", "",
             f"Scenario `{_md_cell(batch.scenario.name)}`; {len(batch.items)} log(s): "
             + ", ".join(f"{n} {k}" for k, n in counts.items() if n) + ".", "",
             "| log | verdict | exit | failed checks | inconclusive checks | worst margin [m] | first violation [s] "
             "| error |", "|---|---|---|---|---|---|---|---|"]
    target = "report.md" if reports else "certificate.json"
    for row in rows:
        link = (f"[{_md_cell(row['log'])}]({row['folder']}/{target})" if row["exit_code"] in (0, 1, 2)
                else _md_cell(row["log"]))
        lines.append(f"| {link} | {row['verdict']} | {row['exit_code']} | {_md_cell(row['failed_checks'])} | "
                     f"{_md_cell(row['inconclusive_checks'])} | {_md_cell(row['worst_margin_m'])} | "
                     f"{_md_cell(row['first_violation_s'])} | {_md_cell(row['error'])} |")
    (out / "summary.md").write_text("\n".join(lines) + "\n", encoding="utf-8")
    (out / "summary.html").write_text(_summary_html(batch, rows, reports), encoding="utf-8")
    return {"summary.md": out / "summary.md", "summary.html": out / "summary.html", "summary.csv": out / "summary.csv",
            "junit.xml": write_junit(suites, out / "junit.xml")}
