"""Plan: WTS + formula -> a re-timed accepting timed run and the controller targets that execute it.

input: a WTS (``build_wts``) or a scenario to build it from, and a formula (the scenario's by default) -> output: a
frozen ``Plan``: the timed run ``[(region, time_s)]`` (starting with the initial region at 0; prefix plus one copy of
the repeating suffix), the margin of its times, and the targets ``(region, planned arrival, depart after)`` for the
closed loop.

Dwell modes: ``silent`` (default) — a wait adds no position, the run lists only arrivals (what Definition 3
reconstructs from a log) and each wait is a planned departure time of a target (a wait in the initial region before
the first departure is a first target for the initial region); ``observed`` — each dwell is a position of the run.
"""

from __future__ import annotations

import math
from collections.abc import Mapping
from dataclasses import dataclass
from fractions import Fraction
from typing import TYPE_CHECKING, Any

import networkx as nx

from tubempc.errors import DesignError
from tubempc.mitl import Formula
from tubempc.planning.reference_semantics import LassoRun
from tubempc.planning.retime import OBJECTIVES, retime
from tubempc.planning.search import DEFAULT_MAX_STATES, DWELL_MODES, SILENT, SearchResult, find_run
from tubempc.planning.wts import TransitionOracle, build_wts, wts_all_labels, wts_failed, wts_oracle
from tubempc.scenario import Scenario

if TYPE_CHECKING:
    from tubempc.control.closed_loop import Target

__all__ = ["Plan", "PlannedTarget", "plan_from_run", "plan_from_wts", "plan_mission", "require_transitions"]


@dataclass(frozen=True, slots=True)
class PlannedTarget:
    """Go to ``region`` (planned arrival ``arrival_s``); hold there until ``depart_after_s`` (None: leave at once,
    or, for the last target, stay)."""

    region: str
    arrival_s: float
    depart_after_s: float | None


@dataclass(frozen=True, slots=True)
class Plan:
    """A planned mission. ``run[loop_start:]`` repeats forever, ``period_s`` after its first position;
    ``period_s == 0``: the run ends at its last position and the robot stays there (no further position)."""

    formula: str
    run: tuple[tuple[str, float], ...]
    kinds: tuple[str, ...]
    loop_start: int
    period_s: float
    margin_s: float
    targets: tuple[PlannedTarget, ...]
    labels: Mapping[str, tuple[str, ...]]
    exact_times: tuple[Fraction, ...]
    tick_s: Fraction
    wait: bool
    dwell: str  # "silent", "observed" or "none" (no waiting)
    retimed: bool
    oracle: str
    search_s: float
    product_states: int
    objective: str = "time"  # "time": the cost is the search's optimum; "margin": re-timed for margin alone
    method: str = ""  # how the search established the run (exact search, or first attempt proved optimal)

    def __post_init__(self) -> None:
        if not self.run or self.run[0][1] != 0.0:
            raise ValueError("a plan's run must start at time 0")
        if not 0 <= self.loop_start < len(self.run):
            raise ValueError(f"loop_start={self.loop_start} is not a position of the run")

    def controller_targets(self) -> list[Target]:
        """The targets as ``tubempc.control.closed_loop.Target`` values (imports the controller)."""
        from tubempc.control.closed_loop import Target

        return [Target(region=t.region, depart_after_s=t.depart_after_s) for t in self.targets]

    def to_json(self) -> dict[str, Any]:
        return {
            "formula": self.formula,
            "run": [{"region": r, "time": t, "kind": k, "labels": list(self.labels.get(r, ()))}
                    for (r, t), k in zip(self.run, self.kinds, strict=True)],
            "loop_start": self.loop_start,
            "period_s": self.period_s,
            "margin_s": None if math.isinf(self.margin_s) else self.margin_s,
            "targets": [{"region": t.region, "arrival_s": t.arrival_s, "depart_after_s": t.depart_after_s}
                        for t in self.targets],
            "wait": self.wait,
            "dwell": self.dwell,
            "retimed": self.retimed,
            "objective": self.objective,
            "tick_s": str(self.tick_s),
            "oracle": self.oracle,
        }


def _targets(run: LassoRun, kinds: tuple[str, ...]) -> tuple[PlannedTarget, ...]:
    out: list[PlannedTarget] = []
    n = run.size
    k = 0
    while k < n:
        if kinds[k] == "dwell" and k > 0 and out and out[-1].region == run.regions[k]:
            k += 1
            continue
        region, arrival = run.regions[k], float(run.times[k])
        last = k
        while last + 1 < n and kinds[last + 1] == "dwell":
            last += 1
        depart = float(run.times[last]) if last > k else None
        if k == 0 and last == 0:
            k += 1
            continue  # starting in the initial region and leaving at once: no target
        out.append(PlannedTarget(region, arrival, depart))
        k = last + 1
    return tuple(out)


def _silent_targets(run: LassoRun, weights: list[Fraction]) -> tuple[PlannedTarget, ...]:
    """One target per arrival; a silent wait before a departure is the previous target's ``depart_after_s`` (a
    wait before the first departure: a first target for the initial region, held from time 0)."""
    n = run.size
    departs: list[float | None] = [None] * n  # planned departure from position k (None: leave on arrival)
    for k in range(1, n):
        if run.times[k] - run.times[k - 1] > weights[k]:
            departs[k - 1] = float(run.times[k] - weights[k])
    out: list[PlannedTarget] = []
    if departs[0] is not None:
        out.append(PlannedTarget(run.regions[0], 0.0, departs[0]))
    out.extend(PlannedTarget(run.regions[k], float(run.times[k]), departs[k]) for k in range(1, n))
    return tuple(out)


