"""Output levels of every subcommand: ``-q/--quiet`` and ``-v/--verbose`` -> what goes to stdout and stderr.

The group in ``tubempc.cli`` adds both options to the group and to every subcommand (``tubempc -q certify ...`` and
``tubempc certify -q ...`` mean the same) and keeps the level in ``click.Context.meta[VERBOSITY_KEY]``: -1 quiet,
0 normal, 1 verbose, 2 and more debug. Quiet prints no progress or summary lines: only what was asked for (a
``--json`` document, ``scenario show``'s YAML, ``spec``'s canonical formula), errors on stderr, and the exit code.
Verbose adds detail on stderr and turns on the ``logging`` records of both packages (INFO; DEBUG with ``-vv``).
"""

from __future__ import annotations

import logging
from typing import Any

import click

__all__ = ["VERBOSITY_KEY", "add_verbosity_options", "detail", "progress_line", "say", "verbosity"]

VERBOSITY_KEY = "verbosity"


def verbosity() -> int:
    ctx = click.get_current_context(silent=True)
    return int(ctx.meta.get(VERBOSITY_KEY, 0)) if ctx is not None else 0


def say(text: str) -> None:
    """A progress or summary line on stdout (not in quiet mode)."""
    if verbosity() >= 0:
        click.echo(text)


def detail(text: str) -> None:
    """An extra line on stderr (verbose mode only)."""
    if verbosity() > 0:
        click.echo(text, err=True)


def _set_quiet(ctx: click.Context, _param: click.Parameter, value: bool) -> None:
    if value:
        ctx.meta[VERBOSITY_KEY] = -1


def _set_verbose(ctx: click.Context, _param: click.Parameter, value: int) -> None:
    if value:
        level = max(int(ctx.meta.get(VERBOSITY_KEY, 0)), 0) + value
        ctx.meta[VERBOSITY_KEY] = level
        logging.basicConfig(level=logging.DEBUG if level > 1 else logging.INFO,
                            format="%(name)s: %(levelname)s: %(message)s")


def _options() -> list[click.Option]:
    quiet = click.Option(["-q", "--quiet"], is_flag=True, expose_value=False, is_eager=True, callback=_set_quiet,
                         help="Print nothing but what was asked for and errors; the exit code tells the rest.")
    verbose = click.Option(["-v", "--verbose"], count=True, expose_value=False, callback=_set_verbose,
                           help="More detail on stderr (repeat for debug logging).")
    return [quiet, verbose]


def add_verbosity_options(command: Any) -> None:
    """Give ``command`` (and, for a group, every subcommand in it) the -q and -v options."""
    names = {opt for p in command.params for opt in getattr(p, "opts", [])}
    if "-q" not in names:
        command.params.extend(_options())
    if isinstance(command, click.Group):
        for sub in command.commands.values():
            add_verbosity_options(sub)


def progress_line(text: str) -> None:
    """A progress line on stderr (not in quiet mode)."""
    if verbosity() >= 0:
        click.echo(text, err=True)
