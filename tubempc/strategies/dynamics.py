"""Control-affine dynamics with known L_f, L_g, g_min; nominal inputs; bounded disturbance signals."""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass
from typing import Literal

import numpy as np

from tubempc.strategies._common import FloatArray, Matrix, Vector, centi, st


def _spectral_norm(m: Matrix) -> float:
    return float(np.linalg.norm(np.array(m, dtype=float), 2)) if m else 0.0


@dataclass(frozen=True, slots=True)
class ControlAffineDynamics:
    """``x' = f(x) + g(x) u`` on R^n (n = ``dim``, square g) with stated Assumption 1-2 constants.

    ``f(x) = A x + c * sin(B x)`` with ``A`` skew-symmetric (``drift_skew``), ``c`` = ``drift_amp``,
    ``B`` = ``drift_freq`` (so ``|f(x)|`` grows at most linearly and trajectories stay bounded);
    ``g(x) = s * Rot(phi(x)) + k * diag(sin(b * x)) + W`` with ``s`` = ``gain_scale``, a rotation of the first two
    coordinates by ``phi(x) = phi_max * sin(w . x)`` (``gain_tilt_max``, ``gain_tilt_freq``; only for n >= 2),
    ``k`` = ``gain_ripple``, ``b`` = ``gain_ripple_freq`` and ``W`` skew-symmetric (``gain_skew``, no effect on the
    symmetric part). Proven constants (properties):
    ``L_f = |A| + |c| |B|``, ``L_g = s phi_max |w| + |k| max|b|`` (``|Rot(a) - Rot(b)| <= |a - b|``),
    ``g_min = s cos(phi_max) - |k|`` (lower bound of ``lambda_min(sym g(x))``; exact when ``phi_max = k = 0``).
    """

    dim: int
    gain_scale: float
    drift_skew: Matrix = ()
    drift_amp: float = 0.0
    drift_freq: Matrix = ()
    gain_tilt_max: float = 0.0
    gain_tilt_freq: Vector = ()
    gain_ripple: float = 0.0
    gain_ripple_freq: Vector = ()
    gain_skew: Matrix = ()

    def __post_init__(self) -> None:
        n = self.dim
        if n < 1:
            raise ValueError(f"dim={n!r} must be >= 1")
        for name in ("drift_skew", "drift_freq", "gain_skew"):
            m = getattr(self, name)
            if m and (len(m) != n or any(len(row) != n for row in m)):
                raise ValueError(f"{name}={m!r} must be an {n}x{n} matrix or empty")
        for name in ("drift_skew", "gain_skew"):
            m = np.array(getattr(self, name) or np.zeros((n, n)), dtype=float)
            if not np.allclose(m, -m.T, atol=0.0):
                raise ValueError(f"{name}={getattr(self, name)!r} must be skew-symmetric")
        for name in ("gain_tilt_freq", "gain_ripple_freq"):
            v = getattr(self, name)
            if v and len(v) != n:
                raise ValueError(f"{name}={v!r} must have {n} entries or be empty")
        if self.gain_tilt_max and n < 2:
            raise ValueError(f"gain_tilt_max={self.gain_tilt_max!r} needs dim >= 2")
        if not 0 <= self.gain_tilt_max < math.pi / 2:
            raise ValueError(f"gain_tilt_max={self.gain_tilt_max!r} must lie in [0, pi/2)")
        if not self.g_min > 0:
            raise ValueError(f"g_min={self.g_min!r} must be positive (gain_scale={self.gain_scale!r}, "
                             f"gain_tilt_max={self.gain_tilt_max!r}, gain_ripple={self.gain_ripple!r})")

    # -- the proven constants of Assumptions 1-2
    @property
    def l_f(self) -> float:
        return _spectral_norm(self.drift_skew) + abs(self.drift_amp) * _spectral_norm(self.drift_freq)

    @property
    def l_g(self) -> float:
        tilt = self.gain_scale * self.gain_tilt_max * float(np.linalg.norm(self.gain_tilt_freq)) \
            if self.gain_tilt_freq else 0.0
        ripple = abs(self.gain_ripple) * max((abs(b) for b in self.gain_ripple_freq), default=0.0)
        return tilt + ripple

    @property
    def g_min(self) -> float:
        return self.gain_scale * math.cos(self.gain_tilt_max) - abs(self.gain_ripple)

    @property
    def g_max(self) -> float:
        """An upper bound of ``|g(x)|_2`` over all x."""
        return self.gain_scale + abs(self.gain_ripple) + _spectral_norm(self.gain_skew)

    # -- numpy-callable model
    def f(self, x: FloatArray) -> FloatArray:
        out = np.zeros(self.dim)
        if self.drift_skew:
            out = out + np.array(self.drift_skew) @ x
        if self.drift_amp and self.drift_freq:
            out = out + self.drift_amp * np.sin(np.array(self.drift_freq) @ x)
        return out

    def g(self, x: FloatArray) -> FloatArray:
        n = self.dim
        out = self.gain_scale * np.eye(n)
        if self.gain_tilt_max and self.gain_tilt_freq:
            phi = self.gain_tilt_max * math.sin(float(np.dot(self.gain_tilt_freq, x)))
            c, s = math.cos(phi), math.sin(phi)
            out[:2, :2] = self.gain_scale * np.array([[c, -s], [s, c]])
        if self.gain_ripple and self.gain_ripple_freq:
            out = out + self.gain_ripple * np.diag(np.sin(np.array(self.gain_ripple_freq) * x))
        if self.gain_skew:
            out = out + np.array(self.gain_skew)
        return out

    def __str__(self) -> str:
        parts = []
        f_terms = []
        if self.drift_skew:
            f_terms.append(f"{self.drift_skew} x")
        if self.drift_amp and self.drift_freq:
            f_terms.append(f"{self.drift_amp} sin({self.drift_freq} x)")
        parts.append("f(x) = " + (" + ".join(f_terms) if f_terms else "0"))
        g_terms = [f"{self.gain_scale}" + (" I" if self.dim > 1 else "")]
        if self.gain_tilt_max and self.gain_tilt_freq:
            g_terms[0] += f" Rot({self.gain_tilt_max} sin({self.gain_tilt_freq} . x))"
        if self.gain_ripple and self.gain_ripple_freq:
            g_terms.append(f"{self.gain_ripple} diag(sin({self.gain_ripple_freq} x))")
        if self.gain_skew:
            g_terms.append(f"{self.gain_skew}")
        parts.append("g(x) = " + " + ".join(g_terms))
        return (f"{', '.join(parts)} on R^{self.dim} (L_f={self.l_f:.4g}, L_g={self.l_g:.4g}, "
                f"g_min={self.g_min:.4g})")


