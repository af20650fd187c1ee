"""Abstraction: scenario + a transition oracle (Algorithm 1 by default) -> weighted transition system (WTS).

input: a ``Scenario`` and a ``TransitionOracle`` (``tubempc.control.algorithm1.transition_time`` unless another is
given) -> output: a networkx ``DiGraph`` whose nodes are the *safe* regions (their labels: ``wts_labels``; unsafe
regions are never entered, so they are not states of the WTS) and whose edge ``i -> j`` carries the exact rational
t_ij (seconds, a ``Fraction``: ``wts_weight``) when the tube-MPC closed loop drives the robot from region ``i`` into the
terminal set of ``j`` without violating the tightened constraints. Pairs that fail are listed with the oracle's
reason (``wts_failed``). The graph's attribute keys are private to this module: everything else reads the graph
through the typed accessors at its end.

The pairs are evaluated in parallel by ``runkit.executor.parallel_map`` (a process pool, or a Dask cluster
when a client or address is given; a worker that dies is rerun alone), with a progress bar on a terminal, and the
result is cached on disk (``$TUBEMPC_CACHE`` or ``~/.cache/tubempc``) under the sha256 of the scenario, the oracle, its
settings and its code.
"""

from __future__ import annotations

import contextlib
import hashlib
import importlib
import inspect
import json
import os
import sys
import tempfile
from collections.abc import Callable, Iterable
from dataclasses import dataclass
from fractions import Fraction
from pathlib import Path
from typing import Any, Protocol

import networkx as nx

import tubempc
from tubempc.errors import AbstractionError, TubeMPCError
from tubempc.scenario import Scenario

__all__ = [
    "CACHE_ENV",
    "AbstractionError",
    "PairResult",
    "TransitionOracle",
    "TransitionOutcome",
    "build_wts",
    "cache_dir",
    "default_oracle",
    "make_wts",
    "set_wts_failed",
    "wts_all_labels",
    "wts_cache_file",
    "wts_edges",
    "wts_failed",
    "wts_from_weights",
    "wts_initial",
    "wts_labels",
    "wts_oracle",
    "wts_summary",
    "wts_weight",
]

_WEIGHT = "t_ij"  # edge attribute: Algorithm 1 time (Fraction, seconds)
_LABELS = "labels"  # node attribute: tuple of atomic propositions
_FAILED = "failed"  # graph attribute: {(i, j): reason} of pairs the controller cannot drive
_INITIAL = "initial"  # graph attribute: the initial region
_SCENARIO_SHA = "scenario_sha256"  # graph attribute
_ORACLE = "oracle"  # graph attribute: which oracle built the weights
_CACHE = "cache"  # graph attribute: the cache file (None without the cache)
CACHE_ENV = "TUBEMPC_CACHE"
_FORMAT = 1


class TransitionOutcome(Protocol):
    """What an oracle returns (``tubempc.control.algorithm1.TransitionResult`` has these fields)."""

    @property
    def ok(self) -> bool: ...

    @property
    def reason(self) -> str | None: ...

    @property
    def t_ij_s(self) -> float | None: ...


class TransitionOracle(Protocol):
    """A picklable module-level function ``(scenario, source, target, *, disturbance, seed) -> outcome``."""

    def __call__(self, scenario: Scenario, source: str, target: str, *, disturbance: str = ...,
                 seed: int = ...) -> TransitionOutcome: ...


@dataclass(frozen=True, slots=True)
class PairResult:
    """One evaluated pair: ``t_ij`` exact (seconds) when ``ok``."""

    source: str
    target: str
    ok: bool
    t_ij: Fraction | None
    reason: str | None


def default_oracle() -> TransitionOracle:
    """The controller's Algorithm 1 (imported lazily: casadi loads only when the abstraction is built)."""
    try:
        module = importlib.import_module("tubempc.control.algorithm1")
    except ImportError as err:
        raise tubempc.NotAvailableError(
            f"the controller's Algorithm 1 (tubempc.control.algorithm1) is not available: {err}") from err
    oracle: TransitionOracle = module.transition_time
    return oracle


def cache_dir() -> Path:
    """``$TUBEMPC_CACHE`` or ``~/.cache/tubempc``."""
    env = os.environ.get(CACHE_ENV)
    return Path(env) if env else Path.home() / ".cache" / "tubempc"


def _oracle_identity(oracle: Callable[..., Any]) -> dict[str, str]:
    module = getattr(oracle, "__module__", "?")
    name = getattr(oracle, "__qualname__", repr(oracle))
    code = ""
    try:
        mod = sys.modules.get(module)
        src = inspect.getsourcefile(mod) if mod is not None else None
        if src:
            # the whole package of the oracle: Algorithm 1 depends on the MPC and tube modules next to it
            pkg = Path(src).parent
            digest = hashlib.sha256()
            for path in sorted(pkg.glob("*.py")):
                digest.update(path.name.encode())
                digest.update(path.read_bytes())
            code = digest.hexdigest()
    except (OSError, TypeError):
        code = ""
    return {"oracle": f"{module}.{name}", "code": code}


