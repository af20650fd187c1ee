"""The ``tubempc plan`` subcommand: scenario (+ formula) -> WTS by Algorithm 1 -> timed run table (and JSON).

``--dwell silent`` (default): waits add no position, the run lists the arrivals a log will show and the targets carry
the planned departure times; ``--dwell observed``: each dwell is a position; ``--no-wait``: no waiting at all.

``--objective time`` (default): the plan is time-optimal (its last obligation met as early as any run on the tick
grid allows) and re-timed for margin only where that keeps the optimum; ``--objective margin``: re-timed for the
largest margin even if later.

Exit codes: 0 a plan was found; 1 no accepting run (proved by the exact search; the message names a conjunct set
only when that set alone is proved unsatisfiable); 2 undecided: the search reached ``--max-states`` (raise it);
3 unusable input (a scenario the planner cannot abstract: a missing controller field, a unicycle input model,
polygon shapes, overlapping regions; or every transition failing the controller's design check, named); 4 the
controller (Algorithm 1) is not available.
"""

from __future__ import annotations

import json
import math
from pathlib import Path

import click

from tubempc.cli.options import load_scenario_ref, scenario_option
from tubempc.cli.output import say

__all__ = ["plan"]


@click.command("plan")
@scenario_option()
@click.option("--spec", "spec_text", default=None, help="MITL formula (default: the scenario's spec).")
@click.option("--no-wait", is_flag=True, help="Strict WTS of the paper: no dwelling in a region.")
@click.option("--dwell", type=click.Choice(["silent", "observed"]), default="silent", show_default=True,
              help="silent: a wait in a region adds no position (the move after it arrives later; what a log "
                   "shows); observed: each dwell is a position of the planned run.")
@click.option("--objective", type=click.Choice(["time", "margin"]), default="time", show_default=True,
              help="time: keep the time-optimal run's cost when re-timing for margin; margin: largest margin even "
                   "if the last obligation is then met later.")
@click.option("--max-states", type=click.IntRange(min=1), default=None,
              help="Product states a search may create before it gives up undecided (exit 2); default 500000.")
@click.option("--json", "json_out", type=click.Path(dir_okay=False, writable=True), default=None,
              help="Write the plan as JSON to this file.")
@click.option("--no-cache", is_flag=True, help="Rebuild the abstraction even when it is cached.")
@click.option("--workers", type=int, default=None, help="Processes for the abstraction (default: all cores).")
@click.option("--dask", "dask_address", default=None, help="Dask scheduler address for the abstraction.")
@click.option("--dot", "dot_out", type=click.Path(dir_okay=False, writable=True), default=None,
              help="Write the explored product graph as Graphviz DOT.")
def plan(*, scenario: str, spec_text: str | None, no_wait: bool, dwell: str, objective: str,
         max_states: int | None, json_out: str | None, no_cache: bool, workers: int | None, dask_address: str | None,
         dot_out: str | None) -> None:
    """Plan a time-optimal timed run of the scenario's WTS that satisfies the MITL formula."""
    from runkit.extras import require

    require("plan", *(("dask",) if dask_address else ()), feature="tubempc plan")
    from tubempc.control.dynamics import model_for
    from tubempc.control.tube import design_tube
    from tubempc.errors import DesignError
    from tubempc.mitl import parse
    from tubempc.planning.plan import plan_from_run, require_transitions
    from tubempc.planning.search import DEFAULT_MAX_STATES, export_dot, find_run
    from tubempc.planning.wts import build_wts, wts_oracle

    sc = load_scenario_ref(scenario)
    sc.require_planning()  # exit 3 naming the field: missing controller data, unicycle, polygons, overlaps
    formula = parse(spec_text) if spec_text is not None else sc.formula
    try:  # an impossible design is unusable input (exit 3), not "no accepting run" over a WTS without edges
        design_tube(sc, model_for(sc))
    except DesignError as err:
        raise DesignError(f"{scenario}: the tube MPC cannot be designed for this scenario: {err}") from err
    wts = build_wts(sc, use_cache=not no_cache, workers=workers, dask=dask_address)
    require_transitions(wts, scenario_name=sc.name)
    limit = max_states if max_states is not None else DEFAULT_MAX_STATES
    found = find_run(wts, formula, wait=not no_wait, dwell=dwell, initial=sc.initial_region, max_states=limit)
    result = plan_from_run(wts, formula, found, wait=not no_wait, objective=objective)
    say(f"scenario {sc.name} ({wts.number_of_nodes()} safe regions, {wts.number_of_edges()} "
        f"transitions, weights from {wts_oracle(wts)}); formula {formula}")
    say(f"{'region':<8} {'time [s]':>10}  {'kind':<6} labels")
    for k, ((region, t), kind) in enumerate(zip(result.run, result.kinds, strict=True)):
        mark = "  <- repeats from here" if k == result.loop_start and result.period_s > 0 else ""
        labels = ",".join(result.labels.get(region, ())) or "-"
        say(f"{region:<8} {t:>10.3f}  {kind:<6} {labels}{mark}")
    if result.period_s > 0:
        say(f"repeating part: from position {result.loop_start}, period {result.period_s:.3f} s")
    else:
        say(f"the run ends in {result.run[-1][0]}: the robot stays there (no further position)")
    say(f"waits: {result.dwell}; controller targets (region, planned arrival, depart after):")
    for tg in result.targets:
        depart = "-" if tg.depart_after_s is None else f"{tg.depart_after_s:.3f}"
        say(f"  {tg.region:<8} {tg.arrival_s:>10.3f} {depart:>10}")
    margin = "inf (no timing constraint)" if math.isinf(result.margin_s) else f"{result.margin_s:.3f} s"
    say(f"margin to interval endpoints: {margin} (objective {result.objective}); search "
        f"{result.search_s * 1000:.1f} ms, {result.product_states} product states ({result.method})")
    if json_out is not None:
        Path(json_out).write_text(json.dumps(result.to_json(), indent=2) + "\n")
    if dot_out is not None:  # the explored product of the one search above
        Path(dot_out).write_text(export_dot(found.explored()))
