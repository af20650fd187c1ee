"""The ``tubempc compare`` subcommand: runs before and after a change (logs or certificates) -> a diff per metric.

input: BEFORE and AFTER (folders, globs or files of logs, or folders of certificates), a scenario, tolerances ->
output: the readable diff on stdout (regressions first); with ``--out DIR``: ``diff.txt``, ``compare.html``,
``junit.xml`` and ``compare.json``; ``--json`` prints the JSON on stdout (the diff then goes to stderr).
Exit 0 no regression, 1 a metric regressed, 2 the runs cannot tell (too few, or a change they cannot decide),
3 unusable input (one line naming the file).
"""

from __future__ import annotations

import click

from tubempc.cli.exits import leave
from tubempc.cli.options import scenario_option
from tubempc.cli.output import say, verbosity

__all__ = ["compare"]


@click.command()
@click.argument("before")
@click.argument("after")
@scenario_option(required=True)
@click.option("--spec", default=None, help="MITL formula the logs are certified against (default: the scenario's).")
@click.option("--pair-pattern", default=None, metavar="REGEX",
              help="Pair runs by this regular expression searched in each log's path relative to its side's folder "
                   "(its first group, or the match); default: the whole relative path without the suffix.")
@click.option("--pair-by", default=None, metavar="FIELD",
              help="Pair runs by a certificate field instead (dotted, e.g. generator.seed).")
@click.option("--unpaired", is_flag=True, help="Compare the sides as two samples even where runs pair.")
@click.option("--tolerances", "tolerances_path", default=None, type=click.Path(dir_okay=False),
              help="Tolerances YAML (default: <scenario>.compare.yaml beside a scenario file, if there is one).")
@click.option("--tol", "tol", multiple=True, metavar="NAME=ABS[+RELx]",
              help="Tolerance of one metric or family, e.g. check_margin=0.005 or entry_s=0.5+0.02x; repeatable.")
@click.option("--confidence", type=float, default=None,
              help="Confidence of the one-sided tests (default 0.95, or the tolerances file's).")
@click.option("--out", "out_dir", default=None, type=click.Path(file_okay=False),
              help="Write diff.txt, compare.html, junit.xml and compare.json here.")
@click.option("--force", is_flag=True, help="Replace the files in an existing, non-empty --out folder.")
@click.option("--json", "as_json", is_flag=True, help="Print the comparison as JSON on stdout (diff on stderr).")
@click.option("--time-base", type=click.Choice(["auto", "header", "log"]), default="auto", show_default=True,
              help="Time base when certifying logs (as certify's).")
@click.option("--workers", type=click.IntRange(min=1), default=None,
              help="Processes certifying the logs (default: one per core).")
@click.option("--progress/--no-progress", default=None, help="Progress bar (default: when stderr is a terminal).")
def compare(*, before: str, after: str, scenario: str, spec: str | None, pair_pattern: str | None,
            pair_by: str | None, unpaired: bool, tolerances_path: str | None, tol: tuple[str, ...],
            confidence: float | None, out_dir: str | None, force: bool, as_json: bool, time_base: str,
            workers: int | None, progress: bool | None) -> None:
    """Compare runs recorded before and after a change: per metric n, median, p05/p95, worst and the difference;
    regressed = worse beyond the tolerance and significant at the confidence.

    Exit 0 no regression, 1 regression, 2 not enough runs to tell, 3 unusable input."""
    from runkit.extras import require

    if out_dir is not None:  # compare.html's plots (scipy, for the tests, is a base dependency)
        require("report", feature="compare.html (compare --out)", alternative="drop --out and use --json")
    from pathlib import Path

    from tubempc.compare import format_diff, judge, load_settings, load_side, outcome_json, pair_runs
    from tubempc.compare.outcome import outcome_junit
    from tubempc.compare.page import write_page
    from tubempc.compare.settings import settings_path_for
    from tubempc.errors import CompareInputError
    from verify.certify import resolve_scenario
    from verify.junit import write_junit
    from verify.semantics.timed_run import parse_spec

    if pair_by is not None and pair_pattern is not None:
        raise CompareInputError("--pair-by and --pair-pattern: give one of them")
    sc = resolve_scenario(scenario)
    formula = str(parse_spec(spec if spec is not None else sc.spec))
    settings = load_settings(tolerances_path if tolerances_path is not None else settings_path_for(scenario),
                             overrides=tol, confidence=confidence)
    if out_dir is not None:
        from runkit.outputs import prepare_output_dir

        prepare_output_dir(out_dir, force=force, inputs=[before, after])
    sides = [load_side(text, sc, formula=formula, spec=spec, time_base=time_base, workers=workers,
                       progress=progress, pair_by=pair_by, pair_pattern=pair_pattern) for text in (before, after)]
    outcome = judge(sides[0], sides[1], pair_runs(sides[0], sides[1], unpaired=unpaired), settings)
    text = format_diff(outcome, verbose=verbosity() > 0)
    report = outcome_json(outcome)
    if as_json:
        click.echo(report.model_dump_json(indent=2))
    if verbosity() >= 0:
        click.echo(text, err=as_json)
    if out_dir is not None:
        out = Path(out_dir)
        (out / "diff.txt").write_text(text + "\n", encoding="utf-8")
        (out / "compare.json").write_text(report.model_dump_json(indent=2) + "\n", encoding="utf-8")
        write_junit([outcome_junit(outcome)], out / "junit.xml")
        say(f"compare: {write_page(outcome, out / 'compare.html')}")
    if outcome.exit_code:
        leave(outcome.exit_code)
