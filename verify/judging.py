"""The judging core: the rules every front-end shares, and the formula's judgement per obligation.

Rules, each stated once (``certify``, the online monitor, ``watch``, falsify, regress and batch import them):

* ``EXIT_CODES``: verdict -> exit code (0 pass, 1 fail, 2 inconclusive);
* ``tube_tolerance_m``: the tube check's noise tolerance (``TUBE_TOLERANCE_RULE`` says how);
* ``formula_of``: the formula judged (the scenario's, or ``--spec``), refused (exit 3) when an atom labels no region
  and names no signal; a name that is both is the signal;
* ``overall_verdict``: the run's verdict over the selected checks and the problems of its streams;
* ``margin_entry``: how a margin is stated (a number, or null with the reason there is no finite one).

The formula (``judge_formula``): evaluated once under the trajectory semantics (``verify.semantics.trajectory``);
from those values, for the whole formula and for each top-level conjunct (an *obligation*): its verdict, its margin
with the atom (and so the unit) whose value it is, its first violation, the time the data decided it
(``verify.semantics.analysis``), and for an undecided one which atom or window was unknown, when, why, and what would
decide it -- with one sentence that says it (``explanation``), which every front-end shows as is.
"""

from __future__ import annotations

import math
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field
from typing import Any

import numpy as np
import numpy.typing as npt

from tubempc.mitl import (
    Always,
    And,
    Atom,
    Eventually,
    Formula,
    Next,
    Not,
    Until,
    atoms,
    subformulas,
)
from tubempc.scenario import Scenario
from verify.errors import SpecError
from verify.ingest.fields import SignalStream
from verify.monitor.engine import UNTIL_ROBUSTNESS_LIMIT, Explanation, explain, verdict_of
from verify.semantics.analysis import decided_times, margin_source
from verify.semantics.timed_run import parse_spec
from verify.semantics.trajectory import reported_margin, trajectory_values
from verify.signals import SignalBounds, signal_bounds

__all__ = ["EXIT_CODES", "POSITION_ROUNDING_M", "TUBE_TOLERANCE_RULE", "FormulaJudgement", "ObligationResult",
           "Unknown", "check_explanation", "formula_of", "judge_formula", "margin_entry", "overall_verdict",
           "split_obligations", "timed_run_explanation", "tube_tolerance_m"]

FloatArray = npt.NDArray[np.float64]
IntArray = npt.NDArray[np.int64]

#: verdict -> exit code, for certify, watch, batch and regress alike
EXIT_CODES = {"pass": 0, "fail": 1, "inconclusive": 2}
#: added to the tube's tolerance: logged positions are absolute float64 (metres from the workspace origin), so a
#: deviation computed from two of them carries ~1e-15 m of rounding; a run that rides the tube's boundary exactly (the
#: lemma's worst case) must not fail on it
POSITION_ROUNDING_M = 1e-9
TUBE_TOLERANCE_RULE = "3 * scenario.mocap.noise_std + 1e-9 m (rounding of logged positions)"


def tube_tolerance_m(scenario: Scenario) -> float:
    """The tube check's tolerance: three standard deviations of the MoCap noise plus the rounding of positions."""
    return 3.0 * scenario.mocap.noise_std + POSITION_ROUNDING_M


def formula_of(scenario: Scenario, spec: str | None) -> Formula:
    """The formula to judge (``spec``, else the scenario's); ``SpecError`` (exit 3) when it is malformed or one of
    its atoms labels no region and names no signal of the scenario."""
    formula = parse_spec(spec if spec is not None else scenario.spec)
    if scenario.robots or any("." in a for a in atoms(formula)):
        problem = scenario.atom_problem(formula)
        if problem:
            raise SpecError(f"formula {formula}: {problem}")
        return formula
    known = {lab for r in scenario.regions for lab in r.labels} | set(scenario.signals)
    unknown = sorted(atoms(formula) - known)
    if unknown:
        raise SpecError(f"formula {formula}: proposition(s) {', '.join(unknown)} label no region and name no "
                        f"signal of scenario {scenario.name!r}")
    return formula


