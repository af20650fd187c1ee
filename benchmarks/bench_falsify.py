"""Benchmark: falsification methods on seeded faulty designs and on the correct design (same budget, same seeds).

    python3 benchmarks/bench_falsify.py [--budget 100] [--seeds 5] [--correct-seeds 3] [--workers 2]

Designs (the judged scenario is always the built-in one: r_q = 0.01 m for sigma_low = 2, delta_bar = 0.02 m/s):

- ``sigma_low_0.5``: the controller runs with ``tube.sigma_low=0.5`` while the certificate holds r_q of sigma_low 2;
- ``bound_1.5x``: disturbances up to 1.5 times the design's bound (``--bound-scale 1.5``);
- ``tube_ignored``: the tightening ignores the tube (the controller designed with ``disturbance.bound=0``: obstacles
  grown by the robot radius only, inputs not shrunk, the same ancillary gain);
- ``correct``: the design as stated.

The run is the R4 -> R5 transition (around obs_4, along the east wall: the obstacle and the input box are active
constraints; ~20 s). Per design and method: simulations until the first violation (median over seeds; ``>B`` when
none within the budget B) and the lowest margin found. A fourth row per design, ``monte-carlo``, is what random
testing did before a search existed: the closed loop under the ``random`` disturbance model (i.i.d. uniform in
the ball at every sample, the regression suite's), one seed per simulation, judged the same way (``--mc-seeds``
repetitions). Also the cost of one simulation of the paper's mission (110 s, the regression suite's targets)
judged in memory, against writing and certifying its log (the baseline, same process).
Last line: ``targeted_vs_random_sims= best_method= correct_design_violations=``.
"""

from __future__ import annotations

import argparse
import dataclasses
import os
import statistics
import tempfile
import time
from dataclasses import dataclass
from pathlib import Path

from tubempc.falsify import FalsifyRequest, run_falsify
from tubempc.scenario import builtin_scenario

DESIGNS: dict[str, dict[str, object]] = {
    "sigma_low_0.5": {"overrides": ("tube.sigma_low=0.5",)},
    "bound_1.5x": {"bound_scale": 1.5},
    "tube_ignored": {"overrides": ("disturbance.bound=0",)},
    "correct": {},
}
FAULTS = ("sigma_low_0.5", "bound_1.5x", "tube_ignored")
METHODS = ("random", "targeted", "optimizer")
BASELINES = ("monte-carlo",)


@dataclass(frozen=True)
class Job:
    design: str
    method: str
    seed: int
    budget: int
    stop_at_first: bool


@dataclass(frozen=True)
class Outcome:
    job: Job
    first: int | None
    sims: int
    lowest: float
    check: str | None
    violations: int
    seconds: float


def monte_carlo(job: Job) -> Outcome:
    """The ``random`` disturbance model (i.i.d. in the ball per sample), seeds ``job.seed * budget + k``."""
    import numpy as np

    from tubempc.control.disturbance import make_disturbance
    from tubempc.falsify import prepare
    from tubempc.falsify.objective import judge, simulate
    from tubempc.rosio.memory import in_memory_log
    from verify import certify_data

    sc = builtin_scenario()
    req = FalsifyRequest("nexus-sml", source="R4", target="R5", budget=job.budget,
                         **DESIGNS[job.design])  # type: ignore[arg-type]
    setup, _ = prepare(req, sc)
    start = time.perf_counter()
    first, lowest, check, violations = None, float("inf"), None, 0
    centre = setup.space.decode(np.zeros(setup.space.dim))
    for k in range(job.budget):
        rng = np.random.default_rng(job.seed * job.budget + k)
        signal = make_disturbance("random", setup.space.bound, rng)
        cand = dataclasses.replace(centre, signal=signal)  # type: ignore[arg-type]
        run = simulate(setup, cand)
        margin, name, violated, _, _ = judge(setup, certify_data(in_memory_log(run, sc), sc, spec=setup.spec).typed)
        violations += violated
        if margin < lowest:
            lowest, check = margin, name
        if violated and first is None:
            first = k + 1
            if job.stop_at_first:
                break
    return Outcome(job, first, k + 1, lowest, check, violations, time.perf_counter() - start)


def run_job(job: Job) -> Outcome:
    if job.method == "monte-carlo":
        return monte_carlo(job)
    sc = builtin_scenario()
    req = FalsifyRequest("nexus-sml", source="R4", target="R5", method=job.method,  # type: ignore[arg-type]
                         budget=job.budget, seed=job.seed, stop_at_first=job.stop_at_first, shrink_budget=0,
                         **DESIGNS[job.design])  # type: ignore[arg-type]
    start = time.perf_counter()
    out = run_falsify(req, sc, workers=1)
    worst = out.result.worst
    return Outcome(job, out.result.first_violation, len(out.result.evaluations),
                   worst.margin if worst else float("nan"), worst.worst_check if worst else None,
                   sum(1 for e in out.result.evaluations if e.violated), time.perf_counter() - start)


