"""The ``tubempc simulate`` subcommand: one closed-loop transition -> a ROS log and a printed summary.

input: a scenario (file or built-in name), source and target regions, disturbance model, seed, output path ->
output: the log at ``--out`` (``.mcap`` ROS2 by default, ``.bag`` ROS1, ``.db3``, or a bag directory) and a
summary on stdout: t_ij (Algorithm 1), arrival time, max |q| against r_q, largest body-frame command, solver
statistics. Exit 0 when the target was reached, 1 when it was not, 3 for unusable input.
"""

from __future__ import annotations

from typing import TYPE_CHECKING

import click

from tubempc.cli.exits import EXIT_FAIL, leave
from tubempc.cli.options import load_scenario_ref, scenario_option
from tubempc.cli.output import say

if TYPE_CHECKING:
    from tubempc.scenario import Scenario

__all__ = ["simulate"]

EXIT_NOT_REACHED = EXIT_FAIL


@click.command()
@scenario_option()
@click.option("--from", "source", default=None, help="Start region (default: the scenario's initial region).")
@click.option("--to", "target", required=True, help="Target region.")
@click.option("--disturbance", type=click.Choice(["none", "random", "worst", "bias", "sine"]), default="random",
              show_default=True)
@click.option("--seed", type=int, default=0, show_default=True)
@click.option("--mocap-noise", "mocap_noise_m", type=float, default=0.0, show_default=True,
              help="Standard deviation (m) of simulated MoCap position noise.")
@click.option("--hold", "hold_s", type=float, default=None,
              help="Keep simulating until this time (s), holding position in the target.")
@click.option("--out", "out_path", required=True, type=click.Path(dir_okay=True),
              help="Output log: .mcap (ROS2), .bag (ROS1), .db3, or a directory name for a ROS2 bag.")
@click.option("--force", is_flag=True, help="Replace an existing log at --out.")
@click.option("--controller", "controller_spec", default=None, metavar="PACKAGE.MODULE:FACTORY",
              help="Run your own controller (docs/controller.md, 'Your controller in the loop') instead of the tube "
                   "MPC; --to may list several targets, comma-separated.")
def simulate(*, scenario: str, source: str | None, target: str, disturbance: str, seed: int, mocap_noise_m: float,
             hold_s: float | None, out_path: str, force: bool, controller_spec: str | None) -> None:
    """Simulate the tube MPC (or your --controller) from one region to another and write the robot's log."""
    from runkit.extras import require

    require("plan", feature="tubempc simulate")
    import numpy as np

    from runkit.outputs import prepare_output_log, replace_output_log
    from tubempc.control import Target, run_closed_loop
    from tubempc.errors import DesignError
    from tubempc.rosio import write_log

    prepare_output_log(out_path, force=force)
    sc = load_scenario_ref(scenario)
    if controller_spec is not None:
        _simulate_controller(sc, controller_spec, source=source, targets=target.split(","),
                             disturbance=disturbance, seed=seed, mocap_noise_m=mocap_noise_m, hold_s=hold_s,
                             out_path=out_path, force=force)
        return
    sc.require_planning()  # exit 3 naming the field the controller needs (or its unicycle/polygon problem)
    try:
        result = run_closed_loop(sc, [Target(target)], start_region=source, disturbance=disturbance, seed=seed,
                                 t_end_s=hold_s, mocap_noise_m=mocap_noise_m)
    except DesignError as err:  # exit 3, and the line names the scenario file
        raise DesignError(f"{scenario}: the tube MPC cannot be designed for this scenario: {err}") from err
    if force:
        replace_output_log(out_path)
    path = write_log(result, sc, out_path)
    arrival = result.arrivals[0]
    times_ms = np.array([r.solve_time_s for r in result.solver]) * 1e3
    iters = np.array([r.iterations for r in result.solver])
    t_ij = "not reached" if arrival.t_ij_s is None else f"{arrival.t_ij_s:.1f} s"
    inside = "never" if arrival.inside_s is None else f"{arrival.inside_s:.2f} s"
    say(f"{result.start_region} -> {target}: t_ij = {t_ij} (Algorithm 1), robot inside {target} at {inside}")
    say(f"tube: max |x - x_hat| = {result.max_tube_error_m:.5f} m vs r_q = {result.tube_radius_m:.5f} m "
               f"(sigma = {result.sigma:.4g}, disturbance {disturbance}, seed {seed})")
    say(f"input: max |u_body| per axis = {np.round(np.max(np.abs(result.u_body), axis=0), 4).tolist()}")
    say(f"solver: {len(result.solver)} solves, {sum(r.success for r in result.solver)} succeeded, "
               f"{sum(r.backup for r in result.solver)} backups; solve time median {np.median(times_ms):.3f} ms, "
               f"p95 {np.percentile(times_ms, 95):.3f} ms, max {np.max(times_ms):.3f} ms; iterations median "
               f"{np.median(iters):.0f}, max {np.max(iters)}")
    say(f"log: {path}")
    if not result.ok:
        click.echo(f"tubempc: {result.reason}", err=True)
        leave(EXIT_NOT_REACHED)


def _simulate_controller(scenario: Scenario, spec: str, *, source: str | None, targets: list[str],
                         disturbance: str, seed: int, mocap_noise_m: float, hold_s: float | None, out_path: str,
                         force: bool) -> None:
    """``--controller``: the user's controller on the kinematic plant of its input model (``tubempc.control.user``)."""
    import numpy as np

    from runkit.outputs import replace_output_log
    from tubempc.control import Target
    from tubempc.control.user import checked_controller, run_controller
    from tubempc.rosio import write_log

    controller = checked_controller(spec, scenario)
    result = run_controller(scenario, controller, [Target(t.strip()) for t in targets], start_region=source,
                            disturbance=disturbance, seed=seed, t_end_s=hold_s, mocap_noise_m=mocap_noise_m)
    if force:
        replace_output_log(out_path)
    path = write_log(result, scenario, out_path, metadata={"controller": spec})
    for arrival in result.arrivals:
        inside = "never" if arrival.inside_s is None else f"{arrival.inside_s:.2f} s"
        say(f"{arrival.region}: robot inside at {inside}")
    say(f"input: max |command| (linear.x, linear.y, angular.z) = "
        f"{np.round(np.max(np.abs(result.u_body), axis=0), 4).tolist()} ({controller.input_model})")
    say(f"log: {path}")
    if not result.ok:
        click.echo(f"tubempc: {result.reason}", err=True)
        leave(EXIT_NOT_REACHED)
