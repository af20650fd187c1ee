"""Benchmark: the Python work per chunk of the ROS1 reader (what it does beside decompression), this tree against
another tree of the project (a previous version), in one process.

    python3 benchmarks/bench_chunk_costs.py LOG.bag --base-tree DIR [--repeat 15]

``LOG.bag``: an indexed, compressed ROS1 bag (``bench_bigbag.py`` writes one: ``bigbag_1gb_ros1_lz4.bag``).
``DIR``: the root of another checkout (``git archive <commit> | tar -x -C DIR``); its ``verify/ingest/ros1.py`` is
loaded beside this tree's under another module name (the rest of ``verify`` is this tree's). For each version, over
every chunk holding a wanted topic of the built-in scenario: the chunk's index data records read (``_wanted_index``,
the reading thread's work per chunk) and its wanted records copied out of the decompressed chunk (``_copy_records``,
each decompressing thread's work per chunk, on the first 150 chunks, decompressed once beforehand). Each is timed in
thread CPU, best of ``--repeat`` passes, the versions alternating pass by pass: on a shared machine the host's load
moves both alike. On two cores, every microsecond of such Python per chunk costs about half a microsecond of wall
time beside the two decompressing threads (``docs/certifier.md``, "Ours' reading against the floor").

The last line is ``index_us_this= index_us_base= copy_us_this= copy_us_base= ratio_this_vs_base=`` (the ratio of
the sums).
"""

from __future__ import annotations

import argparse
import importlib.util
import sys
import time
from pathlib import Path
from types import ModuleType
from typing import Any

import verify.ingest.ros1 as this_ros1
from tubempc.scenario import builtin_scenario
from verify.ingest.log import wanted_topics


def _load_base(tree: Path) -> ModuleType:
    spec = importlib.util.spec_from_file_location("ros1_base", tree / "verify" / "ingest" / "ros1.py")
    if spec is None or spec.loader is None:
        raise SystemExit(f"{tree}: no verify/ingest/ros1.py")
    module = importlib.util.module_from_spec(spec)
    sys.modules["ros1_base"] = module  # (dataclasses look their module up while the class is made)
    spec.loader.exec_module(module)
    return module


def _prepared(r: Any, fd: int, wanted: set[str]) -> dict[str, Any]:
    """The reader's own steps up to the chunks: its index (connections, chunk infos, chunk headers), then each
    wanted chunk's index entries, and the first 150 wanted chunks decompressed."""
    f = r._File(fd)
    header, *_ = f.record(len(r._MAGIC))
    index_pos = r._u64(header["index_pos"], "index_pos")
    conns, pos = r._connections(f, index_pos, r._u32(header["conn_count"], "conn_count"))
    selected = {c.cid: c for c in conns if c.topic in wanted}
    infos = list(r._chunk_infos(f, pos, r._u32(header["chunk_count"], "chunk_count")))
    heads = [r._chunk_head(f, p) for p, _n, _ids in infos]
    plans = [r._wanted_index(f, h[4], n, ids, selected) for h, (_p, n, ids) in zip(heads, infos, strict=True)]
    wanted_chunks = [(h, plan[0]) for h, plan in zip(heads, plans, strict=True) if plan[0]][:150]
    bodies = [(r._chunk_body(f, h[0], h[1], h[2], h[3]), mine) for h, mine in wanted_chunks]
    return {"r": r, "f": f, "selected": selected, "infos": infos, "heads": heads, "bodies": bodies}


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("log", type=Path)
    ap.add_argument("--base-tree", type=Path, required=True)
    ap.add_argument("--repeat", type=int, default=15)
    args = ap.parse_args()
    wanted = wanted_topics(builtin_scenario())
    with args.log.open("rb") as fh:
        sides = {"this": _prepared(this_ros1, fh.fileno(), wanted),
                 "base": _prepared(_load_base(args.base_tree), fh.fileno(), wanted)}
        best = {(side, what): float("inf") for side in sides for what in ("index", "copy")}
        for _ in range(args.repeat):
            for side, d in sides.items():
                r, f, selected = d["r"], d["f"], d["selected"]
                t0 = time.thread_time()
                for h, (_p, n, ids) in zip(d["heads"], d["infos"], strict=True):
                    r._wanted_index(f, h[4], n, ids, selected)
                best[side, "index"] = min(best[side, "index"], (time.thread_time() - t0) / len(d["infos"]))
                t0 = time.thread_time()
                for body, mine in d["bodies"]:
                    r._copy_records(body, mine)
                best[side, "copy"] = min(best[side, "copy"], (time.thread_time() - t0) / max(len(d["bodies"]), 1))
    n_chunks = len(sides["this"]["infos"])
    print(f"{args.log.name}: {n_chunks} chunks; thread CPU per chunk, best of {args.repeat} passes")
    us = {k: v * 1e6 for k, v in best.items()}
    for side in sides:
        print(f"  {side}: index data records {us[side, 'index']:.1f} us, "
              f"wanted records copied {us[side, 'copy']:.1f} us")
    ratio = (us["this", "index"] + us["this", "copy"]) / (us["base", "index"] + us["base", "copy"])
    print(f"index_us_this={us['this', 'index']:.1f} index_us_base={us['base', 'index']:.1f} "
          f"copy_us_this={us['this', 'copy']:.1f} copy_us_base={us['base', 'copy']:.1f} "
          f"ratio_this_vs_base={ratio:.2f}")


if __name__ == "__main__":
    main()
