"""The ``tubempc certify`` subcommand: log paths + scenario -> certificate(s) and reports on disk, summary, exit code.

One log file (or one ROS2 bag folder): ``verify.certify_log``; with ``--out DIR``, ``certificate.json``,
``report.md``, ``report.html`` and ``junit.xml`` go into DIR: a new or empty folder, or any folder with
``--force`` (``runkit.outputs`` states the policy shared by every command). Unusable input raises
``UnusableInputError``, which ``tubempc.cli.main`` turns into exit 3 and one line naming the file and the problem.

Several logs, or a folder of logs: ``verify.batch.certify_many`` in parallel (processes; ``--dask local`` or
``--dask tcp://host:port`` for Dask distributed), one sub-folder per log plus ``summary.md``/``.html``/``.csv``
under ``--out``, and the worst exit code by severity: pass 0 < inconclusive 2 < violation 1 < unusable 3.
"""

from __future__ import annotations

import json
from pathlib import Path
from typing import TYPE_CHECKING, Any, Literal, NoReturn, cast

import click

from tubempc.cli.exits import EXIT_UNUSABLE, leave
from tubempc.cli.options import checks_option, clock_offset_option, scenario_option
from tubempc.cli.output import verbosity
from verify.errors import UnusableInputError
from verify.ingest.digest import DEFAULT_DIGEST, DIGESTS, MESSAGES_DIGEST

if TYPE_CHECKING:
    from tubempc.scenario import Scenario
    from verify.certify import CertifyResult

__all__ = ["certify", "digest_command"]


def _json_entry(item: Any) -> dict[str, Any]:
    """A batch item for ``--json``: its certificate, or the log, verdict, exit code and error of an unusable log."""
    if item.result is not None:
        return dict(item.result.certificate)
    return {"log": item.path, "verdict": item.verdict, "exit_code": item.exit_code, "error": item.error}


def _single_log(logs: tuple[Path, ...]) -> bool:
    if len(logs) != 1:
        return False
    path = logs[0]
    return not path.is_dir() or (path / "metadata.yaml").is_file()


def _parse_offsets(items: tuple[str, ...]) -> dict[str, float]:
    from verify.ingest.clocks import parse_clock_offsets

    return parse_clock_offsets(items)


def _write_one(result: CertifyResult, sc: Scenario, log: Path, out_dir: Path, *, reports: bool,
               junit_inconclusive: str) -> Path:
    """certificate.json (and the reports) of one log into ``out_dir``; the certificate's path."""
    from verify.certify import write_certificate
    from verify.junit import InconclusiveAs

    try:
        path = write_certificate(result, out_dir)
        if reports:
            from verify.report import write_reports

            write_reports(result, sc, out_dir, suite_name=log.name,
                          junit_inconclusive=cast(InconclusiveAs, junit_inconclusive))
    except OSError as err:
        raise UnusableInputError(f"cannot write the reports ({err.strerror or err})", path=str(out_dir)) from None
    return path


@click.command()
@click.argument("logs", nargs=-1, required=True, type=click.Path(path_type=Path))
@scenario_option(required=True)
@click.option("--spec", default=None, help="MITL formula (default: the scenario's spec).")
@click.option("--out", "out_dir", default=None, type=click.Path(path_type=Path),
              help="Write certificate.json and reports here (one sub-folder per log when several are given).")
@click.option("--time-base", type=click.Choice(["auto", "header", "log"]), default="auto", show_default=True,
              help="auto: header stamps unless they cannot order the samples (then log time, noted in the "
                   "certificate); header: header stamps (no pass if they cannot order the samples); log: receive time.")
@checks_option()
@clock_offset_option()
@click.option("--salvage", is_flag=True, help="Read what complete chunks of a truncated log remain (never a pass).")
@click.option("--force", is_flag=True, help="Replace the reports in an existing, non-empty --out folder.")
@click.option("--no-report", is_flag=True, help="Write only certificate.json (no report.md/html, junit.xml).")
@click.option("--workers", type=click.IntRange(min=1), default=None,
              help="Worker processes for several logs (default: one per core).")
@click.option("--dask", "dask", default=None, metavar="local|tcp://HOST:PORT",
              help="Certify several logs on Dask distributed (a local cluster, or a running scheduler).")
@click.option("--progress/--no-progress", default=None, help="Progress bar (default: on a terminal).")
@click.option("--junit-inconclusive", type=click.Choice(["failure", "skipped"]), default="failure", show_default=True,
              help="junit.xml: an inconclusive check is a <failure type=\"inconclusive\"> (CI turns red: not a pass) "
                   "or <skipped> (shown green or grey by most dashboards).")
@click.option("--json", "as_json", is_flag=True,
              help="Print the certificate as JSON on stdout (a list for several logs); the summary goes to stderr.")
@click.option("--digest", type=click.Choice(list(DIGESTS)), default=DEFAULT_DIGEST, show_default=True,
              help="The certificate's digest: blake3-messages, of the messages judged (no extra read of the file); "
                   "blake3 / sha256, of the whole file's bytes (b3sum's / sha256sum's value for a file).")
