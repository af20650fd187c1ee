"""Benchmark: the paper's formula on a long trajectory, our monitor vs argus-temporal-logic and RTAMT (same signals).

    python3 benchmarks/bench_monitor.py [--samples 1000000] [--rtamt-samples 100000] [--repeat 3]

Prints the best-of-N wall time of each monitor and the ratios. RTAMT's discrete-time offline monitor is run on
``--rtamt-samples`` (it takes minutes on 1e6) and its time is scaled linearly to the full length; the printout says
so. Also shows the obstacle crossed between two samples: the peers pass it, ours must not. The same formula on a
variant of the scenario whose mission_2 region (R3) and obstacle obs_3 (R8) are polygons (a square and a rectangle)
prints the cost of polygon atoms against the discs, measured in the same process.
"""

from __future__ import annotations

import argparse
import os
import time
from collections.abc import Callable

import numpy as np

from tubempc.mitl import parse
from tubempc.scenario import Scenario, builtin_scenario, scenario_from_dict
from verify.geometry import label_margins
from verify.semantics.trajectory import check_trajectory

# argus needs float literals (an integer 0 makes it panic)
STL = ("G(!(obs_1 > 0.0 || obs_2 > 0.0 || obs_3 > 0.0 || obs_4 > 0.0)) && F[{a},{b}](mission_2 >= 0.0) && "
       "F[{c},{d}](mission_1 >= 0.0)")


def trajectory(sc: Scenario, n: int, rate_hz: float = 100.0) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """R1 -> R3 (inside from ~33 s) -> R1 (inside from ~86 s), then small loops inside R1 until the end."""
    t_s = np.arange(n) / rate_hz
    r1, r3 = sc.region("R1").center, sc.region("R3").center
    kt = [0.0, 18.0, 36.0, 55.0, 70.0, 88.0]
    kx = [r1[0], -0.6, r3[0], r3[0], -0.6, r1[0]]
    ky = [r1[1], -0.5, r3[1], r3[1], -0.5, r1[1]]
    x = np.interp(t_s, kt, kx)
    y = np.interp(t_s, kt, ky)
    late = t_s > 88.0
    x[late] += 0.05 * np.sin(0.5 * (t_s[late] - 88.0))
    return (np.round(t_s * 1e9)).astype(np.int64), x, y


def polygon_variant(sc: Scenario) -> Scenario:
    """R3 (mission_2) as a square of half-side 0.45 m and R8 (obs_3) as a 0.9 m x 0.6 m rectangle, same centres."""
    data = sc.to_dict()
    for region in data["regions"]:
        if region["name"] in ("R3", "R8"):
            (cx, cy), hx = region.pop("center"), region.pop("radius")
            hy = hx if region["name"] == "R3" else 0.3
            region["polygon"] = [[cx - hx, cy - hy], [cx + hx, cy - hy], [cx + hx, cy + hy], [cx - hx, cy + hy]]
    return scenario_from_dict(data, source="<polygon variant>")


def best(fn: Callable[[], object], repeat: int) -> tuple[float, float, object]:
    """Best-of-``repeat`` wall time (s), the CPU time of that run (s) and the last result."""
    times, cpus, out = [], [], None
    for _ in range(repeat):
        t0, c0 = time.perf_counter(), time.process_time()
        out = fn()
        times.append(time.perf_counter() - t0)
        cpus.append(time.process_time() - c0)
    k = int(np.argmin(times))
    return times[k], cpus[k], out


def run_argus(t_s: np.ndarray, sig: dict[str, np.ndarray], formula: str) -> float:
    import argus

    trace = argus.Trace({k: argus.FloatSignal.from_samples(list(zip(t_s.tolist(), v.tolist(), strict=True)),
                                                           interpolation_method="linear") for k, v in sig.items()})
    expr = argus.parse_expr(formula)
    return float(argus.eval_robust_semantics(expr, trace).at(0.0))


