"""Certify one log: log path + scenario (+ formula) -> ``CertifyResult`` (certificate dict, exit code, tables).

input: a log path, a scenario (value, file path or built-in name), an optional MITL formula, the time base, the
salvage flag and an optional time 0 -> output: a frozen ``CertifyResult``; ``write_certificate`` writes its JSON.

``certify_log`` is a module-level, picklable function that never writes files (the batch runner calls it in worker
processes). Only the selected checks run (``verify.selection``); the others are listed under ``not_checked`` with
the reason. The overall verdict, over the selected checks, is "fail" if any fails, else "inconclusive" if any is
inconclusive, the log is partial (salvaged) or no check ran, else "pass".
"""

from __future__ import annotations

import json
import math
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import TYPE_CHECKING, Any, Protocol

import numpy as np
import numpy.typing as npt

from runkit.outputs import write_output_file
from tubempc.mitl import atoms
from tubempc.scenario import Scenario, ScenarioError, load_scenario
from verify.certificate import CERTIFICATE_VERSION, Certificate, build_in_background
from verify.checks import CheckResult, check_clearance, check_input_box, check_tube, check_workspace
from verify.errors import ScenarioInputError
from verify.geometry import containment, label_margins
from verify.ingest import LogData, read_log
from verify.ingest.digest import DEFAULT_DIGEST
from verify.ingest.fields import SignalStream, outside_span
from verify.judging import (
    EXIT_CODES,
    POSITION_ROUNDING_M,
    TUBE_TOLERANCE_RULE,
    FormulaJudgement,
    ObligationResult,
    check_explanation,
    formula_of,
    judge_formula,
    margin_entry,
    overall_verdict,
    timed_run_explanation,
    tube_tolerance_m,
)
from verify.scenario_check import data_findings
from verify.selection import Selection, select_checks
from verify.semantics.timed_run import check_timed_run, entry_exits, parse_spec, timed_run_of_sets
from verify.signals import signal_margin, signal_summary, values_at

if TYPE_CHECKING:
    import pandas as pd

__all__ = ["CERTIFICATE_VERSION", "EXIT_CODES", "POSITION_ROUNDING_M", "CertifyResult", "HasCertificate",
           "certify_data", "certify_log", "check_lines", "resolve_scenario", "verdict_line", "write_certificate"]



Columns = dict[str, npt.NDArray[np.floating[Any]]]


@dataclass(frozen=True, slots=True)
class CertifyResult:
    """The certificate (JSON-ready dict), the exit code, and tables for reports (times in seconds from time 0).

    The tables are kept as numpy columns and become pandas DataFrames when first read (``trajectory``, ...): a
    certification that writes no report (``certify --json``) never imports pandas."""

    certificate: dict[str, Any]
    exit_code: int
    columns: dict[str, Columns | None]  # "trajectory", "nominal", "inputs", "robustness" -> column name -> values
    _frames: dict[str, pd.DataFrame] = field(default_factory=dict, compare=False, repr=False)
    _typed: list[Certificate] = field(default_factory=list, compare=False, repr=False)

    @property
    def typed(self) -> Certificate:
        """The certificate as the typed model (validated once, on first use): what the tools read."""
        if not self._typed:
            self._typed.append(Certificate.model_validate(self.certificate))
        return self._typed[0]

    def _table(self, name: str) -> pd.DataFrame | None:
        cols = self.columns.get(name)
        if cols is None:
            return None
        if name not in self._frames:
            import pandas as pd  # only the reports read the tables

            self._frames[name] = pd.DataFrame(cols)
        return self._frames[name]

    @property
    def trajectory(self) -> pd.DataFrame:
        """t_s, x_m, y_m, theta_rad."""
        table = self._table("trajectory")
        if table is None:
            raise KeyError("a certification result always has a trajectory table")
        return table

    @property
    def nominal(self) -> pd.DataFrame | None:
        """t_s, x_m, y_m, theta_rad (when the tube check ran on a nominal stream)."""
        return self._table("nominal")

    @property
    def inputs(self) -> pd.DataFrame | None:
        """t_s, u1, u2, u3."""
        return self._table("inputs")

    @property
    def robustness(self) -> pd.DataFrame | None:
        """t_s, rho_m."""
        return self._table("robustness")
    #: the judgement the obligations come from (curves for the reports)
    formula: FormulaJudgement | None = field(default=None, compare=False)

    @property
    def verdict(self) -> str:
        return str(self.certificate["verdict"])

    @property
    def model(self) -> Certificate:
        """The certificate as the typed model (``verify.certificate``)."""
        return Certificate.model_validate(self.certificate)


