"""The ``tubempc`` command: a thin front over both packages; maps errors to exit codes and one clear line.

Exit codes (all subcommands): 0 success / all checks pass; 1 a violation was found (certify, regress) or no
accepting run exists (plan, proved); 2 inconclusive (certify) or undecided (plan: the search reached its state
limit, ``--max-states``); 3 unusable input (unreadable or truncated log, missing topic, malformed formula or
scenario, impossible controller design, an abstraction without any usable transition); 4 feature not available
(among others: an optional dependency is not installed; the line names the extra, ``verify.extras``); 70 internal
error.
"""

from __future__ import annotations

import sys
import traceback
import warnings
from typing import NoReturn

import click

from tubempc.commands.compare import compare
from tubempc.commands.demo import demo
from tubempc.commands.falsify import falsify
from tubempc.commands.output import add_verbosity_options, say
from tubempc.commands.plan import plan
from tubempc.commands.regress import regress
from tubempc.commands.simulate import simulate
from tubempc.errors import NoAcceptingRunError, NotAvailableError, SearchLimitError, TubeMPCError
from tubempc.mitl import parse
from tubempc.scenario import BUILTIN_SCENARIOS, builtin_scenario_text, dump_scenario, load_scenario
from verify.command import certify, digest_command
from verify.errors import MissingExtraError, VerifyError
from verify.online.command import watch

__all__ = ["EXIT_FAIL", "EXIT_INCONCLUSIVE", "EXIT_INTERNAL", "EXIT_NOT_AVAILABLE", "EXIT_OK", "EXIT_UNUSABLE",
           "cli", "main"]

EXIT_OK = 0
EXIT_FAIL = 1
EXIT_INCONCLUSIVE = 2
EXIT_UNUSABLE = 3
EXIT_NOT_AVAILABLE = 4
EXIT_INTERNAL = 70


@click.group(context_settings={"help_option_names": ["-h", "--help"]})
@click.version_option(None, "-V", "--version", package_name="tubempc")
@click.option("--debug", is_flag=True, help="Show full tracebacks instead of one-line errors.")
@click.pass_context
def cli(ctx: click.Context, debug: bool) -> None:
    """Plan timed robot missions with tube MPC under MITL, and certify their ROS logs."""
    ctx.ensure_object(dict)
    ctx.obj["debug"] = debug


@cli.group()
def scenario() -> None:
    """Inspect and validate scenario files."""


@scenario.command("list")
def scenario_list() -> None:
    """List the built-in scenarios (name, regions, formula); any of them is a valid --scenario value."""
    for name in BUILTIN_SCENARIOS:
        s = load_scenario(name)
        click.echo(f"{name}: {len(s.regions)} regions ({len(s.unsafe_regions)} unsafe), workspace "
                   f"{s.workspace.x[1] - s.workspace.x[0]:g} m x {s.workspace.y[1] - s.workspace.y[0]:g} m, "
                   f"spec {s.formula}")


@scenario.command("show")
@click.argument("name", default="nexus-sml")
def scenario_show(name: str) -> None:
    """Print a built-in scenario (default: the paper's Nexus setup) or a scenario file, as YAML."""
    if name in BUILTIN_SCENARIOS:
        click.echo(builtin_scenario_text(name), nl=False)
    else:
        click.echo(dump_scenario(load_scenario(name)), nl=False)


@scenario.command("validate")
@click.argument("path")
def scenario_validate(path: str) -> None:
    """Validate a scenario file; print a summary or one line naming the problem (exit 3).

    Then one line per geometry warning of the (lenient) certifier, and what keeps the (strict) planner from using
    the scenario, if anything: both name the field."""
    s = load_scenario(path)
    say(f"{path}: ok: scenario {s.name!r}, {len(s.regions)} regions "
               f"({len(s.unsafe_regions)} unsafe), spec {s.formula}, sha256 {s.sha256()[:16]}")
    for warning in s.certification_warnings():
        say(f"{path}: warning: {warning}")
    problems = s.planning_problems()
    if problems:
        field, what = problems[0]
        more = f" (and {len(problems) - 1} more)" if len(problems) > 1 else ""
        say(f"{path}: certification only: the planner cannot use it: {field}: {what}{more}")