def _cache_key(scenario: Scenario, oracle: Callable[..., Any], disturbance: str, seed: int) -> str:
    blob = json.dumps({"scenario": scenario.sha256(), "disturbance": disturbance, "seed": seed,
                       "version": tubempc.__version__, "format": _FORMAT, **_oracle_identity(oracle)},
                      sort_keys=True).encode()
    return hashlib.sha256(blob).hexdigest()


def _exact(t_s: float) -> Fraction:
    """Algorithm 1 times are multiples of h: the millisecond rounding removes float noise only."""
    return Fraction(str(round(t_s, 3)))


@dataclass(frozen=True, slots=True)
class _Job:
    oracle: TransitionOracle
    scenario: Scenario
    source: str
    target: str
    disturbance: str
    seed: int


def _evaluate(job: _Job) -> PairResult:
    source, target = job.source, job.target
    out = job.oracle(job.scenario, source, target, disturbance=job.disturbance, seed=job.seed)
    if out.ok:
        if out.t_ij_s is None or not out.t_ij_s > 0:
            return PairResult(source, target, False, None, f"oracle returned ok with t_ij_s={out.t_ij_s!r}")
        return PairResult(source, target, True, _exact(out.t_ij_s), None)
    return PairResult(source, target, False, None, out.reason or "the controller did not reach the target")


def wts_from_weights(scenario: Scenario, pairs: Iterable[PairResult], *, oracle_name: str) -> nx.DiGraph:
    """Assemble the WTS from evaluated pairs (also used to rebuild it from the cache)."""
    g = nx.DiGraph()
    g.graph[_INITIAL] = scenario.initial_region
    g.graph[_SCENARIO_SHA] = scenario.sha256()
    g.graph[_ORACLE] = oracle_name
    g.graph[_FAILED] = {}
    for r in scenario.safe_regions:
        g.add_node(r.name, **{_LABELS: tuple(r.labels)})
    for p in pairs:
        if p.ok and p.t_ij is not None:
            g.add_edge(p.source, p.target, **{_WEIGHT: p.t_ij})
        else:
            g.graph[_FAILED][(p.source, p.target)] = p.reason or "failed"
    return g


def _load_cache(path: Path) -> list[PairResult] | None:
    try:
        data = json.loads(path.read_text())
        return [PairResult(d["source"], d["target"], bool(d["ok"]),
                           None if d["t_ij"] is None else Fraction(d["t_ij"]), d["reason"]) for d in data["pairs"]]
    except (OSError, ValueError, KeyError, TypeError):
        return None  # a missing or corrupt cache entry is rebuilt


def _store_cache(path: Path, pairs: list[PairResult], key_info: dict[str, Any]) -> None:
    path.parent.mkdir(parents=True, exist_ok=True)
    data = {"key": key_info, "pairs": [{"source": p.source, "target": p.target, "ok": p.ok,
                                        "t_ij": None if p.t_ij is None else str(p.t_ij), "reason": p.reason}
                                       for p in pairs]}
    fd, tmp = tempfile.mkstemp(dir=path.parent, prefix=".wts-", suffix=".json")
    with os.fdopen(fd, "w") as fh:
        json.dump(data, fh, indent=1)
    os.replace(tmp, path)


