"""Suite runs -> metrics: simulate with the current controller, write the log, certify it, measure.

input: ``RunCase`` values (from ``expand_suite``) -> output: one ``RunOutcome`` per case with a flat metric dict:
``verdict`` and ``check.<name>.verdict`` / ``check.<name>.margin`` from the certificate of the written log;
``arrived``, ``t_ij_s.<k>.<region>`` (Algorithm 1), ``tube_ratio`` (max |x - x_hat| / r_q of the scenario),
``max_tube_error_m``, ``min_clearance_m`` (robot disc to the nearest unsafe region), ``workspace_margin_m``,
``input_margin`` (min over time and axes of max_abs_i - |u_i| of the logged body-frame command),
``solver_failures``, ``solver_backups``, ``solve_time_p50_ms``, ``solve_time_p95_ms``.

A falsification case (``FalsifyCase``) searches its run with its budget (``tubempc falsify``, in the worker, one
simulation at a time) and has the metrics ``falsify.violation`` (a counterexample was found: regresses where the
baseline had none), ``falsify.margin`` (the lowest margin found), ``falsify.first_violation_sim`` and
``falsify.simulations``; with ``out_dir`` its ``falsify.json`` and the worst case's log and certificate are kept.

A run that cannot be executed (design refused, log not certifiable) is an outcome with ``error`` set, never an
exception, so that one broken case does not hide the others.
"""

from __future__ import annotations

import math
import tempfile
import time
from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np

from tubempc.errors import TubeMPCError
from tubempc.regress.suite import FalsifyCase, RunCase
from tubempc.scenario import Scenario

if TYPE_CHECKING:
    from verify.certificate import Certificate

__all__ = ["RunJob", "RunOutcome", "closed_loop_metrics", "falsify_metrics", "run_case", "run_cases"]


@dataclass(frozen=True, slots=True)
class RunOutcome:
    run_id: str
    metrics: dict[str, Any]
    error: str | None
    elapsed_s: float
    log_path: str | None


@dataclass(frozen=True, slots=True)
class RunJob:
    """A case plus where to put its log and certificate (``out_dir`` None: a temporary folder, removed)."""

    case: RunCase | FalsifyCase
    out_dir: str | None
    reports: bool = False
    controller: str | None = None  # ``package.module:factory`` run instead of the tube MPC (tubempc.control.user)


def closed_loop_metrics(result: Any, scenario: Scenario) -> dict[str, Any]:
    """Metrics of a ``ClosedLoopResult`` measured on the real state and the logged command."""
    x = np.asarray(result.x, dtype=float)
    x_hat = np.asarray(result.x_hat, dtype=float)
    u_body = np.asarray(result.u_body, dtype=float)
    eta = scenario.robot.radius
    err_m = float(np.max(np.linalg.norm(x - x_hat, axis=1))) if len(x) else 0.0
    # a controller without a nominal state (NaN) or a scenario without a tube has no tube metrics
    tube = math.isfinite(err_m) and scenario.tube_spec is not None
    metrics: dict[str, Any] = {
        "arrived": bool(result.ok),
        "max_tube_error_m": err_m if tube else None,
        "tube_ratio": err_m / scenario.tube_radius_m if tube else None,
    }
    for k, arrival in enumerate(result.arrivals):
        metrics[f"t_ij_s.{k}.{arrival.region}"] = arrival.t_ij_s
    if len(x):
        clear = [np.hypot(x[:, 0] - r.center[0], x[:, 1] - r.center[1]) - r.radius - eta
                 for r in scenario.unsafe_regions]
        metrics["min_clearance_m"] = float(np.min(clear)) if clear else None
        ws = scenario.workspace
        margins = np.stack([x[:, 0] - eta - ws.x[0], ws.x[1] - eta - x[:, 0], x[:, 1] - eta - ws.y[0],
                            ws.y[1] - eta - x[:, 1]])
        metrics["workspace_margin_m"] = float(np.min(margins))
        limits = scenario.inputs
        bounds = np.asarray(limits.max_abs if limits.model == "holonomic" else  # (vx, vy, wz) as logged
                            (limits.max_abs[0], limits.lateral_tolerance, limits.max_abs[1]), dtype=float)
        metrics["input_margin"] = float(np.min(bounds[None, :] - np.abs(u_body)))
    solve_ms = np.array([r.solve_time_s for r in result.solver], dtype=float) * 1e3
    metrics["solver_failures"] = sum(1 for r in result.solver if not r.success)
    metrics["solver_backups"] = sum(1 for r in result.solver if r.backup)
    metrics["solve_time_p50_ms"] = float(np.percentile(solve_ms, 50)) if len(solve_ms) else None
    metrics["solve_time_p95_ms"] = float(np.percentile(solve_ms, 95)) if len(solve_ms) else None
    return metrics


def certificate_metrics(certificate: Certificate) -> dict[str, Any]:
    """``verdict``, ``check.<name>.verdict`` and ``check.<name>.margin`` (finite margins only) of a certificate."""
    metrics: dict[str, Any] = {"verdict": str(certificate.verdict)}
    for check in certificate.checks:
        metrics[f"check.{check.name}.verdict"] = str(check.verdict)
        if check.margin is not None and math.isfinite(check.margin):
            metrics[f"check.{check.name}.margin"] = float(check.margin)
    return metrics


