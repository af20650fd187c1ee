"""Plan: WTS + formula -> a re-timed accepting timed run and the controller targets that execute it.

input: a WTS (``build_wts``) or a scenario to build it from, and a formula (the scenario's by default) -> output: a
frozen ``Plan``: the timed run ``[(region, time_s)]`` (one entry per arrival or dwell position, starting with the
initial region at 0; prefix plus one copy of the repeating suffix), the margin of its times, and the targets
``(region, planned arrival, depart after)`` for the closed loop.
"""

from __future__ import annotations

import math
from collections.abc import Mapping
from dataclasses import dataclass
from fractions import Fraction
from typing import TYPE_CHECKING, Any

import networkx as nx

from tubempc.mitl import Formula
from tubempc.planning.retime import retime
from tubempc.planning.search import DEFAULT_MAX_STATES, SearchResult, find_run
from tubempc.planning.semantics import LassoRun
from tubempc.planning.wts import LABELS, ORACLE, TransitionOracle, build_wts
from tubempc.scenario import Scenario

if TYPE_CHECKING:
    from tubempc.control.closed_loop import Target

__all__ = ["Plan", "PlannedTarget", "plan_from_wts", "plan_mission"]


@dataclass(frozen=True, slots=True)
class PlannedTarget:
    """Go to ``region`` (planned arrival ``arrival_s``); hold there until ``depart_after_s`` (None: leave at once,
    or, for the last target, stay)."""

    region: str
    arrival_s: float
    depart_after_s: float | None


@dataclass(frozen=True, slots=True)
class Plan:
    """A planned mission. ``run[loop_start:]`` repeats forever, ``period_s`` after its first position."""

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
    retimed: bool
    oracle: str
    search_s: float
    product_states: int

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
            "retimed": self.retimed,
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


def plan_from_wts(wts: nx.DiGraph, formula: Formula, *, wait: bool = True, initial: str | None = None,
                  max_states: int = DEFAULT_MAX_STATES) -> Plan:
    """Search, re-time and map to targets (raises ``NoAcceptingRunError`` when no run exists)."""
    found: SearchResult = find_run(wts, formula, wait=wait, initial=initial, max_states=max_states)
    labels = {n: tuple(wts.nodes[n].get(LABELS, ())) for n in wts.nodes}
    re = retime(found.run, found.kinds, formula, labels, min_dwell_s=found.tick_s)
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
        targets=_targets(run, found.kinds),
        labels=labels,
        exact_times=run.times,
        tick_s=found.tick_s,
        wait=wait,
        retimed=re.retimed,
        oracle=str(wts.graph.get(ORACLE, "?")),
        search_s=found.seconds,
        product_states=found.states,
    )


def plan_mission(scenario: Scenario, *, formula: Formula | None = None, wait: bool = True,
                 wts: nx.DiGraph | None = None, oracle: TransitionOracle | None = None, use_cache: bool = True,
                 workers: int | None = None, dask: Any = None, progress: bool | None = None) -> Plan:
    """Build (or reuse) the scenario's WTS and plan ``formula`` (default: the scenario's spec) on it."""
    graph = wts if wts is not None else build_wts(scenario, oracle=oracle, use_cache=use_cache, workers=workers,
                                                  dask=dask, progress=progress)
    return plan_from_wts(graph, formula if formula is not None else scenario.formula, wait=wait,
                         initial=scenario.initial_region)
