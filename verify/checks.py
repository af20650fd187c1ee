"""Non-temporal checks: sampled streams + scenario -> ``CheckResult`` values (verdict, worst margin, first violation).

input: pose samples (relative ns), nominal samples, inputs, scenario -> output: tube containment, input box,
workspace containment and obstacle clearance results. A failed check is a value, never an exception.

Between samples the workspace and clearance checks are conservative: a margin that is 1-Lipschitz in the position
cannot fall below ``(m_i + m_{i+1} - D) / 2`` over a gap in which the robot moves at most ``D``
(``geometry.gap_bounds``); a sample with a negative margin is a fail with evidence, a gap whose bound is negative
makes the check inconclusive. NaN samples make the checks inconclusive (unless a violation is found elsewhere).
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any

import numpy as np
import numpy.typing as npt

from tubempc.scenario import InputLimits, Scenario
from verify.geometry import gap_bounds, region_margins, step_bound_m, workspace_margin

__all__ = ["INPUT_COMPONENTS", "INPUT_TOLERANCE", "CheckResult", "check_clearance", "check_input_box", "check_tube",
           "check_workspace"]

FloatArray = npt.NDArray[np.float64]
IntArray = npt.NDArray[np.int64]

#: absolute slack on the input box (floating-point rounding of a clipped command), stated in the certificate
INPUT_TOLERANCE = 1e-9


@dataclass(frozen=True, slots=True)
class CheckResult:
    name: str
    verdict: str
    margin: float | None
    first_violation_ns: int | None
    details: dict[str, Any] = field(default_factory=dict)


def _finite_min(a: FloatArray) -> float | None:
    finite = a[np.isfinite(a)]
    return float(finite.min()) if finite.size else None


def _least(a: FloatArray) -> float:
    """A failed check's margin: the least margin over its samples, -inf included (a value that overflowed violates
    by an unbounded amount; the certificate then states a null margin with the reason), NaN ignored."""
    with np.errstate(all="ignore"):
        return float(np.nanmin(a))


def margin_check(name: str, t_ns: IntArray, margin: FloatArray, step_m: FloatArray,
                 details: dict[str, Any]) -> CheckResult:
    """Samples: fail where the margin < 0; gaps: inconclusive where the conservative bound < 0 (or data is NaN)."""
    if t_ns.size == 0:
        return CheckResult(name, "inconclusive", None, None, {**details, "reason": "no samples"})
    bad = margin < 0
    if np.any(bad):
        k = int(np.argmax(bad))
        return CheckResult(name, "fail", _least(margin), int(t_ns[k]), details)
    gaps = gap_bounds(margin, step_m)
    nan = np.isnan(margin)
    worst_gap = float(gaps.lo.min()) if gaps.lo.size else np.inf
    guaranteed = min(float(np.nanmin(margin)) if not nan.all() else -np.inf, worst_gap)
    if nan.any() or worst_gap < 0:
        why = []
        if nan.any():
            why.append(f"{int(nan.sum())} NaN sample(s)")
        if worst_gap < 0:
            k = int(np.argmin(gaps.lo))
            why.append(f"the robot may have crossed the limit between samples at {t_ns[k]} ns and {t_ns[k + 1]} ns "
                       f"(bound {worst_gap:.4f} m)")
        return CheckResult(name, "inconclusive", _finite_min(margin),
                           None, {**details, "reason": "; ".join(why), "guaranteed_margin_m": None})
    return CheckResult(name, "pass", guaranteed, None, {**details, "sample_margin_m": _finite_min(margin)})


def check_workspace(t_ns: IntArray, x_m: FloatArray, y_m: FloatArray, scenario: Scenario) -> CheckResult:
    step = step_bound_m(t_ns, x_m, y_m, scenario.max_speed_mps)
    return margin_check("workspace", t_ns, workspace_margin(x_m, y_m, scenario), step,
                        {"margin_unit": "m", "between_samples": "bounded by max(v_max * dt, step)"})


def check_clearance(t_ns: IntArray, x_m: FloatArray, y_m: FloatArray, scenario: Scenario) -> CheckResult:
    """Clearance of the robot disc from every unsafe region (metres; negative = intersecting)."""
    unsafe = [k for k, r in enumerate(scenario.regions) if r.unsafe]
    if not unsafe:
        return CheckResult("obstacle_clearance", "pass", None, None, {"reason": "no unsafe regions"})
    margins = region_margins(x_m, y_m, scenario)[unsafe]
    clearance = -np.max(margins, axis=0)  # > 0: the disc is away from every obstacle
    step = step_bound_m(t_ns, x_m, y_m, scenario.max_speed_mps)
    res = margin_check("obstacle_clearance", t_ns, clearance, step, {"margin_unit": "m"})
    if res.verdict == "fail" and res.first_violation_ns is not None:
        k = int(np.searchsorted(t_ns, res.first_violation_ns))
        res.details["region"] = scenario.regions[unsafe[int(np.argmax(margins[:, k]))]].name
    return res


def check_tube(t_ns: IntArray, x_m: FloatArray, y_m: FloatArray, nominal: tuple[IntArray, FloatArray, FloatArray]
               | None, *, radius_m: float, tolerance_m: float, match_ns: int) -> CheckResult:
    """``|p - p_hat| <= r_q + tolerance`` at every pose sample that has a nominal sample within ``match_ns``."""
    details: dict[str, Any] = {"margin_unit": "m", "radius_m": radius_m, "noise_tolerance_m": tolerance_m,
                               "checked_at": "logged samples (pose matched to the nearest nominal sample)"}
    if nominal is None or nominal[0].size == 0:
        return CheckResult("tube", "inconclusive", None, None,
                           {**details, "reason": "no nominal state logged: tube containment cannot be checked"})
    nt, nx, ny = nominal
    j = np.clip(np.searchsorted(nt, t_ns), 1, max(nt.size - 1, 1))
    j = np.where((j > 0) & (np.abs(nt[j - 1] - t_ns) <= np.abs(nt[np.minimum(j, nt.size - 1)] - t_ns)), j - 1, j)
    j = np.minimum(j, nt.size - 1)
    matched = np.abs(nt[j] - t_ns) <= match_ns
    dev = np.hypot(x_m - nx[j], y_m - ny[j])
    dev = np.where(matched, dev, np.nan)
    margin = radius_m + tolerance_m - dev
    details["matched_samples"] = int(matched.sum())
    details["unmatched_samples"] = int((~matched).sum())
    bad = margin < 0
    if np.any(bad):
        k = int(np.argmax(bad))
        return CheckResult("tube", "fail", _least(margin), int(t_ns[k]),
                           {**details, "max_deviation_m": float(np.nanmax(dev))})
    if np.isnan(margin).any():
        return CheckResult("tube", "inconclusive", _finite_min(margin), None,
                           {**details, "reason": f"{int(np.isnan(margin).sum())} pose sample(s) without a usable "
                                                 f"nominal sample or with NaN positions"})
    return CheckResult("tube", "pass", _finite_min(margin), None, {**details, "max_deviation_m": float(dev.max())})


#: the unit of each command component
COMPONENT_UNITS = {"linear.x": "m/s", "linear.y": "m/s", "angular.z": "rad/s"}
#: the component names of each input model, in the order of the bounds (``inputs.max_abs``)
INPUT_COMPONENTS = {"holonomic": ("linear.x", "linear.y", "angular.z"),
                    "unicycle": ("linear.x", "angular.z", "linear.y")}


def check_input_box(t_ns: IntArray | None, u: FloatArray | None, limits: InputLimits) -> CheckResult:
    """Each command ``(linear.x, linear.y, angular.z)`` (body frame, as logged) against the input model's box.

    holonomic: ``|u_i| <= max_abs[i]``; unicycle: ``|linear.x| <= v``, ``|angular.z| <= w`` and
    ``|linear.y| <= lateral_tolerance`` (a differential drive cannot move sideways). Margins in the component's unit
    (m/s or rad/s); the worst component is named."""
    names = INPUT_COMPONENTS[limits.model]
    if limits.model == "holonomic":
        bounds = np.asarray(limits.max_abs, dtype=np.float64)
        cols = [0, 1, 2]
    else:
        bounds = np.array([limits.max_abs[0], limits.max_abs[1], limits.lateral_tolerance], dtype=np.float64)
        cols = [0, 2, 1]
    details: dict[str, Any] = {"model": limits.model, "max_abs": list(limits.max_abs),
                               "bounds": dict(zip(names, bounds.tolist(), strict=True)),
                               "tolerance": INPUT_TOLERANCE, "frame": "body (as logged)",
                               "margin_unit": "m/s or rad/s"}
    if t_ns is None or u is None or t_ns.size == 0:
        return CheckResult("input_box", "inconclusive", None, None, {**details, "reason": "no cmd_vel logged"})
    per = bounds[None, :] + INPUT_TOLERANCE - np.abs(u[:, cols])
    unknown = np.isnan(per)
    # a command's margin is its worst known component: one unknown (NaN) component never hides a known violation
    margin = np.min(np.where(unknown, np.inf, per), axis=1)
    margin[unknown.all(axis=1)] = np.nan
    with np.errstate(all="ignore"):
        worst = np.nanmin(per, axis=0) if np.isfinite(per).any() else np.full(3, np.nan)
    details["component_margins"] = {n: (float(m) if np.isfinite(m) else None) for n, m in zip(names, worst,
                                                                                              strict=True)}
    if np.isfinite(worst).any():  # the margin is the tightest component's, in that component's unit
        tight = names[int(np.nanargmin(np.where(np.isnan(worst), np.inf, worst)))]
        details["margin_component"] = tight
        details["margin_unit"] = COMPONENT_UNITS[tight]
    bad = margin < 0
    if np.any(bad):
        k = int(np.argmax(bad))
        comp = int(np.argmin(np.where(unknown[k], np.inf, per[k])))
        return CheckResult("input_box", "fail", _least(margin), int(t_ns[k]),
                           {**details, "component": names[comp], "value": float(u[k, cols[comp]])})
    if unknown.any():
        return CheckResult("input_box", "inconclusive", _finite_min(margin), None,
                           {**details, "reason": f"{int(unknown.any(axis=1).sum())} command(s) with a NaN component"})
    return CheckResult("input_box", "pass", _finite_min(margin), None, details)