def _skew(draw: st.DrawFn, n: int, scale: float) -> Matrix:
    if n == 1 or scale == 0:
        return ()
    m = [[0.0] * n for _ in range(n)]
    for i in range(n):
        for j in range(i + 1, n):
            v = draw(centi(-scale, scale))
            m[i][j] = v
            m[j][i] = -v
    if not any(any(row) for row in m):
        return ()
    return tuple(tuple(row) for row in m)


@st.composite
def dynamics(draw: st.DrawFn, *, dims: Sequence[int] = (1, 2, 3), g_min_range: tuple[float, float] = (0.2, 1.5),
             max_l_f: float = 2.0, max_l_g: float = 1.0) -> ControlAffineDynamics:
    """Control-affine dynamics satisfying Assumptions 1-2 with ``g_min`` in ``g_min_range`` (below 1 included),
    ``L_f <= max_l_f`` and ``L_g <= max_l_g`` (stated constants proven for the family, see
    ``ControlAffineDynamics``). Shrinks towards ``f = 0`` and a constant scalar gain."""
    n = draw(st.sampled_from(list(dims)))
    g_lo, g_hi = g_min_range
    if not 0 < g_lo <= g_hi:
        raise ValueError(f"g_min_range={g_min_range!r} must satisfy 0 < lo <= hi")
    target_g_min = draw(centi(g_lo, g_hi))
    # f: skew linear part (|A| <= l_f/2) plus a sinusoid (|c| |B| <= l_f/2)
    budget_f = draw(centi(0.0, max_l_f))
    drift_skew = _skew(draw, n, budget_f / (2 * max(n - 1, 1)))
    drift_amp = 0.0
    drift_freq: Matrix = ()
    if budget_f > 0 and draw(st.booleans()):
        drift_amp = draw(centi(-1.0, 1.0))
        if drift_amp:
            freq_scale = budget_f / 2 / abs(drift_amp) / n
            drift_freq = tuple(tuple(draw(centi(-freq_scale, freq_scale)) for _ in range(n)) for _ in range(n))
    # g: scale, tilt, ripple, chosen so that the proven g_min equals target_g_min (up to rounding) and L_g fits
    budget_g = draw(centi(0.0, max_l_g))
    tilt_max = 0.0
    tilt_freq: Vector = ()
    ripple = 0.0
    ripple_freq: Vector = ()
    if n >= 2 and budget_g > 0 and draw(st.booleans()):
        tilt_max = draw(st.sampled_from([0.2, 0.5, 1.0]))
    if budget_g > 0 and draw(st.booleans()):
        ripple = draw(centi(-0.5, 0.5))
    scale = (target_g_min + abs(ripple)) / math.cos(tilt_max)
    if tilt_max:
        w_scale = budget_g / 2 / (scale * tilt_max * math.sqrt(n))
        tilt_freq = tuple(draw(centi(-w_scale, w_scale)) for _ in range(n))
        if not any(tilt_freq):
            tilt_max, tilt_freq = 0.0, ()
            scale = target_g_min + abs(ripple)
    if ripple:
        b_scale = budget_g / 2 / abs(ripple)
        ripple_freq = tuple(draw(centi(-b_scale, b_scale)) for _ in range(n))
    gain_skew = _skew(draw, n, 0.5) if draw(st.booleans()) else ()
    return ControlAffineDynamics(
        dim=n, gain_scale=scale, drift_skew=drift_skew, drift_amp=drift_amp, drift_freq=drift_freq,
        gain_tilt_max=tilt_max, gain_tilt_freq=tilt_freq, gain_ripple=ripple, gain_ripple_freq=ripple_freq,
        gain_skew=gain_skew,
    )


