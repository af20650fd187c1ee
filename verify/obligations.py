"""Formula + trajectory -> one verdict and one margin signal per top-level obligation, for the reports.

input: the certificate's formula text, the trajectory table (``t_s``, ``x_m``, ``y_m``), the scenario and the speed
bound -> output: a tuple of ``Obligation`` values, one per top-level conjunct of the formula.

A formula such as ``G !obs & F[30,50] mission_2 & F[80,110] mission_1`` is a list of obligations, each with its own
window. One robustness curve for the whole formula hides which of them failed and when (an unbounded window that
reaches past the log end makes the whole curve undecided). Here every conjunct is judged on its own under the
trajectory semantics (``verify.semantics.trajectory``), and the signal drawn is the margin of its *body* at every
sample: the sub-formula the temporal operator asks about (``mission_2`` for ``F[30,50] mission_2``: metres to go into
the region, negative outside), with the window in which it counts. A missed window then reads as what it is: a curve
that turns positive only after the shaded span closes.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
import numpy.typing as npt
import pandas as pd

from tubempc.mitl import Always, And, Eventually, Formula, SpecSyntaxError, Until, parse
from tubempc.scenario import Scenario
from verify.semantics.trajectory import check_trajectory

__all__ = ["Obligation", "obligations_of", "split_obligations"]

FloatArray = npt.NDArray[np.float64]


@dataclass(frozen=True, slots=True)
class Obligation:
    """One top-level conjunct: its text, its verdict at time 0, its window and the margin signal of its body."""

    formula: str
    verdict: str
    margin_m: float | None  # guaranteed margin of the conjunct at time 0 (None: undecided)
    violation_s: float | None  # the witness time of a fail (seconds from time 0)
    subformula: str | None  # the sub-formula the witness names
    reason: str | None  # why it failed or could not be decided
    body: str  # what the signal measures
    window_s: tuple[float, float] | None  # [lo, hi] in seconds from time 0 (hi may be inf); None: at time 0 only
    t_s: FloatArray
    body_margin_m: FloatArray


def split_obligations(formula: Formula) -> tuple[Formula, ...]:
    """The top-level conjuncts (the formula itself when it is not a conjunction)."""
    return formula.args if isinstance(formula, And) else (formula,)


def _body_and_window(f: Formula) -> tuple[Formula, tuple[float, float] | None]:
    if isinstance(f, Eventually | Always):
        return f.arg, (f.interval.lo_s, f.interval.hi_s)
    if isinstance(f, Until):
        return f.right, (f.interval.lo_s, f.interval.hi_s)
    return f, None


def obligations_of(formula_text: str, trajectory: pd.DataFrame, scenario: Scenario, *,
                   max_speed_mps: float) -> tuple[Obligation, ...]:
    """Judge every top-level conjunct of ``formula_text`` on ``trajectory`` (empty when either is unusable)."""
    try:
        formula = parse(formula_text)
    except SpecSyntaxError:
        return ()
    if not {"t_s", "x_m", "y_m"} <= set(trajectory.columns) or len(trajectory) == 0:
        return ()
    t_ns = np.rint(trajectory["t_s"].to_numpy(dtype=float) * 1e9).astype(np.int64)
    keep = np.concatenate(([True], np.diff(t_ns) > 0))  # the checker needs strictly increasing stamps
    if not keep.all() and not bool(np.all(np.diff(t_ns[keep]) > 0)):
        return ()
    t_ns = t_ns[keep]
    x_m = trajectory["x_m"].to_numpy(dtype=float)[keep]
    y_m = trajectory["y_m"].to_numpy(dtype=float)[keep]
    out: list[Obligation] = []
    for conjunct in split_obligations(formula):
        whole = check_trajectory(conjunct, t_ns, x_m, y_m, scenario, max_speed_mps=max_speed_mps)
        body, window = _body_and_window(conjunct)
        signal = check_trajectory(body, t_ns, x_m, y_m, scenario, max_speed_mps=max_speed_mps)
        margin = whole.margin_m if whole.verdict != "inconclusive" and math.isfinite(whole.margin_m) else None
        out.append(Obligation(
            formula=str(conjunct), verdict=whole.verdict, margin_m=margin,
            violation_s=whole.time_ns * 1e-9 if whole.verdict == "fail" and whole.time_ns is not None else None,
            subformula=whole.subformula, reason=whole.reason, body=str(body), window_s=window,
            t_s=signal.signal_t_ns.astype(np.float64) * 1e-9, body_margin_m=signal.signal_rho_m.astype(np.float64)))
    return tuple(out)
