"""The ``tubempc`` command: one package, one module per command; maps errors to exit codes and one clear line.

``tubempc --help`` is built from ``COMMANDS`` alone: a command's module (and what it imports: pandas, matplotlib,
casadi, rosbags...) is imported only when that command runs or its own ``--help`` is asked for. Exit codes:
``tubempc.cli.exits``; options shared by several commands (``--scenario``): ``tubempc.cli.options``; output levels
(``-q``/``-v``, read once): ``tubempc.cli.output``.
"""

from __future__ import annotations

import gc
import importlib
import sys
import traceback
import warnings
from typing import NoReturn

import click

from tubempc.cli.exits import (
    EXIT_FAIL,
    EXIT_INCONCLUSIVE,
    EXIT_INTERNAL,
    EXIT_INTERRUPTED,
    EXIT_NOT_AVAILABLE,
    EXIT_OK,
    EXIT_UNUSABLE,
    exit_code,
    is_ours,
)
from tubempc.cli.output import add_verbosity_options

__all__ = [
    "EXIT_FAIL",
    "EXIT_INCONCLUSIVE",
    "EXIT_INTERNAL",
    "EXIT_INTERRUPTED",
    "EXIT_NOT_AVAILABLE",
    "EXIT_OK",
    "EXIT_UNUSABLE",
    "cli",
    "main",
]

#: subcommand -> (module:attribute of its click command, the one line ``tubempc --help`` shows). A command's
#: module (and what it imports: pandas, matplotlib, casadi, rosbags...) is imported only when that command runs or
#: its own --help is asked for, so ``tubempc -V`` and ``tubempc --help`` start at once.
COMMANDS: dict[str, tuple[str, str]] = {
    "certify": ("tubempc.cli.certify:certify", "Certify ROS logs against a scenario and a formula."),
    "compare": ("tubempc.cli.compare:compare", "Compare runs before and after a change, metric by metric."),
    "demo": ("tubempc.cli.demo:demo", "Simulate the paper's mission and certify its log (a first run)."),
    "digest": ("tubempc.cli.certify:digest_command", "Print the digest a certificate states for each log."),
    "falsify": ("tubempc.cli.falsify:falsify", "Search the admissible perturbations of a run for the one "
                                                    "that breaks it."),
    "info": ("tubempc.cli.info:info", "What a log holds: topics, types, rates, gaps, clock, where the robot "
                                           "went."),
    "plan": ("tubempc.cli.plan:plan", "Plan a timed run of the scenario's formula on its abstraction."),
    "regress": ("tubempc.cli.regress:regress", "Run a suite of scenarios and seeds against a baseline."),
    "scenario": ("tubempc.cli.scenario:scenario", "Inspect, scaffold and validate scenario files."),
    "schema": ("tubempc.cli.scenario:schema", "Print the JSON Schema of an output other programs parse."),
    "simulate": ("tubempc.cli.simulate:simulate", "Simulate one transition of the tube MPC closed loop."),
    "spec": ("tubempc.cli.scenario:spec", "Parse an MITL formula and print its canonical form."),
    "watch": ("tubempc.cli.watch:watch", "Monitor a log online (a growing file) against the formula."),
}


def _import_command_module(module: str, *, freeze: bool) -> object:
    """A command's module, imported without cyclic garbage collection: an import makes tens of thousands of
    long-lived objects (modules, classes, functions) and next to no garbage, yet each collection meanwhile would scan
    them all again. ``freeze`` (a process started for this one command, ``main()``): the objects alive after the
    import are then moved out of every later collection (``gc.freeze``), which otherwise rescans them while the
    command works (about a fifth of ``certify --json``'s CPU time on a one-minute log)."""
    enabled = gc.isenabled()
    gc.disable()
    try:
        return importlib.import_module(module)
    finally:
        if freeze:
            gc.freeze()
        if enabled:
            gc.enable()


