"""What the online monitor reports: the state of a check or obligation, a decision, the monitor's state, the result
of ``close``.

input: the monitor's heads and accumulated checks -> output: frozen values (``CheckState``, ``Decision``,
``MonitorState``, ``OnlineResult``) whose times are seconds from the first pose sample and whose margins follow the
certificate's rule (``verify.semantics.trajectory.reported_margin``).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

from verify.checks import CheckResult
from verify.judging import EXIT_CODES

__all__ = ["CheckState", "Decision", "MonitorState", "OnlineResult", "final_line", "rel_s"]


@dataclass(frozen=True, slots=True)
class CheckState:
    """One check or obligation: verdict so far, whether final, when decided (s from the first pose sample), the
    margin so far (the certificate's rule, ``verify.semantics.trajectory.reported_margin``, on the bounds so far),
    whether that margin is final (no later sample can change it), since when (s: the sample after which none can)
    and the first violation (s)."""

    name: str
    verdict: str
    decided: bool
    decided_at_s: float | None
    margin: float | None
    first_violation_s: float | None
    margin_final: bool = False
    unit: str | None = None
    margin_final_at_s: float | None = None

    def decision(self) -> Decision:
        """The decision of a decided check: its margin only if that was final at the decision's time (a margin that
        became final later, e.g. an ``F`` true at 1 s whose window runs to 2 s, is left out here and shown at the
        end), so that a decision states the same whatever the batching."""
        final = (self.margin_final and self.margin_final_at_s is not None and self.decided_at_s is not None
                 and self.margin_final_at_s <= self.decided_at_s)
        return Decision(self.name, self.verdict, self.decided_at_s or 0.0, self.margin if final else None,
                        self.first_violation_s, self.unit)


@dataclass(frozen=True, slots=True)
class Decision:
    """A check or obligation became final: its verdict, when (``time_s``), its first violation, and its margin when
    that is final too (None while a later sample can still change it: an ``F`` already true may become more so,
    a violated ``G`` more violated; the margin is then in ``final_lines`` at the end). So nothing a decision states
    depends on how the samples were batched."""

    name: str
    verdict: str
    time_s: float
    margin: float | None
    first_violation_s: float | None
    unit: str | None = "m"  # the margin's unit (None: not stated, e.g. a formula mixing metres and a signal's unit)

    def line(self) -> str:
        margin = "" if self.margin is None or not math.isfinite(self.margin) else f" margin {self.margin:+.4g}"
        unit = "" if not margin or not self.unit else f" {self.unit}"
        at = "" if self.first_violation_s is None else f" (violated at {self.first_violation_s:.2f} s)"
        return f"{self.time_s:8.2f} s  {self.name} {self.verdict.upper()}{margin}{unit}{at}"


@dataclass(frozen=True, slots=True)
class MonitorState:
    verdict: str  # "fail" as soon as one check fails; "pass" only after close
    checks: tuple[CheckState, ...]
    obligations: tuple[CheckState, ...]
    samples: dict[str, int]
    closed: bool

    @property
    def all_decided(self) -> bool:
        return all(c.decided for c in (*self.checks, *self.obligations))

    def final_lines(self) -> list[str]:
        """At the end (``close``): one line per obligation and check with its final verdict, margin and first
        violation, the values the certificate states for the same samples."""
        return [final_line(c.name, c.verdict, c.margin, c.unit, c.first_violation_s)
                for c in (*self.obligations, *self.checks)]


def final_line(name: str, verdict: str, margin: float | None, unit: str | None,
               first_violation_s: float | None) -> str:
    """The line ``watch`` prints for one obligation or check at the end, one robot's or a fleet's alike."""
    shown = "" if margin is None else f" margin {margin:+.4g}" + (f" {unit}" if unit else "")
    at = "" if first_violation_s is None else f" (violated at {first_violation_s:.2f} s)"
    return f"   final  {name} {verdict.upper()}{shown}{at}"


@dataclass(frozen=True, slots=True)
class OnlineResult:
    """What ``close`` returns: the checks (as ``verify.checks.CheckResult``), the overall verdict and exit code."""

    verdict: str
    verdict_reason: str | None
    checks: tuple[CheckResult, ...]
    state: MonitorState

    @property
    def exit_code(self) -> int:
        return EXIT_CODES[self.verdict]


def rel_s(t_ns: int | None, t0: int | None) -> float | None:
    """``t_ns`` in seconds from ``t0`` (rounded to the ns), None if either is."""
    return None if t_ns is None or t0 is None else round((t_ns - t0) * 1e-9, 9)
