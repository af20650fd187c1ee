"""Benchmark: our FHOCP solver vs an NLopt SLSQP implementation (the paper's library) on the same problems.

input: the built-in scenario (h = 0.1 s, N = 12, obstacles active) -> output: timing lines; the LAST line is
``median_ms=<ours> p95_ms=<ours> nlopt_median_ms=<x> ratio_vs_nlopt=<nlopt/ours>``.

The FHOCP instances (nominal state, references, obstacle slots) are recorded along a closed-loop run of the
paper's tour R1 -> R2 -> R3 -> R4 -> R5 -> R1 under the worst-case disturbance, then solved in sequence by both
solvers in this process, each warm-started from its own previous (shifted) solution. NLopt gets the condensed
(single-shooting) problem with exact CasADi gradients and Jacobians. Also prints the wall time of a 110 s
closed-loop simulation and its ratio to real time.

Run: ``python3 benchmarks/bench_fhocp.py`` (options: ``--max-instances N``).
"""

from __future__ import annotations

import argparse
import math
import os
import time

import casadi as ca
import nlopt
import numpy as np

from tubempc.control import Target, design_tube, model_for, run_closed_loop
from tubempc.control.fhocp import CHECK_TOL, NominalMPC, SolveOutcome, build_fhocp, discrete_step
from tubempc.scenario import Scenario, builtin_scenario

TOUR = ("R2", "R3", "R4", "R5", "R1")
Instance = tuple[np.ndarray, np.ndarray, np.ndarray]


def record_instances(scenario: Scenario) -> list[Instance]:
    """Every FHOCP solved along the tour (only the 4-slot problem, which is every one on this scenario)."""
    instances: list[Instance] = []
    original = NominalMPC.solve

    def recording(self: NominalMPC, x_hat: np.ndarray, refs: np.ndarray, obstacles: np.ndarray) -> SolveOutcome:
        instances.append((x_hat.copy(), refs.copy(), obstacles.copy()))
        return original(self, x_hat, refs, obstacles)

    NominalMPC.solve = recording  # type: ignore[method-assign]
    try:
        res = run_closed_loop(scenario, [Target(n) for n in TOUR], disturbance="worst", seed=0)
    finally:
        NominalMPC.solve = original  # type: ignore[method-assign]
    if not res.ok:
        raise SystemExit(f"closed loop failed: {res.reason}")
    return [inst for inst in instances if inst[2].shape[1] == 4]


class NloptFhocp:
    """The same FHOCP, condensed over U (3N variables), solved by NLopt LD_SLSQP with CasADi derivatives."""

    def __init__(self, scenario: Scenario) -> None:
        model = model_for(scenario)
        tube = design_tube(scenario, model)
        self.n = n = scenario.mpc.steps
        h = scenario.mpc.h
        Q, R, P = (np.asarray(v, dtype=float) for v in (scenario.mpc.Q, scenario.mpc.R, scenario.mpc.P))
        F = discrete_step(model, h, substeps=2)
        u = ca.SX.sym("u", 3 * n)
        x0 = ca.SX.sym("x0", 3)
        ref = ca.SX.sym("ref", 3, n + 1)
        obs = ca.SX.sym("obs", 3, 4)
        U = ca.reshape(u, 3, n)
        xs = [x0]
        for k in range(n):
            xs.append(F(xs[-1], U[:, k]))
        cost = ca.SX(0)
        for k in range(n):
            e = xs[k] - ref[:, k]
            cost += h * (ca.dot(Q * e, e) + ca.dot(R * U[:, k], U[:, k]))
        e_n = xs[n] - ref[:, n]
        cost += ca.dot(P * e_n, e_n)
        tol = CHECK_TOL
        ineq = []  # c(u) <= 0
        for k in range(n):
            ineq.append(ca.sumsqr(U[:2, k]) - (tube.planar_disc_mps - tol) ** 2)  # type: ignore[operator]
        for k in range(1, n + 1):
            p = xs[k][:2]
            ineq += [tube.workspace_x[0] + tol - p[0], p[0] - tube.workspace_x[1] + tol,
                     tube.workspace_y[0] + tol - p[1], p[1] - tube.workspace_y[1] + tol]
            for m in range(4):
                ineq.append((obs[2, m] + tol) ** 2 - ca.sumsqr(p - obs[:2, m]))
        g = ca.vertcat(*ineq)
        self.m = g.shape[0]
        par = [x0, ref, obs]
        self.f_grad = ca.Function("fg", [u, *par], [cost, ca.gradient(cost, u)])
        self.g_jac = ca.Function("gj", [u, *par], [g, ca.jacobian(g, u)])
        self.rollout = ca.Function("roll", [u, x0], [ca.horzcat(*xs)])
        self.u_box = tube.u_box
        self.prev: np.ndarray | None = None

    def solve(self, inst: Instance) -> tuple[float, bool, float]:
        x0, refs, obstacles = inst
        par = (x0, refs.T, obstacles)
        opt = nlopt.opt(nlopt.LD_SLSQP, 3 * self.n)
        lo = -np.tile(np.asarray(self.u_box), self.n) + CHECK_TOL
        opt.set_lower_bounds(lo)
        opt.set_upper_bounds(-lo)

        def objective(u: np.ndarray, grad: np.ndarray) -> float:
            f, gr = self.f_grad(u, *par)
            if grad.size > 0:
                grad[:] = np.asarray(gr).ravel()
            return float(f)

        def constraints(result: np.ndarray, u: np.ndarray, grad: np.ndarray) -> None:
            gv, jac = self.g_jac(u, *par)
            result[:] = np.asarray(gv).ravel()
            if grad.size > 0:
                grad[:, :] = np.asarray(ca.densify(jac))

        opt.set_min_objective(objective)
        opt.add_inequality_mconstraint(constraints, np.full(self.m, 1e-7))
        opt.set_ftol_rel(1e-8)
        opt.set_xtol_rel(1e-6)
        opt.set_maxeval(500)
        u0 = np.zeros(3 * self.n) if self.prev is None else np.concatenate([self.prev[3:], self.prev[-3:]])
        u0 = np.clip(u0, lo, -lo)
        start = time.perf_counter()
        try:
            u_opt = opt.optimize(u0)
            code = opt.last_optimize_result()
        except (nlopt.RoundoffLimited, RuntimeError, ValueError):
            u_opt, code = u0, -1
        elapsed = time.perf_counter() - start
        gv, _ = self.g_jac(u_opt, *par)
        feasible = float(np.max(np.asarray(gv))) <= 1e-6
        ok = code > 0 and feasible
        if ok:
            self.prev = np.asarray(u_opt, dtype=float)
        cost = float(self.f_grad(u_opt, *par)[0])
        return elapsed, ok, cost


