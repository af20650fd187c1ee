"""The ``tubempc watch`` subcommand: a log that is still being written + scenario -> decisions as lines, exit code.

Prints one line per decision (``12.34 s  obstacle_clearance FAIL (violated at 12.34 s)``; with its margin once that is
final), then one ``final`` line per obligation and check with the margin the certificate states, then, for a run
that did not pass, one ``why`` line per obligation and check that did not pass (the certificate's one-sentence
``explanation``: where it was violated, or why it could not be decided and what would decide it), then a summary
line, and exits with certify's codes (0 pass, 1 violation, 2 inconclusive, 3 unusable input). The ``why`` lines and
``--out DIR`` (the certificate and reports) come from the certificate ``tubempc certify`` (with ``--salvage`` for a
log its recorder did not close) gives for the log as read at the end: watch reads them, it does not judge again.
"""

from __future__ import annotations

import sys
from pathlib import Path

import click

from tubempc.cli.exits import leave
from tubempc.cli.options import checks_option, clock_offset_option, scenario_option
from tubempc.cli.output import verbosity

__all__ = ["watch"]


def _certified_path(path: Path, finished: bool) -> Path:
    """A ROS2 bag folder without its metadata.yaml (the recorder was stopped) is certified through its one storage
    file, as ``--salvage`` reads it."""
    if finished or not path.is_dir() or (path / "metadata.yaml").is_file():
        return path
    files = sorted(p for p in path.iterdir() if p.suffix == ".mcap")
    return files[0] if len(files) == 1 else path


@click.command()
@click.argument("log", type=click.Path(path_type=Path))
@scenario_option(required=True)
@click.option("--spec", default=None, help="MITL formula (default: the scenario's spec).")
@click.option("--follow", is_flag=True, help="Keep reading as the log grows (until it is closed or idle).")
@click.option("--idle-timeout", "idle_timeout", type=click.FloatRange(min=0.0), default=10.0, show_default=True,
              help="With --follow: stop when the log has not grown for this many seconds.")
@click.option("--poll", "poll_s", type=click.FloatRange(min=0.01), default=0.2, show_default=True,
              help="Seconds between two reads of the log.")
@click.option("--time-base", type=click.Choice(["auto", "header", "log"]), default="header", show_default=True,
              help="Header stamps, log (receive) time, or auto: certify's rule (header stamps unless they cannot "
                   "order the samples) applied to the first pose messages.")
@clock_offset_option()
@click.option("--out", "out_dir", default=None, type=click.Path(path_type=Path),
              help="Write certificate.json and reports here at the end, as certify does.")
@click.option("--no-report", is_flag=True, help="With --out: write only certificate.json.")
@checks_option()
def watch(log: Path, scenario: str, spec: str | None, follow: bool, idle_timeout: float,  # noqa: PLR0917
          poll_s: float, time_base: str, clock_offsets: tuple[str, ...], out_dir: Path | None, no_report: bool,
          checks_text: str | None) -> None:
    """Certify a log while it is being recorded: one line per decision, as soon as it is decided.

    Exit 0 all checks pass, 1 a violation was found, 2 inconclusive, 3 unusable input.
    """
    from verify.certify import resolve_scenario
    from verify.ingest.clocks import parse_clock_offsets
    from verify.online.monitor import OnlineMonitor
    from verify.online.watch import watch_log
    from verify.selection import parse_check_list

    sc = resolve_scenario(scenario)
    checks = parse_check_list(checks_text) if checks_text is not None else None
    if sc.robots:  # several robots: one monitor per robot, the joint checks at the end (verify.online.fleet)
        from verify.online.fleet import FleetMonitor

        monitor: OnlineMonitor | FleetMonitor = FleetMonitor(sc, spec=spec, checks=checks)
    else:
        monitor = OnlineMonitor(sc, spec=spec, checks=checks)
    offsets = parse_clock_offsets(clock_offsets)

    def show(d: object) -> None:
        click.echo(d.line())  # type: ignore[attr-defined]
        sys.stdout.flush()

    res = watch_log(log, monitor, follow=follow, idle_timeout_s=idle_timeout, poll_s=poll_s, time_base=time_base,
                    clock_offsets=offsets, on_decision=show)
    quiet = verbosity() < 0  # -q: the decisions and the exit code only
    if not quiet:  # the final margins (a decision states its margin only once no later sample can change it)
        for text in res.result.state.final_lines():
            click.echo(text)
    for note in [] if quiet else res.notes:
        click.echo(f"note: {note}")
    line = f"{log}: {res.result.verdict} ({res.stop_reason}; {monitor.counts['pose']} pose samples)"
    result = None
    if out_dir is not None or (res.result.verdict != "pass" and not quiet):
        from verify.certify import certify_log
        from verify.errors import VerifyError

        try:
            result = certify_log(_certified_path(log, res.finished), sc, spec=spec, time_base=time_base,
                                 salvage=not res.finished, checks=checks, clock_offsets=offsets)
        except VerifyError as err:
            if out_dir is not None:
                raise
            click.echo(f"   why    not available: the log as read at the end cannot be certified ({err})")
    if result is not None and not quiet:  # the certificate's one-sentence explanation of each result not a pass
        cert = result.typed
        whys = [(o.formula, o.explanation) for o in cert.obligations[1:]]
        whys += [(c.name, c.explanation) for c in cert.checks]
        for what, why in whys:
            if why:
                click.echo(f"   why    {what}: {why}")
    if out_dir is not None and result is not None:
        from verify.certify import write_certificate

        line += f" -> {write_certificate(result, out_dir)}"
        if not no_report:
            from verify.report import write_reports

            write_reports(result, sc, out_dir, suite_name=log.name)
    if not quiet:
        click.echo(line)
    leave(res.result.exit_code)