@dataclass(frozen=True, slots=True)
class NominalInput:
    """A smooth nominal input ``u_hat(t) = max_norm * (bias + swing * sin(omega t + phase))``.

    ``|bias| + |swing| <= 1`` (Euclidean), so ``|u_hat(t)| <= max_norm`` for all t.
    """

    max_norm: float
    bias: Vector
    swing: Vector
    omega: float = 0.0
    phase: float = 0.0

    def __post_init__(self) -> None:
        if len(self.bias) != len(self.swing):
            raise ValueError(f"bias={self.bias!r} and swing={self.swing!r} differ in length")
        total = float(np.linalg.norm(self.bias) + np.linalg.norm(self.swing))
        if total > 1 + 1e-12:
            raise ValueError(f"|bias| + |swing| = {total!r} exceeds 1")
        if not self.max_norm >= 0:
            raise ValueError(f"max_norm={self.max_norm!r} must be non-negative")

    def __call__(self, t_s: float) -> FloatArray:
        return self.max_norm * (np.array(self.bias) + np.array(self.swing) * math.sin(self.omega * t_s + self.phase))


def _ball_vector(draw: st.DrawFn, n: int, radius: float) -> Vector:
    """A vector of norm <= radius: a centimetre-grid direction scaled to a drawn fraction of the radius."""
    raw = [draw(centi(-1.0, 1.0)) for _ in range(n)]
    norm = math.sqrt(sum(v * v for v in raw))
    if norm == 0:
        return tuple(0.0 for _ in range(n))
    frac = draw(st.sampled_from([1.0, 0.5, 0.0, 0.25, 0.75]))
    return tuple(radius * frac * v / norm for v in raw)


