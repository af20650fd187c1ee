"""The ``tubempc scenario`` group (list, show, init, validate), ``tubempc schema`` and ``tubempc spec``.

``scenario init LOG``: a commented starting scenario from a log (``tubempc.scaffold``) on stdout.
``scenario validate S [--log LOG]``: the scenario's own problems (all of them, one line, exit 3), then with
``--log`` what keeps it from certifying that log (``verify.scenario_check``: every problem on one line, exit 3) and
what the data say about it (warnings); the geometry warnings of the lenient certifier; what keeps the strict planner
from using it.
"""

from __future__ import annotations

import json
from pathlib import Path

import click

from tubempc.cli.output import say

__all__ = ["scenario", "schema", "spec"]


@click.group()
def scenario() -> None:
    """Inspect, scaffold and validate scenario files."""


@scenario.command("list")
def scenario_list() -> None:
    """List the built-in scenarios (name, regions, formula); any of them is a valid --scenario value."""
    from tubempc.scenario import BUILTIN_SCENARIOS, load_scenario

    for name in BUILTIN_SCENARIOS:
        s = load_scenario(name)
        click.echo(f"{name}: {len(s.regions)} regions ({len(s.unsafe_regions)} unsafe), workspace "
                   f"{s.workspace.x[1] - s.workspace.x[0]:g} m x {s.workspace.y[1] - s.workspace.y[0]:g} m, "
                   f"spec {s.formula}")


@scenario.command("show")
@click.argument("name", default="nexus-sml")
def scenario_show(name: str) -> None:
    """Print a built-in scenario (default: the paper's Nexus setup) or a scenario file, as YAML."""
    from tubempc.scenario import BUILTIN_SCENARIOS, builtin_scenario_text, dump_scenario, load_scenario

    if name in BUILTIN_SCENARIOS:
        click.echo(builtin_scenario_text(name), nl=False)
    else:
        click.echo(dump_scenario(load_scenario(name)), nl=False)


@scenario.command("init")
@click.argument("log", type=click.Path(path_type=Path))
@click.option("--pose-topic", default=None, metavar="TOPIC",
              help="The pose topic (default: the first PoseStamped, else Odometry, else a /tf child frame; "
                   "/tf#FRAME for a child frame of /tf).")
@click.option("--name", default=None, help="The scenario's name (default: my-lab).")
def scenario_init(log: Path, pose_topic: str | None, name: str | None) -> None:
    """Print a commented starting scenario for LOG (`tubempc scenario init LOG > my-lab.yaml`): its topics, a
    workspace box around the data, input limits from the commands, the robot radius and formula as placeholders.
    It certifies LOG (pass or inconclusive) before any edit; the lines to edit are marked EDIT."""
    from tubempc.scaffold import scenario_text
    from verify.info import log_info

    click.echo(scenario_text(log_info(log), pose_topic=pose_topic, name=name), nl=False)


@scenario.command("validate")
@click.argument("path")
@click.option("--log", "log", default=None, type=click.Path(path_type=Path),
              help="Also check the scenario against this log: topics present with usable types, signal fields "
                   "present and numeric, the data inside the workspace, coordinates in metres.")
def scenario_validate(path: str, log: Path | None) -> None:
    """Validate a scenario file; print a summary, or one line listing every problem (exit 3).

    Then one line per warning of the (lenient) certifier, and what keeps the (strict) planner from using the
    scenario, if anything: each names the field."""
    from tubempc.errors import ScenarioError
    from tubempc.scenario import Scenario, load_scenario

    s = load_scenario(path)
    if log is not None:
        from verify.ingest import read_log
        from verify.scenario_check import data_findings, scenario_problems

        problems = scenario_problems(s, log)
        if problems:
            raise ScenarioError(f"cannot certify {log}: {'; '.join(problems)}", source=path)
        each: list[tuple[str | None, Scenario]] = [(r.name, s.robot_scenario(r.name)) for r in s.robots]
        for name, one in each or [(None, s)]:
            data = read_log(log, one)
            every = data.pose_samples
            findings = data_findings(one, every.t_ns, every.x_m, every.y_m, data.time0_ns)
            span_s = (every.t_ns[-1] - every.t_ns[0]) * 1e-9 if every.t_ns.size else 0.0
            who = f" (robot {name})" if name else ""
            say(f"{path}: ok with {log}{who}: pose {data.pose_source.get('topic', one.topics.pose)}, "
                f"{every.t_ns.shape[0]} samples over {span_s:.3f} s")
            for finding in findings:
                say(f"{path}: warning: {finding}" if name is None else f"{path}: warning: {name}: {finding}")
    say(f"{path}: ok: scenario {s.name!r}, {len(s.regions)} regions "
        f"({len(s.unsafe_regions)} unsafe), spec {s.formula}, sha256 {s.sha256()[:16]}")
    for warning in s.certification_warnings():
        say(f"{path}: warning: {warning}")
    problems_planning = s.planning_problems()
    if problems_planning:
        field, what = problems_planning[0]
        more = f" (and {len(problems_planning) - 1} more)" if len(problems_planning) > 1 else ""
        say(f"{path}: certification only: the planner cannot use it: {field}: {what}{more}")


@click.group("schema")
def schema() -> None:
    """Print the JSON Schema of an output other programs parse."""


@schema.command("certificate")
def schema_certificate() -> None:
    """The JSON Schema of certificate.json and of `certify --json` (also docs/certificate.schema.json)."""
    from verify.certificate import certificate_schema

    click.echo(json.dumps(certificate_schema(), indent=2))


@schema.command("certify-json")
def schema_certify_json() -> None:
    """The JSON Schema of `certify --json`: a certificate, or a list of certificates and unusable logs."""
    from verify.certificate import certify_json_schema

    click.echo(json.dumps(certify_json_schema(), indent=2))


@schema.command("info")
def schema_info() -> None:
    """The JSON Schema of `tubempc info --json` (also docs/info.schema.json)."""
    from verify.info import info_schema

    click.echo(json.dumps(info_schema(), indent=2))


@click.command("spec")
@click.argument("text")
def spec(text: str) -> None:
    """Parse an MITL formula and print its canonical form (exit 3 with the column of the error)."""
    from tubempc.mitl import parse

    click.echo(str(parse(text)))
