"""The ``tubempc falsify`` subcommand: search the admissible perturbations of a run for the one that breaks it.

input: a scenario, a run (``--from/--to`` or ``--plan``), a method, a budget and a seed (plus the search space and
``--set`` overrides of what the controller runs with) -> output: a summary on stdout, ``falsify.json`` and the
worst case's log, certificate and report under ``--out``. ``--replay Z`` simulates one point of a previous search.

Exit codes: 1 a violation was found; 0 none within the budget (the lowest margin is printed); 2 no violation but
some run could not be fully checked; 3 unusable input (bad scenario, region, override or an impossible design).
"""

from __future__ import annotations

import math
import time
from pathlib import Path
from typing import TYPE_CHECKING, cast

import click

from tubempc.cli.exits import EXIT_FAIL, EXIT_OK, leave
from tubempc.cli.options import load_scenario_ref, scenario_option

if TYPE_CHECKING:
    from tubempc.falsify.search import Method
    from tubempc.falsify.space import Family

__all__ = ["falsify"]


def _g(value: object, spec: str = ".9g") -> str:
    """A number for the summary lines; ``-`` for a missing or non-finite one (nothing was simulated or judged)."""
    if isinstance(value, int | float) and not isinstance(value, bool) and math.isfinite(value):
        return format(value, spec)
    return "-"


def _z(text: str) -> tuple[float, ...]:
    try:
        values = tuple(float(v) for v in text.split(","))
    except ValueError:
        raise click.BadParameter(f"{text!r}: expected comma-separated numbers in [-1, 1]") from None
    if not values or not all(math.isfinite(v) and abs(v) <= 1.0 for v in values):
        raise click.BadParameter(f"{text!r}: every coordinate must be a number in [-1, 1]")
    return values


@click.command("falsify")
@scenario_option(extra="The claims the runs are judged against.")
@click.option("--from", "source", default=None, help="Start region of one transition (default: initial region).")
@click.option("--to", "target", default=None,
              help="Target region of one transition (several, comma-separated: through each in turn).")
@click.option("--plan", is_flag=True, help="Run the scenario's planned mission instead of one transition.")
@click.option("--budget", type=click.IntRange(min=1), default=100, show_default=True,
              help="Simulations the search may spend before its first violation.")
@click.option("--method", type=click.Choice(["random", "targeted", "optimizer"]), default="targeted",
              show_default=True, help="random: uniform in the search space; targeted: hypothesis with target() "
                                      "and shrinking; optimizer: differential evolution (scipy).")
@click.option("--seed", type=int, default=0, show_default=True)
@click.option("--family", type=click.Choice(["steps", "sine", "switch"]), default="steps", show_default=True,
              help="Disturbance family: piecewise constant, sinusoids per axis, or the worst-case direction with "
                   "switching times.")
@click.option("--knots", type=click.IntRange(min=1), default=4, show_default=True,
              help="steps: values per axis over the run.")
@click.option("--switches", type=click.IntRange(min=1), default=3, show_default=True,
              help="switch: switching times over the run.")
@click.option("--bound-scale", type=float, default=1.0, show_default=True,
              help="Search disturbances up to this times the scenario's bound (> 1 stress-tests past the design).")
@click.option("--fixed-start", is_flag=True, help="Start at the region's centre (do not search the terminal set).")
@click.option("--checks", "checks_text", default="tube,obstacle_clearance,input_box,workspace,spec_trajectory",
              show_default=True, help="Comma-separated checks whose smallest margin is minimised.")
@click.option("--spec", default=None, help="MITL formula (default: the scenario's with --plan; for a transition, "
                                           "clear of every obstacle and reaching the target's labels).")
@click.option("--set", "overrides", multiple=True, metavar="KEY=VALUE",
              help="Change what the controller runs with (e.g. tube.sigma_low=0.5); the checks keep the scenario's "
                   "claims. Repeatable.")
@click.option("--horizon", "horizon_s", type=float, default=None,
              help="Seconds the knots/switches spread over (default: the unperturbed run's length).")
@click.option("--first", "stop_at_first", is_flag=True, help="Stop at the first violation (no shrinking).")
@click.option("--shrink-budget", type=click.IntRange(min=0), default=None,
              help="targeted: simulations for shrinking a counterexample (default: the budget).")
@click.option("--replay", "replay_text", default=None, metavar="Z",
              help="Simulate this one point (from a previous falsify.json) and write its log and certificate.")
@click.option("--workers", type=click.IntRange(min=1), default=None,
              help="Parallel processes (default: CPU count; 1 runs in this process).")
@click.option("--dask", default=None, metavar="local|tcp://HOST:PORT", help="Run the simulations on Dask.")
@click.option("--out", "out_dir", type=click.Path(file_okay=False), default=None,
              help="Output folder (default: reports/falsify-<time>).")
@click.option("--controller", "controller", default=None, metavar="PACKAGE.MODULE:FACTORY",
              help="Search against your own controller instead of the tube MPC (docs/controller.md).")