def overall_verdict(checks: Sequence[tuple[str, str]], *, partial: bool,
                    problems: Mapping[str, str] | None = None) -> tuple[str, str | None]:
    """The run's verdict over ``(name, verdict)`` of the selected checks, and why a run without a violation is not a
    pass: fail if any check fails; else inconclusive if a stream has a problem that no check can pass over (samples
    not judged), if any check is inconclusive, if the log is partial (salvaged) or if no check ran; else pass."""
    if not checks:
        return "inconclusive", "no check was run: nothing is certified"
    if any(v == "fail" for _, v in checks):
        return "fail", None
    if problems:
        return "inconclusive", "; ".join(f"{k}: {v}" for k, v in sorted(problems.items()))
    undecided = [n for n, v in checks if v == "inconclusive"]
    if undecided:
        return "inconclusive", f"check(s) not decided: {', '.join(undecided)}"
    if partial:
        return "inconclusive", "the log is partial (salvaged): a partial log is never certified as pass"
    return "pass", None


def margin_entry(verdict: str, margin: float | None, *, reason: str | None = None) -> tuple[float | None, str | None]:
    """A margin as the certificate states it: a finite number, or null with the reason there is none
    (``reason``: the check's own; otherwise said from the value). An infinite margin is always said; an undecided
    check, or a pass stated without a margin (the timed run's), needs no reason."""
    if margin is not None and math.isfinite(margin):
        return float(margin), None
    if reason is not None:
        return None, reason
    if margin is not None and math.isinf(margin):
        sign = "+inf" if margin > 0 else "-inf"
        return None, (f"the margin is {sign}: a value at or beyond float64's range (a position, field value or region "
                      f"size that overflowed)")
    if verdict != "fail":  # undecided, or a pass stated without a margin (the timed run's)
        return None, None
    if margin is not None:  # NaN
        return None, "the margin is not a number (NaN data)"
    return None, "the check computed no margin"


#: what would decide a check that could not be, by the start of its reason
_DECIDE = (
    ("no nominal state logged", "log the MPC's nominal state on topics.nominal"),
    ("no cmd_vel logged", "log the applied commands on topics.cmd_vel"),
    ("no samples", "a log with pose samples"),
    ("the robot may have crossed", "samples closer together there (or a lower speed bound) would decide it"),
    ("may have come closer than", "samples of both robots closer together there would decide it"),
    ("NaN", "usable values there would decide it"),
    ("pose sample(s) without a usable nominal", "a nominal sample within half a MoCap period of each pose sample"),
)


def check_explanation(entry: Mapping[str, Any]) -> str | None:
    """One sentence for a check's entry whose verdict is not pass: where it was violated and by how much, or why it
    could not be decided and what would decide it."""
    verdict = entry.get("verdict")
    if verdict == "pass":
        return None
    if verdict == "fail":
        at = entry.get("first_violation_time")
        where = f" at {at:.2f} s" if isinstance(at, int | float) else ""
        what = [f"{k} {entry[k]}" for k in ("region", "component", "pair") if entry.get(k) is not None]
        margin = entry.get("margin")
        how = (f"margin {margin:.4g} {entry.get('margin_unit') or ''}".rstrip() if isinstance(margin, int | float)
               else f"no finite margin ({entry.get('margin_reason')})")
        return f"violated{where}" + (f" ({', '.join(what)})" if what else "") + f"; {how}"
    reason = str(entry.get("reason") or "not decided")
    decide = next((d for key, d in _DECIDE if key in reason), "more or better data would decide it")
    return f"{reason}; {decide}"


def timed_run_explanation(tr: Any, end_s: float) -> str | None:
    """The sentence of the timed-run check (``verify.semantics.timed_run.TimedRunVerdict``)."""
    if tr.verdict == "pass":
        return None
    if tr.verdict == "fail":
        at = "" if tr.time_s is None else f" at {tr.time_s:.2f} s"
        how = f"margin {tr.margin_s:.4g} s" if tr.margin_s is not None else "no finite margin"
        return f"violated{at}: {tr.subformula} ({tr.reason}); {how}"
    if tr.reason == "the timed run is empty":
        return ("the timed run is empty: the robot disc was never fully inside a region; a run that enters a "
                "region would decide it")
    if tr.reason and tr.reason.startswith("the window"):
        return (f"{tr.subformula}: its window reaches past the end of the log at {end_s:.2f} s; a longer log would "
                f"decide it")
    when = "" if tr.time_s is None else f" at {tr.time_s:.2f} s"
    return f"{tr.subformula} unknown{when}: {tr.reason}; data that decides its atoms there would decide it"


