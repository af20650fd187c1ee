"""Benchmark: ours' reading of one log (``verify.ingest.raw.read_raw`` of the built-in scenario's topics) against
the floor (``bench_bigbag.py``'s: reading and decompressing the chunks that hold those topics, nothing else), for
this tree and another tree of the project (a previous version), child processes alternating round by round.

    python3 benchmarks/bench_read_ab.py LOG --base-tree DIR [--rounds 6] [--reads 4]

``LOG``: a ROS1 bag, MCAP file or folder, or sqlite3 bag folder (``bench_bigbag.py --dir D`` writes 1 GB ones).
``DIR``: the root of another checkout (``git archive <commit> | tar -x -C DIR``). Each round runs three children
in turn -- the floor, the other tree's reading, this tree's reading -- each reading the log once to warm up and then
``--reads`` times, keeping the least wall time. Ratios are taken round by round (on a shared machine the host's
load moves the three children of a round alike) and their median is printed.

The last line is ``floor_ms= base_ms= this_ms= base_vs_floor= this_vs_floor=`` (medians of the rounds' least times
and of the per-round ratios).
"""

from __future__ import annotations

import argparse
import json
import os
import statistics
import subprocess
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]

_CHILD = r"""
import json, sys, time
from pathlib import Path
import benchmarks.bench_bigbag as bb
from verify.ingest.raw import detect_format, read_raw
path, side, reads = Path(sys.argv[1]), sys.argv[2], int(sys.argv[3])
wanted = bb._wanted()
fmt = detect_format(path)
if side == "floor":
    floor = bb._floor_ros1 if fmt == "ros1" else bb._floor_sqlite if fmt == "sqlite3" else bb._floor_mcap
    def once(): floor(path, wanted)
else:
    def once(): read_raw(path, wanted)
once()
best = float("inf")
for _ in range(reads):
    t0 = time.perf_counter()
    once()
    best = min(best, time.perf_counter() - t0)
print(json.dumps(best))
"""


def _child(tree: Path, log: Path, side: str, reads: int) -> float:
    env = {**os.environ, "PYTHONPATH": str(tree)}
    out = subprocess.run([sys.executable, "-c", _CHILD, str(log), side, str(reads)], cwd=tree, env=env,
                         capture_output=True, text=True, check=True).stdout
    return float(json.loads(out.strip().splitlines()[-1]))


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("log", type=Path)
    ap.add_argument("--base-tree", type=Path, required=True)
    ap.add_argument("--rounds", type=int, default=6)
    ap.add_argument("--reads", type=int, default=4)
    args = ap.parse_args()
    base = args.base_tree.resolve()
    if not (base / "verify" / "ingest" / "raw.py").is_file():
        raise SystemExit(f"{base}: not a tree of this project (no verify/ingest/raw.py)")
    if not args.log.exists():
        raise SystemExit(f"{args.log}: no such file or directory")
    runs: dict[str, list[float]] = {"floor": [], "base": [], "this": []}
    for k in range(args.rounds):
        runs["floor"].append(_child(ROOT, args.log, "floor", args.reads))
        runs["base"].append(_child(base, args.log, "ours", args.reads))
        runs["this"].append(_child(ROOT, args.log, "ours", args.reads))
        print(f"round {k + 1}: floor {runs['floor'][-1] * 1e3:.1f} ms, base {runs['base'][-1] * 1e3:.1f} ms, "
              f"this {runs['this'][-1] * 1e3:.1f} ms", flush=True)
    ratio = {side: statistics.median(a / f for a, f in zip(runs[side], runs["floor"], strict=True))
             for side in ("base", "this")}
    med = {side: statistics.median(v) * 1e3 for side, v in runs.items()}
    print(f"floor_ms={med['floor']:.1f} base_ms={med['base']:.1f} this_ms={med['this']:.1f} "
          f"base_vs_floor={ratio['base']:.3f} this_vs_floor={ratio['this']:.3f}")


if __name__ == "__main__":
    main()
