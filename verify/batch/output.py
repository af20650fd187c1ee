"""A ``BatchResult`` -> one folder per log (certificate and reports) and the summary files at the top."""

from __future__ import annotations

import csv
import dataclasses
import io
import re
from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING, Any

from runkit.executor import parallel_map
from runkit.outputs import output_subdir, write_output_file
from tubempc.scenario import Scenario
from verify.batch.run import _PRELOAD, BatchItem, BatchResult
from verify.certificate import Certificate
from verify.junit import InconclusiveAs, JUnitCase, JUnitSuite, certificate_suite, write_junit

if TYPE_CHECKING:  # verify.report imports matplotlib (the 'report' extra): only when reports are written
    from verify.report import CertifyResultLike

__all__ = ["write_batch"]


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
    item, folder = job.item, Path(job.folder)
    folder.parent.mkdir(parents=True, exist_ok=True)
    sub = output_subdir(folder.parent, folder.name)
    if item.result is not None:
        _write_certificate(item.result, sub)
        if job.reports:
            from verify.report import write_reports

            write_reports(item.result, job.scenario, sub, suite_name=item.name,
                          junit_inconclusive=job.junit_inconclusive, figure_workers=1)  # logs are written in parallel
        suite = certificate_suite(Certificate.model_validate(item.result.certificate), suite_name=item.name,
                                  inconclusive=job.junit_inconclusive)
        return dataclasses.replace(suite, time_s=item.elapsed_s)
    write_output_file(sub / "error.txt", (item.error or "unknown error") + "\n")
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

    With ``reports``, the per-log folders are written in parallel like ``certify_many`` (figures take about 2 s per
    log); certificates alone are written in this process (``workers`` and ``dask`` are then unused).
    Returns the top-level files: ``summary.md``, ``summary.html`` (links to each ``report.html``),
    ``summary.csv``, ``junit.xml`` (one suite per log; an unusable log is a suite with one errored test case).
    """
    from runkit.extras import require
    from runkit.outputs import prepare_output_dir

    if reports:
        require("report", feature="report.html", alternative="write certificates only (reports=False, --no-report)")
    out = prepare_output_dir(out_dir, force=True, inputs=[item.path for item in batch.items])
    jobs = [_WriteJob(item, batch.scenario, str(out / item.name), reports, junit_inconclusive)
            for item in batch.items]
    if reports:
        suites = parallel_map(_write_item, jobs, workers=workers, dask=dask, progress=progress, desc="reports",
                              preload=_PRELOAD)
    else:
        # certificates only: a few milliseconds of JSON per log, written here; shipping every result (with its
        # trajectory frames) to a pool, or starting a second Dask cluster, costs more than the writing
        suites = [_write_item(job) for job in jobs]
    rows = batch.rows()
    columns = list(rows[0]) if rows else ["log", "folder", "verdict", "exit_code"]
    table = io.StringIO(newline="")
    writer = csv.DictWriter(table, fieldnames=columns)
    writer.writeheader()
    writer.writerows(rows)
    write_output_file(out / "summary.csv", table.getvalue())
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
    write_output_file(out / "summary.md", "\n".join(lines) + "\n")
    write_output_file(out / "summary.html", _summary_html(batch, rows, reports))
    return {"summary.md": out / "summary.md", "summary.html": out / "summary.html", "summary.csv": out / "summary.csv",
            "junit.xml": write_junit(suites, out / "junit.xml")}