class LazyGroup(click.Group):
    """A group whose subcommands are imported when used (``COMMANDS``); its --help lists them from the table."""

    def list_commands(self, ctx: click.Context) -> list[str]:
        return sorted({*COMMANDS, *self.commands})

    def get_command(self, ctx: click.Context, cmd_name: str) -> click.Command | None:
        if cmd_name in self.commands:
            return self.commands[cmd_name]
        if cmd_name not in COMMANDS:
            return None
        module, _, attr = COMMANDS[cmd_name][0].partition(":")
        one_command = isinstance(ctx.obj, dict) and ctx.obj.get("one_command_process", False)
        command = getattr(_import_command_module(module, freeze=one_command), attr)
        if not isinstance(command, click.Command):
            raise TypeError(f"{COMMANDS[cmd_name][0]} is not a click command")
        add_verbosity_options(command)  # -q/--quiet and -v/--verbose on every subcommand
        self.add_command(command, cmd_name)
        return command

    def format_commands(self, ctx: click.Context, formatter: click.HelpFormatter) -> None:
        rows = [(name, COMMANDS[name][1] if name in COMMANDS else (self.commands[name].get_short_help_str()))
                for name in self.list_commands(ctx)]
        with formatter.section("Commands"):
            formatter.write_dl(rows)


@click.group(cls=LazyGroup, context_settings={"help_option_names": ["-h", "--help"]})
@click.version_option(None, "-V", "--version", package_name="tubempc")
@click.option("--debug", is_flag=True, help="Show full tracebacks instead of one-line errors.")
@click.pass_context
def cli(ctx: click.Context, debug: bool) -> None:
    """Plan timed robot missions with tube MPC under MITL, and certify their ROS logs.

    Every --scenario names a scenario YAML file or a built-in scenario: a file of that name first, then a built-in
    name (`tubempc scenario list`)."""
    ctx.ensure_object(dict)
    ctx.obj["debug"] = debug


add_verbosity_options(cli)  # on the group; LazyGroup adds them to each subcommand it loads


def _one_line(text: str, limit: int = 600) -> str:
    """An error message as one stderr line: lines joined with '; ', long messages cut at ``limit`` characters."""
    line = "; ".join(part.strip() for part in text.splitlines() if part.strip())
    return line if len(line) <= limit else line[: limit - 3] + "..."


def main(argv: list[str] | None = None) -> NoReturn:
    """Console entry point: run the CLI, turning expected errors into one stderr line and an exit code.

    ``--debug`` prints the traceback before that line; it never changes the exit code. Without ``argv`` (the
    ``tubempc`` program, ``python -m tubempc``) the process runs this one command: the command's imported modules
    are frozen out of garbage collection (``_import_command_module``); a caller that runs several commands in one
    process passes ``argv``."""
    args = sys.argv[1:] if argv is None else argv
    debug = "--debug" in args
    try:
        with warnings.catch_warnings():
            # numeric edge cases of damaged data and matplotlib's degenerate axes are handled by the code; their
            # library warnings are not the user's business (one stderr line per error is the contract)
            warnings.filterwarnings("ignore", category=RuntimeWarning, module=r"(numpy|verify|pandas)(\..*)?")
            warnings.filterwarnings("ignore", category=UserWarning, module=r"(matplotlib|verify)(\..*)?")
            # standalone_mode=False turns ctx.exit(code) / sys.exit(code) inside a command into a return value
            code = cli.main(args=args, prog_name="tubempc", standalone_mode=False,
                            obj={"one_command_process": argv is None})
    except click.exceptions.Exit as err:
        sys.exit(err.exit_code)
    except click.Abort:
        click.echo("tubempc: aborted", err=True)
        sys.exit(EXIT_INTERRUPTED)
    except click.ClickException as err:
        err.show()
        sys.exit(EXIT_UNUSABLE if err.exit_code == 2 else err.exit_code)
    except KeyboardInterrupt:
        click.echo("tubempc: interrupted", err=True)
        sys.exit(EXIT_INTERRUPTED)
    except Exception as err:
        if is_ours(err):
            if debug:
                traceback.print_exc()
            click.echo(f"tubempc: error: {_one_line(str(err))}", err=True)
            sys.exit(exit_code(err))
        if debug:
            traceback.print_exc()
        hint = "" if debug else " (rerun with --debug for the traceback)"
        click.echo(f"tubempc: internal error: {err.__class__.__name__}: {_one_line(str(err))}{hint}", err=True)
        sys.exit(EXIT_INTERNAL)
    sys.exit(code if isinstance(code, int) else EXIT_OK)