def build_wts(
    scenario: Scenario,
    *,
    oracle: TransitionOracle | None = None,
    disturbance: str = "none",
    seed: int = 0,
    workers: int | None = None,
    dask: Any = None,
    use_cache: bool = True,
    cache_path: Path | None = None,
    progress: bool | None = None,
) -> nx.DiGraph:
    """Evaluate every ordered pair of safe regions with the oracle and return the WTS.

    ``workers``: processes (default: CPU count; 1 evaluates in this process). ``dask``: a
    ``dask.distributed.Client``, a scheduler address or ``"local"``; when given, the pairs run on that cluster
    instead (``runkit.executor.parallel_map``).
    ``cache_path``: a directory (default ``cache_dir()``).
    """
    fn: TransitionOracle = default_oracle() if oracle is None else oracle
    ident = _oracle_identity(fn)
    key = _cache_key(scenario, fn, disturbance, seed)
    path = (cache_path or cache_dir()) / f"wts-{key}.json"
    if use_cache:
        cached = _load_cache(path)
        if cached is not None:
            g = wts_from_weights(scenario, cached, oracle_name=ident["oracle"])
            g.graph[_CACHE] = str(path)
            return g
    names = [r.name for r in scenario.safe_regions]
    todo = [_Job(fn, scenario, a, b, disturbance, seed) for a in names for b in names if a != b]
    from runkit.errors import RunkitError
    from runkit.executor import parallel_map  # the one executor (processes or Dask) of both packages

    oracle_module = getattr(fn, "__module__", None)
    preload = ("tubempc.planning.wts", *([oracle_module] if oracle_module and oracle_module != "__main__" else []))
    try:
        results = parallel_map(_evaluate, todo, workers=workers, dask=dask, progress=progress,
                               desc="abstraction (Algorithm 1 per region pair)", unit="pair", preload=preload)
    except (TubeMPCError, RunkitError, OSError) as err:
        raise AbstractionError(f"building the WTS of scenario {scenario.name!r} failed: {err}") from err
    if use_cache:
        with contextlib.suppress(OSError):  # an unwritable cache directory only costs time on the next run
            _store_cache(path, results, {"scenario": scenario.sha256(), **ident})
    g = wts_from_weights(scenario, results, oracle_name=ident["oracle"])
    g.graph[_CACHE] = str(path) if use_cache else None
    return g


def make_wts(labels: dict[str, Iterable[str]], weights: dict[tuple[str, str], Fraction | int | str], *,
             initial: str, oracle_name: str = "given") -> nx.DiGraph:
    """A WTS from explicit labels and exact weights (seconds), e.g. for tests or hand-made abstractions."""
    g = nx.DiGraph()
    g.graph.update({_INITIAL: initial, _SCENARIO_SHA: None, _ORACLE: oracle_name, _FAILED: {}})
    for name, labs in labels.items():
        g.add_node(name, **{_LABELS: tuple(labs)})
    for (a, b), w in weights.items():
        if a not in g or b not in g:
            raise ValueError(f"weights: edge {a}->{b} names a region without labels")
        wf = Fraction(w)
        if wf <= 0:
            raise ValueError(f"weights[{a}->{b}]={w!r} must be positive")
        g.add_edge(a, b, **{_WEIGHT: wf})
    if initial not in g:
        raise ValueError(f"initial={initial!r} is not a region of the WTS")
    return g


def wts_summary(wts: nx.DiGraph) -> list[tuple[str, str, Fraction]]:
    """Edges as ``(source, target, t_ij)`` sorted by name."""
    return sorted((a, b, d[_WEIGHT]) for a, b, d in wts.edges(data=True))


# Typed accessors: the attribute keys above are read and written here alone; every other module (the search, the
# planner, the demo, the tests) goes through these.


def wts_labels(wts: nx.DiGraph, region: str) -> tuple[str, ...]:
    """The atomic propositions of ``region``."""
    return tuple(wts.nodes[region].get(_LABELS, ()))


def wts_all_labels(wts: nx.DiGraph) -> dict[str, tuple[str, ...]]:
    """Every region's atomic propositions."""
    return {n: wts_labels(wts, n) for n in wts.nodes}


def wts_weight(wts: nx.DiGraph, source: str, target: str) -> Fraction:
    """The exact time t_ij (seconds) of the transition ``source -> target`` (KeyError when there is none)."""
    weight: Fraction = wts.edges[source, target][_WEIGHT]
    return weight


def wts_edges(wts: nx.DiGraph) -> list[tuple[str, str, Any]]:
    """Every transition as ``(source, target, t_ij)`` in the graph's order (t_ij as stored: checked by the search)."""
    return [(a, b, d[_WEIGHT]) for a, b, d in wts.edges(data=True)]


def wts_initial(wts: nx.DiGraph) -> str | None:
    """The initial region the abstraction was built with (None when it names none)."""
    initial: str | None = wts.graph.get(_INITIAL)
    return initial


def wts_failed(wts: nx.DiGraph) -> dict[tuple[str, str], str]:
    """The region pairs the controller cannot drive, with the oracle's reason."""
    failed: dict[tuple[str, str], str] = wts.graph.get(_FAILED) or {}
    return failed


def set_wts_failed(wts: nx.DiGraph, failed: dict[tuple[str, str], str]) -> None:
    """Replace the failed pairs (a hand-made abstraction; ``make_wts`` starts with none)."""
    wts.graph[_FAILED] = dict(failed)


def wts_oracle(wts: nx.DiGraph) -> str | None:
    """Which oracle built the weights (None when the graph does not say)."""
    oracle: str | None = wts.graph.get(_ORACLE)
    return oracle


def wts_cache_file(wts: nx.DiGraph) -> str | None:
    """The cache file the abstraction was read from or stored in (None without the cache)."""
    cache: str | None = wts.graph.get(_CACHE)
    return cache
