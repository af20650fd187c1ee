"""A falsification request -> the search, its certificate-like JSON, and the worst case's log, certificate and report.

input: a ``FalsifyRequest`` (what the command line says: scenario, run, method, budget, seed, family, overrides)
-> output: a ``FalsifyOutcome`` (``prepare`` + ``search``): the worst margin found, the parameters that produce it,
the command that replays it, and ``to_json()``; ``write_outcome`` writes ``falsify.json`` and, for the worst case
only, ``worst/run.mcap``, its ``certificate.json`` (certified from the written log) and ``report.md/html``.

Verdict and exit code: ``fail`` (1) when some candidate violates a selected check; otherwise ``inconclusive`` (2)
when some candidate's selected check could not be decided, else ``no_violation_found`` (0) with the lowest margin.
A search never proves the absence of a violation: 0 means none was found within the budget. An unperturbed run
(z = 0) that already violates is the counterexample, found at simulation 0: no search is run.
"""

from __future__ import annotations

import json
import math
import shlex
import statistics
from dataclasses import dataclass, field, replace
from pathlib import Path
from typing import Any

from tubempc.errors import FalsifyError
from tubempc.falsify.objective import DEFAULT_CHECKS, MARGIN_CHECKS, Evaluation, FalsifySetup, evaluate, simulate
from tubempc.falsify.overrides import apply_overrides
from tubempc.falsify.search import Method, SearchResult, search
from tubempc.falsify.space import Family, make_space
from tubempc.scenario import Scenario

__all__ = ["FALSIFY_FORMAT", "FalsifyError", "FalsifyOutcome", "FalsifyRequest", "prepare", "replay_command",
           "run_falsify", "write_case", "write_outcome"]

FALSIFY_FORMAT = "tubempc-falsify/1"
EXIT_CODES = {"fail": 1, "inconclusive": 2, "no_violation_found": 0}
KNOWN_CHECKS = (*MARGIN_CHECKS, "spec_timed_run")


@dataclass(frozen=True)
class FalsifyRequest:
    """The command line, as values (``scenario_ref``: the built-in name or file path, for the replay command)."""

    scenario_ref: str
    source: str | None = None
    target: str | None = None
    plan: bool = False
    method: Method = "random"
    budget: int = 100
    seed: int = 0
    family: Family = "steps"
    knots: int = 4
    switches: int = 3
    bound_scale: float = 1.0
    vary_start: bool = True
    checks: tuple[str, ...] = DEFAULT_CHECKS
    spec: str | None = None
    overrides: tuple[str, ...] = ()
    horizon_s: float | None = None
    stop_at_first: bool = False
    shrink_budget: int | None = None
    controller: str | None = None  # package.module:factory run instead of the tube MPC (tubempc.control.user)

    def __post_init__(self) -> None:
        if self.plan == (self.target is not None):
            raise FalsifyError("give either --to REGION (one transition) or --plan (the scenario's mission)")
        unknown = [c for c in self.checks if c not in KNOWN_CHECKS]
        if unknown or not self.checks:
            raise FalsifyError(f"--checks {','.join(self.checks)!r}: unknown check(s) {unknown} (known: "
                               f"{', '.join(KNOWN_CHECKS)})")
        if self.budget < 1:
            raise FalsifyError(f"--budget {self.budget!r} must be at least 1")