def cost_of(inst: Instance, inputs: np.ndarray, scenario: Scenario, nl: NloptFhocp) -> float:
    x0, refs, obstacles = inst
    return float(nl.f_grad(inputs.ravel(), x0, refs.T, obstacles)[0])


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--max-instances", type=int, default=0, help="limit the number of instances (0: all)")
    args = parser.parse_args()
    scenario = builtin_scenario()
    instances = record_instances(scenario)
    if args.max_instances > 0:
        instances = instances[: args.max_instances]
    model = model_for(scenario)
    tube = design_tube(scenario, model)
    ours = NominalMPC(build_fhocp(scenario, model, tube, 4))
    nl = NloptFhocp(scenario)
    our_ms, nl_ms, our_ok, nl_ok, gaps = [], [], 0, 0, []
    our_cpu_ms, nl_cpu_ms = [], []
    for inst in instances:
        c0 = time.process_time()
        out = ours.solve(*inst)
        our_cpu_ms.append((time.process_time() - c0) * 1e3)
        our_ms.append(out.solve_time_s * 1e3)
        our_ok += out.success
        c0 = time.process_time()
        t_s, ok, nl_cost = nl.solve(inst)
        nl_cpu_ms.append((time.process_time() - c0) * 1e3)
        nl_ms.append(t_s * 1e3)
        nl_ok += ok
        if ok and out.success:
            ours_cost = cost_of(inst, out.inputs, scenario, nl)
            gaps.append((ours_cost - nl_cost) / max(abs(nl_cost), 1e-12))
    ours_arr, nl_arr = np.array(our_ms), np.array(nl_ms)
    n = len(instances)
    print(f"load average at start: {os.getloadavg()[0]:.2f} on {os.cpu_count()} cores")
    print(f"instances: {n} FHOCPs (N = {scenario.mpc.steps}, h = {scenario.mpc.h} s, 4 obstacle slots) along the "
          f"tour R1 -> {' -> '.join(TOUR)} (worst-case disturbance)")
    print(f"ours (CasADi sqpmethod + DAQP, warm start): solved {our_ok}/{n} ({100 * our_ok / n:.1f} %), median "
          f"{np.median(ours_arr):.3f} ms, p95 {np.percentile(ours_arr, 95):.3f} ms, max {ours_arr.max():.3f} ms")
    print(f"NLopt LD_SLSQP (CasADi gradients, warm start): solved {nl_ok}/{n} ({100 * nl_ok / n:.1f} %), median "
          f"{np.median(nl_arr):.3f} ms, p95 {np.percentile(nl_arr, 95):.3f} ms, max {nl_arr.max():.3f} ms")
    print(f"CPU time per call (process_time, whole call incl. warm start and plan check; less load-sensitive): "
          f"ours median "
          f"{np.median(our_cpu_ms):.3f} ms, p95 {np.percentile(our_cpu_ms, 95):.3f} ms; NLopt median "
          f"{np.median(nl_cpu_ms):.3f} ms, p95 {np.percentile(nl_cpu_ms, 95):.3f} ms")
    if gaps:
        g = np.array(gaps)
        print(f"relative cost gap (ours - nlopt) / nlopt where both solved: median {np.median(g):.2e}, "
              f"max {g.max():.2e}, min {g.min():.2e}")
    sim_s = 110.0
    walls, cpus = [], []
    for _ in range(3):  # repeated: one run is exposed to whatever else the machine is doing
        start, cpu0 = time.perf_counter(), time.process_time()
        res = run_closed_loop(scenario, [Target(n_) for n_ in TOUR], disturbance="worst", seed=0, t_end_s=sim_s)
        walls.append(time.perf_counter() - start)
        cpus.append(time.process_time() - cpu0)
    wall, cpu = float(np.median(walls)), float(np.median(cpus))
    print(f"closed loop: {sim_s:.0f} s simulated ({len(res.t_s)} MoCap samples, {len(res.solver)} MPC steps), median "
          f"of 3 runs {wall:.2f} s wall = {sim_s / wall:.1f}x faster than real time ({cpu:.2f} s CPU = "
          f"{sim_s / cpu:.1f}x; best {sim_s / min(walls):.1f}x); arrivals "
          f"{[(a.region, a.t_ij_s) for a in res.arrivals]}")
    med = float(np.median(ours_arr))
    ratio = float(np.median(nl_arr)) / med if med > 0 else math.inf
    print(f"median_ms={med:.3f} p95_ms={np.percentile(ours_arr, 95):.3f} "
          f"nlopt_median_ms={np.median(nl_arr):.3f} ratio_vs_nlopt={ratio:.1f}")


if __name__ == "__main__":
    main()

