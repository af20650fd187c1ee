"""The certificate as a typed contract: pydantic models -> validation of every certificate and its JSON Schema.

input: the certificate's JSON-ready dict (``verify.certify``) or a ``certificate.json`` read back -> output: a
frozen ``Certificate`` (``Certificate.model_validate``), and ``certificate_schema()``: the JSON Schema published as
``docs/certificate.schema.json`` and printed by ``tubempc schema certificate``.

Verdicts are an enum; every check states its margin's unit; a failed check must carry its first violation time and
a margin, or a null margin with ``margin_reason`` saying why no finite one exists (a formula false by constants or
timing, a value that overflowed); a validator refuses anything else. ``obligations`` holds the formula's judgement
per top-level conjunct (and for the whole formula), computed by the judging code (``verify.judging``): verdict,
margin with the atom and unit it comes from, first violation, when it was decided, and for an undecided one which
atom or window was unknown, when, why and what would decide it, with a one-sentence ``explanation`` that every
report shows as is. Checks keep their own detail fields (``subformula``, ``reason``,
``radius_m``, ...) beside the common ones; the top level admits no field the schema does not name, so a new field
is a schema change (and a ``CERTIFICATE_VERSION`` bump), never a silent one. Every model is built on first use
(``defer_build``): certify validates one ``Certificate``, whose validator holds the nested models' schemas. That
build (~4 ms of Python) is started in a background thread when certify begins to read a log
(``build_in_background``), whose reading runs mostly outside the GIL; ``Certificate.model_validate`` and its schema
wait for it.
"""

from __future__ import annotations

import contextlib
import threading
from enum import StrEnum
from typing import Any, Literal

from pydantic import BaseModel, ConfigDict, Field, model_validator

__all__ = ["CERTIFICATE_SCHEMA_ID", "CERTIFICATE_VERSION", "CERTIFY_JSON_SCHEMA_ID", "Certificate", "CheckEntry",
           "FleetInfo", "NotChecked", "ObligationEntry", "RobotEntry", "TimedRunEntry", "TubeInfo", "UnknownEntry",
           "UnusableLog", "Verdict", "build_in_background", "certificate_schema", "certify_json_schema"]

#: 3: typed model with a published schema; margin_unit on every check, margins of failed checks always stated
#: 4: per-obligation results; a failed check's margin may be null with margin_reason; decided_at and explanation
#: 5: several robots in one log: ``robots`` and ``fleet``, timed-run entries name their robot
CERTIFICATE_VERSION = 5
CERTIFICATE_SCHEMA_ID = "https://tubempc.invalid/schema/certificate-v5.json"
CERTIFY_JSON_SCHEMA_ID = "https://tubempc.invalid/schema/certify-json-v5.json"


class Verdict(StrEnum):
    """A check's or the whole run's verdict (exit codes 0, 1, 2)."""

    PASS = "pass"
    FAIL = "fail"
    INCONCLUSIVE = "inconclusive"


class CheckEntry(BaseModel):
    """One check: name, verdict, margin with its unit, first violation; check-specific details beside them."""

    model_config = ConfigDict(frozen=True, extra="allow", defer_build=True)

    name: str = Field(description="check name: spec_trajectory, spec_timed_run, tube, input_box, workspace, "
                                  "obstacle_clearance, ...")
    verdict: Verdict
    margin: float | None = Field(description="worst margin in margin_unit (negative: violated); null when the check "
                                             "has no finite one (margin_reason says why) or is undecided")
    margin_unit: str | None = Field(description="unit of margin: m, s, m/s or rad/s, ...")
    first_violation_time: float | None = Field(description="seconds from time 0 of the first violation (fail only)")
    margin_reason: str | None = Field(default=None, description="why a decided check states no finite margin")
    decided_at: float | None = Field(default=None, description="seconds from time 0 when the data decided the "
                                                               "verdict (null: undecided at the end of the log)")
    explanation: str | None = Field(default=None, description="one sentence: why it is not a pass (a violation and "
                                                              "its margin, or what is unknown and what would "
                                                              "decide it)")
    subformula: str | None = Field(default=None, description="the sub-formula a formula check's witness names")
    reason: str | None = Field(default=None, description="why the check failed or could not be decided")

    @model_validator(mode="after")
    def _fail_has_time_and_margin(self) -> CheckEntry:
        if self.verdict is Verdict.FAIL and self.first_violation_time is None:
            raise ValueError(f"check {self.name!r} failed without a first violation time")
        if self.verdict is Verdict.FAIL and self.margin is None and not self.margin_reason:
            raise ValueError(f"check {self.name!r} failed without a margin and without a margin_reason")
        return self

    @property
    def details(self) -> dict[str, Any]:
        """The check-specific fields (everything but the common ones)."""
        return dict(self.model_extra or {}) | {k: v for k, v in (("subformula", self.subformula),
                                                                   ("reason", self.reason)) if v is not None}


