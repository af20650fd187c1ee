"""Several robots in one log: read each robot, judge its own checks, then the formula and the separation jointly.

input: a log path (or each robot's ``LogData``) and a scenario with a ``robots:`` block -> output: a
``CertifyResult`` whose certificate lists the joint checks (``spec_trajectory``, ``separation``), each robot's
checks named ``robot/check`` (``husky/obstacle_clearance``), each robot's timed run and data quality.

Each robot is read by ``verify.ingest.read_log`` with its one-robot scenario (``Scenario.robot_scenario``: the shared
workspace and regions, its own topics, disc, inputs and signals), every robot with the same time base and time 0,
and its checks are judged by ``verify.certify``'s core exactly as a one-robot log's. The formula is judged on the
joint axis (``verify.semantics.joint``): a robot's atoms keep their exact margins at its own samples and today's gap
bounds between them. The separation check keeps, for every pair of robots, the distance between their discs above
``min_m``: a stretch where the bound says it is below for certain is a violation (the first such instant, and the
margin it is violated by at least); one where it may be below is inconclusive.
"""

from __future__ import annotations

import dataclasses
import hashlib
from collections.abc import Mapping, Sequence
from itertools import combinations
from pathlib import Path
from typing import Any

import numpy as np
import numpy.typing as npt

from tubempc.mitl import Formula, atoms
from tubempc.scenario import FleetRobot, Scenario
from verify.certificate import CERTIFICATE_VERSION, Certificate
from verify.checks import CheckResult
from verify.errors import MissingTopicError
from verify.geometry import label_margins, step_bound_m
from verify.ingest import LogData, read_log
from verify.ingest.digest import DEFAULT_DIGEST
from verify.ingest.fields import SignalStream, outside_span
from verify.judging import EXIT_CODES, FormulaJudgement, formula_of, judge_formula, overall_verdict
from verify.monitor.engine import Truth
from verify.selection import Selection, select_checks
from verify.semantics.joint import RobotTrack, joint_axis, margin_bounds, pair_distance_bounds
from verify.semantics.timed_run import parse_spec
from verify.semantics.trajectory import interleave, trajectory_positions
from verify.signals import SignalBounds, signal_bounds, signal_summary

__all__ = ["JointJudgement", "PairSeparation", "certify_fleet_data", "certify_fleet_log", "check_separation",
           "judge_fleet", "judge_joint", "read_fleet", "robot_track", "separation_bounds"]

FloatArray = npt.NDArray[np.float64]
IntArray = npt.NDArray[np.int64]
Columns = dict[str, npt.NDArray[Any]]


def read_fleet(log_path: str | Path, sc: Scenario, *, time_base: str = "auto", salvage: bool = False,
               time0_ns: int | None = None, digest: str = DEFAULT_DIGEST,
               clock_offsets: Mapping[str, float] | None = None) -> dict[str, LogData]:
    """Each robot's streams, read by the one reading rule (``read_log``) with its one-robot scenario; every robot
    in the first robot's time base and with one time 0 (the earliest pose sample of any robot, unless given)."""
    out: dict[str, LogData] = {}
    base = time_base
    for r in sc.robots:
        try:
            out[r.name] = read_log(log_path, sc.robot_scenario(r.name), time_base=base, salvage=salvage,
                                   time0_ns=time0_ns, digest=digest, clock_offsets=clock_offsets)
        except MissingTopicError as err:  # name the robot whose topic is missing
            raise MissingTopicError(f"robot {r.name}: {err.reason}", path=err.path) from err
        base = out[r.name].time_base if time_base == "auto" else time_base
    if time0_ns is None:
        t0 = min(log.time0_ns for log in out.values())
        for r in sc.robots:  # re-read a robot whose quality report counted from another time 0
            if out[r.name].time0_ns != t0:
                out[r.name] = read_log(log_path, sc.robot_scenario(r.name), time_base=base, salvage=salvage,
                                       time0_ns=t0, digest=digest, clock_offsets=clock_offsets)
    if time_base == "auto":  # the first robot's choice was taken by the others: state what was asked
        out = {k: dataclasses.replace(v, time_base_requested="auto") for k, v in out.items()}
    return out