@dataclass(frozen=True)
class FalsifyOutcome:
    request: FalsifyRequest
    setup: FalsifySetup
    reference: Evaluation
    result: SearchResult
    files: dict[str, str] = field(default_factory=dict)

    @property
    def reference_violates(self) -> bool:
        """The unperturbed run already violates a selected check: it is the counterexample (simulation 0)."""
        return self.reference.violated

    @property
    def worst(self) -> Evaluation | None:
        """The worst case: the unperturbed run if it violates, else the search's lowest margin."""
        return self.reference if self.reference_violates else self.result.worst

    @property
    def verdict(self) -> str:
        if self.reference_violates:
            return "fail"
        evs = (*self.result.evaluations, *self.result.shrink_evaluations)
        if any(e.violated for e in evs):
            return "fail"
        if any(e.inconclusive for e in evs):
            return "inconclusive"
        return "no_violation_found"

    @property
    def exit_code(self) -> int:
        return EXIT_CODES[self.verdict]

    def case(self, ev: Evaluation, *, sim: int | None) -> dict[str, Any]:
        cand = self.setup.space.decode(ev.z)
        return {"sim": sim, "margin": ev.margin, "check": ev.worst_check, "violated": ev.violated,
                "inconclusive": ev.inconclusive, "certificate_verdict": ev.verdict, "checks": ev.checks,
                "z": list(ev.z), "parameters": cand.describe(),
                "replay": replay_command(self.request, self.setup, ev.z)}

    def to_json(self) -> dict[str, Any]:
        res = self.result
        order = {id(e): k for k, e in enumerate((*res.evaluations, *res.shrink_evaluations), start=1)}
        order[id(self.reference)] = 0  # the unperturbed run: simulation 0
        worst = self.worst
        sims = [e.sim_s for e in (*res.evaluations, *res.shrink_evaluations) if e.error is None]
        judges = [e.judge_s for e in (*res.evaluations, *res.shrink_evaluations) if e.error is None]
        sc, ctrl = self.setup.scenario, self.setup.controller
        return {
            "format": FALSIFY_FORMAT,
            "verdict": self.verdict,
            "exit_code": self.exit_code,
            "scenario": sc.name,
            "scenario_sha256": sc.sha256(),
            "controller_overrides": list(self.request.overrides),
            "controller_scenario_sha256": ctrl.sha256(),
            "judged_against": "the scenario as given: tube radius, input box, workspace, obstacles, formula, noise "
                              "tolerance (overrides change only what the controller runs with)",
            "run": {"start_region": self.setup.start_region,
                    "targets": [{"region": r, "depart_after_s": d} for r, d in self.setup.targets],
                    "plan": self.request.plan, "formula": self.setup.spec or sc.spec, **self.setup.labels},
            "checks": list(self.setup.checks),
            "search_space": self.setup.space.describe(),
            "method": res.method,
            "budget": res.budget,
            "seed": res.seed,
            "simulations": len(res.evaluations),
            "first_violation_sim": 0 if self.reference_violates else res.first_violation,
            "shrink_simulations": len(res.shrink_evaluations),
            "errors": sum(1 for e in res.evaluations if e.error is not None),
            "reference": {"margin": self.reference.margin, "check": self.reference.worst_check,
                          "violated": self.reference.violated,
                          "checks": self.reference.checks, "duration_s": self.reference.duration_s,
                          "note": "the unperturbed run (z = 0), simulated once before the search, not counted; "
                                  "when it violates, it is the counterexample (simulation 0) and no search is run"},
            "worst": None if worst is None else self.case(worst, sim=order.get(id(worst))),
            "minimal": None if res.minimal is None else self.case(res.minimal, sim=order.get(id(res.minimal))),
            "timing": {"elapsed_s": res.elapsed_s,
                       "simulation_s_median": statistics.median(sims) if sims else None,
                       "judge_s_median": statistics.median(judges) if judges else None},
            "history": [{"sim": k, "margin": None if not math.isfinite(e.margin) else e.margin,
                         "check": e.worst_check, "violated": e.violated,
                         **({"error": e.error} if e.error else {})}
                        for k, e in enumerate(res.evaluations, start=1)],
            "files": self.files,
        }


