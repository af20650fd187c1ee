"""The `tubempc demo` subcommand (placeholder until its feature lands: exits 4 with one clear line)."""

from __future__ import annotations

import click

from tubempc.errors import NotAvailableError

__all__ = ["demo"]


@click.command(context_settings={"ignore_unknown_options": True})
@click.argument("args", nargs=-1, type=click.UNPROCESSED)
def demo(args: tuple[str, ...]) -> None:
    """Not available yet."""
    raise NotAvailableError("'tubempc demo' is not available yet in this version")