def split_obligations(formula: Formula) -> tuple[Formula, ...]:
    """The top-level conjuncts (the formula itself when it is not a conjunction)."""
    return formula.args if isinstance(formula, And) else (formula,)


@dataclass(frozen=True, slots=True)
class Unknown:
    """What left a verdict undecided: the sub-formula (an atom, or a temporal operator whose window the log does not
    cover), the atom if any, the stretch it was unknown over (s from time 0), why, and what would decide it."""

    subformula: str
    atom: str | None
    from_s: float | None
    to_s: float | None
    cause: str
    decide: str

    def to_json(self) -> dict[str, Any]:
        return {"subformula": self.subformula, "atom": self.atom, "from_s": self.from_s, "to_s": self.to_s,
                "cause": self.cause, "decide": self.decide}

    def sentence(self) -> str:
        span = ""
        if self.from_s is not None and self.to_s is not None:
            span = (f" at {self.from_s:.2f} s" if abs(self.to_s - self.from_s) < 5e-3
                    else f" {self.from_s:.2f}-{self.to_s:.2f} s")
        return f"{self.atom or self.subformula} unknown{span}: {self.cause}; {self.decide}"


@dataclass(frozen=True, slots=True)
class ObligationResult:
    """The judgement of the whole formula or of one top-level conjunct, under the trajectory semantics."""

    formula: str
    role: str  # "formula" or "conjunct"
    verdict: str
    lo: float  # robustness bounds at time 0
    hi: float
    margin: float | None
    margin_unit: str | None
    margin_atom: str | None
    margin_time_ns: int | None  # where the atom has the margin's value (relative ns)
    margin_reason: str | None
    first_violation_ns: int | None  # relative ns (fail only)
    decided_ns: int | None  # relative ns; None: undecided at the end of the log
    subformula: str | None  # the witness of a fail, or what is undecided
    reason: str | None
    unknown: Unknown | None
    window_s: tuple[float, float | None] | None  # the conjunct's window (s), None: evaluated at time 0 only
    body: str  # what the curve measures
    body_unit: str | None
    curve_t_ns: IntArray = field(repr=False)
    curve: FloatArray = field(repr=False)  # guaranteed margin of the body at every sample

    @property
    def explanation(self) -> str | None:
        """One sentence saying why it is not a pass (None for a pass)."""
        if self.verdict == "pass":
            return None
        if self.verdict == "inconclusive":
            return self.unknown.sentence() if self.unknown is not None else f"{self.subformula}: {self.reason}"
        at = "" if self.first_violation_ns is None else f" at {_s(self.first_violation_ns):.2f} s"
        what = f"{self.subformula} ({self.reason})" if self.subformula and self.reason else (self.subformula or "")
        if self.margin is not None:
            by = f"margin {self.margin:.4g} {self.margin_unit or ''}".rstrip()
            src = (f" ({self.margin_atom} at {_s(self.margin_time_ns):.2f} s)" if self.margin_atom is not None
                   and self.margin_time_ns is not None else "")
            return f"violated{at}: {what}; {by}{src}"
        return f"violated{at}: {what}; no finite margin ({self.margin_reason})"

    def to_json(self, time0_ns: int = 0) -> dict[str, Any]:
        del time0_ns
        out: dict[str, Any] = {
            "formula": self.formula, "role": self.role, "verdict": self.verdict, "margin": self.margin,
            "margin_unit": self.margin_unit, "margin_atom": self.margin_atom,
            "margin_time": None if self.margin_time_ns is None else _s(self.margin_time_ns),
            "margin_reason": self.margin_reason,
            "first_violation_time": None if self.first_violation_ns is None else _s(self.first_violation_ns),
            "decided_at": None if self.decided_ns is None else _s(self.decided_ns),
            "subformula": self.subformula, "reason": self.reason,
            "unknown": None if self.unknown is None else self.unknown.to_json(),
            "window": None if self.window_s is None else list(self.window_s),
            "explanation": self.explanation}
        return out