def require_transitions(wts: nx.DiGraph, *, scenario_name: str | None = None) -> None:
    """Raise ``DesignError`` (unusable input, exit 3) when the abstraction has no usable transition because every
    region pair failed (the controller's design check, or its runs): the message names the failed quantity and an
    example pair (``scenario_name``, when given, opens the message)."""
    failed = wts_failed(wts)
    if wts.number_of_edges() > 0 or not failed:
        return
    counts: dict[str, list[tuple[str, str]]] = {}
    for pair, reason in failed.items():
        counts.setdefault(reason, []).append(pair)
    reason, pairs = max(counts.items(), key=lambda kv: (len(kv[1]), kv[0]))
    a, b = sorted(pairs)[0]
    others = "" if len(counts) == 1 else f"; {len(counts) - 1} other reason(s) for the other pairs"
    opening = f"scenario {scenario_name}: " if scenario_name is not None else ""
    raise DesignError(f"{opening}every transition between regions failed the controller's design check "
                      f"({len(failed)} of {len(failed)}): the abstraction has no usable transition, so there is "
                      f"nothing to plan on; {len(pairs)} of them with this reason, e.g. {a} -> {b}: {reason}{others}")


def plan_from_wts(wts: nx.DiGraph, formula: Formula, *, wait: bool = True, initial: str | None = None,
                  max_states: int = DEFAULT_MAX_STATES, dwell: str = SILENT, objective: str = "time") -> Plan:
    """Search, re-time and map to targets (raises ``NoAcceptingRunError`` when no run exists, ``SearchLimitError``
    when the search reaches ``max_states`` before it can decide, ``DesignError`` when every region pair of the
    abstraction failed: ``require_transitions``).

    ``wait``: whether the robot may wait in a region; ``dwell`` (with ``wait``): ``silent`` or ``observed``.
    ``objective``: ``time`` (default) re-times for margin without making the run's cost later than the search's
    optimum; ``margin`` maximises the margin even if the last obligation is then met later."""
    if dwell not in DWELL_MODES:
        raise ValueError(f"dwell={dwell!r} must be one of {DWELL_MODES}")
    if objective not in OBJECTIVES:
        raise ValueError(f"objective={objective!r} must be one of {OBJECTIVES}")
    require_transitions(wts)
    found: SearchResult = find_run(wts, formula, wait=wait, initial=initial, max_states=max_states, dwell=dwell)
    return plan_from_run(wts, formula, found, wait=wait, objective=objective)


def plan_from_run(wts: nx.DiGraph, formula: Formula, found: SearchResult, *, wait: bool = True,
                  objective: str = "time") -> Plan:
    """Re-time the run ``find_run`` found on ``wts`` for ``formula`` and map it to targets (``plan_from_wts``'s
    second half: a caller that also needs the search result, e.g. its explored product, searches once)."""
    if objective not in OBJECTIVES:
        raise ValueError(f"objective={objective!r} must be one of {OBJECTIVES}")
    labels = wts_all_labels(wts)
    silent = found.dwell == SILENT
    # the WTS weight of the step into each position (silent mode: its duration without the wait)
    weights = [Fraction(0)] + [found.run.times[k] - found.run.times[k - 1] - found.waits_s[k]
                               for k in range(1, found.run.size)]
    re = retime(found.run, found.kinds, formula, labels, min_dwell_s=found.tick_s,
                waits_s=found.waits_s if silent else None, objective=objective)
    run = re.run
    loop = run.loop_start if run.loop_start is not None else run.size - 1
    period = run.period if run.period is not None else Fraction(0)
    return Plan(
        formula=str(formula),
        run=tuple((r, float(t)) for r, t in zip(run.regions, run.times, strict=True)),
        kinds=found.kinds,
        loop_start=loop,
        period_s=float(period),
        margin_s=re.margin_s,
        targets=_silent_targets(run, weights) if silent else _targets(run, found.kinds),
        labels=labels,
        exact_times=run.times,
        tick_s=found.tick_s,
        wait=wait,
        dwell=found.dwell,
        retimed=re.retimed,
        oracle=str(wts_oracle(wts) or "?"),
        search_s=found.seconds,
        product_states=found.states,
        objective=objective,
        method=found.method,
    )


def plan_mission(scenario: Scenario, *, formula: Formula | None = None, wait: bool = True, dwell: str = SILENT,
                 wts: nx.DiGraph | None = None, oracle: TransitionOracle | None = None, use_cache: bool = True,
                 workers: int | None = None, dask: Any = None, progress: bool | None = None,
                 objective: str = "time") -> Plan:
    """Build (or reuse) the scenario's WTS and plan ``formula`` (default: the scenario's spec) on it."""
    graph = wts if wts is not None else build_wts(scenario, oracle=oracle, use_cache=use_cache, workers=workers,
                                                  dask=dask, progress=progress)
    return plan_from_wts(graph, formula if formula is not None else scenario.formula, wait=wait, dwell=dwell,
                         initial=scenario.initial_region, objective=objective)
