"""The ``tubempc demo`` subcommand: the paper's experiment end to end on the built-in scenario."""

from __future__ import annotations

import time
from pathlib import Path

import click

from tubempc.cli.exits import leave
from tubempc.cli.output import say

__all__ = ["demo"]


@click.command()
@click.option("--out", "out_dir", type=click.Path(file_okay=False, path_type=Path), default=None,
              help="Output folder (default: reports/demo-<timestamp>).")
@click.option("--seed", type=int, default=7, show_default=True, help="Seed of the disturbance generator.")
@click.option("--disturbance", type=click.Choice(["none", "random", "worst", "bias", "sine"]), default="random",
              show_default=True, help="Disturbance model of the simulated run.")
@click.option("--no-cache", is_flag=True, help="Rebuild the abstraction instead of reusing the on-disk cache.")
@click.option("--force", is_flag=True, help="Replace the outputs in an existing, non-empty --out folder.")
def demo(out_dir: Path | None, seed: int, disturbance: str, no_cache: bool, force: bool) -> None:
    """Plan the paper's formula on the built-in scenario, run it with the tube MPC, log, certify and report.

    Exit code: the certificate's (0 pass, 1 fail, 2 inconclusive).
    """
    from runkit.extras import require

    require("plan", "report", feature="the demo")
    from runkit.outputs import prepare_output_dir
    from tubempc.demo import run_demo

    folder = out_dir if out_dir is not None else Path("reports") / time.strftime("demo-%Y%m%d-%H%M%S")
    prepare_output_dir(folder, force=force)
    started = time.perf_counter()
    result = run_demo(folder, seed=seed, disturbance=disturbance, use_cache=not no_cache,
                      log=say, replace=force)
    say(f"certificate: {result.verdict} ({time.perf_counter() - started:.1f} s in all)")
    for key in ("mcap", "bag", "plan", "certificate", "report.md", "report.html", "junit.xml"):
        if key in result.files:
            say(f"  {key:12s} {result.files[key]}")
    leave(result.exit_code)