def _resolve_run(req: FalsifyRequest, scenario: Scenario) -> tuple[str, tuple[tuple[str, float | None], ...],
                                                                 str | None, dict[str, Any]]:
    names = {r.name for r in scenario.regions}
    wanted = [("--from", req.source), *(("--to", t) for t in (req.target or "").split(",") if req.target)]
    for flag, region in wanted:
        if region is not None and region not in names:
            raise FalsifyError(f"{flag} {region}: no such region in scenario {scenario.name!r} (regions: "
                               f"{', '.join(sorted(names))})")
    if req.plan:
        from tubempc.planning.plan import plan_mission

        # the plan is executed: re-timed for the largest margin (the default time-optimal plan may sit on a window end)
        plan = plan_mission(scenario, objective="margin")
        targets = tuple((t.region, t.depart_after_s) for t in plan.controller_targets())
        return scenario.initial_region, targets, req.spec, {"planned_run": [list(p) for p in plan.run]}
    from tubempc.scenario.transition import derived_spec

    if req.target is None:
        raise FalsifyError("give either --to REGION (one transition) or --plan (the scenario's mission)")
    start = req.source or scenario.initial_region
    regions = req.target.split(",")  # --to W,B: through W to B (the formula derived from the last)
    return (start, tuple((t, None) for t in regions),
            req.spec if req.spec is not None else derived_spec(scenario, regions[-1]), {})


def prepare(req: FalsifyRequest, scenario: Scenario) -> tuple[FalsifySetup, Evaluation]:
    """The setup of the search and the unperturbed run (z = 0) that fixes the horizon the signals spread over."""
    controller = apply_overrides(scenario, req.overrides)
    start, targets, spec, labels = _resolve_run(req, scenario)
    try:
        space = make_space(scenario, start, family=req.family, knots=req.knots, switches=req.switches,
                           horizon_s=req.horizon_s or 1.0, bound_scale=req.bound_scale, vary_start=req.vary_start)
    except ValueError as err:
        raise FalsifyError(str(err)) from None
    if req.controller is not None:
        from tubempc.control.user import checked_controller

        checked_controller(req.controller, controller)  # exit 3 naming it, before any simulation
    setup = FalsifySetup(scenario, controller, start, targets, spec, tuple(req.checks), space,
                         overrides=tuple(req.overrides), labels=labels, controller_spec=req.controller)
    reference = evaluate(setup, (0.0,) * space.dim)
    if reference.error is not None:
        raise FalsifyError(f"the unperturbed run cannot be simulated with the controller's scenario: "
                           f"{reference.error}")
    if not any(isinstance(c.get("margin"), int | float) or c.get("verdict") == "fail"
               for c in reference.checks.values()):
        raise FalsifyError(f"--checks {','.join(req.checks)}: none of them is judged with a margin for scenario "
                           f"{scenario.name!r} (the scenario's checks: selection leaves none of them)")
    if req.horizon_s is None:
        setup = replace(setup, space=replace(space, horizon_s=max(reference.duration_s, space.step_s)))
    return setup, reference


def run_falsify(req: FalsifyRequest, scenario: Scenario, *, workers: int | None = None,
                dask: str | None = None) -> FalsifyOutcome:
    setup, reference = prepare(req, scenario)
    if reference.violated:  # the counterexample is the unperturbed run: nothing to search for
        return FalsifyOutcome(req, setup, reference, SearchResult(req.method, req.budget, req.seed, (), (), None, 0.0))
    try:
        result = search(setup, req.method, budget=req.budget, seed=req.seed, workers=workers, dask=dask,
                        stop_at_first=req.stop_at_first, shrink_budget=req.shrink_budget, known=[reference])
    except ValueError as err:
        raise FalsifyError(str(err)) from None
    return FalsifyOutcome(req, setup, reference, result)


