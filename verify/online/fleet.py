"""Online certification of several robots: one ``OnlineMonitor`` per robot, and the joint checks at the end.

input: a scenario with ``robots:`` (and a formula), then each robot's pose / nominal / command samples and its
signals' messages in time order per stream (absolute integer ns) -> output: each robot's decisions as they are made
(named ``robot/check``, times in seconds from the first pose of any robot), and at ``close`` the same checks and
overall verdict as ``verify.certify.certify_log`` on a log holding the same samples.

Each robot's own checks (workspace, obstacle clearance, tube, input box) are judged incrementally by the one-robot
monitor (``verify.online.monitor``), fed with that robot's one-robot scenario. The formula over the joint run and
the separation are judged at ``close`` by the function certify uses (``verify.fleet.judge_joint``) on the samples
pushed: until then they are open ("inconclusive so far"), never decided early.
"""

from __future__ import annotations

import math
from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass
from functools import partial
from pathlib import Path
from typing import Any

import numpy as np

from tubempc.mitl import atoms
from tubempc.scenario import Scenario
from verify.certify import MARGIN_UNITS, resolve_scenario
from verify.checks import CheckResult
from verify.errors import ScenarioInputError
from verify.fleet import judge_joint, robot_track
from verify.ingest import LogData
from verify.ingest.log import _stream as pose_stream
from verify.judging import EXIT_CODES, formula_of, overall_verdict
from verify.online.monitor import Decision, OnlineMonitor
from verify.online.signalfeed import SignalFeed
from verify.online.states import final_line
from verify.selection import select_checks

__all__ = ["FleetMonitor", "FleetResult", "FleetState", "RobotFeed", "feed_fleet_logs"]


@dataclass(frozen=True, slots=True)
class FleetState:
    """The fleet's state: open until ``close`` (the joint checks are decided there), then every check's result."""

    closed: bool
    checks: tuple[CheckResult, ...] = ()
    t0_ns: int | None = None

    @property
    def all_decided(self) -> bool:
        return self.closed

    def final_lines(self) -> list[str]:
        """At the end: one line per check with its final verdict, margin and first violation."""
        return [final_line(c.name, c.verdict,
                           c.margin if c.margin is not None and math.isfinite(c.margin) else None,
                           str(c.details.get("margin_unit") or MARGIN_UNITS.get(c.name.rsplit("/", 1)[-1], "")),
                           None if c.first_violation_ns is None or self.t0_ns is None else
                           (c.first_violation_ns - self.t0_ns) * 1e-9)
                for c in self.checks]


@dataclass(frozen=True, slots=True)
class FleetResult:
    """What ``FleetMonitor.close`` returns: every check (joint ones first, then ``robot/check``), the verdict."""

    verdict: str
    verdict_reason: str | None
    checks: tuple[CheckResult, ...]
    state: FleetState = FleetState(closed=True)

    @property
    def exit_code(self) -> int:
        return EXIT_CODES[self.verdict]