def certify(logs: tuple[Path, ...], scenario: str, spec: str | None, out_dir: Path | None,  # noqa: PLR0917
            time_base: str, salvage: bool, force: bool, no_report: bool, workers: int | None, dask: str | None,
            progress: bool | None, checks_text: str | None, junit_inconclusive: str, as_json: bool,
            digest: str, clock_offsets: tuple[str, ...]) -> None:
    """Certify ROS logs (.bag, .mcap, .db3, ROS2 bag folders, or folders of logs) against a scenario and a formula.

    Exit 0 all checks pass, 1 a violation was found, 2 inconclusive, 3 unusable input, 4 a needed optional
    dependency is not installed (the line names the extra).
    """
    from runkit.extras import require
    from runkit.outputs import prepare_output_dir
    from verify.certify import certify_log, check_lines, resolve_scenario, verdict_line
    from verify.selection import parse_check_list

    if out_dir is not None and not no_report:  # before any work: the reports are what was asked for
        require("report", feature="report.html (certify --out)",
                alternative="pass --no-report for certificate.json only")
    if dask is not None:
        require("dask", feature="certify --dask")
    level = verbosity()
    sc = resolve_scenario(scenario)
    checks = parse_check_list(checks_text) if checks_text is not None else None
    offsets = _parse_offsets(clock_offsets)
    if out_dir is not None:
        prepare_output_dir(out_dir, force=force, inputs=logs)
    if _single_log(logs) and dask is None:
        result = certify_log(logs[0], sc, spec=spec, time_base=time_base, salvage=salvage, checks=checks,
                             digest=digest, clock_offsets=offsets)
        line = verdict_line(logs[0], result.certificate)
        if out_dir is not None:
            written = _write_one(result, sc, logs[0], out_dir, reports=not no_report,
                                 junit_inconclusive=junit_inconclusive)
            line += f" -> {written}"
        if as_json:
            click.echo(json.dumps(result.certificate, indent=2))
        if level >= 0:
            click.echo(line, err=as_json)
        if level > 0:
            click.echo("\n".join(check_lines(result.certificate)), err=True)
        leave(result.exit_code)

    _certify_batch(logs, sc, spec=spec, time_base=time_base, salvage=salvage, workers=workers, dask=dask,
                   progress=progress, checks=checks, digest=digest, offsets=offsets, as_json=as_json,
                   out_dir=out_dir, reports=not no_report, junit_inconclusive=junit_inconclusive, level=level)


def _certify_batch(logs: tuple[Path, ...], sc: Scenario, *, spec: str | None, time_base: str, salvage: bool,
                   workers: int | None, dask: str | None, progress: bool | None, checks: tuple[str, ...] | None,
                   digest: str, offsets: dict[str, float], as_json: bool, out_dir: Path | None, reports: bool,
                   junit_inconclusive: str, level: int) -> NoReturn:
    """Several logs (or a folder, or ``--dask``): ``verify.batch``; the summary, the one line of every unusable
    log, the folders under ``out_dir``; the worst exit code."""
    from verify.batch import certify_many, summary_lines, write_batch
    from verify.junit import InconclusiveAs

    base = cast(Literal["auto", "header", "log"], time_base)
    batch = certify_many(logs, sc, spec=spec, time_base=base, salvage=salvage, workers=workers, dask=dask,
                         progress=progress, checks=checks, digest=digest, clock_offsets=offsets)
    if as_json:
        click.echo(json.dumps([_json_entry(item) for item in batch.items], indent=2))
    if level >= 0:
        for text in summary_lines(batch):
            click.echo(text, err=as_json)
    for item in batch.items:  # every unusable input also gets its one line on stderr
        if item.exit_code == EXIT_UNUSABLE and item.error:
            click.echo(f"tubempc: error: {' '.join(item.error.split())}", err=True)
    if out_dir is not None:
        written = write_batch(batch, out_dir, reports=reports, workers=workers, dask=dask, progress=progress,
                              junit_inconclusive=cast(InconclusiveAs, junit_inconclusive))
        summary = written.get("summary.md")
        if summary is not None and level >= 0:
            click.echo(f"summary: {summary}", err=as_json)
    leave(batch.exit_code)


@click.command("digest")
@click.argument("logs", nargs=-1, required=True, type=click.Path(path_type=Path))
@scenario_option(default=None, extra="Its topics are the messages blake3-messages hashes (required for "
                                       "blake3-messages: give the scenario the certificate was made with).")
@click.option("--digest", type=click.Choice(list(DIGESTS)), default=DEFAULT_DIGEST, show_default=True,
              help="blake3-messages (the messages certification reads), blake3 / sha256 (the whole file).")
@click.option("--salvage", is_flag=True, help="Digest the complete records of a truncated log (as certify --salvage).")
def digest_command(logs: tuple[Path, ...], scenario: str | None, digest: str, salvage: bool) -> None:
    """Print the digest a certificate states for each log (`DIGEST  ALGORITHM  LOG`), to check a certificate
    against a log without certifying it again. blake3-messages (the default) hashes the messages of the scenario's
    topics, so it needs --scenario; blake3 and sha256 hash the file and need none. Exit 3 when a log cannot be read
    or lacks the scenario's pose topic, or when blake3-messages is asked for without a scenario."""
    from verify.certify import resolve_scenario
    from verify.errors import ScenarioInputError
    from verify.ingest.log import log_digest

    if scenario is None and digest == MESSAGES_DIGEST:
        raise ScenarioInputError("digest: blake3-messages hashes the messages of a scenario's topics: give "
                                 "--scenario (the one the certificate names), or --digest blake3 or sha256 for a "
                                 "digest of the whole file")
    sc = resolve_scenario(scenario if scenario is not None else "nexus-sml")
    for log in logs:
        got = log_digest(log, sc, digest, salvage=salvage)
        click.echo(f"{got.hex}  {got.algorithm}  {log}")