def mission_cost(repeat: int) -> tuple[float, float, float, float]:
    """(median s to simulate the 110 s mission, median s to judge it in memory, median s to write + certify its
    log, simulated seconds)."""
    from tubempc.control import Target, run_closed_loop
    from tubempc.rosio import write_log
    from tubempc.rosio.memory import in_memory_log
    from verify import certify_data, certify_log

    sc = builtin_scenario()
    targets = [Target("R1", 16.0), Target("R3", 66.0), Target("R1")]
    sims, judges, files = [], [], []
    length = 0.0
    with tempfile.TemporaryDirectory() as tmp:
        for k in range(repeat):
            t0 = time.perf_counter()
            run = run_closed_loop(sc, targets, disturbance="random", seed=k, t_end_s=110.0)
            t1 = time.perf_counter()
            certify_data(in_memory_log(run, sc), sc)
            t2 = time.perf_counter()
            log = write_log(run, sc, Path(tmp) / f"m{k}.mcap")
            certify_log(log, sc)
            t3 = time.perf_counter()
            sims.append(t1 - t0)
            judges.append(t2 - t1)
            files.append(t3 - t2)
            length = float(run.t_s[-1])
    return statistics.median(sims), statistics.median(judges), statistics.median(files), length


def _fmt_sims(values: list[int | None], budget: int) -> str:
    if all(v is None for v in values):
        return f">{budget}"
    med = statistics.median([budget + 1 if v is None else v for v in values])
    misses = sum(v is None for v in values)
    return f"{med:g}" + (f" ({misses} miss)" if misses else "")


def _median_sims(values: list[int | None], budget: int) -> float:
    return float(statistics.median([budget + 1 if v is None else v for v in values]))


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--budget", type=int, default=100)
    ap.add_argument("--seeds", type=int, default=5, help="seeds per faulty design and method")
    ap.add_argument("--correct-seeds", type=int, default=3, help="seeds for the correct design (full budget each)")
    ap.add_argument("--mc-seeds", type=int, default=2, help="repetitions of the monte-carlo baseline per fault")
    ap.add_argument("--workers", type=int, default=2)
    ap.add_argument("--mission-repeat", type=int, default=3)
    args = ap.parse_args()

    from runkit.executor import parallel_map

    sim_s, judge_s, file_s, length = mission_cost(args.mission_repeat)
    print(f"load average {os.getloadavg()[0]:.1f} on {os.cpu_count()} cores")
    print(f"one simulation of the {length:.0f} s mission: simulate {sim_s:.3f} s + judge in memory {judge_s:.3f} s "
          f"= {sim_s + judge_s:.3f} s (real-time factor {length / (sim_s + judge_s):.0f}x); writing and certifying "
          f"its log instead (baseline): {file_s:.3f} s, {file_s / judge_s:.1f}x the in-memory judgement")

    jobs = [Job(d, m, s, args.budget, True) for d in FAULTS for m in METHODS for s in range(args.seeds)]
    jobs += [Job(d, m, s, args.budget, True) for d in FAULTS for m in BASELINES for s in range(args.mc_seeds)]
    jobs += [Job("correct", m, s, args.budget, False) for m in METHODS for s in range(args.correct_seeds)]
    t0 = time.perf_counter()
    outcomes = parallel_map(run_job, jobs, workers=args.workers, desc="bench_falsify",
                            preload=("verify.batch", "tubempc.falsify", "tubempc.control.closed_loop"))
    elapsed = time.perf_counter() - t0
    total_sims = sum(o.sims for o in outcomes)
    print(f"{len(jobs)} searches, {total_sims} simulations in {elapsed:.0f} s on {args.workers} workers "
          f"(budget {args.budget}; faults: stop at the first violation, {args.seeds} seeds; correct design: full "
          f"budget, {args.correct_seeds} seeds)")

    by: dict[tuple[str, str], list[Outcome]] = {}
    for o in outcomes:
        by.setdefault((o.job.design, o.job.method), []).append(o)
    print()
    print("| design | method | sims to first violation (median) | lowest margin (m, check) | violations |")
    print("|---|---|---|---|---|")
    for d in DESIGNS:
        for m in (*METHODS, *BASELINES):
            if (d, m) not in by:
                continue
            group = by[(d, m)]
            low = min(group, key=lambda o: o.lowest)
            firsts = [o.first for o in group]
            print(f"| {d} | {m} | {_fmt_sims(firsts, args.budget)} | {low.lowest:.3g} ({low.check}) | "
                  f"{sum(o.violations > 0 for o in group)}/{len(group)} runs |")
    print()
    totals = {m: sum(_median_sims([o.first for o in by[(d, m)]], args.budget) for d in FAULTS) for m in METHODS}
    worst_fault = {m: max(_median_sims([o.first for o in by[(d, m)]], args.budget) for d in FAULTS)
                   for m in METHODS}
    closest = {m: min(o.lowest for o in by[("correct", m)]) for m in METHODS}
    best = min(METHODS, key=lambda m: (totals[m], closest[m]))
    for m in METHODS:
        print(f"{m}: sum over the faults of the median sims to the first violation = {totals[m]:g}, worst fault "
              f"{worst_fault[m]:g}; correct design: lowest margin {closest[m]:.3g} m")
    mc = sum(_median_sims([o.first for o in by[(d, "monte-carlo")]], args.budget) for d in FAULTS)
    print(f"monte-carlo (random disturbance model, one seed per simulation): sum of the medians = {mc:g} "
          f"({mc / totals[best]:.1f}x the best method's)")
    correct_violations = sum(o.violations for m in METHODS for o in by[("correct", m)])
    ratio = totals["random"] / totals["targeted"]
    print(f"targeted_vs_random_sims={ratio:.2f} best_method={best} correct_design_violations={correct_violations}")


if __name__ == "__main__":
    main()
