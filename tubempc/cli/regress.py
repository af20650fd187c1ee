"""The `tubempc regress` subcommand: run a suite with the current controller, compare with a baseline.

input: a suite YAML (default: the shipped one), a baseline JSON -> output: a readable diff on stdout, exit 0 when
nothing regressed and 1 otherwise (a falsification case regresses when it finds a counterexample the baseline did
not); ``--update-baseline`` writes the current metrics as the new baseline (exit 0).
With ``--out DIR``: every run's log and certificate under ``DIR/<run>/``, plus ``diff.txt`` and ``junit.xml``.
"""

from __future__ import annotations

from pathlib import Path

import click

from tubempc.cli.exits import EXIT_FAIL, leave
from tubempc.cli.output import progress_line, say

__all__ = ["regress"]


@click.command()
@click.option("--suite", "suite_path", type=click.Path(dir_okay=False), default=None,
              help="Suite YAML (default: the suite shipped for the built-in scenario).")
@click.option("--baseline", "baseline_path", type=click.Path(dir_okay=False), default=None,
              help="Baseline JSON (default: the shipped baseline, only with the default suite).")
@click.option("--update-baseline", is_flag=True, help="Write the current metrics as the new baseline.")
@click.option("--workers", type=click.IntRange(min=1), default=None,
              help="Parallel processes (default: CPU count; 1 runs in this process).")
@click.option("--dask", default=None, metavar="local|tcp://HOST:PORT",
              help="Run on Dask distributed: a local cluster on loopback, or an existing scheduler.")
@click.option("--out", "out_dir", type=click.Path(file_okay=False), default=None,
              help="Keep each run's log and certificate here, with diff.txt and junit.xml.")
@click.option("--reports", is_flag=True, help="With --out: also write report.md/html per run.")
@click.option("--force", is_flag=True, help="Replace the runs in an existing, non-empty --out folder.")
@click.option("--progress/--no-progress", default=None, help="Progress bar (default: when stderr is a terminal).")
@click.option("--controller", "controller", default=None, metavar="PACKAGE.MODULE:FACTORY",
              help="Run your own controller instead of the tube MPC (docs/controller.md); needs --suite/--baseline.")
def regress(*, suite_path: str | None, baseline_path: str | None, update_baseline: bool, workers: int | None,
            dask: str | None, out_dir: str | None, reports: bool, force: bool, progress: bool | None,
            controller: str | None) -> None:
    """Run a regression suite with the current controller (or --controller) and compare it with a baseline."""
    from runkit.extras import require

    require("plan", *(("report",) if reports and out_dir else ()), *(("dask",) if dask else ()),
            feature="tubempc regress")
    from runkit.outputs import write_output_file
    from tubempc.regress import (
        FalsifyCase,
        RunCase,
        compare,
        comparison_junit,
        default_baseline_path,
        expand_falsify,
        expand_suite,
        format_diff,
        load_suite,
        read_baseline,
        run_cases,
        write_baseline,
    )
    from tubempc.regress.compare import BaselineError
    from verify.junit import write_junit

    loaded = load_suite(suite_path)
    if baseline_path is None:
        if suite_path is not None:
            raise BaselineError("--baseline is required with --suite (the shipped baseline belongs to the "
                                "default suite)")
        baseline_path = default_baseline_path()
    if out_dir is None and reports:
        raise click.UsageError("--reports needs --out DIR")
    if out_dir is not None:
        from runkit.outputs import prepare_output_dir

        prepare_output_dir(out_dir, force=force)
    cases: list[RunCase | FalsifyCase] = [*expand_suite(loaded), *expand_falsify(loaded)]
    if controller is not None:
        from tubempc.control.user import checked_controller

        for scenario in {id(c.scenario): c.scenario for c in cases}.values():  # fail fast: exit 3 naming it
            checked_controller(controller, scenario)
    if update_baseline:
        progress_line(f"regress: suite {loaded.suite.name!r} ({loaded.source}): {len(cases)} runs")
        outcomes = run_cases(cases, out_dir=out_dir, reports=reports, workers=workers, dask=dask, progress=progress,
                             controller=controller)
        path = write_baseline(baseline_path, loaded.suite, outcomes)
        say(f"regress: baseline written to {path} ({len(outcomes)} runs)")
        return
    baseline = read_baseline(baseline_path)  # before the runs: a missing baseline fails fast
    progress_line(f"regress: suite {loaded.suite.name!r} ({loaded.source}): {len(cases)} runs")
    outcomes = run_cases(cases, out_dir=out_dir, reports=reports, workers=workers, dask=dask, progress=progress,
                         controller=controller)
    comparison = compare(baseline, outcomes, loaded.suite.tolerances)
    text = format_diff(comparison)
    say(text)
    if out_dir is not None:
        out = Path(out_dir)
        out.mkdir(parents=True, exist_ok=True)
        write_output_file(out / "diff.txt", text + "\n")
        write_junit([comparison_junit(comparison, outcomes, suite_name=loaded.suite.name)], out / "junit.xml")
    if comparison.regressed:
        leave(EXIT_FAIL)
