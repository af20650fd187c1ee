"""The ``tubempc certify`` subcommand: log paths + scenario -> certificate(s) on disk, a summary line, an exit code.

A thin front over ``verify.certify_log``: several logs are certified one after another (one sub-folder per log
under ``--out`` when there is more than one); the exit code is the worst verdict (fail 1 > inconclusive 2 > pass 0).
Unusable input raises ``UnusableInputError`` subclasses, which ``tubempc.cli.main`` turns into exit 3 and one line.
"""

from __future__ import annotations

import sys
from pathlib import Path

import click

__all__ = ["certify", "worst_exit_code"]


def worst_exit_code(codes: list[int]) -> int:
    """fail (1) beats inconclusive (2) beats pass (0)."""
    if 1 in codes:
        return 1
    if 2 in codes:
        return 2
    return 0


def _subfolder(path: Path, used: set[str]) -> str:
    base = path.name.replace(".", "_") or "log"
    name, k = base, 1
    while name in used:
        k += 1
        name = f"{base}_{k}"
    used.add(name)
    return name


@click.command()
@click.argument("logs", nargs=-1, required=True, type=click.Path(path_type=Path))
@click.option("--scenario", "scenario", required=True, help="Scenario YAML file or built-in name (nexus-sml).")
@click.option("--spec", default=None, help="MITL formula (default: the scenario's spec).")
@click.option("--out", "out_dir", default=None, type=click.Path(path_type=Path),
              help="Write certificate.json here (one sub-folder per log when several logs are given).")
@click.option("--time-base", type=click.Choice(["header", "log"]), default="header", show_default=True,
              help="Header stamps or log (receive) time.")
@click.option("--salvage", is_flag=True, help="Read what complete chunks of a truncated log remain (never a pass).")
def certify(logs: tuple[Path, ...], scenario: str, spec: str | None, out_dir: Path | None,  # noqa: PLR0917
            time_base: str, salvage: bool) -> None:
    """Certify ROS logs (.bag, .mcap, .db3 or ROS2 bag folders) against a scenario and an MITL formula.

    Exit 0 all checks pass, 1 a violation was found, 2 inconclusive, 3 unusable input.
    """
    from verify.certify import certify_log, resolve_scenario, write_certificate

    sc = resolve_scenario(scenario)
    codes: list[int] = []
    used: set[str] = set()
    for log in logs:
        result = certify_log(log, sc, spec=spec, time_base=time_base, salvage=salvage)
        cert = result.certificate
        line = f"{log}: {cert['verdict']}"
        failed = [c for c in cert["checks"] if c["verdict"] != "pass"]
        if failed:
            line += " (" + "; ".join(
                f"{c['name']}: {c['verdict']}"
                + (f" at t={c['first_violation_time']} s" if c.get("first_violation_time") is not None else "")
                for c in failed) + ")"
        if out_dir is not None:
            target = out_dir if len(logs) == 1 else out_dir / _subfolder(log, used)
            line += f" -> {write_certificate(result, target)}"
        click.echo(line)
        codes.append(result.exit_code)
    sys.stdout.flush()
    # SystemExit, not click's Exit: in standalone_mode=False click returns Exit's code instead of exiting
    sys.exit(worst_exit_code(codes))