def certify_fleet_log(log_path: str | Path, sc: Scenario, *, spec: str | None = None, time_base: str = "auto",
                      salvage: bool = False, time0_ns: int | None = None, digest: str = DEFAULT_DIGEST,
                      checks: Sequence[str] | None = None,
                      clock_offsets: Mapping[str, float] | None = None) -> Any:
    """``certify_log`` for a scenario with ``robots:`` (it calls this one)."""
    formula_text = str(formula_of(sc, spec))
    selection = select_checks(sc.robot_scenario(sc.robots[0].name), checks)
    logs = read_fleet(log_path, sc, time_base=time_base, salvage=salvage, time0_ns=time0_ns, digest=digest,
                      clock_offsets=clock_offsets)
    return judge_fleet(logs, sc, formula_text=formula_text, checks=checks, selection=selection)


def certify_fleet_data(logs: Mapping[str, LogData], sc: Scenario, *, spec: str | None = None,
                       checks: Sequence[str] | None = None) -> Any:
    """Judge the robots' streams already in memory (the online monitor's, a simulation's) exactly as
    ``certify_fleet_log`` judges the streams it reads."""
    selection = select_checks(sc.robot_scenario(sc.robots[0].name), checks)
    return judge_fleet(logs, sc, formula_text=str(formula_of(sc, spec)), checks=checks, selection=selection)


def robot_track(r: FleetRobot, t_ns: IntArray, x_m: FloatArray, y_m: FloatArray) -> RobotTrack:
    """A robot's judged pose samples with its disc and the bound on its motion between them."""
    return RobotTrack(r.name, t_ns, x_m, y_m, r.radius, step_bound_m(t_ns, x_m, y_m, r.max_speed_mps))


def _track(r: FleetRobot, log: LogData) -> RobotTrack:
    p = log.pose
    return robot_track(r, p.t_ns, p.x_m, p.y_m)


@dataclasses.dataclass(frozen=True, slots=True)
class PairSeparation:
    """One pair's separation margin (distance between the discs minus ``min_m``) on the joint positions."""

    robots: tuple[str, str]
    min_m: float
    bounds: SignalBounds  # at the joint instants and over the gaps between them


def _pair_min(sc: Scenario, a: str, b: str) -> float | None:
    if sc.separation is None:
        return None
    for p in sc.separation.pairs:
        if set(p.robots) == {a, b}:
            return p.min_m
    return sc.separation.min_m


def separation_bounds(sc: Scenario, tracks: Mapping[str, RobotTrack], joint_t: IntArray) -> list[PairSeparation]:
    """Every pair's separation margin bounds on the joint axis (the scenario's ``separation:``)."""
    out: list[PairSeparation] = []
    for a, b in combinations(sc.robot_names, 2):
        min_m = _pair_min(sc, a, b)
        if min_m is None:
            continue
        d = pair_distance_bounds(tracks[a], tracks[b], joint_t)
        out.append(PairSeparation((a, b), min_m, SignalBounds(d.point_lo - min_m, d.point_hi - min_m,
                                                              d.gap_lo - min_m, d.gap_hi - min_m)))
    return out


def _on_positions(b: SignalBounds, joint_rel: IntArray) -> tuple[Any, Truth]:
    pos, point_at, gap_at = trajectory_positions(joint_rel)
    return pos, interleave(b.point_lo, b.point_hi, b.gap_lo, b.gap_hi, point_at=point_at, gap_at=gap_at,
                           size=pos.size)


def _rel_s(t_ns: int) -> float:
    return round(t_ns * 1e-9, 9)