def _s(t_ns: int | float | None) -> float:
    return round(float(t_ns or 0) * 1e-9, 9)


@dataclass(frozen=True, slots=True)
class FormulaJudgement:
    """The whole formula and its top-level conjuncts (none when it is not a conjunction)."""

    whole: ObligationResult
    conjuncts: tuple[ObligationResult, ...]
    signal_t_ns: IntArray  # the whole formula's guaranteed robustness at the samples (relative ns)
    signal: FloatArray

    @property
    def entries(self) -> tuple[ObligationResult, ...]:
        """What the certificate lists under ``obligations``: the whole formula, then each conjunct."""
        return (self.whole, *self.conjuncts)

    @property
    def panels(self) -> tuple[ObligationResult, ...]:
        """One per obligation a reader checks: the conjuncts, or the formula itself."""
        return self.conjuncts or (self.whole,)


def _units(streams: Mapping[str, SignalStream]) -> dict[str, str]:
    return {name: s.spec.unit or "field unit" for name, s in streams.items()}


def _body_and_window(f: Formula) -> tuple[Formula, tuple[float, float | None] | None]:
    if isinstance(f, Eventually | Always):
        return f.arg, (f.interval.lo_s, None if f.interval.hi is None else f.interval.hi_s)
    if isinstance(f, Until):
        return f.right, (f.interval.lo_s, None if f.interval.hi is None else f.interval.hi_s)
    return f, None


class _Context:
    """What the explanations need beside the values: sample times, the scenario, the signal streams."""

    def __init__(self, scenario: Scenario, t_ns: IntArray, time0_ns: int, streams: Mapping[str, SignalStream],
                 max_speed_mps: float, *, joint_units: Mapping[str, str] | None = None) -> None:
        self.scenario = scenario
        self.joint_units = dict(joint_units or {})  # atoms given as bounds on a joint run (robots' atoms)
        self.t_ns = t_ns  # relative
        self.time0_ns = time0_ns
        self.streams = streams
        self.v_max = max_speed_mps
        self.end_ns = int(t_ns[-1]) if t_ns.size else 0

    def unit(self, atom: str | None) -> str | None:
        if atom is None:
            return None
        if atom in self.joint_units:
            return self.joint_units[atom]
        if atom in self.streams:
            return self.streams[atom].spec.unit or "field unit"
        return "m"

    def regions(self, atom: str) -> str:
        names = [r.name for r in self.scenario.regions if atom in r.labels]
        return " or ".join(names) if names else f"no region (label {atom})"