@st.composite
def nominal_inputs(draw: st.DrawFn, dim: int, max_norm: tuple[float, float] = (0.0, 3.0)) -> NominalInput:
    """Nominal inputs of ``dim`` components with ``max |u_hat|`` drawn in ``max_norm`` (above 1 included)."""
    bound = draw(centi(*max_norm))
    share = draw(st.sampled_from([1.0, 0.5, 0.0]))
    bias = _ball_vector(draw, dim, share)
    swing = _ball_vector(draw, dim, 1.0 - share)
    return NominalInput(max_norm=bound, bias=bias, swing=swing, omega=draw(centi(0.0, 3.0)),
                        phase=draw(centi(0.0, 3.14)))


DisturbanceKind = Literal["random", "adversarial", "switching", "constant"]


@dataclass(frozen=True, slots=True)
class DisturbanceSignal:
    """A disturbance ``delta(t, q)`` with ``|delta| <= bound`` everywhere.

    - ``adversarial``: ``bound * q/|q|`` (pushes the tube error outward; ``knots[0]`` direction when q = 0);
    - ``random``: piecewise constant, ``knots[k % len(knots)]`` on ``[k period_s, (k+1) period_s)``;
    - ``switching``: alternates every ``period_s`` between the adversarial push and the next knot;
    - ``constant``: ``knots[0]`` always (a bias).
    Knots have norm <= bound. ``breakpoints`` lists where the signal may jump (integrators should step there).
    """

    kind: DisturbanceKind
    bound: float
    knots: tuple[Vector, ...]
    period_s: float = 1.0

    def __post_init__(self) -> None:
        if not self.knots:
            raise ValueError("knots must not be empty")
        if not (math.isfinite(self.bound) and self.bound >= 0):
            raise ValueError(f"bound={self.bound!r} must be a finite non-negative number")
        for k in self.knots:
            if float(np.linalg.norm(k)) > self.bound * (1 + 1e-12):
                raise ValueError(f"knot {k!r} exceeds bound={self.bound!r}")
        if not self.period_s > 0:
            raise ValueError(f"period_s={self.period_s!r} must be positive")

    @property
    def dim(self) -> int:
        return len(self.knots[0])

    def _outward(self, q: FloatArray) -> FloatArray:
        norm = float(np.linalg.norm(q))
        if norm > 0:
            return self.bound * q / norm
        d = np.array(self.knots[0], dtype=float)
        dn = float(np.linalg.norm(d))
        if dn == 0:
            d = np.zeros(self.dim)
            d[0] = 1.0
            dn = 1.0
        return self.bound * d / dn

    def __call__(self, t_s: float, q: FloatArray) -> FloatArray:
        k = math.floor(t_s / self.period_s + 1e-9)
        if self.kind == "adversarial":
            return self._outward(q)
        if self.kind == "constant":
            return np.array(self.knots[0], dtype=float)
        if self.kind == "switching" and k % 2 == 0:
            return self._outward(q)
        return np.array(self.knots[k % len(self.knots)], dtype=float)

    def breakpoints(self, horizon_s: float) -> list[float]:
        """Times in (0, horizon_s) where the signal may jump (multiples of ``period_s`` unless constant)."""
        if self.kind in ("adversarial", "constant"):
            return []
        return [k * self.period_s for k in range(1, math.ceil(horizon_s / self.period_s)) if
                k * self.period_s < horizon_s]


@st.composite
def disturbances(draw: st.DrawFn, dim: int, bound: tuple[float, float] = (0.0, 0.2),
                 kinds: Sequence[DisturbanceKind] = ("adversarial", "random", "switching", "constant"),
                 ) -> DisturbanceSignal:
    """Bounded disturbance signals of ``dim`` components with ``delta_bar`` drawn in ``bound``."""
    kind = draw(st.sampled_from(list(kinds)))
    delta_bar = draw(centi(*bound))
    n_knots = draw(st.integers(1, 4))
    knots = tuple(_ball_vector(draw, dim, delta_bar) for _ in range(n_knots))
    return DisturbanceSignal(kind=kind, bound=delta_bar, knots=knots,
                             period_s=draw(st.sampled_from([0.25, 0.5, 1.0, 2.0])))