def check_separation(pairs: list[PairSeparation], joint_t: IntArray, t0: int) -> CheckResult:
    """Fail where a pair's distance is below ``min_m`` for certain (first instant; margin: the least upper bound,
    violated by at least that much); inconclusive where it may be; pass with the least lower bound."""
    details: dict[str, Any] = {"margin_unit": "m",
                               "checked_at": "the joint samples and the gaps between them (each robot's motion "
                                             "between its own samples bounded by its speed bound)"}
    if joint_t.size == 0:
        return CheckResult("separation", "inconclusive", None, None,
                           {**details, "reason": "no stretch in which every robot was observed"})
    rel = joint_t - t0
    per: list[dict[str, Any]] = []
    fails: list[tuple[int, float, str]] = []
    undecided: list[str] = []
    least = np.inf
    for p in pairs:
        pos, v = _on_positions(p.bounds, rel)
        name = f"{p.robots[0]}-{p.robots[1]}"
        bad = v.hi < 0
        entry: dict[str, Any] = {"robots": list(p.robots), "min_m": p.min_m}
        if bad.any():
            k = int(np.argmax(bad))
            at = int(pos.start_ns[k])  # a gap: its first instant (violated at every instant of it)
            margin = float(np.min(v.hi))
            fails.append((at, margin, name))
            entry.update(verdict="fail", margin=margin, first_violation_time=_rel_s(at))
        elif (v.lo < 0).any():
            k = int(np.argmax(v.lo < 0))
            lo = float(v.lo[k])
            where = (f"between {_rel_s(int(pos.start_ns[k]) - 1)} s and {_rel_s(int(pos.stop_ns[k]) + 1)} s"
                     if not pos.is_point[k] else f"at {_rel_s(int(pos.start_ns[k]))} s")
            why = ("a robot was not observed (NaN)" if not np.isfinite(lo) else
                   f"bound {lo:.4f} m below min_m")
            undecided.append(f"{name} may have come closer than {p.min_m:g} m {where} ({why})")
            entry.update(verdict="inconclusive", margin=None, first_violation_time=None)
        else:
            least = min(least, float(np.min(v.lo)))
            entry.update(verdict="pass", margin=float(np.min(v.lo)), first_violation_time=None)
        per.append(entry)
    details["pairs"] = per
    if fails:
        at, _, name = min(fails)
        details["pair"] = name
        return CheckResult("separation", "fail", min(m for _, m, _ in fails), at + t0, details)
    if undecided:
        return CheckResult("separation", "inconclusive", None, None,
                           {**details, "reason": "; ".join(undecided)})
    return CheckResult("separation", "pass", least if np.isfinite(least) else None, None, details)


def _joint_atoms(sc: Scenario, used: frozenset[str], streams: Mapping[str, SignalStream],
                 tracks: Mapping[str, RobotTrack], joint_t: IntArray) -> dict[str, tuple[SignalBounds, str]]:
    out: dict[str, tuple[SignalBounds, str]] = {}
    for a in sorted(used):
        if a in sc.proximity:
            p = sc.proximity[a]
            d = pair_distance_bounds(tracks[p.robots[0]], tracks[p.robots[1]], joint_t)
            w = p.within_m
            out[a] = (SignalBounds(w - d.point_hi, w - d.point_lo, w - d.gap_hi, w - d.gap_lo), "m")
            continue
        who, what = a.split(".", 1)
        robot = sc.fleet_robot(who)
        if what in robot.signals:
            out[a] = (signal_bounds(streams[a], joint_t), robot.signals[what].unit or "field unit")
        else:
            t = tracks[who]
            margin = label_margins(t.x_m, t.y_m, sc.robot_scenario(who), {what})[what]
            out[a] = (margin_bounds(t, margin, joint_t), "m")
    return out


def _atom_margins(bounds: Mapping[str, tuple[SignalBounds, str]]) -> dict[str, dict[str, Any]]:
    """Per atom: its least and largest value at the joint instants (the bounds there)."""
    from verify.certify import _num

    out: dict[str, dict[str, Any]] = {}
    for name, (b, unit) in sorted(bounds.items()):
        lo = b.point_lo[np.isfinite(b.point_lo)]
        hi = b.point_hi[np.isfinite(b.point_hi)]
        out[name] = {"min": _num(float(lo.min())) if lo.size else None,
                     "max": _num(float(hi.max())) if hi.size else None, "unit": unit}
    return out


def _prefixed(prefix: str, mapping: Mapping[str, Any]) -> dict[str, Any]:
    return {f"{prefix}/{k}": v for k, v in mapping.items()}


def _digest(logs: Mapping[str, LogData]) -> tuple[str, str]:
    digests = {log.log_digest for log in logs.values()}
    first = next(iter(logs.values()))
    if len(digests) == 1:
        return first.log_digest, first.digest_algorithm
    blob = "".join(f"{k}:{v.log_digest}\n" for k, v in logs.items()).encode()
    return hashlib.sha256(blob).hexdigest(), f"sha256 of each robot's {first.digest_algorithm}"


