"""The tube lemma, corrected: ancillary gain and invariant radius from the model constants.

input: Lipschitz constants L_f, L_g, the largest nominal input norm, g_min, sigma_low, delta_bar
-> output: the gain sigma of ``u = u_hat - sigma q`` and the radius r_q of the robust positively invariant ball.

The paper's proof needs ``q^T g q >= g_min |q|^2`` and ``|h| <= L |q|`` with
``h = f(e) - f(e_hat) + (g(e) - g(e_hat)) u_hat``, hence ``L = L_f + L_g * max|u_hat|`` (not ``max(L_f, L_g)``),
and ``d/dt |q|^2/2 <= -(sigma g_min - L)|q|^2 + delta_bar |q| = -sigma_low g_min |q|^2 + delta_bar |q|`` with
``sigma = L / g_min + sigma_low``: the invariant radius is ``delta_bar / (sigma_low * g_min)``. The printed bound
``delta_bar / sigma_low`` is kept (``printed_*``) only so that tests can exhibit its counterexample.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

__all__ = [
    "TubeGain",
    "corrected_tube",
    "printed_tube",
]


@dataclass(frozen=True, slots=True)
class TubeGain:
    """Ancillary gain ``sigma`` and invariant radius ``radius_m`` of ``|q| <= radius_m``, with the ``L`` used."""

    sigma: float
    radius_m: float
    lipschitz: float

    def __post_init__(self) -> None:
        if not (self.sigma > 0 and self.radius_m >= 0 and self.lipschitz >= 0):
            raise ValueError(f"invalid tube gain sigma={self.sigma!r} radius_m={self.radius_m!r}")


def _check(name: str, value: float, *, positive: bool = False) -> None:
    if not math.isfinite(value) or value < 0 or (positive and value == 0):
        kind = "positive" if positive else "non-negative"
        raise ValueError(f"{name}={value!r} must be a finite {kind} number")


def corrected_tube(*, l_f: float, l_g: float, u_hat_max: float, g_min: float, sigma_low: float,
                   delta_bar: float) -> TubeGain:
    """sigma = L/g_min + sigma_low with L = L_f + L_g*max|u_hat|; r_q = delta_bar / (sigma_low * g_min)."""
    for name, value in (("l_f", l_f), ("l_g", l_g), ("u_hat_max", u_hat_max), ("delta_bar", delta_bar)):
        _check(name, value)
    _check("g_min", g_min, positive=True)
    _check("sigma_low", sigma_low, positive=True)
    lip = l_f + l_g * u_hat_max
    return TubeGain(sigma=lip / g_min + sigma_low, radius_m=delta_bar / (sigma_low * g_min), lipschitz=lip)


def printed_tube(*, l_f: float, l_g: float, g_min: float, sigma_low: float, delta_bar: float) -> TubeGain:
    """The paper's printed lemma (L = max(L_f, L_g), r = delta_bar / sigma_low): false when g_min < 1."""
    for name, value in (("l_f", l_f), ("l_g", l_g), ("delta_bar", delta_bar)):
        _check(name, value)
    _check("g_min", g_min, positive=True)
    _check("sigma_low", sigma_low, positive=True)
    lip = max(l_f, l_g)
    return TubeGain(sigma=lip / g_min + sigma_low, radius_m=delta_bar / sigma_low, lipschitz=lip)
