"""Search methods: a setup, a budget and a seed -> the evaluated candidates in the order they were simulated.

input: a ``FalsifySetup``, the method (``random``, ``targeted``, ``optimizer``), the budget (simulations), the seed,
and where to run (processes or Dask, through ``runkit.executor.parallel_map``) -> output: a frozen
``SearchResult``.

- ``random``: ``budget`` points drawn uniformly in the cube by ``numpy.random.default_rng(seed)`` (the baseline);
- ``targeted``: hypothesis generates the points (``hypothesis.seed(seed)``), ``target()`` steers it to the lowest
  margin of every selected check, and a violation is shrunk towards ``z = 0`` (the smallest perturbation that still
  breaks the run) with its own budget of simulations; one simulation at a time;
- ``optimizer``: scipy's differential evolution (``seed``; a Latin-hypercube first population of ``min(10,
  budget)`` points, each later generation simulated in parallel), minimising the margin.

Every method simulates at most ``budget`` points before its first violation (the shrinking of ``targeted`` is
counted apart); with ``stop_at_first`` it stops at the first violation. A point seen before is not simulated again.
"""

from __future__ import annotations

import contextlib
import math
import time
from collections.abc import Iterator, Sequence
from dataclasses import dataclass
from typing import Any, Literal

import numpy as np

from tubempc.falsify.objective import NO_MARGIN, Evaluation, FalsifySetup, evaluate_job

__all__ = ["METHODS", "Method", "SearchResult", "search"]

Method = Literal["random", "targeted", "optimizer"]
METHODS: tuple[Method, ...] = ("random", "targeted", "optimizer")
DE_POPULATION = 10
_PRELOAD = ("verify.batch", "verify", "tubempc.falsify.objective", "tubempc.control.closed_loop",
            "tubempc.rosio.memory")


@dataclass(frozen=True, slots=True)
class SearchResult:
    """The simulated candidates in order (``evaluations``) and, for ``targeted``, the shrinking's."""

    method: Method
    budget: int
    seed: int
    evaluations: tuple[Evaluation, ...]
    shrink_evaluations: tuple[Evaluation, ...]
    minimal: Evaluation | None  # targeted: the shrunk counterexample
    elapsed_s: float

    @property
    def first_violation(self) -> int | None:
        """1-based number of the simulation that found the first violation (None: none found)."""
        for k, ev in enumerate(self.evaluations, start=1):
            if ev.violated:
                return k
        return None

    @property
    def worst(self) -> Evaluation | None:
        """The lowest margin over every simulated candidate (violations first when margins tie)."""
        pool = [e for e in (*self.evaluations, *self.shrink_evaluations) if e.error is None]
        if not pool:
            return None
        return min(pool, key=lambda e: (e.margin, not e.violated))

    @property
    def sims(self) -> int:
        return len(self.evaluations) + len(self.shrink_evaluations)


class _Runner:
    """Simulates points through ``parallel_map``; remembers what it has seen."""

    def __init__(self, setup: FalsifySetup, *, workers: int | None, dask: str | None,
                 known: Sequence[Evaluation]) -> None:
        self.setup = setup
        self.workers = workers
        self.dask = dask
        self.cache: dict[tuple[float, ...], Evaluation] = {e.z: e for e in known}
        self.order: list[Evaluation] = []

    def run(self, points: Sequence[tuple[float, ...]], *, inline: bool = False) -> list[Evaluation]:
        from runkit.executor import parallel_map

        todo = [z for z in dict.fromkeys(points) if z not in self.cache]
        if todo:
            jobs = [(self.setup, z) for z in todo]
            if inline or (self.dask is None and (self.workers == 1 or len(jobs) == 1)):
                done = [evaluate_job(j) for j in jobs]
            else:
                done = parallel_map(evaluate_job, jobs, workers=self.workers, dask=self.dask, progress=False,
                                    desc="falsify", preload=_PRELOAD)
            for ev in done:
                self.cache[ev.z] = ev
                self.order.append(ev)
        return [self.cache[z] for z in points]


@contextlib.contextmanager
def _dask_scheduler(dask: str | None, workers: int | None, *, needed: bool) -> Iterator[str | None]:
    """``"local"``: one local cluster for the whole search (not one per generation); its address is handed to
    ``parallel_map``. Other values pass through."""
    if dask != "local" or not needed:
        yield dask
        return
    import importlib
    import logging
    import os

    distributed: Any = importlib.import_module("distributed")  # partly typed: untyped at this one boundary
    cluster = distributed.LocalCluster(n_workers=workers or min(2, os.cpu_count() or 1), threads_per_worker=1,
                                       processes=True, host="127.0.0.1", dashboard_address=None,
                                       silence_logs=logging.ERROR)
    try:
        yield str(cluster.scheduler_address)
    finally:
        cluster.close()


def _score(ev: Evaluation) -> float:
    return ev.margin if math.isfinite(ev.margin) else NO_MARGIN


def _random(runner: _Runner, dim: int, budget: int, seed: int, *, stop_at_first: bool, chunk: int) -> None:
    rng = np.random.default_rng(seed)
    points = [tuple(float(v) for v in row) for row in rng.uniform(-1.0, 1.0, size=(budget, dim))]
    step = chunk if stop_at_first else budget
    for i in range(0, budget, step):
        evs = runner.run(points[i:i + step])
        if stop_at_first and any(e.violated for e in evs):
            return