class UnknownEntry(BaseModel):
    """What left an obligation undecided: an atom over a stretch of time, or a window the log does not cover."""

    model_config = ConfigDict(frozen=True, extra="forbid", defer_build=True)

    subformula: str = Field(description="the undecided sub-formula the witness walk reached")
    atom: str | None = Field(description="the atom that was unknown (null: a window or next sample, not an atom)")
    from_s: float | None = Field(description="start of the unknown stretch or of the window (s from time 0)")
    to_s: float | None = Field(description="end of the unknown stretch or of the window (null: unbounded)")
    cause: str = Field(description="why it is unknown")
    decide: str = Field(description="what data would decide it")


class ObligationEntry(BaseModel):
    """The formula's judgement under the trajectory semantics: for the whole formula (role ``formula``, the same
    values as the spec_trajectory check) and for each top-level conjunct (role ``conjunct``)."""

    model_config = ConfigDict(frozen=True, extra="forbid", defer_build=True)

    formula: str = Field(description="canonical text of the obligation")
    role: Literal["formula", "conjunct"]
    verdict: Verdict
    margin: float | None = Field(description="pass: guaranteed robustness; fail: the optimistic one (violated by at "
                                             "least that much), in margin_unit; null: none finite (margin_reason) "
                                             "or undecided")
    margin_unit: str | None = Field(description="unit of the atom the margin is the value of: m (regions) or the "
                                                "signal field's unit")
    margin_atom: str | None = Field(description="the atom whose value the margin is")
    margin_time: float | None = Field(description="where that atom has that value (s from time 0; over a gap: the "
                                                  "sample before it)")
    margin_reason: str | None = Field(description="why a decided obligation states no finite margin")
    first_violation_time: float | None = Field(description="the witness of the violation (s from time 0; fail only)")
    decided_at: float | None = Field(description="when the data decided the verdict (s from time 0; null: undecided)")
    subformula: str | None = Field(description="the sub-formula the witness names (fail or inconclusive)")
    reason: str | None = Field(description="why that sub-formula is false or undecided")
    unknown: UnknownEntry | None = Field(description="inconclusive only: what was unknown, when and why")
    window: list[float | None] | None = Field(description="the conjunct's time window [lo, hi] in seconds (hi null: "
                                                          "unbounded; null: no temporal operator at the top)")
    explanation: str | None = Field(description="one sentence for a verdict other than pass")

    @model_validator(mode="after")
    def _complete(self) -> ObligationEntry:
        if self.verdict is Verdict.FAIL and (self.first_violation_time is None or self.decided_at is None):
            raise ValueError(f"obligation {self.formula!r} failed without a first violation and decision time")
        if self.verdict is not Verdict.INCONCLUSIVE and self.margin is None and not self.margin_reason:
            raise ValueError(f"obligation {self.formula!r} is decided without a margin and without a margin_reason")
        if self.verdict is Verdict.INCONCLUSIVE and self.unknown is None:
            raise ValueError(f"obligation {self.formula!r} is inconclusive without saying what is unknown")
        return self


class TimedRunEntry(BaseModel):
    """Definition 3: the robot disc became fully contained in ``region`` at ``time`` (s from time 0)."""

    model_config = ConfigDict(frozen=True, extra="forbid", defer_build=True)

    region: str
    time: float
    robot: str | None = Field(default=None, description="the robot (several robots in one log; absent for one)")


class TubeInfo(BaseModel):
    model_config = ConfigDict(frozen=True, extra="forbid", defer_build=True)

    radius_m: float
    noise_tolerance_m: float
    noise_tolerance_rule: str


