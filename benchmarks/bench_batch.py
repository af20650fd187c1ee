"""Batch certification benchmark: what a batch of many small logs costs per log beyond ``certify_log`` itself.

Run: ``python3 benchmarks/bench_batch.py [--logs 200] [--duration-s 60] [--workers 2] [--dask local]
[--baseline-logs 20] [--reports]``.

Setup (not timed): one closed-loop run of the built-in scenario (tube MPC, random disturbance, seed 0) of
``--duration-s`` simulated seconds, written by the project's log writer (``tubempc.rosio.write_log``, MCAP) and
copied to ``--logs`` files. Baseline, in a fresh process: ``verify.certify_log`` on ``--baseline-logs`` of them after
one warm-up call (imports done, caches built), per log: median wall time and mean CPU time. Batch, in a fresh
process each: ``verify.batch.certify_many`` over every log with ``--workers`` processes, then ``write_batch``
(certificates and summaries; ``--reports`` adds the figures): wall time from the call to the written summary, and
the CPU time of the whole process tree (the process itself with its imports, the process server, every worker),
read from the operating system's accounting of the reaped children. ``--dask local`` runs the same batch on a Dask
``LocalCluster`` (the ``dask`` extra), cluster start-up included.

Overhead per log, the work a batch does beyond certifying each log as ``certify_log`` does in one warm process:
``cpu: (tree CPU - logs * baseline CPU) / logs`` and ``wall: wall * workers / logs - baseline wall``. The target
(<= 0.1 s) is judged on the CPU overhead: on a machine shared with other jobs the wall times follow the load
(the baseline and the batch run at different moments), the CPU times do not. The last line gives the processes
batch's overheads and logs per second.
"""

from __future__ import annotations

import argparse
import importlib.util
import json
import os
import resource
import shutil
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path

TARGET_OVERHEAD_S = 0.1
TOUR = ("R3", "R1", "R3", "R1")


def write_logs(directory: Path, count: int, duration_s: float) -> list[Path]:
    from tubempc.control import Target, run_closed_loop
    from tubempc.rosio import write_log
    from tubempc.scenario import builtin_scenario

    sc = builtin_scenario()
    run = run_closed_loop(sc, [Target(name) for name in TOUR], disturbance="random", seed=0, t_end_s=duration_s)
    first = write_log(run, sc, directory / "run000.mcap")
    paths = [first]
    for k in range(1, count):
        target = directory / f"run{k:03d}.mcap"
        shutil.copyfile(first, target)
        paths.append(target)
    return paths


def _child_baseline(paths: list[Path], count: int) -> dict[str, float]:
    from tubempc.scenario import builtin_scenario
    from verify import certify_log

    sc = builtin_scenario()
    certify_log(paths[0], sc)  # warm-up: imports and caches, as a long-lived worker has them
    walls = []
    c0 = time.process_time()
    for path in paths[:count]:
        t0 = time.perf_counter()
        certify_log(path, sc)
        walls.append(time.perf_counter() - t0)
    return {"wall_s": statistics.median(walls), "cpu_s": (time.process_time() - c0) / count}


def _child_batch(paths: list[Path], out: Path, *, workers: int, dask: str | None, reports: bool) -> dict[str, float]:
    import multiprocessing.forkserver

    from tubempc.scenario import builtin_scenario
    from verify.batch import certify_many, write_batch

    sc = builtin_scenario()
    t0 = time.perf_counter()
    batch = certify_many(paths, sc, workers=workers, dask=dask, progress=False)
    write_batch(batch, out, reports=reports, workers=workers, dask=dask, progress=False)
    wall = time.perf_counter() - t0
    # stop the process server and reap it, so that its CPU time and its reaped workers' count for this process tree
    # (multiprocessing's own method for that; private, used by its tests: benchmark code only)
    stop = getattr(getattr(multiprocessing.forkserver, "_forkserver", None), "_stop", None)
    if stop is not None:
        stop()
    return {"wall_s": wall, "exit_code": float(batch.exit_code)}