def _optimizer(runner: _Runner, dim: int, budget: int, seed: int, *, stop_at_first: bool) -> None:
    from runkit.extras import require

    require("plan", feature="falsify --method optimizer")
    from scipy.optimize import differential_evolution
    from scipy.stats.qmc import LatinHypercube

    pop = min(DE_POPULATION, budget)
    if pop < 5:
        raise ValueError(f"budget={budget!r}: the optimizer needs at least 5 simulations (one population)")
    generations = budget // pop - 1
    init = LatinHypercube(d=dim, seed=np.random.default_rng(seed)).random(pop) * 2.0 - 1.0
    state = {"stop": False}

    def mapper(_func: object, population: Sequence[np.ndarray]) -> list[float]:
        if state["stop"]:  # scipy may ask once more after the callback stopped it: answer without simulating
            return [NO_MARGIN] * len(population)
        evs = runner.run([tuple(float(v) for v in z) for z in population])
        if stop_at_first and any(e.violated for e in evs):
            state["stop"] = True
        return [_score(e) for e in evs]

    def unused(_z: np.ndarray) -> float:  # the mapper simulates; scipy's wrapper of this is never called
        raise AssertionError("the mapper evaluates the population")

    def callback(*_args: object, **_kwargs: object) -> bool:
        return state["stop"]

    if generations >= 0:
        differential_evolution(unused, [(-1.0, 1.0)] * dim, init=init, maxiter=max(generations, 0), polish=False,
                               updating="deferred", workers=mapper, seed=seed, tol=0.0, atol=0.0,
                               callback=callback)


@dataclass
class _Tally:
    search: int = 0  # simulations before the first violation
    violated: bool = False
    last: Evaluation | None = None  # the last violation seen: after shrinking, hypothesis' minimal example


class _Counterexample(Exception):  # noqa: N818 (hypothesis needs an exception to shrink; this is not an error)
    pass


def _targeted(runner: _Runner, dim: int, budget: int, seed: int, *, stop_at_first: bool,
              shrink_budget: int) -> tuple[list[Evaluation], Evaluation | None]:
    from runkit.extras import require

    require("testing", feature="falsify --method targeted")
    from hypothesis import HealthCheck, Phase, Verbosity, given, settings, target
    from hypothesis import seed as hseed
    from hypothesis import strategies as st

    shrunk: list[Evaluation] = []
    state = _Tally()
    phases = [Phase.generate, Phase.target] + ([] if stop_at_first else [Phase.shrink])

    @settings(max_examples=2 * budget + 10, database=None, deadline=None, derandomize=False, phases=phases,
              suppress_health_check=list(HealthCheck), report_multiple_bugs=False, verbosity=Verbosity.quiet,
              print_blob=False)
    @hseed(seed)
    @given(st.tuples(*[st.floats(-1.0, 1.0, allow_nan=False)] * dim))
    def probe(z: tuple[float, ...]) -> None:
        key = tuple(float(v) for v in z)
        ev = runner.cache.get(key)
        if ev is None:
            if not state.violated:
                if state.search >= budget:
                    return  # the search budget is spent: hypothesis may ask, nothing more is simulated
                state.search += 1
                ev = runner.run([key], inline=True)[0]
            else:
                if len(shrunk) >= shrink_budget:
                    return  # the shrink budget is spent: the shrinker sees no further failure
                ev = runner.run([key], inline=True)[0]
                shrunk.append(ev)
        if ev.error is not None:
            return
        for name, entry in ev.checks.items():
            margin = entry.get("margin")
            if isinstance(margin, int | float) and math.isfinite(float(margin)):
                target(-float(margin), label=name)
        target(-_score(ev), label="margin")
        if ev.violated:
            state.violated = True
            state.last = ev
            raise _Counterexample

    with contextlib.suppress(_Counterexample):
        probe()
    return shrunk, state.last


def search(setup: FalsifySetup, method: Method, *, budget: int, seed: int = 0, workers: int | None = None,
           dask: str | None = None, stop_at_first: bool = False, shrink_budget: int | None = None,
           known: Sequence[Evaluation] = ()) -> SearchResult:
    """Run one method with ``budget`` simulations (``known``: evaluations to reuse, e.g. the unperturbed run)."""
    if method not in METHODS:
        raise ValueError(f"method={method!r} is not one of {', '.join(METHODS)}")
    if budget < 1:
        raise ValueError(f"budget={budget!r} must be at least 1")
    dim = setup.space.dim
    start = time.perf_counter()
    shrunk: list[Evaluation] = []
    minimal = None
    with _dask_scheduler(dask, workers, needed=method != "targeted") as address:
        runner = _Runner(setup, workers=workers, dask=address, known=known)
        if method == "random":
            import os

            _random(runner, dim, budget, seed, stop_at_first=stop_at_first,
                    chunk=max(1, workers or os.cpu_count() or 1))
        elif method == "optimizer":
            _optimizer(runner, dim, budget, seed, stop_at_first=stop_at_first)
        else:
            shrunk, minimal = _targeted(runner, dim, budget, seed, stop_at_first=stop_at_first,
                                        shrink_budget=budget if shrink_budget is None else shrink_budget)
    shrink_ids = {id(e) for e in shrunk}
    ordered = tuple(e for e in runner.order if id(e) not in shrink_ids)
    return SearchResult(method, budget, seed, ordered, tuple(shrunk), minimal, time.perf_counter() - start)