def replay_command(req: FalsifyRequest, setup: FalsifySetup, z: tuple[float, ...]) -> str:
    """The ``tubempc falsify`` command that simulates exactly ``z`` again and writes its log and certificate."""
    args = ["tubempc", "falsify", "--scenario", req.scenario_ref]
    if req.plan:
        args.append("--plan")
    else:
        args += ["--from", setup.start_region, "--to", str(req.target)]
    if req.spec is not None:
        args += ["--spec", req.spec]
    for o in req.overrides:
        args += ["--set", o]
    if req.controller is not None:
        args += ["--controller", req.controller]
    sp = setup.space
    args += ["--family", sp.family, "--knots", str(sp.knots), "--switches", str(sp.switches)]
    if req.bound_scale != 1.0:
        args += ["--bound-scale", repr(req.bound_scale)]
    if not sp.vary_start:
        args.append("--fixed-start")
    args += ["--checks", ",".join(setup.checks), "--horizon", repr(sp.horizon_s),
             "--replay", ",".join(repr(float(v)) for v in z)]
    return shlex.join(args)


def _section(outcome: FalsifyOutcome, ev: Evaluation) -> Any:
    from verify.report import ReportSection

    cand = outcome.setup.space.decode(ev.z)
    rows: list[tuple[Any, ...]] = [
        ("method", outcome.result.method), ("budget / simulations", f"{outcome.result.budget} / "
                                                                   f"{len(outcome.result.evaluations)}"),
        ("seed", outcome.result.seed), ("controller overrides", ", ".join(outcome.request.overrides) or "none"),
        ("margin (selected checks)", f"{ev.margin:.9g} m ({ev.worst_check})"),
        ("disturbance", json.dumps(cand.signal.params)), ("start pose", list(cand.start_pose)),
        ("MoCap noise", f"std {cand.noise_std_m:g} m, seed {cand.noise_seed}")]
    return ReportSection("Falsification: the worst case found", ("item", "value"), tuple(rows),
                         (f"replay: {replay_command(outcome.request, outcome.setup, ev.z)}",))


def write_case(setup: FalsifySetup, ev: Evaluation, out_dir: Path, *, sections: tuple[Any, ...] = (),
               metadata: dict[str, Any] | None = None) -> dict[str, Any]:
    """Simulate ``ev.z`` again, write its log, certify the written log, write the reports; returns the paths, the
    certificate's verdict and the file's margin beside the in-memory one."""
    from tubempc.rosio import write_log
    from verify import certify_log, write_certificate  # type: ignore[attr-defined,unused-ignore]
    from verify.report import write_reports

    out_dir.mkdir(parents=True, exist_ok=True)
    log_path = out_dir / "run.mcap"
    log_path.unlink(missing_ok=True)
    result = simulate(setup, setup.space.decode(ev.z))
    write_log(result, setup.scenario, log_path, metadata={"falsify": metadata or {}})
    certified = certify_log(log_path, setup.scenario, spec=setup.spec)
    cert_path = write_certificate(certified, out_dir)
    written = write_reports(certified, setup.scenario, out_dir, suite_name="falsify", sections=sections)
    from tubempc.falsify.objective import judge

    margin, check, violated, _, _ = judge(setup, certified.typed)
    return {"log": str(log_path), "certificate": str(cert_path),
            "report_html": str(written.get("report.html", "")), "report_md": str(written.get("report.md", "")),
            "certificate_verdict": certified.verdict, "margin_from_log": margin, "check_from_log": check,
            "violated_from_log": violated, "margin_in_memory": ev.margin}


def write_outcome(outcome: FalsifyOutcome, out_dir: str | Path) -> FalsifyOutcome:
    """``falsify.json`` and, for the worst case only, its log, certificate and report under ``worst/``."""
    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    files: dict[str, Any] = {"json": str(out / "falsify.json")}
    worst = outcome.worst
    if worst is not None:
        meta = {"method": outcome.result.method, "seed": outcome.result.seed, "z": list(worst.z),
                "overrides": list(outcome.request.overrides)}
        files["worst"] = write_case(outcome.setup, worst, out / "worst", sections=(_section(outcome, worst),),
                                    metadata=meta)
    done = replace(outcome, files=files)
    (out / "falsify.json").write_text(json.dumps(done.to_json(), indent=2) + "\n", encoding="utf-8")
    return done