def resolve_scenario(scenario: Scenario | str | Path) -> Scenario:
    if isinstance(scenario, Scenario):
        return scenario
    try:
        return load_scenario(scenario)
    except ScenarioError as err:
        raise ScenarioInputError(f"scenario: {err}") from err


def _num(v: float | None) -> float | None:
    """JSON numbers only: infinities and NaN become null."""
    if v is None or not math.isfinite(v):
        return None
    return round(float(v), 9)


def _rel_s(t_ns: int | None, time0_ns: int) -> float | None:
    return None if t_ns is None else round((t_ns - time0_ns) * 1e-9, 9)


#: unit of each check's margin (a check may state its own as ``details["margin_unit"]``)
MARGIN_UNITS = {"spec_trajectory": "m", "spec_timed_run": "s", "tube": "m", "input_box": "m/s or rad/s",
                "workspace": "m", "obstacle_clearance": "m"}


def _check_entry(c: CheckResult, time0_ns: int, end_s: float) -> dict[str, Any]:
    """A check as the certificate states it: the margin (or null with the reason), its unit, the first violation,
    when the data decided it, and one sentence for a verdict other than pass (``verify.judging``)."""
    unit = c.details.get("margin_unit", MARGIN_UNITS.get(c.name))
    margin, margin_reason = margin_entry(c.verdict, c.margin, reason=c.details.get("margin_reason"))
    first = _rel_s(c.first_violation_ns, time0_ns)
    decided = c.details.get("decided_at", first if c.verdict == "fail" else
                            (round(end_s, 9) if c.verdict == "pass" else None))
    entry = {"name": c.name, "verdict": c.verdict, "margin": margin, "margin_unit": unit,
             "first_violation_time": first,
             **{k: v for k, v in c.details.items() if k not in ("name", "verdict", "margin", "margin_unit",
                                                                 "margin_reason", "decided_at", "explanation")}}
    entry["margin_reason"] = margin_reason
    entry["decided_at"] = decided
    entry["explanation"] = c.details.get("explanation") or check_explanation(entry)
    return entry


def certify_log(log_path: str | Path, scenario: Scenario | str | Path, *, spec: str | None = None,
                time_base: str = "auto", salvage: bool = False, time0_ns: int | None = None,
                digest: str = DEFAULT_DIGEST, checks: Sequence[str] | None = None,
                clock_offsets: Mapping[str, float] | None = None) -> CertifyResult:
    """Judge one log against the scenario and the formula (default: the scenario's). Never writes files.
    ``digest`` names the certificate's digest (``verify.ingest.digest``): "blake3-messages" (default: of the
    messages read), "blake3" or "sha256" (of the file's bytes).
    ``checks``: the checks to run (default: the scenario's ``checks:``, else every check whose data it names).
    ``clock_offsets``: topic -> seconds added to that topic's times (extends the scenario's ``clock_offsets``)."""
    sc = resolve_scenario(scenario)
    build_in_background()  # the certificate model, built while the log is read
    if sc.robots:  # several robots in one log: verify.fleet reads each robot and judges them jointly
        from verify.fleet import certify_fleet_log

        result: CertifyResult = certify_fleet_log(log_path, sc, spec=spec, time_base=time_base, salvage=salvage,
                                                  time0_ns=time0_ns, digest=digest, checks=checks,
                                                  clock_offsets=clock_offsets)
        return result
    selection = select_checks(sc, checks)
    formula_text = str(formula_of(sc, spec))
    log = read_log(log_path, sc, time_base=time_base, salvage=salvage, time0_ns=time0_ns, digest=digest,
                   clock_offsets=clock_offsets)
    return _judge(log, sc, formula_text=formula_text, selection=selection)