@cli.group("schema")
def schema() -> None:
    """Print the JSON Schema of an output other programs parse."""


@schema.command("certificate")
def schema_certificate() -> None:
    """The JSON Schema of certificate.json and of `certify --json` (also docs/certificate.schema.json)."""
    import json

    from verify.certificate import certificate_schema

    click.echo(json.dumps(certificate_schema(), indent=2))


@schema.command("certify-json")
def schema_certify_json() -> None:
    """The JSON Schema of `certify --json`: a certificate, or a list of certificates and unusable logs."""
    import json

    from verify.certificate import certify_json_schema

    click.echo(json.dumps(certify_json_schema(), indent=2))


@cli.command("spec")
@click.argument("text")
def spec(text: str) -> None:
    """Parse an MITL formula and print its canonical form (exit 3 with the column of the error)."""
    click.echo(str(parse(text)))


cli.add_command(certify)
cli.add_command(digest_command)
cli.add_command(watch)
cli.add_command(plan)
cli.add_command(simulate)
cli.add_command(regress)
cli.add_command(demo)
cli.add_command(falsify)
cli.add_command(compare)
add_verbosity_options(cli)  # -q/--quiet and -v/--verbose on the group and on every subcommand


def _exit_code(err: BaseException) -> int:
    if isinstance(err, NotAvailableError | MissingExtraError):
        return EXIT_NOT_AVAILABLE
    if isinstance(err, NoAcceptingRunError):
        return EXIT_FAIL
    if isinstance(err, SearchLimitError):
        return EXIT_INCONCLUSIVE
    if isinstance(err, TubeMPCError | VerifyError):
        return EXIT_UNUSABLE
    return EXIT_INTERNAL


def _one_line(text: str, limit: int = 600) -> str:
    """An error message as one stderr line: lines joined with '; ', long messages cut at ``limit`` characters."""
    line = "; ".join(part.strip() for part in text.splitlines() if part.strip())
    return line if len(line) <= limit else line[: limit - 3] + "..."


def main(argv: list[str] | None = None) -> NoReturn:
    """Console entry point: run the CLI, turning expected errors into one stderr line and an exit code.

    ``--debug`` prints the traceback before that line; it never changes the exit code."""
    args = sys.argv[1:] if argv is None else argv
    debug = "--debug" in args
    try:
        with warnings.catch_warnings():
            # numeric edge cases of damaged data and matplotlib's degenerate axes are handled by the code; their
            # library warnings are not the user's business (one stderr line per error is the contract)
            warnings.filterwarnings("ignore", category=RuntimeWarning, module=r"(numpy|verify|pandas)(\..*)?")
            warnings.filterwarnings("ignore", category=UserWarning, module=r"(matplotlib|verify)(\..*)?")
            # standalone_mode=False turns ctx.exit(code) / sys.exit(code) inside a command into a return value
            code = cli.main(args=args, prog_name="tubempc", standalone_mode=False)
    except click.exceptions.Exit as err:
        sys.exit(err.exit_code)
    except click.Abort:
        click.echo("tubempc: aborted", err=True)
        sys.exit(130)
    except click.ClickException as err:
        err.show()
        sys.exit(EXIT_UNUSABLE if err.exit_code == 2 else err.exit_code)
    except (TubeMPCError, VerifyError) as err:
        if debug:
            traceback.print_exc()
        click.echo(f"tubempc: error: {_one_line(str(err))}", err=True)
        sys.exit(_exit_code(err))
    except KeyboardInterrupt:
        click.echo("tubempc: interrupted", err=True)
        sys.exit(130)
    except Exception as err:
        if debug:
            traceback.print_exc()
        hint = "" if debug else " (rerun with --debug for the traceback)"
        click.echo(f"tubempc: internal error: {err.__class__.__name__}: {_one_line(str(err))}{hint}", err=True)
        sys.exit(EXIT_INTERNAL)
    sys.exit(code if isinstance(code, int) else EXIT_OK)
