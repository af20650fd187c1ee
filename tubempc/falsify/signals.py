"""Disturbance signals the falsifier searches over: parameters -> a ``DisturbanceLike`` the closed loop runs with.

input: the family's parameters (already scaled into the bound) -> output: a frozen signal with ``|delta|_2 <= bound``
at every sample, ``batch(t)`` for its state-independent part and ``worst_at(t)`` for the MPC steps on which it is the
outward push ``bound q/|q|``.

- ``StepSignal``: piecewise constant, ``k`` knots (one 3-vector each) on equal segments of ``[0, horizon_s)``;
- ``SineSignal``: one sinusoid per axis (amplitude, frequency, phase), projected into the ball where the sum of the
  three exceeds the bound;
- ``SwitchSignal``: the worst-case direction with switching times: on alternate intervals between the switching
  times (multiples of the MPC step h) the outward push ``bound q/|q|``, on the others a constant vector.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any

import numpy as np

__all__ = ["SineSignal", "StepSignal", "SwitchSignal", "into_ball"]

_STATE_DIM = 3


def into_ball(v: np.ndarray, bound: float) -> np.ndarray:
    """Rows of ``v`` scaled down (never up) onto the ball of radius ``bound``."""
    v = np.asarray(v, dtype=float)
    norm = np.linalg.norm(v, axis=-1, keepdims=True)
    scale = np.where(norm > bound, bound / np.where(norm > 0, norm, 1.0), 1.0)
    out: np.ndarray = v * scale
    return out


def _unit_or_x(v: np.ndarray) -> np.ndarray:
    n = float(np.linalg.norm(v))
    if n > 0:
        return np.asarray(v, dtype=float) / n
    return np.array([1.0, 0.0, 0.0])


def _check(bound: float, values: np.ndarray, what: str) -> None:
    if not (math.isfinite(bound) and bound >= 0):
        raise ValueError(f"bound={bound!r} must be a finite non-negative number")
    if values.ndim != 2 or values.shape[1] != _STATE_DIM or not np.isfinite(values).all():
        raise ValueError(f"{what} must be finite rows of {_STATE_DIM} components, got shape {values.shape}")
    if values.size and float(np.max(np.linalg.norm(values, axis=1))) > bound * (1 + 1e-12):
        raise ValueError(f"{what} exceed bound={bound!r}")


@dataclass(frozen=True, eq=False)
class StepSignal:
    """``values[j]`` on ``[j T/k, (j+1) T/k)`` (T = ``horizon_s``); the last value holds after T."""

    bound: float
    values: np.ndarray  # k x 3, each of norm <= bound
    horizon_s: float

    def __post_init__(self) -> None:
        _check(self.bound, self.values, "values")
        if not (math.isfinite(self.horizon_s) and self.horizon_s > 0) or len(self.values) == 0:
            raise ValueError(f"horizon_s={self.horizon_s!r} must be positive and values non-empty")

    @property
    def kind(self) -> str:
        return "falsify-steps"

    @property
    def direction(self) -> np.ndarray:
        return _unit_or_x(self.values[0])

    @property
    def may_be_worst(self) -> bool:
        return False

    def worst_at(self, t_s: float) -> bool:
        return False

    def batch(self, t_s: np.ndarray) -> np.ndarray:
        k = len(self.values)
        idx = np.clip(np.floor(np.asarray(t_s, dtype=float) * k / self.horizon_s + 1e-9).astype(int), 0, k - 1)
        out: np.ndarray = self.values[idx]
        return out

    @property
    def params(self) -> dict[str, Any]:
        return {"model": self.kind, "bound": self.bound, "horizon_s": self.horizon_s,
                "segment_s": self.horizon_s / len(self.values), "values": self.values.tolist()}


@dataclass(frozen=True, eq=False)
class SineSignal:
    """``delta_i(t) = amplitude_i sin(2 pi frequency_i t + phase_i)``, projected into the ball of ``bound``."""

    bound: float
    amplitude: np.ndarray  # 3
    frequency_hz: np.ndarray  # 3
    phase_rad: np.ndarray  # 3

    def __post_init__(self) -> None:
        for name in ("amplitude", "frequency_hz", "phase_rad"):
            a = getattr(self, name)
            if a.shape != (_STATE_DIM,) or not np.isfinite(a).all():
                raise ValueError(f"{name} must be {_STATE_DIM} finite numbers, got {a!r}")
        if not (math.isfinite(self.bound) and self.bound >= 0) or np.any(np.abs(self.amplitude) > self.bound):
            raise ValueError(f"amplitudes {self.amplitude.tolist()} must lie within bound={self.bound!r}")

    @property
    def kind(self) -> str:
        return "falsify-sine"

    @property
    def direction(self) -> np.ndarray:
        return _unit_or_x(self.amplitude)

    @property
    def may_be_worst(self) -> bool:
        return False

    def worst_at(self, t_s: float) -> bool:
        return False

    def batch(self, t_s: np.ndarray) -> np.ndarray:
        t = np.asarray(t_s, dtype=float)[:, None]
        raw = self.amplitude[None, :] * np.sin(2 * math.pi * self.frequency_hz[None, :] * t + self.phase_rad[None, :])
        return into_ball(raw, self.bound)

    @property
    def params(self) -> dict[str, Any]:
        return {"model": self.kind, "bound": self.bound, "amplitude": self.amplitude.tolist(),
                "frequency_hz": self.frequency_hz.tolist(), "phase_rad": self.phase_rad.tolist()}


@dataclass(frozen=True, eq=False)
class SwitchSignal:
    """Intervals ``[s_j, s_{j+1})`` between the switching times (``s_0 = 0``): the outward push ``bound q/|q|`` on
    every other interval (the first one when ``first_outward``), ``values[j]`` on the rest."""

    bound: float
    switch_s: tuple[float, ...]  # sorted, multiples of the MPC step
    first_outward: bool
    values: np.ndarray  # (len(switch_s) + 1) x 3

    def __post_init__(self) -> None:
        _check(self.bound, self.values, "values")
        if len(self.values) != len(self.switch_s) + 1:
            raise ValueError(f"{len(self.switch_s)} switching times need {len(self.switch_s) + 1} values, got "
                             f"{len(self.values)}")
        if any(b < a for a, b in zip(self.switch_s, self.switch_s[1:], strict=False)):
            raise ValueError(f"switch_s={self.switch_s!r} must be sorted")

    @property
    def kind(self) -> str:
        return "falsify-switch"

    @property
    def direction(self) -> np.ndarray:
        return _unit_or_x(self.values[0])

    @property
    def may_be_worst(self) -> bool:
        return True

    def _interval(self, t_s: np.ndarray) -> np.ndarray:
        out: np.ndarray = np.searchsorted(np.asarray(self.switch_s, dtype=float), np.asarray(t_s) + 1e-9,
                                          side="right")
        return out

    def worst_at(self, t_s: float) -> bool:
        j = int(self._interval(np.array([t_s]))[0])
        return (j % 2 == 0) == self.first_outward

    def batch(self, t_s: np.ndarray) -> np.ndarray:
        out: np.ndarray = self.values[self._interval(t_s)]
        return out

    @property
    def params(self) -> dict[str, Any]:
        return {"model": self.kind, "bound": self.bound, "switch_s": list(self.switch_s),
                "first_outward": self.first_outward, "values": self.values.tolist()}