def certify_data(log: LogData, scenario: Scenario | str | Path, *, spec: str | None = None,
                 checks: Sequence[str] | None = None) -> CertifyResult:
    """Judge streams already in memory (e.g. a simulated run, never written) exactly as ``certify_log`` judges the
    streams it reads from a file: same checks, same margins, same verdicts."""
    sc = resolve_scenario(scenario)
    if sc.robots:
        raise ScenarioInputError(f"scenario {sc.name!r} names robots {', '.join(sc.robot_names)}: judge each robot's "
                                 "streams together (verify.fleet.certify_fleet_data)")
    selection = select_checks(sc, checks)
    return _judge(log, sc, formula_text=str(formula_of(sc, spec)), selection=selection)


def _atom_margins(sc: Scenario, x_m: np.ndarray, y_m: np.ndarray, labels: set[str] | frozenset[str],
                  streams: Mapping[str, SignalStream]) -> dict[str, dict[str, Any]]:
    """Per atom of the formula: its least and largest margin at the pose samples (regions: metres, as the
    trajectory semantics defines them; signals: over their messages, in the field's unit, and relative to the
    threshold, unit-free)."""
    out: dict[str, dict[str, Any]] = {}
    for name, m in label_margins(x_m, y_m, sc, labels).items():
        finite = m[np.isfinite(m)]
        out[name] = {"min": _num(float(finite.min())) if finite.size else None,
                     "max": _num(float(finite.max())) if finite.size else None, "unit": "m"}
    for name, stream in streams.items():
        sm = signal_margin(stream.spec, stream.value)
        finite = sm[np.isfinite(sm)]
        lo = float(finite.min()) if finite.size else None
        hi = float(finite.max()) if finite.size else None
        scale = abs(stream.spec.value)
        out[name] = {"min": _num(lo), "max": _num(hi), "unit": stream.spec.unit,
                     "relative_min": _num(lo / scale) if lo is not None and scale > 0 else None,
                     "relative_max": _num(hi / scale) if hi is not None and scale > 0 else None}
    return dict(sorted(out.items()))


def _rel(t_ns: int | None) -> float | None:
    return None if t_ns is None else round(t_ns * 1e-9, 9)


def formula_check(whole: ObligationResult, t0: int, atom_margins: dict[str, dict[str, Any]]) -> CheckResult:
    """The spec_trajectory check: the whole formula's obligation, told as a check (one robot or a joint run)."""
    rel = _rel
    return CheckResult(
        # pass: the guaranteed robustness; fail: the optimistic one (violated by at least that much)
        "spec_trajectory", whole.verdict, whole.margin,
        whole.first_violation_ns + t0 if whole.first_violation_ns is not None else None,
        {"semantics": "trajectory (disc intersects unsafe regions / inside other regions; motion between samples "
                      "bounded by the speed bound)",
         "guaranteed_margin_m": _num(whole.lo), "optimistic_margin_m": _num(whole.hi),
         "margin_unit": whole.margin_unit, "margin_atom": whole.margin_atom, "margin_time": rel(whole.margin_time_ns),
         "margin_reason": whole.margin_reason, "decided_at": rel(whole.decided_ns),
         "explanation": whole.explanation,
         "atom_margins": atom_margins,
         **({"subformula": whole.subformula, "reason": whole.reason,
             "time": rel(whole.first_violation_ns) if whole.verdict == "fail" else
             (whole.unknown.from_s if whole.unknown is not None else None)}
            if whole.verdict != "pass" else {})})


def _judge(log: LogData, sc: Scenario, *, formula_text: str,
           selection: Selection | None = None) -> CertifyResult:
    with np.errstate(all="ignore"):  # damaged values (1e308, inf) overflow to inf margins: judged, not warned
        return _judge_streams(log, sc, formula_text=formula_text,
                              selection=selection if selection is not None else select_checks(sc))