@dataclasses.dataclass(frozen=True, slots=True)
class JointJudgement:
    """The robots judged together: the joint checks (spec_trajectory when asked, separation when the scenario has
    it), the formula's judgement, the joint axis and span, each pair's separation bounds, and the problems that keep
    the joint run from passing (a robot observed long outside the joint span)."""

    checks: tuple[CheckResult, ...]
    judged: FormulaJudgement
    joint_t: IntArray
    span: tuple[int, int] | None
    pairs: list[PairSeparation]
    problems: dict[str, str]


def judge_joint(sc: Scenario, formula: Formula, tracks: Mapping[str, RobotTrack],
                streams: Mapping[str, SignalStream], t0: int, *, spec: bool = True) -> JointJudgement:
    """The formula and the separation over the joint run (certify and the online monitor's ``close`` alike).
    ``streams``: the robots' signal streams by qualified atom (``jackal.slow``)."""
    from verify.certify import formula_check

    problems: dict[str, str] = {}
    joint_t, span = joint_axis(list(tracks.values()))
    if span is not None:
        hold = 1.5 * max((float(np.median(np.diff(t.t_ns))) if t.t_ns.size > 1 else 0.0) for t in tracks.values())
        for name, t in tracks.items():
            s = t.span_ns
            if s is not None and (span[0] - s[0] > hold or s[1] - span[1] > hold):
                problems[f"robot {name}"] = (
                    f"observed {_rel_s(s[0] - t0)}-{_rel_s(s[1] - t0)} s, but every robot only "
                    f"{_rel_s(span[0] - t0)}-{_rel_s(span[1] - t0)} s: the formula and the separation are judged "
                    "over the joint span only")
    elif any(t.span_ns is not None for t in tracks.values()):
        problems["robots"] = "no stretch in which every robot was observed: nothing is judged jointly"
    joint_rel = joint_t - t0
    bounds = _joint_atoms(sc, atoms(formula), streams, tracks, joint_t)
    v_max = max(r.max_speed_mps for r in sc.robots)
    nan = np.full(joint_t.shape[0], np.nan)
    judged = judge_formula(formula, joint_rel, nan, nan, sc, time0_ns=t0, max_speed_mps=v_max, joint_atoms=bounds)
    pairs = separation_bounds(sc, tracks, joint_t)
    results: list[CheckResult] = []
    if spec:
        results.append(formula_check(judged.whole, t0, _atom_margins(bounds)))
    if sc.separation is not None:
        results.append(check_separation(pairs, joint_t, t0))
    return JointJudgement(tuple(results), judged, joint_t, span, pairs, problems)


def judge_fleet(logs: Mapping[str, LogData], sc: Scenario, *, formula_text: str,
                checks: Sequence[str] | None = None, selection: Selection | None = None) -> Any:
    """Judge the robots' streams (one time 0) against the fleet scenario; returns a ``CertifyResult``."""
    with np.errstate(all="ignore"):
        return _judge_fleet(logs, sc, formula_text=formula_text, checks=checks, selection=selection)


def _judge_robots(logs: Mapping[str, LogData], sc: Scenario, *, checks: Sequence[str] | None,
                  used: set[str] | frozenset[str]) -> tuple[dict[str, Any], dict[str, RobotTrack], dict[str, str]]:
    """Each robot's own checks, judged by the one-robot core (the formula aside): per robot its ``CertifyResult``
    and its track, and the stream problems that keep the run from passing (a signal's only when the formula uses
    it)."""
    from verify.certify import _judge

    per: dict[str, Any] = {}
    tracks: dict[str, RobotTrack] = {}
    problems: dict[str, str] = {}
    for r in sc.robots:
        rsc = sc.robot_scenario(r.name)
        sel = select_checks(rsc, checks)
        own = Selection(tuple(c for c in sel.selected if c != "spec"), sel.not_checked, sel.source)
        per[r.name] = _judge(logs[r.name], rsc, formula_text="true", selection=own)
        tracks[r.name] = _track(r, logs[r.name])
        log = logs[r.name]
        mine = {f"{r.name}.{k.removeprefix('signal ')}" for k in log.stream_problems if k.startswith("signal ")}
        for k, v in log.stream_problems.items():
            if not k.startswith("signal ") or f"{r.name}.{k.removeprefix('signal ')}" in used & mine:
                problems[f"{r.name}: {k}"] = v
        if log.pose.t_ns.size:
            for name, stream in log.signals.items():
                if f"{r.name}.{name}" in used and outside_span(stream, int(log.pose.t_ns[0]),
                                                               int(log.pose.t_ns[-1]))[2] is not None:
                    problems[f"{r.name}: signal {name}"] = (
                        "messages outside the pose's span violate its predicate: the run is the pose's span, so "
                        "they are not judged and the run cannot pass")
    return per, tracks, problems