class RobotEntry(BaseModel):
    """One robot of a multi-robot scenario: where its poses came from, its disc and speed bound, its own checks
    (named ``robot/check`` under ``checks``), its timed run and the quality of its streams."""

    model_config = ConfigDict(frozen=True, extra="forbid", defer_build=True)

    name: str
    pose_source: Any = Field(description="topic and type the robot's poses were read from")
    radius_m: float
    speed_bound_mps: float
    input_model: str
    span_s: tuple[float, float] | None = Field(description="[first, last] pose sample of this robot (s)")
    checks: list[str] = Field(description="this robot's checks (names under checks)")
    timed_run: list[TimedRunEntry]
    samples: dict[str, Any]
    data_quality: dict[str, Any]
    log_digest: str = Field(description="digest of the messages read for this robot (or of the log's bytes)")
    signals: dict[str, Any] | None = Field(default=None, description="per signal atom of this robot")


class FleetInfo(BaseModel):
    """How the robots were judged together: the joint span (every robot observed), the separation asked for."""

    model_config = ConfigDict(frozen=True, extra="forbid", defer_build=True)

    robots: list[str]
    joint_span_s: tuple[float, float] | None = Field(description="[start, end] of the stretch every robot was "
                                                                 "observed in (s); the formula and the separation "
                                                                 "are judged over it; null: no such stretch")
    separation: dict[str, Any] | None = Field(description="min_m for every pair and the pairs' own")
    proximity: dict[str, Any] = Field(description="proximity atoms: robots and within_m")


class NotChecked(BaseModel):
    """A check that was not run, and why (not selected, or its data is not in the scenario)."""

    model_config = ConfigDict(frozen=True, extra="forbid", defer_build=True)

    name: str
    reason: str


class Certificate(BaseModel):
    """The certificate of one log (``certificate.json``, ``tubempc certify --json``)."""

    model_config = ConfigDict(frozen=True, extra="forbid", title="tubempc certificate", defer_build=True)

    certificate_version: Literal[5] = Field(description="bumped on every change of this schema")
    verdict: Verdict = Field(description="fail if any check fails; else inconclusive if any check is inconclusive "
                                         "or the log is partial; else pass")
    verdict_reason: str | None = Field(default=None, description="why a run without a violation is not a pass")
    formula: str = Field(description="the MITL formula judged (canonical text)")
    scenario: str
    scenario_sha256: str
    log: str = Field(description="the log's path as given")
    log_format: str
    log_digest: str = Field(description="hash of the messages judged (blake3-messages) or of the log's bytes")
    log_digest_algorithm: str = Field(description="blake3-messages (the messages read), blake3 or sha256 (the file)")
    log_sha256: str | None = Field(default=None, description="the log's SHA-256 (only when that digest was asked)")
    partial: bool = Field(description="true when a truncated log was salvaged (never a pass)")
    time_base: str = Field(description="the time base used: header or log")
    time_base_requested: str | None = None
    time_base_note: str | None = None
    time0_ns: int = Field(description="time 0 (ns, in the chosen time base); every time below is seconds from it")
    duration_s: float
    judged_span_s: tuple[float, float] = Field(description="[first, last] sample time judged (s)")
    samples: dict[str, Any] = Field(description="per stream: samples read, judged, merged, re-timed")
    pose_source: Any = Field(description="topic and type the poses were read from")
    speed_bound_mps: float
    robot_radius_m: float
    tube: TubeInfo | None = Field(default=None, description="the tube the tube check used (when it ran)")
    input_model: str = Field(description="holonomic or unicycle: how input_box reads the commands")
    checks_selected: list[str] = Field(description="the checks that ran")
    checks_source: str = Field(description="where the selection came from: --checks, the scenario, or default")
    not_checked: list[NotChecked] = Field(description="checks that did not run, each with the reason")
    scenario_warnings: list[str] = Field(description="geometry the certifier accepts but a user may not mean")
    clock_findings: list[Any] | None = Field(default=None, description="what the clock checks found between topics")
    checks: list[CheckEntry]
    obligations: list[ObligationEntry] = Field(description="the formula's judgement (trajectory semantics): the whole "
                                                           "formula, then each top-level conjunct; empty when the "
                                                           "formula checks were not selected")
    timed_run: list[TimedRunEntry]
    signals: dict[str, Any] | None = Field(default=None, description="per signal atom: topic, field, samples, range")
    data_quality: dict[str, Any]
    generator: dict[str, Any] | None = Field(default=None, description="the log's own metadata (simulated runs)")
    robots: list[RobotEntry] | None = Field(default=None, description="several robots in one log: each robot")
    fleet: FleetInfo | None = Field(default=None, description="several robots in one log: how they were judged "
                                                              "together")

    @classmethod
    def model_validate(cls, obj: Any, **kwargs: Any) -> Certificate:
        """pydantic's, once the model's build started in the background (``build_in_background``) is done."""
        _built()
        return super().model_validate(obj, **kwargs)

    @classmethod
    def model_json_schema(cls, *args: Any, **kwargs: Any) -> dict[str, Any]:
        """pydantic's, once the model's build started in the background (``build_in_background``) is done."""
        _built()
        return super().model_json_schema(*args, **kwargs)

    def check(self, name: str) -> CheckEntry | None:
        return next((c for c in self.checks if c.name == name), None)

    @property
    def panels(self) -> list[ObligationEntry]:
        """The obligations a reader checks one by one: the conjuncts, or the whole formula if it is not a
        conjunction."""
        parts = [o for o in self.obligations if o.role == "conjunct"]
        return parts or [o for o in self.obligations if o.role == "formula"]

    def to_json_dict(self) -> dict[str, Any]:
        """The JSON-ready dict (optional fields that are null are left out)."""
        out = self.model_dump(mode="json", exclude={
            k for k in ("verdict_reason", "log_sha256", "time_base_requested", "time_base_note", "tube",
                        "clock_findings", "signals", "generator", "robots", "fleet")
            if getattr(self, k) is None})
        for entry in [*out["timed_run"], *(e for r in out.get("robots") or [] for e in r["timed_run"])]:
            if entry.get("robot") is None:
                entry.pop("robot", None)
        for robot in out.get("robots") or []:
            if robot.get("signals") is None:
                robot.pop("signals", None)
        for check in out["checks"]:
            for key in ("subformula", "reason", "margin_reason", "decided_at", "explanation"):
                if check.get(key) is None:
                    check.pop(key, None)
        return out


