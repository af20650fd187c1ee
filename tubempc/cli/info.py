"""The ``tubempc info`` subcommand: a log path -> what it holds (``verify.info``), as text or ``--json``.

Exit codes: 0 described; 3 unusable input (the log cannot be read: one line naming the file and the problem).
"""

from __future__ import annotations

import json
from pathlib import Path

import click

__all__ = ["info"]


@click.command("info")
@click.argument("log", type=click.Path(path_type=Path))
@click.option("--json", "as_json", is_flag=True, help="Print the description as JSON (info_version 1).")
@click.option("--salvage", is_flag=True, help="Describe the complete records of a truncated or unindexed ROS1 or "
                                              "MCAP log (a recorder that was killed).")
def info(log: Path, as_json: bool, salvage: bool) -> None:
    """What a log holds: every topic with its type, count, rate (median period, largest gaps), span on log and
    header time and clock (wall or simulated); for pose-like topics (PoseStamped, Odometry, /tf child frames) the
    x/y extents and the speed distribution. The start for a scenario: `tubempc scenario init LOG`."""
    from verify.info import info_dict, info_lines, log_info

    got = log_info(log, salvage=salvage)
    if as_json:
        click.echo(json.dumps(info_dict(got), indent=2))
        return
    for line in info_lines(got):
        click.echo(line)