def judge_formula(formula: Formula, t_rel_ns: IntArray, x_m: FloatArray, y_m: FloatArray, scenario: Scenario, *,
                  time0_ns: int, max_speed_mps: float, streams: Mapping[str, SignalStream] | None = None,
                  joint_atoms: Mapping[str, tuple[SignalBounds, str]] | None = None) -> FormulaJudgement:
    """Evaluate ``formula`` once on the pose samples (relative ns, strictly increasing) and read off the whole
    formula's and every obligation's result. ``streams``: the signal atoms' data (absolute times).
    ``joint_atoms``: atoms already bounded at these samples and gaps, with their unit (the robots' atoms of a joint
    run, ``verify.semantics.joint``)."""
    used = atoms(formula)
    sig_streams = {k: v for k, v in (streams or {}).items() if k in used}
    joint = {k: v for k, v in (joint_atoms or {}).items() if k in used}
    ctx = _Context(scenario, t_rel_ns, time0_ns, sig_streams, max_speed_mps,
                   joint_units={k: unit for k, (_, unit) in joint.items()})
    conjuncts = split_obligations(formula)
    if t_rel_ns.size == 0:
        empty_i, empty_f = np.zeros(0, dtype=np.int64), np.zeros(0)
        none = Unknown(str(formula), None, None, None, "the log has no pose samples", "a log with pose samples")

        def nothing(f: Formula, role: str) -> ObligationResult:
            body, window = _body_and_window(f)
            return ObligationResult(str(f), role, "inconclusive", -math.inf, math.inf, None, None, None, None, None,
                                    None, None, str(f), "no pose samples", none, window, str(body), None, empty_i,
                                    empty_f)

        return FormulaJudgement(nothing(formula, "formula"), tuple(nothing(c, "conjunct") for c in conjuncts)
                                if len(conjuncts) > 1 else (), empty_i, empty_f)
    abs_t = t_rel_ns + time0_ns
    bounds = {k: signal_bounds(v, abs_t) for k, v in sig_streams.items()}
    bounds.update({k: b for k, (b, _) in joint.items()})
    tv = trajectory_values(formula, t_rel_ns, x_m, y_m, scenario, max_speed_mps=max_speed_mps, signals=bounds)
    decided = decided_times(formula, tv.pos, tv.values)
    big_until = tv.pos.size > UNTIL_ROBUSTNESS_LIMIT and any(isinstance(g, Until) for g in subformulas(formula))

    def result(f: Formula, role: str) -> ObligationResult:
        v = tv.values[f]
        lo, hi = float(v.lo[0]), float(v.hi[0])
        verdict = verdict_of(lo, hi)
        margin = reported_margin(verdict, lo, hi)  # None only when undecided or infinite both ways
        bound = "lo" if verdict == "pass" or not math.isfinite(hi) else "hi"
        src = margin_source(f, 0, bound, tv.pos, tv.values, infinite=True) if verdict != "inconclusive" else None
        atom_name, atom_at = None, None
        if src is not None:
            atom_name = src[0]
            k = src[1]
            atom_at = int(tv.pos.start_ns[k]) - (0 if tv.pos.is_point[k] else 1)  # a gap: from the sample before it
        margin_reason = None
        if verdict != "inconclusive" and (margin is None or not math.isfinite(margin)):
            value = margin if margin is not None else (lo if verdict == "pass" else hi)
            margin_reason = _no_margin_reason(value, atom_name, atom_at, big_until)
            margin = None
        why: Explanation | None = explain(f, 0, tv.pos, tv.values) if verdict != "pass" else None
        d = float(decided[f][0])
        decided_ns = int(d) if math.isfinite(d) else None
        first = None
        if verdict == "fail" and why is not None:
            first = why.time_ns
        unknown = _unknown(why, tv, ctx) if verdict == "inconclusive" and why is not None else None
        body, window = _body_and_window(f)
        bv = tv.values.get(body, v)
        curve = bv.lo[tv.point_at].astype(np.float64)
        body_units = {ctx.unit(a) for a in atoms(body)}
        body_unit = body_units.pop() if len(body_units) == 1 else (
            None if not body_units else "mixed: " + ", ".join(
                f"{a} {ctx.unit(a)}" for a in sorted(atoms(body))))
        return ObligationResult(
            str(f), role, verdict, lo, hi, margin, ctx.unit(atom_name) if margin is not None else None,
            atom_name, atom_at, margin_reason, first, decided_ns, None if why is None else why.subformula,
            None if why is None else why.reason, unknown, window, str(body), body_unit, t_rel_ns, curve)

    whole = result(formula, "formula")
    parts = tuple(result(c, "conjunct") for c in conjuncts) if len(conjuncts) > 1 else ()
    signal = tv.values[formula].lo[tv.point_at].astype(np.float64)
    return FormulaJudgement(whole, parts, t_rel_ns, signal)


def _no_margin_reason(value: float, atom: str | None, at_ns: int | None, big_until: bool) -> str:
    """Why a decided formula states no finite margin."""
    if big_until:
        return (f"Until over more than {UNTIL_ROBUSTNESS_LIMIT} positions: only its verdict is computed, not its "
                f"robustness")
    sign = "+inf" if value > 0 else "-inf"
    if atom is not None:
        return (f"{sign}: the margin of {atom} at {_s(at_ns):.2f} s is {sign} (a position, field value or region size "
                f"at or beyond float64's range)")
    return f"{sign}: decided by constants or timing (a window or next sample), not by an atom's value"