class UnusableLog(BaseModel):
    """A log that could not be certified, as ``certify --json`` lists it among several logs' certificates."""

    model_config = ConfigDict(frozen=True, extra="forbid", defer_build=True)

    log: str
    verdict: Literal["unusable", "error"] = Field(description="unusable input (exit 3) or an internal error (70)")
    exit_code: Literal[3, 70]
    error: str | None = Field(description="the one-line reason")


_BUILDING = threading.Lock()
_builder: list[threading.Thread] = []  # the one background build of this process, once started


def build_in_background() -> None:
    """Start building ``Certificate``'s validator (pydantic's schema of it and its nested models: ~4 ms of Python,
    the first call's one cost in judging) in a thread, once per process: certify starts it before it reads a log,
    whose reading mostly runs outside the GIL (decompression, reads, SQLite), so the certificate's validation at the
    end finds the model built. Every use of the model's validator or schema waits for the build
    (``Certificate.model_validate``, ``Certificate.model_json_schema``); a build that fails leaves the model to be
    built on first use, as without this. Not a daemon: a process that stops at once (a log that cannot be read,
    exit 3) waits the few ms for it at exit rather than tearing it down mid-build (which may write to stderr)."""
    with _BUILDING:
        if _builder or Certificate.__pydantic_complete__:
            return
        thread = threading.Thread(target=_build, name="certificate-model", daemon=False)
        _builder.append(thread)
        thread.start()


def _build() -> None:
    with contextlib.suppress(Exception):  # the model is then built on first use instead, and raises there
        Certificate.model_rebuild()


def _built() -> None:
    if _builder and _builder[0] is not threading.current_thread():
        _builder[0].join()


def certify_json_schema() -> dict[str, Any]:
    """The JSON Schema of ``tubempc certify --json``: one certificate, or for several logs a list of certificates
    and unusable-log entries."""
    cert = Certificate.model_json_schema(mode="serialization", ref_template="#/$defs/{model}")
    unusable = UnusableLog.model_json_schema(mode="serialization")
    defs = {**cert.pop("$defs", {}), "Certificate": cert, "UnusableLog": unusable}
    return {"$schema": "https://json-schema.org/draft/2020-12/schema", "$id": CERTIFY_JSON_SCHEMA_ID,
            "title": "tubempc certify --json", "$defs": defs,
            "oneOf": [{"$ref": "#/$defs/Certificate"},
                      {"type": "array", "items": {"anyOf": [{"$ref": "#/$defs/Certificate"},
                                                            {"$ref": "#/$defs/UnusableLog"}]}}]}


def certificate_schema() -> dict[str, Any]:
    """The JSON Schema (draft 2020-12) of ``Certificate``."""
    schema = Certificate.model_json_schema(mode="serialization")
    return {"$schema": "https://json-schema.org/draft/2020-12/schema", "$id": CERTIFICATE_SCHEMA_ID, **schema}
