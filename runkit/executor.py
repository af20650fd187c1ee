"""The one executor of both packages: a function and its jobs -> their results in input order, run in parallel.

input: a picklable ``fn``, its items, and where to run them (``workers``: processes, 1 = inline; ``dask``: a Dask
cluster) -> output: ``[fn(x) for x in items]``. Used by the abstraction (``tubempc.planning.wts``: Algorithm 1 per
region pair), batch certification (``verify.batch``), ``tubempc regress`` and the falsifier (``tubempc.falsify``).

Processes: a ``ProcessPoolExecutor`` on the ``forkserver`` start method (``spawn`` where there is none): the server
imports ``preload`` once and workers fork from it in milliseconds. A worker that dies (a segfault or an
out-of-memory kill in native code) breaks the pool: every item not finished then is rerun alone in a fresh process,
so one bad item cannot take the others down; an item whose lone rerun dies too gets ``on_crash(item)`` as its result
(without ``on_crash``: ``RuntimeError``, an internal error, exit 70). Dask distributed (the ``dask`` extra):
``dask="local"`` (a ``LocalCluster`` on loopback, worker processes, one thread each, no dashboard),
``dask="tcp://host:port"`` (an existing scheduler whose workers can import this package and see the same paths),
or a ``distributed.Client`` the caller owns (used, not closed). On Dask the items go in chunks (a few per worker:
one task, one message and one pickled copy of objects the items share, such as a batch's scenario, per chunk rather
than per item); a local cluster's worker processes fork from a server that imported ``preload`` once, as the
process pool's do. Exceptions raised by ``fn`` propagate.
"""

from __future__ import annotations

import importlib
import logging
import multiprocessing
import os
import re
import sys
from collections.abc import Callable, Sequence
from concurrent.futures import Future, ProcessPoolExecutor, as_completed
from concurrent.futures.process import BrokenProcessPool
from typing import Any, TypeVar

from tqdm import tqdm

from runkit.errors import OutputError

__all__ = ["parallel_map"]

T = TypeVar("T")
R = TypeVar("R")


def _show_progress(progress: bool | None) -> bool:
    return sys.stderr.isatty() if progress is None else progress


def _process_context(preload: Sequence[str]) -> multiprocessing.context.BaseContext:
    """forkserver where available: the server imports ``preload`` once, workers fork from it in milliseconds
    (spawn would re-import pandas, rosbags, casadi in every worker; fork is unsafe with threads)."""
    if "forkserver" in multiprocessing.get_all_start_methods():
        ctx = multiprocessing.get_context("forkserver")
        ctx.set_forkserver_preload(list(preload))
        return ctx
    return multiprocessing.get_context("spawn")


def parallel_map(fn: Callable[[T], R], items: Sequence[T], *, workers: int | None = None, dask: Any = None,
                 progress: bool | None = None, desc: str = "", unit: str = "job", preload: Sequence[str] = (),
                 on_crash: Callable[[T], R] | None = None) -> list[R]:
    """``[fn(x) for x in items]`` in parallel, results in input order. ``fn`` and items must be picklable.

    ``workers``: processes (default: CPU count; 1 runs inline). ``dask``: ``"local"``, a scheduler address or a
    ``distributed.Client``. ``progress``: a tqdm bar on stderr (default: only when stderr is a terminal), labelled
    ``desc`` and counting ``unit``. ``preload``: modules the process server imports once for all workers.
    Exceptions raised by ``fn`` propagate; callers that must not stop (``certify_many``) catch inside ``fn``. Worker
    processes re-import the caller's ``__main__`` module: scripts must guard their top level with
    ``if __name__ == "__main__":``. A worker crash: see the module docstring (``on_crash``).
    """
    if workers is not None and workers < 1:
        raise ValueError(f"workers={workers!r} must be at least 1")
    bar = tqdm(total=len(items), desc=desc or None, unit=unit, disable=not _show_progress(progress),
               file=sys.stderr, leave=True)
    try:
        if dask is not None:
            return _dask_map(fn, items, workers=workers, dask=dask, bar=bar, preload=preload)
        n = min(workers or os.cpu_count() or 1, len(items))
        if n <= 1:
            out = []
            for item in items:
                out.append(fn(item))
                bar.update()
            return out
        results: dict[int, R] = {}
        context = _process_context(preload)
        broken: list[int] = []
        pool = ProcessPoolExecutor(max_workers=n, mp_context=context)
        try:
            futures: dict[Future[R], int] = {}
            for i, item in enumerate(items):
                try:
                    futures[pool.submit(fn, item)] = i
                except BrokenProcessPool:  # a worker died before the last items were handed out: rerun them too
                    broken.extend(range(i, len(items)))
                    break
            for fut in as_completed(futures):
                try:
                    results[futures[fut]] = fut.result()
                except BrokenProcessPool:
                    broken.append(futures[fut])
                    continue
                bar.update()
        finally:
            _shut_down(pool, broken=bool(broken))
        for i in sorted(broken):  # rerun alone: an item that was only a bystander of the crash now finishes
            results[i] = _run_alone(fn, items[i], context, on_crash)
            bar.update()
        return [results[i] for i in range(len(items))]
    finally:
        bar.close()