def _run_in(case: RunCase, folder: Path, reports: bool, controller: str | None = None) -> tuple[dict[str, Any], str]:
    from tubempc.control.closed_loop import Target, run_closed_loop
    from tubempc.rosio import write_log
    from verify import certify_log, write_certificate  # type: ignore[attr-defined,unused-ignore]

    targets = [Target(region, depart) for region, depart in case.targets]
    if controller is None:
        result = run_closed_loop(case.scenario, targets, start_region=case.start, disturbance=case.disturbance,
                                 seed=case.seed, t_end_s=case.t_end_s, mocap_noise_m=case.mocap_noise_m)
    else:
        from tubempc.control.user import checked_controller, run_controller

        result = run_controller(case.scenario, checked_controller(controller, case.scenario), targets,
                                start_region=case.start, disturbance=case.disturbance, seed=case.seed,
                                t_end_s=case.t_end_s, mocap_noise_m=case.mocap_noise_m)
    folder.mkdir(parents=True, exist_ok=True)
    (folder / "run.mcap").unlink(missing_ok=True)  # a previous regress run into the same --out folder
    extra = {"regress_run": case.run_id, "spec": case.spec, **({"controller": controller} if controller else {})}
    log = write_log(result, case.scenario, folder / "run.mcap", metadata=extra)
    certified = certify_log(log, case.scenario, spec=case.spec)
    write_certificate(certified, folder)
    if reports:
        from verify.report import write_reports

        write_reports(certified, case.scenario, folder, suite_name=case.run_id)
    metrics = closed_loop_metrics(result, case.scenario)
    metrics.update(certificate_metrics(certified.typed))
    return metrics, str(log)


def falsify_metrics(case: FalsifyCase, out_dir: Path | None, controller: str | None = None) -> dict[str, Any]:
    """Run one falsification case (inline); its metrics. With ``out_dir``: falsify.json and the worst case there.
    ``controller``: a user's controller searched instead of the tube MPC."""
    from tubempc.falsify import FalsifyRequest, run_falsify, write_outcome

    f = case.spec
    req = FalsifyRequest(scenario_ref=case.scenario_ref, source=f.start, target=f.target, plan=f.plan,
                         method=f.method, budget=f.budget, seed=f.seed, family=f.family, knots=f.knots,
                         switches=f.switches, bound_scale=f.bound_scale, vary_start=not f.fixed_start,
                         controller=controller)
    outcome = run_falsify(req, case.scenario, workers=1)
    if out_dir is not None:
        outcome = write_outcome(outcome, out_dir)
    worst = outcome.result.worst
    return {"falsify.violation": outcome.verdict == "fail",
            "falsify.margin": None if worst is None or not math.isfinite(worst.margin) else worst.margin,
            "falsify.first_violation_sim": outcome.result.first_violation,
            "falsify.simulations": len(outcome.result.evaluations)}


def run_case(job: RunJob) -> RunOutcome:
    """Execute one case (module level: runs in worker processes and on Dask workers)."""
    from runkit.errors import RunkitError
    from verify.errors import VerifyError

    start = time.perf_counter()
    case = job.case
    try:
        if isinstance(case, FalsifyCase):
            folder = None if job.out_dir is None else Path(job.out_dir) / case.run_id
            metrics = falsify_metrics(case, folder, job.controller)
            return RunOutcome(case.run_id, metrics, None, time.perf_counter() - start,
                              None if folder is None else str(folder / "worst" / "run.mcap"))
        if job.out_dir is None:
            with tempfile.TemporaryDirectory(prefix="tubempc-regress-") as tmp:
                metrics, _ = _run_in(case, Path(tmp), job.reports, job.controller)
                log_path = None
        else:
            metrics, log_path = _run_in(case, Path(job.out_dir) / case.run_id, job.reports, job.controller)
    except (TubeMPCError, RunkitError, VerifyError) as err:
        return RunOutcome(case.run_id, {}, f"{err.__class__.__name__}: {err}", time.perf_counter() - start, None)
    except Exception as err:  # one broken case must not hide the others; the diff reports it
        return RunOutcome(case.run_id, {}, f"internal error: {err.__class__.__name__}: {err}",
                          time.perf_counter() - start, None)
    return RunOutcome(case.run_id, metrics, None, time.perf_counter() - start, log_path)


def run_cases(cases: Sequence[RunCase | FalsifyCase], *, out_dir: str | Path | None = None, reports: bool = False,
              workers: int | None = None, dask: str | None = None, progress: bool | None = None,
              controller: str | None = None) -> list[RunOutcome]:
    """Run every case in parallel (processes by default; ``dask``: ``"local"`` or a scheduler address).
    ``controller``: ``package.module:factory`` runs instead of the tube MPC (``tubempc.control.user``)."""
    from runkit.executor import parallel_map

    jobs = [RunJob(case, None if out_dir is None else str(out_dir), reports, controller) for case in cases]
    preload = ("verify.batch", "verify", "tubempc.regress.runner", "tubempc.control.closed_loop", "tubempc.rosio",
               "tubempc.falsify")
    return parallel_map(run_case, jobs, workers=workers, dask=dask, progress=progress, desc="regress",
                        preload=preload)