def falsify(*, scenario: str, source: str | None, target: str | None, plan: bool, budget: int, method: str,
            seed: int, family: str, knots: int, switches: int, bound_scale: float, fixed_start: bool,
            checks_text: str, spec: str | None, overrides: tuple[str, ...], horizon_s: float | None,
            stop_at_first: bool, shrink_budget: int | None, replay_text: str | None, workers: int | None,
            dask: str | None, out_dir: str | None, controller: str | None) -> None:
    """Search disturbances, start poses and MoCap noise within the scenario's bounds for a run that breaks a check."""
    import os
    import tempfile

    from runkit.extras import require

    # hypothesis caches what it learns about the code under test in its storage folder (./.hypothesis unless
    # HYPOTHESIS_STORAGE_DIRECTORY says otherwise): a scratch folder removed when the command ends keeps the
    # working folder clean (docs/falsify.md: no files outside --out); the worker processes inherit it
    if "HYPOTHESIS_STORAGE_DIRECTORY" not in os.environ:
        ctx = click.get_current_context()
        ctx.call_on_close(lambda: os.environ.pop("HYPOTHESIS_STORAGE_DIRECTORY", None))
        os.environ["HYPOTHESIS_STORAGE_DIRECTORY"] = ctx.with_resource(
            tempfile.TemporaryDirectory(prefix="tubempc-falsify-"))

    require("plan", *(("testing",) if method == "targeted" else ()), *(("dask",) if dask else ()),
            feature=f"tubempc falsify --method {method}")
    from tubempc.cli.output import detail, say
    from tubempc.falsify import (
        FalsifyRequest,
        apply_overrides,
        evaluate,
        prepare,
        run_falsify,
        write_case,
        write_outcome,
    )

    sc = load_scenario_ref(scenario)
    apply_overrides(sc, overrides)  # a bad override is one line on stderr before anything else
    if horizon_s is not None and not (math.isfinite(horizon_s) and horizon_s > 0):
        raise click.BadParameter(f"--horizon {horizon_s!r} must be a positive number")
    # click.Choice has checked both against the same names as the Literal types
    req = FalsifyRequest(scenario_ref=scenario, source=source, target=target, plan=plan,
                         method=cast("Method", method), budget=budget, seed=seed, family=cast("Family", family),
                         knots=knots, switches=switches,
                         bound_scale=bound_scale, vary_start=not fixed_start,
                         checks=tuple(c.strip() for c in checks_text.split(",") if c.strip()), spec=spec,
                         overrides=overrides, horizon_s=horizon_s, stop_at_first=stop_at_first,
                         shrink_budget=shrink_budget, controller=controller)
    out = Path(out_dir) if out_dir is not None else Path("reports") / f"falsify-{time.strftime('%Y%m%d-%H%M%S')}"
    if replay_text is not None:
        z = _z(replay_text)
        setup, _ = prepare(req, sc)
        if len(z) != setup.space.dim:
            raise click.BadParameter(f"--replay has {len(z)} coordinates; this search space has {setup.space.dim} "
                                     f"({', '.join(setup.space.names())})")
        ev = evaluate(setup, z)
        if ev.error is not None:
            raise click.ClickException(f"the replayed run failed: {ev.error}")
        files = write_case(setup, ev, out, metadata={"replay": list(z)})
        state = "VIOLATION" if ev.violated else "no violation"
        say(f"replay: {state}: margin {_g(ev.margin)} ({ev.worst_check}) in memory, "
                   f"{_g(files['margin_from_log'])} ({files['check_from_log']}) from the written log; certificate "
                   f"verdict {files['certificate_verdict']}")
        say(f"log: {files['log']}\ncertificate: {files['certificate']}\nreport: {files['report_html']}")
        leave(EXIT_FAIL if files["violated_from_log"] else EXIT_OK)

    detail(f"falsify: scenario {sc.name}, method {method}, budget {budget}, seed {seed}, family {family}"
           + (f", controller overrides {', '.join(overrides)}" if overrides else ""))
    outcome = write_outcome(run_falsify(req, sc, workers=workers, dask=dask), out)
    data = outcome.to_json()
    ref = data["reference"]
    say(f"unperturbed run: margin {_g(ref['margin'])} ({ref['check']}), {_g(ref['duration_s'], '.1f')} s")
    shrink = f" + {data['shrink_simulations']} shrinking" if data["shrink_simulations"] else ""
    if ref.get("violated"):
        say("search: none (the unperturbed run already violates: it is the counterexample, simulation 0)")
    else:
        say(f"search: {data['simulations']} simulations{shrink} ({data['search_space']['dim']} parameters), "
            f"{_g(data['timing']['elapsed_s'], '.1f')} s; median {_g(data['timing']['simulation_s_median'], '.3f')} "
            f"s per simulation + {_g(data['timing']['judge_s_median'], '.3f')} s to judge it")
    worst = data["worst"]
    if worst is not None:
        first = data["first_violation_sim"]
        found = f"VIOLATION first found at simulation {first}" if first is not None else "no violation found"
        say(f"{found}; worst margin {_g(worst['margin'])} ({worst['check']}) at simulation {worst['sim']}")
        if data["minimal"] is not None and data["minimal"]["sim"] != worst["sim"]:
            mini = data["minimal"]
            say(f"shrunk counterexample: margin {_g(mini['margin'])} ({mini['check']})\n"
                       f"  replay: {mini['replay']}")
        say(f"worst case: certificate verdict {data['files']['worst']['certificate_verdict']} (from the "
                   f"written log: margin {_g(data['files']['worst']['margin_from_log'])})\n  replay: {worst['replay']}")
    say(f"verdict: {data['verdict']}; {out / 'falsify.json'}")
    leave(outcome.exit_code)