def _unknown(why: Explanation, tv: Any, ctx: _Context) -> Unknown:
    """The undecided leaf the witness walk reached, said for people."""
    node, i = why.node, why.index
    pos = tv.pos
    atom = node.name if isinstance(node, Atom) else (
        node.arg.name if isinstance(node, Not) and isinstance(node.arg, Atom) else None)
    if atom is not None and i >= 0:
        return _unknown_atom(atom, str(node), i, tv, ctx)
    t_i = int(pos.start_ns[i]) if i >= 0 else 0
    end_s = _s(pos.end_ns)
    if isinstance(node, Eventually | Always | Until):
        lo_s = _s(t_i) + node.interval.lo_s
        hi = node.interval.hi
        to_s = None if hi is None else _s(int(pos.stop_ns[i])) + float(hi)
        if why.reason.startswith("the window"):
            arg = node.arg if isinstance(node, Eventually | Always) else node.right
            extra = (f" (or {arg} holding before {end_s:.2f} s)" if isinstance(node, Eventually) and lo_s < end_s
                     else "")
            return Unknown(str(node), None, round(lo_s, 9), None if to_s is None else round(to_s, 9),
                           f"its window {lo_s:.2f}-{'inf' if to_s is None else f'{to_s:.2f}'} s reaches past the end "
                           f"of the log at {end_s:.2f} s",
                           f"a log that runs to {to_s:.2f} s would decide it{extra}" if to_s is not None else
                           "a longer log would decide it")
        return Unknown(str(node), None, round(lo_s, 9), None if to_s is None else round(to_s, 9),
                       f"undecided at the end of the log ({end_s:.2f} s)", "a longer log would decide it")
    if isinstance(node, Next):
        return Unknown(str(node), None, _s(t_i), end_s,
                       f"no sample after {_s(t_i):.2f} s within its window before the log ends at {end_s:.2f} s",
                       "a later sample would decide it")
    return Unknown(str(node) if node is not None else why.subformula, None, _s(t_i), _s(t_i), why.reason,
                   "data that decides its arguments would decide it")


def _stretch(v_lo: FloatArray, v_hi: FloatArray, i: int) -> tuple[int, int]:
    """The maximal run of positions around ``i`` where the value is unknown."""
    with np.errstate(invalid="ignore"):
        unk = ~((v_lo > 0) | (v_hi < 0))
    a = i
    while a > 0 and unk[a - 1]:
        a -= 1
    b = i
    while b + 1 < unk.shape[0] and unk[b + 1]:
        b += 1
    return a, b


def _unknown_atom(atom: str, sub: str, i: int, tv: Any, ctx: _Context) -> Unknown:
    pos = tv.pos
    v = tv.values[Atom(atom)]
    a, b = _stretch(v.lo, v.hi, i)
    from_ns, to_ns = int(pos.start_ns[a]), int(pos.stop_ns[b]) + (0 if pos.is_point[b] else 1)
    from_s, to_s = _s(from_ns), _s(to_ns)
    if atom in ctx.streams:
        return _unknown_signal(atom, sub, i, from_s=from_s, to_s=to_s, tv=tv, ctx=ctx)
    if atom in ctx.joint_units:
        return _unknown_joint(atom, sub, from_s=from_s, to_s=to_s, ctx=ctx)
    regions = ctx.regions(atom)
    if pos.is_point[i]:
        return Unknown(sub, atom, from_s, to_s,
                       f"the pose at {_s(pos.start_ns[i]):.2f} s is unknown (NaN, or samples at one time that "
                       f"disagree)", "a usable pose sample there would decide it")
    k = int(np.searchsorted(tv.point_at, i))  # the sample after the gap
    p0, p1 = int(tv.point_at[k - 1]), int(tv.point_at[min(k, tv.point_at.size - 1)])
    m0, m1 = float(v.lo[p0]), float(v.lo[p1])
    t0_s, t1_s = _s(pos.start_ns[p0]), _s(pos.start_ns[p1])
    if not (math.isfinite(m0) and math.isfinite(m1)):
        return Unknown(sub, atom, from_s, to_s,
                       f"a pose next to the gap {t0_s:.2f}-{t1_s:.2f} s is unknown (NaN or conflicting samples)",
                       "usable pose samples there would decide it")
    step = float(v.hi[i] - v.lo[i])
    need = abs(m0 + m1) / ctx.v_max if ctx.v_max > 0 else 0.0
    return Unknown(sub, atom, from_s, to_s,
                   f"the samples at {t0_s:.2f} s and {t1_s:.2f} s are {m0:+.3g} m and {m1:+.3g} m from "
                   f"{regions}'s boundary, and the robot may move {step:.3g} m between them (speed bound "
                   f"{ctx.v_max:g} m/s): it may have crossed",
                   f"samples at most {need:.3g} s apart there (or a lower speed bound) would decide it")


