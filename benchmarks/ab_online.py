"""Before/after in one process: the online monitor of two source trees fed the same run with an ``update()`` after
every pose sample (or the default batching), in alternating passes, so that both see the same load.

    python3 benchmarks/ab_online.py BEFORE_TREE AFTER_TREE [--hours 1.0] [--passes 4] [--batching]

A tree is a folder holding ``verify/`` and ``tubempc/`` (e.g. ``git archive <commit> | tar -x -C /tmp/before``). The
run is ``bench_online.py``'s (the paper's formula and five checks, 100 Hz, one pose, nominal and command sample per
tick). Per tree: the mean CPU time per call (push-and-update), the largest of each call's median over the passes
after the first call (a call preempted or interrupted in one pass does not make it the slowest), the slowest calls,
and whether both trees made the same decisions (their ``Decision.line()``).
"""

from __future__ import annotations

import argparse
import gc
import sys
import time
from types import ModuleType

import numpy as np


def _load(tree: str) -> tuple[ModuleType, ModuleType, ModuleType]:
    """``verify.online``, ``tubempc.scenario`` and ``bench_monitor`` of ``tree`` (the other tree's modules stay in use
    by the objects made from them)."""
    for name in list(sys.modules):
        if name.split(".")[0] in ("verify", "tubempc", "bench_monitor"):
            del sys.modules[name]
    sys.path[:0] = [tree, f"{tree}/benchmarks"]
    try:  # imported from the tree just put first on the path
        import bench_monitor

        import tubempc.scenario
        import verify.online
    finally:
        del sys.path[:2]
    return verify.online, tubempc.scenario, bench_monitor


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("trees", nargs=2)
    ap.add_argument("--hours", type=float, default=1.0)
    ap.add_argument("--passes", type=int, default=4)
    ap.add_argument("--batching", action="store_true", help="no update() calls: the default batching's pushes")
    args = ap.parse_args()
    n = round(args.hours * 3600 * 100)
    loaded = [_load(t) for t in args.trees]
    _, scenario, bench = loaded[1]
    sc = scenario.builtin_scenario()
    t_ns, x, y = bench.trajectory(sc, n)
    tl = (t_ns + 1_767_225_600 * 10**9).tolist()
    xl, yl, nxl, nyl = x.tolist(), y.tolist(), (x + 0.002).tolist(), (y - 0.002).tolist()
    u = np.clip(np.gradient(x) * 100.0, -0.2, 0.2).tolist()
    v = np.clip(np.gradient(y) * 100.0, -0.2, 0.2).tolist()
    gc.collect()
    gc.freeze()  # the harness's input lists out of the collector's view (as bench_online.py)
    cpu = time.thread_time_ns
    times: list[list[np.ndarray]] = [[], []]
    lines: list[list[str]] = [[], []]
    for p in range(args.passes):
        for k in (0, 1) if p % 2 == 0 else (1, 0):
            mon = loaded[k][0].OnlineMonitor(loaded[k][1].builtin_scenario())
            ts = np.zeros(n, dtype=np.int64)
            got: list[str] = []
            for i in range(n):
                c = cpu()
                mon.push_nominal(tl[i], nxl[i], nyl[i])
                mon.push_pose(tl[i], xl[i], yl[i])
                mon.push_cmd(tl[i], u[i], v[i], 0.0)
                decisions = [] if args.batching else mon.update()
                ts[i] = cpu() - c
                got += [d.line() for d in decisions]
            got += [d.line() for d in mon.update()]
            mon.close()
            times[k].append(ts)
            lines[k] = got + [d.line() for d in mon.final_decisions]
    for k, tree in enumerate(args.trees):
        a = np.array(times[k])[:, 1:]
        med = np.median(a, axis=0)
        top = np.argsort(med)[::-1][:5]
        print(f"{tree}: mean {a.mean() / 1e3:.2f} us CPU per call; slowest call (median over {args.passes} passes) "
              f"{med.max() / 1e6:.3f} ms; slowest calls " + " ".join(f"#{j + 1}:{med[j] / 1e6:.3f}" for j in top))
    print(f"the same decisions: {'yes' if lines[0] == lines[1] else 'NO'}")


if __name__ == "__main__":
    main()