@dataclasses.dataclass
class _Merged:
    """The fleet certificate's lists, the joint run's first, each robot's own added after them, named
    ``robot/check``."""

    entries: list[dict[str, Any]]
    selected: list[str]
    warnings: list[str]
    not_checked: list[dict[str, str]] = dataclasses.field(default_factory=list)
    timed: list[dict[str, Any]] = dataclasses.field(default_factory=list)
    samples: dict[str, Any] = dataclasses.field(default_factory=dict)
    clock: list[Any] = dataclasses.field(default_factory=list)
    robots: list[dict[str, Any]] = dataclasses.field(default_factory=list)

    def add_robot(self, r: FleetRobot, cert: dict[str, Any], log: LogData, t: RobotTrack, t0: int) -> None:
        own_entries = [{**c, "name": f"{r.name}/{c['name']}"} for c in cert["checks"]]
        self.entries += own_entries
        self.selected += [f"{r.name}/{c}" for c in cert["checks_selected"] if c != "spec"]
        self.not_checked += [{"name": f"{r.name}/{n['name']}", "reason": n["reason"]} for n in cert["not_checked"]
                             if n["name"] != "spec"]
        run = [{**e, "robot": r.name} for e in cert["timed_run"]]
        self.timed += run
        self.warnings += [f"{r.name}: {w}" for w in cert["scenario_warnings"] if w not in self.warnings]
        self.samples.update(_prefixed(r.name, cert["samples"]))
        self.clock += [f for f in cert.get("clock_findings") or [] if f not in self.clock]
        self.robots.append({
            "name": r.name, "pose_source": cert["pose_source"], "radius_m": r.radius,
            "speed_bound_mps": r.max_speed_mps, "input_model": r.inputs.model,
            "span_s": None if t.span_ns is None else [_rel_s(t.span_ns[0] - t0), _rel_s(t.span_ns[1] - t0)],
            "checks": [c["name"] for c in own_entries], "timed_run": run, "samples": cert["samples"],
            "data_quality": cert["data_quality"], "log_digest": log.log_digest,
            **({"signals": {k: signal_summary(v, t0, int(log.pose.t_ns[-1]) if log.pose.t_ns.size else t0)
                            for k, v in log.signals.items()}} if log.signals else {})})


def _tables(sc: Scenario, per: Mapping[str, Any], joint: JointJudgement, t0: int) -> dict[str, Columns | None]:
    """The report's tables: each robot's trajectory (the first one's also as ``trajectory``), the formula's
    robustness over the joint run and each separation pair's distance bounds."""
    tables: dict[str, Columns | None] = {"nominal": None, "inputs": None, "robustness": None}
    for i, r in enumerate(sc.robots):
        traj = per[r.name].columns["trajectory"]
        tables[f"trajectory/{r.name}"] = traj
        if i == 0:
            tables["trajectory"] = traj
    joint_t = joint.joint_t
    if joint_t.size:
        tables["robustness"] = {"t_s": joint.judged.signal_t_ns * 1e-9, "rho_m": joint.judged.signal}
        for p in joint.pairs:
            tables[f"separation/{p.robots[0]}-{p.robots[1]}"] = {
                "t_s": (joint_t - t0) * 1e-9, "lo_m": p.bounds.point_lo, "hi_m": p.bounds.point_hi, "min_m":
                    np.full(joint_t.shape[0], p.min_m)}
    return tables


