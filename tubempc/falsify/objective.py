"""One candidate -> its margin: the closed loop in process, judged by the certifier's own code, no log written.

input: a ``FalsifySetup`` (the judged scenario, the scenario the controller runs with, the targets, the formula, the
selected checks, the search space) and a point ``z`` -> output: an ``Evaluation``: the smallest margin over the
selected checks (negative: a violation), each check's verdict and margin, and the simulation time.

The judged scenario supplies every claim (tube radius r_q, input box, workspace, obstacles, formula, noise
tolerance); ``--set`` overrides reach only ``FalsifySetup.controller``. ``evaluate_job`` is module-level and
picklable: it runs in worker processes and on Dask workers.
"""

from __future__ import annotations

import math
import time
from collections.abc import Sequence
from dataclasses import dataclass, field
from typing import TYPE_CHECKING, Any

import numpy as np

from tubempc.control.closed_loop import ClosedLoopResult, Target, run_closed_loop
from tubempc.errors import TubeMPCError
from tubempc.falsify.space import Candidate, SearchSpace
from tubempc.scenario import Scenario

if TYPE_CHECKING:
    from verify.certificate import Certificate

__all__ = ["DEFAULT_CHECKS", "MARGIN_CHECKS", "Evaluation", "FalsifySetup", "evaluate", "evaluate_job",
           "judge", "simulate"]

#: the checks whose margins the objective takes by default (the timed-run check has a verdict, no margin)
DEFAULT_CHECKS = ("tube", "obstacle_clearance", "input_box", "workspace", "spec_trajectory")
#: checks of the certificate that have a margin in SI units
MARGIN_CHECKS = ("tube", "obstacle_clearance", "input_box", "workspace", "spec_trajectory")
#: the objective of a run whose selected checks have no finite margin at all (never a violation by itself)
NO_MARGIN = 1e3


@dataclass(frozen=True)
class FalsifySetup:
    """Everything a worker needs to simulate and judge one candidate (all picklable)."""

    scenario: Scenario  # judged against: the claims
    controller: Scenario  # what the controller runs with (the scenario with the --set overrides)
    start_region: str
    targets: tuple[tuple[str, float | None], ...]
    spec: str | None
    checks: tuple[str, ...]
    space: SearchSpace
    t_end_s: float | None = None
    overrides: tuple[str, ...] = ()
    labels: dict[str, Any] = field(default_factory=dict)  # free-form description (run, plan) for the output
    controller_spec: str | None = None  # a user's controller (package.module:factory) instead of the tube MPC

    def controller_targets(self) -> list[Target]:
        return [Target(region, depart) for region, depart in self.targets]


@dataclass(frozen=True, slots=True)
class Evaluation:
    """The judged outcome of one candidate (``error``: it could not be simulated; margin is then NaN)."""

    z: tuple[float, ...]
    margin: float
    worst_check: str | None
    violated: bool
    inconclusive: bool
    checks: dict[str, dict[str, Any]]  # name -> {verdict, margin}
    verdict: str  # the certificate's overall verdict
    sim_s: float
    judge_s: float
    duration_s: float = math.nan  # length of the simulated run
    error: str | None = None


def simulate(setup: FalsifySetup, cand: Candidate) -> ClosedLoopResult:
    """The closed loop of ``cand`` with the controller's scenario (the --set overrides apply here only); a user's
    controller (``controller_spec``) is made afresh for every candidate."""
    if setup.controller_spec is not None:
        from tubempc.control.user import checked_controller, run_controller

        return run_controller(setup.controller, checked_controller(setup.controller_spec, setup.controller),
                              setup.controller_targets(), start_region=setup.start_region, disturbance=cand.signal,
                              seed=cand.noise_seed, t_end_s=setup.t_end_s, mocap_noise_m=cand.noise_std_m,
                              start_pose=cand.start_pose)
    return run_closed_loop(setup.controller, setup.controller_targets(), start_region=setup.start_region,
                           disturbance=cand.signal, seed=cand.noise_seed, t_end_s=setup.t_end_s,
                           mocap_noise_m=cand.noise_std_m, start_pose=cand.start_pose)


def judge(setup: FalsifySetup, certificate: Certificate) -> tuple[float, str | None, bool, bool,
                                                                dict[str, dict[str, Any]]]:
    """(objective, its check, violated, inconclusive, per-check entries) of a certificate's selected checks."""
    entries = {c.name: c for c in certificate.checks}
    picked: dict[str, dict[str, Any]] = {}
    objective, worst = math.inf, None
    violated = inconclusive = False
    for name in setup.checks:
        entry = entries.get(name)
        if entry is None:
            continue
        verdict, margin = str(entry.verdict), entry.margin
        picked[name] = {"verdict": verdict, "margin": margin}
        violated |= verdict == "fail"
        inconclusive |= verdict == "inconclusive"
        value = margin if margin is not None and math.isfinite(margin) else None
        if value is None and verdict == "fail":
            value = 0.0  # a failed check without a margin (the timed run) still counts as a violation at 0
        if value is not None and value < objective:
            objective, worst = value, name
    if not math.isfinite(objective):
        objective = NO_MARGIN
    return objective, worst, violated, inconclusive, picked


def evaluate(setup: FalsifySetup, z: Sequence[float]) -> Evaluation:
    """Simulate and judge one point of the search space (certifier: ``verify.certify_data``, same as for files)."""
    from runkit.errors import RunkitError
    from tubempc.rosio.memory import in_memory_log
    from verify import certify_data  # type: ignore[attr-defined,unused-ignore]
    from verify.errors import VerifyError

    key = tuple(float(v) for v in z)
    start = time.perf_counter()
    try:
        cand = setup.space.decode(np.asarray(key))
        result = simulate(setup, cand)
        sim_s = time.perf_counter() - start
        certified = certify_data(in_memory_log(result, setup.scenario), setup.scenario, spec=setup.spec)
    except (TubeMPCError, RunkitError, VerifyError, ValueError) as err:
        return Evaluation(key, math.nan, None, False, False, {}, "error", time.perf_counter() - start, 0.0,
                          error=f"{err.__class__.__name__}: {err}")
    judge_s = time.perf_counter() - start - sim_s
    typed = certified.typed
    objective, worst, violated, inconclusive, picked = judge(setup, typed)
    duration = float(result.t_s[-1]) if len(result.t_s) else 0.0
    return Evaluation(key, objective, worst, violated, inconclusive, picked, str(typed.verdict),
                      sim_s, judge_s, duration)


def evaluate_job(job: tuple[FalsifySetup, tuple[float, ...]]) -> Evaluation:
    """``evaluate`` on one (setup, z) pair (module level: picklable for process pools and Dask)."""
    return evaluate(job[0], job[1])