class FleetMonitor:
    """Incremental certifier of several robots in one run (``push_*(robot, ...)`` in time order per stream)."""

    def __init__(self, scenario: Scenario | str | Path, *, spec: str | None = None,
                 checks: Sequence[str] | None = None, max_pending: int = 100) -> None:
        sc = resolve_scenario(scenario)
        if not sc.robots:
            raise ScenarioInputError(f"scenario {sc.name!r} has no robots: block: use OnlineMonitor")
        self.scenario = sc
        self.formula = formula_of(sc, spec)
        self.selection = select_checks(sc.robot_scenario(sc.robots[0].name), checks)
        used = atoms(self.formula)
        self.monitors: dict[str, OnlineMonitor] = {}
        self._feeds: dict[str, SignalFeed] = {}
        for r in sc.robots:
            rsc = sc.robot_scenario(r.name)
            own = tuple(c for c in select_checks(rsc, checks).selected if c != "spec")
            self.monitors[r.name] = OnlineMonitor(rsc, checks=own, max_pending=max_pending)
            for name, sig in r.signals.items():
                if f"{r.name}.{name}" in used:
                    self._feeds[f"{r.name}.{name}"] = SignalFeed(name, sig, pose_topic=r.topics.pose)
        self._poses: dict[str, tuple[list[int], list[float], list[float], list[float]]] = {
            r.name: ([], [], [], []) for r in sc.robots}
        self.t0_ns: int | None = None
        self._result: FleetResult | None = None
        self._final_decisions: list[Decision] = []

    def robot_feed(self, robot: str) -> RobotFeed:
        """One robot's push interface (that of ``OnlineMonitor``), for a reader that feeds one robot's topics."""
        return RobotFeed(self, robot)

    @property
    def counts(self) -> dict[str, int]:
        """Samples pushed, over every robot."""
        out: dict[str, int] = {}
        for m in self.monitors.values():
            for k, v in m.counts.items():
                out[k] = out.get(k, 0) + v
        return out

    def state(self) -> FleetState:
        if self._result is not None:
            return self._result.state
        return FleetState(closed=False, t0_ns=self.t0_ns)

    @property
    def final_decisions(self) -> list[Decision]:
        """The decisions made by ``close``: each robot's checks still open, then the joint checks."""
        return list(self._final_decisions)

    # ---- input ----------------------------------------------------------------------------------------------------
    def push_pose(self, robot: str, t_ns: int, x_m: float, y_m: float, yaw_rad: float = 0.0) -> None:
        self.monitors[robot].push_pose(t_ns, x_m, y_m, yaw_rad)
        t, x, y, yaw = self._poses[robot]
        t.append(t_ns)
        x.append(x_m)
        y.append(y_m)
        yaw.append(yaw_rad)
        if self.t0_ns is None or t_ns < self.t0_ns:
            self.t0_ns = t_ns

    def push_nominal(self, robot: str, t_ns: int, x_m: float, y_m: float, yaw_rad: float = 0.0) -> None:
        self.monitors[robot].push_nominal(t_ns, x_m, y_m, yaw_rad)

    def push_cmd(self, robot: str, t_ns: int, u1: float, u2: float, u3: float) -> None:
        self.monitors[robot].push_cmd(t_ns, u1, u2, u3)

    def push_signal(self, robot: str, name: str, t_ns: int, value: float) -> None:
        feed = self._feeds.get(f"{robot}.{name}")
        if feed is not None:
            feed.push(t_ns, value)

    # ---- decisions ------------------------------------------------------------------------------------------------
    def _renamed(self, robot: str, decisions: list[Decision]) -> list[Decision]:
        m = self.monitors[robot]
        shift = 0.0 if m.t0_ns is None or self.t0_ns is None else (m.t0_ns - self.t0_ns) * 1e-9
        return [Decision(f"{robot}/{d.name}", d.verdict, round(d.time_s + shift, 9), d.margin,
                         None if d.first_violation_s is None else round(d.first_violation_s + shift, 9), d.unit)
                for d in decisions]

    def update(self) -> list[Decision]:
        """Each robot's checks decided since the last call (the joint checks are decided at ``close``)."""
        return [d for r in self.scenario.robot_names for d in self._renamed(r, self.monitors[r].update())]

    # ---- end of the run -------------------------------------------------------------------------------------------
    def close(self, *, partial: bool = False,
              stream_problems: Mapping[str, Mapping[str, str]] | None = None) -> FleetResult:
        """The final verdict of every check, as ``certify_log`` gives for a log with the same samples
        (``stream_problems``: robot -> stream -> why nothing judged on it can pass, as ``OnlineMonitor.close``
        takes them; as certify, a signal's problem counts when the formula uses that robot's signal)."""
        if self._result is not None:
            return self._result
        sc = self.scenario
        checks: list[CheckResult] = []
        problems: dict[str, str] = {}
        tracks = {}
        for r in sc.robots:
            mine = dict((stream_problems or {}).get(r.name, {}))
            res = self.monitors[r.name].close(partial=partial, problems=mine)
            for k, v in mine.items():
                if not k.startswith("signal ") or f"{r.name}.{k.removeprefix('signal ')}" in self._feeds:
                    problems[f"{r.name}: {k}"] = v
            checks += [CheckResult(f"{r.name}/{c.name}", c.verdict, c.margin, c.first_violation_ns, c.details)
                       for c in res.checks]
            t, x, y, yaw = (np.asarray(v) for v in self._poses[r.name])
            one, _, _ = pose_stream(t.astype(np.int64), x.astype(np.float64), y.astype(np.float64),
                                    yaw.astype(np.float64))
            tracks[r.name] = robot_track(r, one.t_ns, one.x_m, one.y_m)
            late = self.monitors[r.name].out_of_order["pose"]
            if late:
                problems[f"{r.name}: pose"] = f"{late} pose sample(s) arrived out of time order and were not judged"
            for name, feed in self._feeds.items():
                if name.startswith(f"{r.name}.") and one.t_ns.size and feed.violates_outside(int(one.t_ns[0]),
                                                                                             int(one.t_ns[-1])):
                    problems[f"{r.name}: signal {name.split('.', 1)[1]}"] = (
                        "messages outside the pose's span violate its predicate: the run is the pose's span, so "
                        "they are not judged and the run cannot pass")
        streams = {k: f.stream() for k, f in self._feeds.items()}
        t0 = self.t0_ns if self.t0_ns is not None else 0
        joint = judge_joint(sc, self.formula, tracks, streams, t0, spec="spec" in self.selection)
        problems.update(joint.problems)
        every = [*joint.checks, *checks]
        verdict, why = overall_verdict([(c.name, c.verdict) for c in every], partial=partial, problems=problems)
        end_s = max(((int(t.t_ns[-1]) - t0) * 1e-9 for t in tracks.values() if t.t_ns.size), default=0.0)
        self._final_decisions = [d for r in sc.robot_names
                                 for d in self._renamed(r, self.monitors[r].final_decisions)]
        for c in joint.checks:
            first = None if c.first_violation_ns is None else round((c.first_violation_ns - t0) * 1e-9, 9)
            self._final_decisions.append(Decision(c.name, c.verdict, round(first if first is not None else end_s, 9),
                                                  c.margin, first, c.details.get("margin_unit")))
        self._result = FleetResult(verdict, why, tuple(every), FleetState(True, tuple(every), self.t0_ns))
        return self._result