def _unknown_signal(atom: str, sub: str, i: int, *, from_s: float, to_s: float, tv: Any, ctx: _Context) -> Unknown:
    stream = ctx.streams[atom]
    spec = stream.spec
    pos = tv.pos
    t_abs = int(pos.start_ns[i]) + ctx.time0_ns
    hold_s = stream.hold_ns * 1e-9
    source = "rate_hz" if spec.rate_hz is not None else "the median spacing of its messages"
    period = f"hold {hold_s:.3g} s = 1.5 periods of {stream.period_ns * 1e-9:.3g} s from {source}"
    rate_hint = (f"give signals.{atom}.rate_hz if {spec.topic} publishes less often" if spec.rate_hz is None else
                 f"messages of {spec.topic} at least every {hold_s:.3g} s would decide it")
    st = stream.t_ns
    j = int(np.searchsorted(st, t_abs, side="right")) - 1
    if not pos.is_point[i]:
        j = int(np.searchsorted(st, int(pos.stop_ns[i]) + ctx.time0_ns, side="right")) - 1
    if j < 0:
        first = f" (its first at {_s(int(st[0]) - ctx.time0_ns):.2f} s)" if st.size else " (it has none)"
        return Unknown(sub, atom, from_s, to_s, f"no message of {spec.topic} before {from_s:.2f} s{first}",
                       f"a message of {spec.topic} by {from_s:.2f} s would decide it")
    value = float(stream.value[j])
    if math.isnan(value):
        return Unknown(sub, atom, from_s, to_s,
                       f"the message of {spec.topic} at {_s(int(st[j]) - ctx.time0_ns):.2f} s has no usable "
                       f"{spec.field} (NaN, or messages at one time that disagree)",
                       f"a usable {spec.field} there would decide it")
    end_ns = int(pos.stop_ns[i]) + ctx.time0_ns
    k, until_ns = j, end_ns
    if not pos.is_point[i]:  # the first silence longer than the hold within the gap (where it became unknown)
        k0 = max(int(np.searchsorted(st, t_abs, side="right")) - 1, 0)
        held = st[k0 : j + 1].astype(np.int64)
        ends = np.append(held[1:], end_ns)
        longer = np.flatnonzero(ends - held > stream.hold_ns)
        if longer.size:
            k, until_ns = k0 + int(longer[0]), int(ends[longer[0]])
    silent = (until_ns - int(st[k])) * 1e-9
    if silent > hold_s:
        from_s = max(from_s, _s(int(st[k]) + stream.hold_ns - ctx.time0_ns))  # unknown once the hold ran out
        return Unknown(sub, atom, from_s, to_s,
                       f"{spec.topic} silent {silent:.2f} s after its message at "
                       f"{_s(int(st[k]) - ctx.time0_ns):.2f} s > {period}", rate_hint)
    return Unknown(sub, atom, from_s, to_s,
                   f"{spec.field} is on both sides of {spec.op} {spec.value} between the pose samples around "
                   f"{from_s:.2f} s (or a message in between is missing: {period})",
                   "pose samples closer together there would decide it")


def _unknown_joint(atom: str, sub: str, *, from_s: float, to_s: float, ctx: _Context) -> Unknown:
    """An atom of a joint run (a robot's own atom, or a proximity atom) that the robots' samples leave open."""
    if "." in atom:
        who, what = atom.split(".", 1)
        regions = ctx.regions(what)
        subject = (f"robot {who} may have crossed the boundary of {regions} between its own samples (or was not "
                   f"observed there)" if not regions.startswith("no region") else
                   f"{who}'s signal {what} is on both sides of its threshold or not known there")
        return Unknown(sub, atom, from_s, to_s, subject,
                       f"samples of {who} closer together there (or a lower speed bound) would decide it")
    return Unknown(sub, atom, from_s, to_s,
                   "the robots may have crossed the proximity distance between their samples (or were not observed)",
                   "samples of both robots closer together there would decide it")
