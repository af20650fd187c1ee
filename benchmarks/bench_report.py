"""Benchmark: writing the reports (every figure, report.md/html, junit.xml) against certifying the same log.

    python3 benchmarks/bench_report.py [--samples 11001 360000 1000000]

``certify_log`` on the demo log gives the certificate; its trajectory is tiled to each length (100 Hz) and the
reports are written for that long trajectory. Prints, per length, the wall time of the formula's judgement with its
per-obligation results and curves (``verify.judging.judge_formula``, part of certify) and of ``write_reports``, and
the ratio of the report time to the time ``certify_log`` takes on the demo log in the same process (the baseline),
and the CPU time of ``write_reports`` (this process and the processes that draw the figures): on a loaded machine the
wall time measures the load, the CPU time the work.
"""

from __future__ import annotations

import argparse
import resource
import tempfile
import time
from pathlib import Path
from types import SimpleNamespace

import numpy as np
import pandas as pd

from tubempc.scenario import builtin_scenario
from verify.certify import certify_log
from verify.judging import judge_formula
from verify.report import write_reports
from verify.semantics.timed_run import parse_spec

DEMO = Path(__file__).resolve().parent.parent / "logs" / "demo.mcap"


def _cpu_s() -> float:
    """CPU seconds used so far by this process and its waited-for children."""
    own, kids = resource.getrusage(resource.RUSAGE_SELF), resource.getrusage(resource.RUSAGE_CHILDREN)
    return own.ru_utime + own.ru_stime + kids.ru_utime + kids.ru_stime


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--samples", type=int, nargs="+", default=[11_001, 360_000, 1_000_000])
    args = parser.parse_args()
    sc = builtin_scenario()
    start = time.perf_counter()
    base = certify_log(DEMO, sc)
    baseline_s = time.perf_counter() - start
    print(f"baseline: certify_log(demo.mcap, {len(base.trajectory)} samples) {baseline_s:.2f} s")
    x0, y0 = base.trajectory["x_m"].to_numpy(), base.trajectory["y_m"].to_numpy()
    for n in args.samples:
        t = np.arange(n) / 100.0
        idx = np.arange(n) % len(x0)
        traj = pd.DataFrame({"t_s": t, "x_m": x0[idx], "y_m": y0[idx], "theta_rad": 0.001 * t})
        cert = {**base.certificate, "duration_s": float(t[-1]), "judged_span_s": [0.0, float(t[-1])]}
        t0 = time.perf_counter()
        judged = judge_formula(parse_spec(cert["formula"]), np.round(t * 1e9).astype(np.int64), x0[idx], y0[idx], sc,
                               time0_ns=0, max_speed_mps=sc.max_speed_mps)
        t1 = time.perf_counter()
        result = SimpleNamespace(certificate=cert, exit_code=0, trajectory=traj, nominal=traj, inputs=None,
                                 robustness=None, formula=judged)
        c1 = _cpu_s()
        with tempfile.TemporaryDirectory() as tmp:
            write_reports(result, sc, tmp)
        t2 = time.perf_counter()
        print(f"{n:>9} samples: obligations {t1 - t0:.2f} s, reports {t2 - t1:.2f} s (CPU {_cpu_s() - c1:.2f} s), "
              f"reports / certify(demo) = {(t2 - t1) / baseline_s:.2f}")


if __name__ == "__main__":
    main()
