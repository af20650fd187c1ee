"""Disturbance models for the closed-loop simulation, all seeded from an explicit generator.

input: a model name, the bound delta_bar and a ``numpy.random.Generator`` -> output: a frozen ``Disturbance``
whose ``sample(t_s, q)`` gives ``delta`` with ``|delta|_2 <= delta_bar`` (held over one MoCap sample), and whose
``params`` (JSON-ready) go into the log's metadata.

- ``none``: 0;  ``random``: uniform in the ball of radius delta_bar, drawn at every sample;
- ``worst``: ``delta_bar q / |q|`` (pushes the tube error outward; a fixed random direction while q = 0);
- ``bias``: a constant vector of norm delta_bar in a random direction;
- ``sine``: ``delta_bar sin(2 pi f t + phase) d`` with a random unit direction d and phase, f = 0.2 Hz.

The closed loop takes any ``DisturbanceLike`` (these models, or signals built elsewhere, e.g. by the falsifier):
``batch(t)`` for the state-independent part and ``worst_at(t)`` for the MPC steps on which the disturbance is the
outward push ``delta_bar q/|q|`` (decided per MPC step, at its start time).
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import Any, Protocol

import numpy as np

from tubempc.errors import InvalidArgumentError

__all__ = ["DISTURBANCE_MODELS", "Disturbance", "DisturbanceLike", "InvalidArgumentError", "make_disturbance"]

DISTURBANCE_MODELS = ("none", "random", "worst", "bias", "sine")
_SINE_FREQUENCY_HZ = 0.2


class DisturbanceLike(Protocol):
    """What the closed loop needs from a disturbance: ``|delta|_2 <= bound`` at every sample."""

    @property
    def kind(self) -> str: ...

    @property
    def bound(self) -> float: ...

    @property
    def direction(self) -> np.ndarray: ...  # the outward push's direction while q = 0

    @property
    def params(self) -> dict[str, Any]: ...

    @property
    def may_be_worst(self) -> bool: ...  # worst_at(t) is true for some t

    def worst_at(self, t_s: float) -> bool: ...

    def batch(self, t_s: np.ndarray) -> np.ndarray: ...


def _unit(rng: np.random.Generator, dim: int) -> np.ndarray:
    v = rng.normal(size=dim)
    return np.asarray(v / np.linalg.norm(v), dtype=float)


@dataclass(frozen=True)
class Disturbance:
    kind: str
    bound: float
    direction: np.ndarray
    phase_rad: float
    rng: np.random.Generator = field(repr=False, compare=False)

    @property
    def may_be_worst(self) -> bool:
        return self.kind == "worst"

    def worst_at(self, t_s: float) -> bool:
        """True when the disturbance is the outward push ``delta_bar q/|q|`` (for ``worst``: always)."""
        return self.kind == "worst"

    def sample(self, t_s: float, q: np.ndarray) -> np.ndarray:
        dim = len(self.direction)
        if self.kind == "none" or self.bound == 0:
            return np.zeros(dim, dtype=float)
        if self.kind == "random":
            radius = self.bound * float(self.rng.uniform()) ** (1.0 / dim)
            out: np.ndarray = radius * _unit(self.rng, dim)
            return out
        if self.kind == "worst":
            norm = float(np.linalg.norm(q))
            return self.bound * (q / norm if norm > 1e-15 else self.direction)
        if self.kind == "bias":
            return self.bound * self.direction
        return self.bound * math.sin(2 * math.pi * _SINE_FREQUENCY_HZ * t_s + self.phase_rad) * self.direction

    def batch(self, t_s: np.ndarray) -> np.ndarray:
        """Samples (len(t_s) x dim) of a state-independent model (every model but ``worst``)."""
        n, dim = len(t_s), len(self.direction)
        if self.kind == "worst":
            raise InvalidArgumentError("disturbance 'worst' depends on the state: use sample(t_s, q)")
        if self.kind == "none" or self.bound == 0:
            return np.zeros((n, dim))
        if self.kind == "random":
            radius = self.bound * self.rng.uniform(size=n) ** (1.0 / dim)
            dirs = self.rng.normal(size=(n, dim))
            out: np.ndarray = radius[:, None] * dirs / np.linalg.norm(dirs, axis=1, keepdims=True)
            return out
        if self.kind == "bias":
            return np.tile(self.bound * self.direction, (n, 1))
        wave = self.bound * np.sin(2 * math.pi * _SINE_FREQUENCY_HZ * np.asarray(t_s) + self.phase_rad)
        sine: np.ndarray = wave[:, None] * self.direction[None, :]
        return sine

    @property
    def params(self) -> dict[str, Any]:
        out: dict[str, Any] = {"model": self.kind, "bound": self.bound}
        if self.kind in ("worst", "bias", "sine"):
            out["direction"] = [float(v) for v in self.direction]
        if self.kind == "sine":
            out["frequency_hz"] = _SINE_FREQUENCY_HZ
            out["phase_rad"] = self.phase_rad
        return out


def make_disturbance(kind: str, bound: float, rng: np.random.Generator, dim: int = 3) -> Disturbance:
    """A disturbance model by name (one of ``DISTURBANCE_MODELS``)."""
    if kind not in DISTURBANCE_MODELS:
        raise InvalidArgumentError(f"disturbance={kind!r} is not one of {', '.join(DISTURBANCE_MODELS)}")
    if not (math.isfinite(bound) and bound >= 0):
        raise InvalidArgumentError(f"disturbance bound={bound!r} must be a finite non-negative number")
    direction = _unit(rng, dim)
    phase = float(rng.uniform(0, 2 * math.pi))
    return Disturbance(kind=kind, bound=bound, direction=direction, phase_rad=phase, rng=rng)