def _judge_fleet(logs: Mapping[str, LogData], sc: Scenario, *, formula_text: str,
                 checks: Sequence[str] | None, selection: Selection | None) -> Any:
    from verify.certify import CertifyResult, _check_entry, _jsonable

    t0 = min(log.time0_ns for log in logs.values())
    logs = {k: (v if v.time0_ns == t0 else dataclasses.replace(v, time0_ns=t0)) for k, v in logs.items()}
    first_sc = sc.robot_scenario(sc.robots[0].name)
    selection = selection if selection is not None else select_checks(first_sc, checks)
    formula = parse_spec(formula_text)
    used = atoms(formula)

    per, tracks, problems = _judge_robots(logs, sc, checks=checks, used=used)

    # ---- the joint run ----------------------------------------------------------------------------------------
    streams = {f"{r.name}.{k}": v for r in sc.robots for k, v in logs[r.name].signals.items()}
    joint = judge_joint(sc, formula, tracks, streams, t0, spec="spec" in selection)
    problems.update(joint.problems)
    judged, span = joint.judged, joint.span
    v_max = max(r.max_speed_mps for r in sc.robots)
    results = list(joint.checks)
    end_s = max((float(t.t_ns[-1] - t0) * 1e-9 for t in tracks.values() if t.t_ns.size), default=0.0)
    merged = _Merged(
        entries=[_check_entry(c, t0, end_s) for c in results],
        selected=[c for c in ("spec",) if c in selection] + (["separation"] if sc.separation is not None else []),
        warnings=list(sc.certification_warnings()))
    for r in sc.robots:
        merged.add_robot(r, per[r.name].certificate, logs[r.name], tracks[r.name], t0)
    entries, selected, not_checked, timed = merged.entries, merged.selected, merged.not_checked, merged.timed
    warnings, samples, clock, robots_out = merged.warnings, merged.samples, merged.clock, merged.robots
    if "spec" in selection:
        not_checked.append({"name": "spec_timed_run", "reason": "the timed run (Definition 3) is one robot's: with "
                                                                "robots: the formula is judged under the trajectory "
                                                                "semantics over the joint run; each robot's timed "
                                                                "run is listed"})
    timed.sort(key=lambda e: (e["time"], e["robot"]))
    partial = any(log.partial for log in logs.values())
    verdict, why = overall_verdict([(c["name"], c["verdict"]) for c in entries], partial=partial, problems=problems)
    first = logs[sc.robots[0].name]
    digest, algorithm = _digest(logs)
    tube = next((per[r.name].certificate["tube"] for r in sc.robots if "tube" in per[r.name].certificate), None)
    cert_out: dict[str, Any] = {
        "certificate_version": CERTIFICATE_VERSION,
        "verdict": verdict,
        **({"verdict_reason": why} if why else {}),
        "formula": formula_text,
        "scenario": sc.name,
        "scenario_sha256": sc.sha256(),
        "log": first.path,
        "log_format": first.format,
        "log_digest": digest,
        "log_digest_algorithm": algorithm,
        **({"log_sha256": digest} if algorithm == "sha256" else {}),
        "partial": partial,
        "time_base": first.time_base,
        "time_base_requested": first.time_base_requested,
        **({"time_base_note": first.time_base_note} if first.time_base_note else {}),
        "time0_ns": t0,
        "duration_s": round(end_s, 9),
        "judged_span_s": [0.0, 0.0] if span is None else [_rel_s(span[0] - t0), _rel_s(span[1] - t0)],
        "samples": samples,
        "pose_source": {r.name: per[r.name].certificate["pose_source"] for r in sc.robots},
        "speed_bound_mps": v_max,
        "robot_radius_m": max(r.radius for r in sc.robots),
        **({"tube": tube} if tube is not None else {}),
        "input_model": ", ".join(f"{r.name}: {r.inputs.model}" for r in sc.robots),
        "checks_selected": selected,
        "checks_source": selection.source,
        "not_checked": not_checked,
        "scenario_warnings": warnings,
        "clock_findings": clock,
        "checks": entries,
        "obligations": [o.to_json() for o in judged.entries] if "spec" in selection else [],
        "timed_run": timed,
        "data_quality": {"robots": {r.name: per[r.name].certificate["data_quality"] for r in sc.robots},
                         **({"problems": dict(sorted(problems.items()))} if problems else {})},
        "generator": first.metadata,
        "robots": robots_out,
        "fleet": {"robots": list(sc.robot_names),
                  "joint_span_s": None if span is None else [_rel_s(span[0] - t0), _rel_s(span[1] - t0)],
                  "separation": None if sc.separation is None else sc.separation.model_dump(mode="json"),
                  "proximity": {k: v.model_dump(mode="json") for k, v in sc.proximity.items()}},
    }
    tables = _tables(sc, per, joint, t0)
    typed = Certificate.model_validate(_jsonable(cert_out))
    return CertifyResult(typed.to_json_dict(), EXIT_CODES[verdict], tables,
                         formula=judged if "spec" in selection else None)