def _judge_streams(log: LogData, sc: Scenario, *, formula_text: str, selection: Selection) -> CertifyResult:
    formula = parse_spec(formula_text)
    t0 = log.time0_ns
    pose = log.pose
    t_rel = pose.t_ns - t0
    v_max = sc.max_speed_mps

    used = atoms(formula)
    streams = {k: v for k, v in log.signals.items() if k in used}
    # a signal atom given no stream (samples handed over in memory without it; a log without the topic is exit 3
    # before this): no message, so unknown everywhere, as the online monitor holds a signal before its first message
    streams.update({k: SignalStream(k, sc.signals[k], np.zeros(0, dtype=np.int64), np.zeros(0), 0, log.time_base)
                    for k in sorted(used & set(sc.signals) - set(streams))})
    judged = judge_formula(formula, t_rel, pose.x_m, pose.y_m, sc, time0_ns=t0, max_speed_mps=v_max,
                           streams=streams)
    end_s = float(t_rel[-1]) * 1e-9 if t_rel.size else 0.0
    # signal messages outside the pose's span that violate their predicate: not judged (the run is the pose's span,
    # and every check and obligation states its verdict over it), but the run cannot pass: a problem of the stream
    doubted = {f"signal {k}": "messages outside the pose's span violate its predicate: the run is the pose's span, "
                              "so they are not judged and the run cannot pass" for k, v in sorted(streams.items())
               if outside_span(v, int(pose.t_ns[0]), int(pose.t_ns[-1]))[2] is not None} if pose.t_ns.size else {}
    obligations = list(judged.entries)
    whole = obligations[0]  # the spec_trajectory check is the whole formula's obligation, told twice

    spec_traj = formula_check(whole, t0, _atom_margins(sc, pose.x_m, pose.y_m, used - set(streams), streams))

    names = [r.name for r in sc.regions]
    inside = containment(pose.x_m, pose.y_m, sc)
    run_times = t_rel.astype(np.float64) * 1e-9
    known = np.isfinite(pose.x_m) & np.isfinite(pose.y_m)
    run, run_labels = timed_run_of_sets(inside, run_times, names, {r.name: list(r.labels) for r in sc.regions},
                                        known=known)
    entry_ns = np.array([t0 + round(t * 1e9) for _, t in run], dtype=np.int64)
    tr = check_timed_run(formula_text, run, run_labels, end=end_s,
                         atom_values={k: values_at(v, entry_ns) for k, v in streams.items()},
                         exits=entry_exits(inside, run_times, known))
    spec_run = CheckResult(
        "spec_timed_run", tr.verdict, tr.margin_s,
        round(tr.time_s * 1e9) + t0 if tr.verdict == "fail" and tr.time_s is not None else None,
        {"semantics": "timed run (paper, Definition 3; pointwise)",
         "explanation": timed_run_explanation(tr, end_s),
         **({"margin_reason": tr.margin_reason} if tr.margin_reason else {}),
         **({"subformula": tr.subformula, "reason": tr.reason, "time": tr.time_s} if tr.verdict != "pass" else {})})

    checks: list[CheckResult] = [spec_traj, spec_run] if "spec" in selection else []
    tol_m = tube_tolerance_m(sc)
    every = log.pose_samples  # per-sample checks judge every sample (duplicates that disagree included)
    tube_info: dict[str, Any] | None = None
    if "tube" in selection:
        nominal = None
        if log.nominal is not None:
            nominal = (log.nominal.t_ns, log.nominal.x_m, log.nominal.y_m)
        period_ns = round(1e9 / sc.mocap.rate_hz)
        checks.append(check_tube(every.t_ns, every.x_m, every.y_m, nominal, radius_m=sc.tube_radius_m,
                                 tolerance_m=tol_m, match_ns=period_ns // 2))
        tube_info = {"radius_m": sc.tube_radius_m, "noise_tolerance_m": tol_m,
                     "noise_tolerance_rule": TUBE_TOLERANCE_RULE}
    if "input_box" in selection:
        checks.append(check_input_box(log.cmd_t_ns, log.cmd_u, sc.inputs))
    if "workspace" in selection:
        checks.append(check_workspace(every.t_ns, every.x_m, every.y_m, sc))
    if "obstacle_clearance" in selection:
        checks.append(check_clearance(every.t_ns, every.x_m, every.y_m, sc))
    entries = [_check_entry(c, t0, end_s) for c in checks]
    problems = {k: v for k, v in log.stream_problems.items()  # a signal's problem counts where the formula uses it
                if not k.startswith("signal ") or k.removeprefix("signal ") in streams}
    problems.update(doubted)
    verdict, why = overall_verdict([(c["name"], c["verdict"]) for c in entries], partial=log.partial,
                                   problems=problems)
    data_quality = dict(log.data_quality)  # the log's own dict is not changed (a LogData may be certified again)
    if log.metadata and log.metadata.get("scenario_sha256") not in (None, sc.sha256()):
        data_quality["notes"] = [*data_quality.get("notes", []), "the log's metadata names a different "
                                 "scenario_sha256 than the scenario given to the certifier"]
    cert: dict[str, Any] = {
        "certificate_version": CERTIFICATE_VERSION,
        "verdict": verdict,
        **({"verdict_reason": why} if why else {}),
        "formula": formula_text,
        "scenario": sc.name,
        "scenario_sha256": sc.sha256(),
        "log": log.path,
        "log_format": log.format,
        "log_digest": log.log_digest,
        "log_digest_algorithm": log.digest_algorithm,
        **({"log_sha256": log.log_digest} if log.digest_algorithm == "sha256" else {}),
        "partial": log.partial,
        "time_base": log.time_base,
        "time_base_requested": log.time_base_requested,
        **({"time_base_note": log.time_base_note} if log.time_base_note else {}),
        "time0_ns": t0,
        "duration_s": round(end_s, 9),
        "judged_span_s": [round(float(t_rel[0]) * 1e-9, 9) if t_rel.size else 0.0, round(end_s, 9)],
        "samples": log.samples,
        "pose_source": log.pose_source,
        "speed_bound_mps": v_max,
        "robot_radius_m": sc.robot.radius,
        **({"tube": tube_info} if tube_info is not None else {}),
        "input_model": sc.inputs.model,
        "checks_selected": list(selection.selected),
        "checks_source": selection.source,
        "not_checked": [{"name": n, "reason": r} for n, r in selection.not_checked],
        "scenario_warnings": sc.certification_warnings() + data_findings(sc, every.t_ns, every.x_m, every.y_m, t0),
        "clock_findings": list(log.data_quality.get("clocks", {}).get("findings", [])),
        "checks": entries,
        "obligations": [o.to_json() for o in obligations] if "spec" in selection else [],
        "timed_run": [{"region": r, "time": round(t, 9)} for r, t in run],
        **({"signals": {k: signal_summary(v, t0, int(pose.t_ns[-1]) if pose.t_ns.size else t0)
                        for k, v in log.signals.items()}} if log.signals else {}),
        "data_quality": data_quality,
        "generator": log.metadata,
    }
    t_s = t_rel * 1e-9
    tables: dict[str, Columns | None] = {
        "trajectory": {"t_s": t_s, "x_m": pose.x_m, "y_m": pose.y_m, "theta_rad": pose.theta_rad},
        "nominal": None, "inputs": None, "robustness": None}
    if log.nominal is not None and "tube" in selection:
        tables["nominal"] = {"t_s": (log.nominal.t_ns - t0) * 1e-9, "x_m": log.nominal.x_m,
                             "y_m": log.nominal.y_m, "theta_rad": log.nominal.theta_rad}
    if log.cmd_t_ns is not None and log.cmd_u is not None:
        tables["inputs"] = {"t_s": (log.cmd_t_ns - t0) * 1e-9, "u1": log.cmd_u[:, 0], "u2": log.cmd_u[:, 1],
                            "u3": log.cmd_u[:, 2]}
    if t_rel.size:
        tables["robustness"] = {"t_s": judged.signal_t_ns * 1e-9, "rho_m": judged.signal}
    typed = Certificate.model_validate(_jsonable(cert))  # the contract: a certificate that breaks it is a bug here
    return CertifyResult(typed.to_json_dict(), EXIT_CODES[verdict], tables,
                         formula=judged if "spec" in selection else None)


def _jsonable(obj: Any) -> Any:
    if isinstance(obj, dict):
        return {str(k): _jsonable(v) for k, v in obj.items()}
    if isinstance(obj, list | tuple):
        return [_jsonable(v) for v in obj]
    if isinstance(obj, np.generic):
        return _jsonable(obj.item())
    if isinstance(obj, float):
        return _num(obj)
    return obj


def verdict_line(log: str | Path, certificate: dict[str, Any]) -> str:
    """``run.mcap: fail (spec_trajectory: fail at t=54.80 s; tube: inconclusive)`` for a terminal."""
    bad = [c for c in certificate.get("checks", []) or [] if isinstance(c, dict) and c.get("verdict") != "pass"]
    parts = []
    for c in bad:
        t = c.get("first_violation_time")
        when = f" at t={t:.2f} s" if isinstance(t, int | float) else ""
        parts.append(f"{c.get('name')}: {c.get('verdict')}{when}")
    line = f"{log}: {certificate.get('verdict')}" + (f" ({'; '.join(parts)})" if parts else "")
    selected = certificate.get("checks_selected")
    if selected is not None:
        line += f" [checks: {', '.join(selected)}"
        skipped = [c.get("name") for c in certificate.get("not_checked", []) or [] if isinstance(c, dict)]
        if skipped:
            line += f"; not checked: {', '.join(str(n) for n in skipped)}"
        line += "]"
    return line


def _margin_text(entry: Mapping[str, Any]) -> str:
    margin = entry.get("margin")
    if not isinstance(margin, int | float):
        return "margin -"
    unit = entry.get("margin_unit") or ""
    atom = entry.get("margin_atom")
    return f"margin {margin:.4g} {unit}".rstrip() + (f" ({atom})" if atom else "")


def _entry_line(name: str, entry: Mapping[str, Any]) -> list[str]:
    t, decided = entry.get("first_violation_time"), entry.get("decided_at")
    line = (f"  {name}: {entry.get('verdict')}, {_margin_text(entry)}"
            + (f", first violation at t={t:.2f} s" if isinstance(t, int | float) else "")
            + (f", decided at t={decided:.2f} s" if isinstance(decided, int | float) else ""))
    why = entry.get("explanation")
    return [line] + ([f"    why: {why}"] if why else [])


def check_lines(certificate: dict[str, Any]) -> list[str]:
    """``certify -v``: one line per check and per obligation of the formula with the certificate's margin (its unit
    and, for a formula, the atom it is the value of), first violation and decision time; under a verdict other than
    pass, the certificate's one-sentence explanation."""
    lines: list[str] = []
    for c in certificate.get("checks", []) or []:
        lines += _entry_line(str(c.get("name")), c)
    for o in certificate.get("obligations", []) or []:
        role = "formula" if o.get("role") == "formula" else "obligation"
        lines += _entry_line(f"{role} {o.get('formula')}", o)
    return lines


class HasCertificate(Protocol):
    @property
    def certificate(self) -> dict[str, Any]: ...


def write_certificate(result: HasCertificate, out_dir: str | Path) -> Path:
    """Write ``certificate.json`` into ``out_dir`` (created if needed); returns its path. The certificate is
    validated against the model first (``verify.certificate``): nothing that breaks the schema is written."""
    Certificate.model_validate(result.certificate)
    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    return write_output_file(out / "certificate.json", json.dumps(result.certificate, indent=2, sort_keys=False)
                             + "\n")