def run_rtamt(steps: np.ndarray, sig: dict[str, np.ndarray], formula: str) -> float:
    import rtamt

    spec = rtamt.StlDiscreteTimeOfflineSpecification()
    for k in sig:
        spec.declare_var(k, "float")
    spec.spec = formula.replace("&&", "and").replace("||", "or").replace("!(", "not(")
    spec.parse()
    data = {"time": steps.tolist(), **{k: v.tolist() for k, v in sig.items()}}
    out = spec.evaluate(data)
    return float(out[0][1])


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--samples", type=int, default=1_000_000)
    ap.add_argument("--rtamt-samples", type=int, default=100_000)
    ap.add_argument("--repeat", type=int, default=3)
    args = ap.parse_args()
    sc = builtin_scenario()
    formula = sc.formula
    t_ns, x, y = trajectory(sc, args.samples)
    v = sc.max_speed_mps

    print(f"load average before the run (2 cores here): {' '.join(f'{v:.2f}' for v in os.getloadavg())}")
    t_ours, cpu_ours, res = best(lambda: check_trajectory(formula, t_ns, x, y, sc, max_speed_mps=v), args.repeat)
    print(f"ours (trajectory semantics, samples + gaps) on {args.samples} samples: {t_ours:.3f} s "
          f"(CPU {cpu_ours:.3f} s) -> {res.verdict} (margin {res.margin_m:.4f} m)")  # type: ignore[attr-defined]

    sc_poly = polygon_variant(sc)
    t_poly, cpu_poly, res_poly = best(lambda: check_trajectory(formula, t_ns, x, y, sc_poly, max_speed_mps=v),
                                      args.repeat)
    print(f"ours with R3 and R8 as polygons: {t_poly:.3f} s (CPU {cpu_poly:.3f} s) -> "
          f"{res_poly.verdict} (margin {res_poly.margin_m:.4f} m); polygon / disc = "  # type: ignore[attr-defined]
          f"{t_poly / t_ours:.2f}x")

    t_s = t_ns * 1e-9
    sig = label_margins(x, y, sc, {"obs_1", "obs_2", "obs_3", "obs_4", "mission_1", "mission_2"})
    stl_s = STL.format(a=30, b=50, c=80, d=110)
    t_arg, cpu_arg, rho_arg = best(lambda: run_argus(t_s, sig, stl_s), max(1, args.repeat - 1))
    print(f"argus on the same signals: {t_arg:.3f} s (CPU {cpu_arg:.3f} s) -> robustness {rho_arg:.4f}")

    m = min(args.rtamt_samples, args.samples)
    steps = np.arange(m)
    stl_steps = STL.format(a=3000, b=5000, c=8000, d=11000)  # 100 Hz: intervals in steps
    t_rt, _cpu_rt, rho_rt = best(lambda: run_rtamt(steps, {k: s[:m] for k, s in sig.items()}, stl_steps), 1)
    t_rt_full = t_rt * args.samples / m
    print(f"RTAMT discrete-time offline on {m} samples: {t_rt:.3f} s (scaled to {args.samples}: "
          f"{t_rt_full:.1f} s) -> robustness {rho_rt:.4f}")
    print(f"ratios: argus / ours = {t_arg / t_ours:.1f}x (CPU time: {cpu_arg / cpu_ours:.1f}x), "
          f"RTAMT(scaled) / ours = {t_rt_full / t_ours:.1f}x; target: ours <= 0.2 s and >= 10x argus")
    print(f"with polygons: argus / ours = {t_arg / t_poly:.1f}x (ours {t_poly:.3f} s; same target)")
    print(f"load average after the run: {' '.join(f'{v:.2f}' for v in os.getloadavg())}")

    # an obstacle crossed between two samples 10 s apart
    r8 = sc.region("R8")
    clear = r8.radius + sc.robot.radius + 0.05
    tx = np.array([0, 10 * 10**9], dtype=np.int64)
    xx = np.array([r8.center[0] - clear, r8.center[0] + clear])
    yy = np.full(2, r8.center[1])
    g = parse("G[0,inf) !obs_3")
    ours = check_trajectory(g, tx, xx, yy, sc, max_speed_mps=v).verdict
    sig2 = label_margins(xx, yy, sc, {"obs_3"})
    peer = run_argus(tx * 1e-9, sig2, "G(!(obs_3 > 0.0))")
    print(f"obstacle crossed between two samples: ours -> {ours}; argus robustness {peer:.3f} "
          f"({'pass' if peer > 0 else 'not pass'})")


if __name__ == "__main__":
    main()