def _shut_down(pool: ProcessPoolExecutor, *, broken: bool) -> None:
    """Shut a pool down. After a worker died, the surviving workers are killed first: waiting for them can hang
    for ever (a survivor blocked reading its call queue is never told to stop once the pool is broken)."""
    if broken:
        processes: dict[int, multiprocessing.process.BaseProcess] = getattr(pool, "_processes", None) or {}
        for proc in list(processes.values()):
            proc.kill()
    pool.shutdown(wait=True, cancel_futures=True)


def _run_alone(fn: Callable[[T], R], item: T, context: multiprocessing.context.BaseContext,
               on_crash: Callable[[T], R] | None) -> R:
    solo = ProcessPoolExecutor(max_workers=1, mp_context=context)
    died = False
    try:
        return solo.submit(fn, item).result()
    except BrokenProcessPool as err:
        died = True
        if on_crash is not None:
            return on_crash(item)
        raise RuntimeError("a worker process died twice on the same item (a crash or out-of-memory kill in "
                           "native code; or a script that starts workers without an `if __name__ == "
                           "\"__main__\":` guard)") from err
    finally:
        _shut_down(solo, broken=died)


#: chunks per Dask worker: few enough that the scheduler's per-task cost is negligible, enough to balance the load
_CHUNKS_PER_WORKER = 4


def _run_chunk(fn: Callable[[T], R], chunk: Sequence[T]) -> list[R]:
    """One Dask task: ``fn`` over a chunk of items, in order."""
    return [fn(item) for item in chunk]


def _chunks(items: Sequence[T], workers: int) -> list[list[T]]:
    """``items`` cut into at most ``workers * _CHUNKS_PER_WORKER`` contiguous chunks of near-equal size."""
    count = min(len(items), max(workers, 1) * _CHUNKS_PER_WORKER)
    if count == 0:
        return []
    size, extra = divmod(len(items), count)
    out: list[list[T]] = []
    start = 0
    for k in range(count):
        stop = start + size + (k < extra)
        out.append(list(items[start:stop]))
        start = stop
    return out


def _local_cluster(dist: Any, workers: int | None, preload: Sequence[str]) -> Any:
    """A ``LocalCluster`` whose worker processes fork from a server that imported ``distributed`` and ``preload``
    once (distributed's default spawns each worker, which then imports everything again)."""
    dask_config: Any = importlib.import_module("dask.config")
    utils: Any = importlib.import_module("distributed.utils")
    method = "forkserver" if "forkserver" in multiprocessing.get_all_start_methods() else "spawn"
    # the periodic work of an idle cluster (event-loop ticks every 20 ms, system and memory monitors) costs CPU in
    # every process for as long as the batch runs; a batch needs none of it at that rate (no dashboard)
    quiet = {"distributed.admin.tick.interval": "1s", "distributed.admin.system-monitor.interval": "5s",
             "distributed.worker.memory.monitor-interval": "1s"}
    with dask_config.set({"distributed.worker.multiprocessing-method": method, **quiet}):
        if method == "forkserver":
            utils.get_mp_context().set_forkserver_preload(["distributed", *preload])
        return dist.LocalCluster(n_workers=workers or min(2, os.cpu_count() or 1), threads_per_worker=1,
                                 processes=True, host="127.0.0.1", dashboard_address=None,
                                 silence_logs=logging.ERROR)


def _dask_map(fn: Callable[[T], R], items: Sequence[T], *, workers: int | None, dask: Any, bar: Any,
              preload: Sequence[str] = ()) -> list[R]:
    from runkit.extras import require

    require("dask", feature="--dask")
    # distributed is only partly typed; treat it as untyped at this one boundary
    dist: Any = importlib.import_module("distributed")
    Client, dask_completed = dist.Client, dist.as_completed

    cluster = None
    owned = isinstance(dask, str)
    try:
        if not owned:
            client = dask  # the caller's client: used, not closed
        elif dask == "local":
            cluster = _local_cluster(dist, workers, preload)
            client = Client(cluster)
        elif re.fullmatch(r"(tcp|tls|inproc|ucx)://\S+", dask):
            client = Client(dask, timeout="20s")
        else:
            raise OutputError(f"dask={dask!r}: expected 'local' or a scheduler address such as "
                                     f"tcp://host:8786", path=dask)
    except OSError as err:  # includes connection timeouts
        raise OutputError(f"cannot reach the Dask scheduler ({err.__class__.__name__}: {err})",
                                 path=str(dask)) from err
    try:
        chunks = _chunks(items, len(client.scheduler_info().get("workers", {})) or workers or 1)
        # ship the inputs as data (certification results carry frames), not embedded in the task graph
        scattered = client.scatter(chunks) if chunks else []
        futures = client.map(_run_chunk, [fn] * len(chunks), scattered, pure=False)
        sizes = {fut.key: len(chunk) for fut, chunk in zip(futures, chunks, strict=True)}
        for fut in dask_completed(futures):
            bar.update(sizes[fut.key])
        gathered: list[list[R]] = client.gather(futures)
        return [r for part in gathered for r in part]
    finally:
        if owned:
            client.close()
        if cluster is not None:
            cluster.close()