class RobotFeed:
    """One robot's side of a ``FleetMonitor`` with ``OnlineMonitor``'s push interface (``verify.online.watch``
    decodes each robot's topics with its one-robot scenario and pushes them here)."""

    def __init__(self, fleet: FleetMonitor, robot: str) -> None:
        self.fleet = fleet
        self.robot = robot
        self.scenario = fleet.scenario.robot_scenario(robot)

    @property
    def signal_names(self) -> tuple[str, ...]:
        """This robot's signals the formula uses."""
        return tuple(sorted(k.split(".", 1)[1] for k in self.fleet._feeds if k.startswith(f"{self.robot}.")))

    @property
    def counts(self) -> dict[str, int]:
        return self.fleet.monitors[self.robot].counts

    def push_pose(self, t_ns: int, x_m: float, y_m: float, yaw_rad: float = 0.0) -> None:
        self.fleet.push_pose(self.robot, t_ns, x_m, y_m, yaw_rad)

    def push_nominal(self, t_ns: int, x_m: float, y_m: float, yaw_rad: float = 0.0) -> None:
        self.fleet.push_nominal(self.robot, t_ns, x_m, y_m, yaw_rad)

    def push_cmd(self, t_ns: int, u1: float, u2: float, u3: float) -> None:
        self.fleet.push_cmd(self.robot, t_ns, u1, u2, u3)

    def push_signal(self, name: str, t_ns: int, value: float) -> None:
        self.fleet.push_signal(self.robot, name, t_ns, value)


def feed_fleet_logs(monitor: FleetMonitor, logs: Mapping[str, LogData]) -> list[Decision]:
    """Push every robot's samples in time order (the robots' streams merged), as a recorder would deliver them."""
    events: list[tuple[int, int, Callable[..., None], tuple[Any, ...]]] = []
    for r, log in logs.items():
        p = log.pose_samples  # every sample (the monitor merges duplicates as the reader does)
        for t, x, y, th in zip(p.t_ns.tolist(), p.x_m.tolist(), p.y_m.tolist(), p.theta_rad.tolist(), strict=True):
            events.append((t, 0, partial(monitor.push_pose, r), (x, y, th)))
        if log.nominal is not None:
            n = log.nominal
            for t, x, y, th in zip(n.t_ns.tolist(), n.x_m.tolist(), n.y_m.tolist(), n.theta_rad.tolist(),
                                   strict=True):
                events.append((t, 1, partial(monitor.push_nominal, r), (x, y, th)))
        if log.cmd_t_ns is not None and log.cmd_u is not None:
            for t, u in zip(log.cmd_t_ns.tolist(), log.cmd_u.tolist(), strict=True):
                events.append((t, 2, partial(monitor.push_cmd, r), tuple(u)))
        for name, sig in log.signals.items():
            for t, v in zip(sig.t_ns.tolist(), sig.value.tolist(), strict=True):
                events.append((t, 3, partial(monitor.push_signal, r, name), (v,)))
    events.sort(key=lambda e: (e[0], e[1]))
    out: list[Decision] = []
    for k, (t_ns, _, fn, args) in enumerate(events):
        fn(t_ns, *args)
        if k % 500 == 499:
            out += monitor.update()
    return out + monitor.update()