def _run_child(args: list[str]) -> tuple[dict[str, float], float]:
    """Run this script as a child with ``args``; its JSON result and the CPU seconds of its whole process tree."""
    before = resource.getrusage(resource.RUSAGE_CHILDREN)
    done = subprocess.run([sys.executable, __file__, *args], capture_output=True, text=True, check=False)
    after = resource.getrusage(resource.RUSAGE_CHILDREN)
    if done.returncode != 0:
        raise SystemExit(f"benchmark child {args[:2]} failed (exit {done.returncode}):\n{done.stderr[-3000:]}")
    cpu = (after.ru_utime - before.ru_utime) + (after.ru_stime - before.ru_stime)
    return json.loads(done.stdout.strip().splitlines()[-1]), cpu


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--logs", type=int, default=200)
    ap.add_argument("--duration-s", type=float, default=60.0)
    ap.add_argument("--workers", type=int, default=2)
    ap.add_argument("--baseline-logs", type=int, default=20)
    ap.add_argument("--dask", choices=["local"], default=None, help="also run the batch on a Dask LocalCluster")
    ap.add_argument("--reports", action="store_true", help="write the figures and reports too (about 2 s per log)")
    ap.add_argument("--child", choices=["baseline", "batch"], default=None, help=argparse.SUPPRESS)
    ap.add_argument("--dir", type=Path, default=None, help=argparse.SUPPRESS)
    ap.add_argument("--executor", default="processes", help=argparse.SUPPRESS)
    args = ap.parse_args(argv)
    if args.logs < 1 or args.workers < 1 or args.baseline_logs < 1:
        ap.error("--logs, --workers and --baseline-logs must be at least 1")
    if args.child is not None:
        paths = sorted((args.dir / "logs").glob("*.mcap"))
        if args.child == "baseline":
            out = _child_baseline(paths, min(args.baseline_logs, len(paths)))
        else:
            dask = None if args.executor == "processes" else args.executor
            out = _child_batch(paths, args.dir / f"out-{args.executor}", workers=args.workers, dask=dask,
                               reports=args.reports)
        print(json.dumps(out))
        return 0
    print(f"load average before: {' '.join(f'{x:.1f}' for x in os.getloadavg())} on {os.cpu_count()} CPUs")
    with tempfile.TemporaryDirectory(prefix="bench-batch-") as tmp:
        root = Path(tmp)
        (root / "logs").mkdir()
        t0 = time.perf_counter()
        paths = write_logs(root / "logs", args.logs, args.duration_s)
        print(f"setup: {len(paths)} logs of {args.duration_s:g} s written in {time.perf_counter() - t0:.1f} s "
              f"({paths[0].stat().st_size / 1e6:.2f} MB each)")
        common = ["--dir", str(root), "--workers", str(args.workers), "--baseline-logs", str(args.baseline_logs),
                  *(["--reports"] if args.reports else [])]
        base, _ = _run_child(["--child", "baseline", *common])
        print(f"baseline: certify_log in one warm process, {base['wall_s'] * 1000:.1f} ms wall (median), "
              f"{base['cpu_s'] * 1000:.1f} ms CPU (mean) per log over {min(args.baseline_logs, len(paths))} logs; "
              f"{1 / base['wall_s']:.1f} logs/s")
        executors = ["processes"]
        if args.dask is not None:
            if importlib.util.find_spec("distributed") is None:
                print("dask: the 'dask' extra is not installed; skipped")
            else:
                executors.append(args.dask)
        ok = True
        lines = []
        for executor in executors:
            res, cpu = _run_child(["--child", "batch", "--executor", executor, *common])
            wall, code = res["wall_s"], int(res["exit_code"])
            over_cpu = (cpu - len(paths) * base["cpu_s"]) / len(paths)
            over_wall = wall * args.workers / len(paths) - base["wall_s"]
            good = over_cpu <= TARGET_OVERHEAD_S and code in (0, 1, 2)
            ok &= good
            name = "processes" if executor == "processes" else f"dask {executor}"
            lines.append(f"batch ({name}, {args.workers} workers, {len(paths)} logs, "
                         f"{'reports' if args.reports else 'certificates'}): {wall:.2f} s wall, {cpu:.2f} s CPU, "
                         f"{len(paths) / wall:.1f} logs/s (exit code {code}); overhead per log beyond certify_log: "
                         f"cpu_ms={over_cpu * 1000:.0f} wall_ms={over_wall * 1000:.0f} (target "
                         f"{TARGET_OVERHEAD_S * 1000:.0f} ms CPU {'met' if good else 'MISSED'})")
            print(lines[-1])
        print(f"load average after: {' '.join(f'{x:.1f}' for x in os.getloadavg())}")
        print(lines[0])
    return 0 if ok else 1


if __name__ == "__main__":
    sys.exit(main())
