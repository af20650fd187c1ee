"""Public hypothesis strategies for users' own property tests.

input: size limits and ranges -> output: hypothesis ``SearchStrategy`` objects that draw frozen values:

- ``formulas``, ``intervals``, ``atom_names``: MITL formulas of bounded depth (every operator of the grammar);
- ``scenarios``: workspaces with non-overlapping circular regions in a box (some unsafe) and a robot radius that
  fits, as validated ``tubempc.scenario.Scenario`` values;
- ``dynamics``: control-affine models ``x' = f(x) + g(x) u`` satisfying Assumptions 1-2 with known ``L_f``,
  ``L_g``, ``g_min`` (``g_min < 1`` included) as ``ControlAffineDynamics``; ``nominal_inputs`` (``|u_hat|`` up to
  a chosen bound, > 1 included) and ``disturbances`` (random, adversarial ``delta_bar q/|q|``, switching, constant);
- ``label_maps`` and ``timed_runs``: finite timed runs ``(region, time)`` over a label map, exact rational times;
- ``trajectories``: sampled poses at a fixed rate with a bounded speed;
- ``log_faults``: a description of damage to a log (truncation, dropped samples, reordering, NaN, zero quaternion,
  missing topic) and ``apply_sample_fault`` to apply the sample-level ones to arrays.

Import as ``from tubempc import strategies``. Every value is frozen and prints readably, so a shrunk counterexample
can be pasted into ``@example(...)``.
"""

from __future__ import annotations

import itertools
import math
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field
from fractions import Fraction
from typing import Any, Literal

import numpy as np
import numpy.typing as npt

try:
    from hypothesis import strategies as st
except ImportError:  # hypothesis comes with the 'testing' extra: one error naming it (exit 4)
    from verify.errors import MissingExtraError
    from verify.extras import require

    try:
        require("testing", feature="tubempc.strategies")
    except MissingExtraError as missing:
        raise missing from None
    raise

from tubempc.mitl import (
    FALSE,
    TRUE,
    Always,
    And,
    Atom,
    Eventually,
    Formula,
    Implies,
    Interval,
    Next,
    Not,
    Or,
    Until,
)
from tubempc.scenario import Scenario, scenario_from_dict

__all__ = [
    "FAULT_KINDS",
    "STAMP_FAULTS",
    "ControlAffineDynamics",
    "DisturbanceSignal",
    "LogFault",
    "NominalInput",
    "TimedRun",
    "Trajectory",
    "apply_sample_fault",
    "atom_names",
    "disturbances",
    "dynamics",
    "formulas",
    "intervals",
    "label_maps",
    "log_faults",
    "nominal_inputs",
    "robot_radii",
    "scenarios",
    "timed_runs",
    "trajectories",
]

FloatArray = npt.NDArray[np.float64]
Matrix = tuple[tuple[float, ...], ...]
Vector = tuple[float, ...]


# ---------------------------------------------------------------------------------------------------- MITL
def atom_names(pool: tuple[str, ...] = ("p", "q", "r", "obs_1", "mission_1")) -> st.SearchStrategy[str]:
    """Atomic proposition names drawn from ``pool``."""
    return st.sampled_from(pool)


@st.composite
def intervals(draw: st.DrawFn, max_s: int = 60, quantum: Fraction = Fraction(1, 2),
              allow_unbounded: bool = True) -> Interval:
    """Non-empty intervals with endpoints on a grid of ``quantum`` seconds, open or closed, maybe unbounded."""
    steps = int(max_s / quantum)
    lo = draw(st.integers(0, steps)) * quantum
    lo_closed = draw(st.booleans())
    if allow_unbounded and draw(st.integers(0, 3)) == 0:
        return Interval(lo, None, lo_closed, False)
    hi = lo + draw(st.integers(0, steps)) * quantum
    if hi == lo:
        return Interval(lo, hi, True, True)
    return Interval(lo, hi, lo_closed, draw(st.booleans()))


def formulas(atoms: st.SearchStrategy[str] | None = None, max_depth: int = 4,
             interval_strategy: st.SearchStrategy[Interval] | None = None,
             temporal: bool = True) -> st.SearchStrategy[Formula]:
    """MITL formulas of depth at most ``max_depth`` over ``atoms``, using every operator of the grammar."""
    names = atoms if atoms is not None else atom_names()
    ivs = interval_strategy if interval_strategy is not None else intervals()
    leaves: st.SearchStrategy[Formula] = st.one_of(names.map(Atom), st.sampled_from([TRUE, FALSE]))

    def extend(children: st.SearchStrategy[Formula]) -> st.SearchStrategy[Formula]:
        options: list[st.SearchStrategy[Formula]] = [
            children.map(Not),
            st.lists(children, min_size=2, max_size=3).map(lambda xs: And(tuple(xs))),
            st.lists(children, min_size=2, max_size=3).map(lambda xs: Or(tuple(xs))),
            st.builds(Implies, children, children),
        ]
        if temporal:
            options += [
                st.builds(Next, ivs, children),
                st.builds(Eventually, ivs, children),
                st.builds(Always, ivs, children),
                st.builds(Until, ivs, children, children),
            ]
        return st.one_of(options)

    return st.recursive(leaves, extend, max_leaves=2 ** max_depth)


# ---------------------------------------------------------------------------------------------------- workspaces
def _centi(lo: float, hi: float) -> st.SearchStrategy[float]:
    """Floats on a 1 cm grid in [lo, hi]: short reprs that paste well into ``@example``."""
    return st.integers(math.ceil(lo * 100 - 1e-9), math.floor(hi * 100 + 1e-9)).map(lambda k: k / 100)


def robot_radii(max_radius_m: float, min_radius_m: float = 0.05) -> st.SearchStrategy[float]:
    """Robot disc radii ``eta`` in [min_radius_m, max_radius_m) on a 1 cm grid (strictly below the maximum)."""
    if not 0 < min_radius_m < max_radius_m:
        raise ValueError(f"min_radius_m={min_radius_m!r} must lie in (0, max_radius_m={max_radius_m!r})")
    return _centi(min_radius_m, max_radius_m - 0.01).filter(lambda r: r < max_radius_m)


@st.composite
def scenarios(draw: st.DrawFn, *, min_regions: int = 2, max_regions: int = 6, max_unsafe: int = 3,
              cell_m: float = 1.2, grid: tuple[int, int] = (4, 4), region_radius_m: tuple[float, float] = (0.3, 0.5),
              delta_bar: tuple[float, float] = (0.0, 0.03), spec: st.SearchStrategy[str] | None = None,
              room_m: float = 0.15, models: Sequence[Literal["world", "body"]] = ("world",),
              ) -> Scenario:
    """Scenarios with ``min_regions..max_regions`` non-overlapping circular regions in a box, some unsafe.

    The box is a ``grid`` of square cells of side ``cell_m``; each region sits in its own cell (distinct cells,
    jittered centre), so regions never overlap and always fit. At least one region is safe (the initial one), at
    most ``max_unsafe`` are unsafe; safe region ``k`` carries label ``mission_k``, unsafe region ``k`` label
    ``obs_k``. The robot radius is at most the smallest safe region's radius minus ``room_m``, and minus the
    terminal ball plus the tube radius of the drawn disturbance bound, ``sigma_low`` and model (so that the
    controller's design check passes unless ``region_radius_m`` is too small for that; ``room_m=0`` allows any
    radius that fits). ``models`` lists the dynamics models to draw from (``body`` gets a heading restriction in
    [0.3, 1.2] rad). ``spec`` draws the MITL text (it may only use those labels); by default: always avoid every
    obstacle and eventually visit ``mission_1``.
    The value is built through ``scenario_from_dict``, so the scenario model's own validation applies.
    """
    nx, ny = grid
    if not 1 <= min_regions <= max_regions <= nx * ny:
        raise ValueError(f"need 1 <= min_regions={min_regions} <= max_regions={max_regions} <= {nx * ny} cells")
    r_lo, r_hi = region_radius_m
    if not 0 < r_lo <= r_hi < cell_m / 2:
        raise ValueError(f"region_radius_m={region_radius_m!r} must satisfy 0 < lo <= hi < cell_m/2={cell_m / 2}")
    cells = draw(st.lists(st.tuples(st.integers(0, nx - 1), st.integers(0, ny - 1)), min_size=min_regions,
                          max_size=max_regions, unique=True))
    n_unsafe = draw(st.integers(0, min(max_unsafe, len(cells) - 1)))
    x0 = -nx * cell_m / 2
    y0 = -ny * cell_m / 2
    regions: list[dict[str, Any]] = []
    n_safe = 0
    n_obs = 0
    for i, (cx, cy) in enumerate(cells):
        radius = draw(_centi(r_lo, r_hi))
        slack = cell_m / 2 - radius
        jx = draw(_centi(-slack, slack))
        jy = draw(_centi(-slack, slack))
        unsafe = i >= len(cells) - n_unsafe
        if unsafe:
            n_obs += 1
            labels = [f"obs_{n_obs}"]
        else:
            n_safe += 1
            labels = [f"mission_{n_safe}"]
        regions.append({
            "name": f"R{i + 1}",
            "center": [round(x0 + (cx + 0.5) * cell_m + jx, 6), round(y0 + (cy + 0.5) * cell_m + jy, 6)],
            "radius": radius, "labels": labels, "unsafe": unsafe,
        })
    bound = draw(_centi(*delta_bar))
    sigma_low = draw(st.sampled_from([1.0, 2.0, 4.0]))
    model = draw(st.sampled_from(list(models)))
    theta_max = draw(_centi(0.3, 1.2)) if model == "body" else None
    g_min = math.cos(theta_max) if theta_max is not None else 1.0
    # room for the terminal ball eps/sqrt(min P) = 0.07/sqrt(0.5) and the tube radius of the drawn parameters
    need = 0.07 / math.sqrt(0.5) + bound / (sigma_low * g_min) + 0.005
    room = max(room_m, need) if room_m > 0 else 0.0
    smallest_safe = min(r["radius"] for r in regions if not r["unsafe"])
    eta = draw(robot_radii(max(min(smallest_safe - room, 0.35), 0.06)))
    obstacles = [f"obs_{k}" for k in range(1, n_obs + 1)]
    if spec is None:
        avoid = f"G[0,inf) !({' | '.join(obstacles)}) & " if obstacles else ""
        text = f"{avoid}F[0,inf) mission_1"
    else:
        text = draw(spec)
    data: dict[str, Any] = {
        "name": "hypothesis",
        "workspace": {"x": [x0, -x0], "y": [y0, -y0]},
        "robot": {"radius": eta},
        "inputs": {"max_abs": [0.2, 0.2, 0.2]},
        "disturbance": {"bound": bound},
        "tube": {"sigma_low": sigma_low},
        "mpc": {"h": 0.1, "horizon": 1.2, "Q": [0.5, 0.5, 0.5], "R": [0.5, 0.5, 0.5], "P": [0.5, 0.5, 0.5],
                "eps": 0.07},
        "regions": regions,
        "initial_region": "R1",
        "spec": text,
    }
    if theta_max is not None:
        data["dynamics"] = {"model": "body", "theta_max": theta_max}
    return scenario_from_dict(data, source="<tubempc.strategies.scenarios>")


# ---------------------------------------------------------------------------------------------------- dynamics
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
            v = draw(_centi(-scale, scale))
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
    target_g_min = draw(_centi(g_lo, g_hi))
    # f: skew linear part (|A| <= l_f/2) plus a sinusoid (|c| |B| <= l_f/2)
    budget_f = draw(_centi(0.0, max_l_f))
    drift_skew = _skew(draw, n, budget_f / (2 * max(n - 1, 1)))
    drift_amp = 0.0
    drift_freq: Matrix = ()
    if budget_f > 0 and draw(st.booleans()):
        drift_amp = draw(_centi(-1.0, 1.0))
        if drift_amp:
            freq_scale = budget_f / 2 / abs(drift_amp) / n
            drift_freq = tuple(tuple(draw(_centi(-freq_scale, freq_scale)) for _ in range(n)) for _ in range(n))
    # g: scale, tilt, ripple, chosen so that the proven g_min equals target_g_min (up to rounding) and L_g fits
    budget_g = draw(_centi(0.0, max_l_g))
    tilt_max = 0.0
    tilt_freq: Vector = ()
    ripple = 0.0
    ripple_freq: Vector = ()
    if n >= 2 and budget_g > 0 and draw(st.booleans()):
        tilt_max = draw(st.sampled_from([0.2, 0.5, 1.0]))
    if budget_g > 0 and draw(st.booleans()):
        ripple = draw(_centi(-0.5, 0.5))
    scale = (target_g_min + abs(ripple)) / math.cos(tilt_max)
    if tilt_max:
        w_scale = budget_g / 2 / (scale * tilt_max * math.sqrt(n))
        tilt_freq = tuple(draw(_centi(-w_scale, w_scale)) for _ in range(n))
        if not any(tilt_freq):
            tilt_max, tilt_freq = 0.0, ()
            scale = target_g_min + abs(ripple)
    if ripple:
        b_scale = budget_g / 2 / abs(ripple)
        ripple_freq = tuple(draw(_centi(-b_scale, b_scale)) for _ in range(n))
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
    raw = [draw(_centi(-1.0, 1.0)) for _ in range(n)]
    norm = math.sqrt(sum(v * v for v in raw))
    if norm == 0:
        return tuple(0.0 for _ in range(n))
    frac = draw(st.sampled_from([1.0, 0.5, 0.0, 0.25, 0.75]))
    return tuple(radius * frac * v / norm for v in raw)


@st.composite
def nominal_inputs(draw: st.DrawFn, dim: int, max_norm: tuple[float, float] = (0.0, 3.0)) -> NominalInput:
    """Nominal inputs of ``dim`` components with ``max |u_hat|`` drawn in ``max_norm`` (above 1 included)."""
    bound = draw(_centi(*max_norm))
    share = draw(st.sampled_from([1.0, 0.5, 0.0]))
    bias = _ball_vector(draw, dim, share)
    swing = _ball_vector(draw, dim, 1.0 - share)
    return NominalInput(max_norm=bound, bias=bias, swing=swing, omega=draw(_centi(0.0, 3.0)),
                        phase=draw(_centi(0.0, 3.14)))


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
    delta_bar = draw(_centi(*bound))
    n_knots = draw(st.integers(1, 4))
    knots = tuple(_ball_vector(draw, dim, delta_bar) for _ in range(n_knots))
    return DisturbanceSignal(kind=kind, bound=delta_bar, knots=knots,
                             period_s=draw(st.sampled_from([0.25, 0.5, 1.0, 2.0])))


# ---------------------------------------------------------------------------------------------------- timed runs
@st.composite
def label_maps(draw: st.DrawFn, *, max_regions: int = 4, atoms: tuple[str, ...] = ("p", "q", "r"),
               min_regions: int = 1) -> dict[str, tuple[str, ...]]:
    """``{region name: labels}`` for min_regions..max_regions regions ``R1, R2, ...`` with labels from ``atoms``."""
    if not 1 <= min_regions <= max_regions:
        raise ValueError(f"need 1 <= min_regions={min_regions} <= max_regions={max_regions}")
    n = draw(st.integers(min_regions, max_regions))
    return {f"R{i + 1}": tuple(sorted(draw(st.sets(st.sampled_from(atoms), max_size=len(atoms)))))
            for i in range(n)}


@dataclass(frozen=True, slots=True)
class TimedRun:
    """A finite timed run: ``entries`` = ((region, time), ...) with exact, non-decreasing times from 0."""

    entries: tuple[tuple[str, Fraction], ...]
    labels: Mapping[str, tuple[str, ...]] = field(hash=False)

    def __post_init__(self) -> None:
        if not self.entries:
            raise ValueError("a timed run needs at least one entry")
        if self.entries[0][1] != 0:
            raise ValueError(f"the first entry's time {self.entries[0][1]} must be 0")
        for (_, a), (_, b) in itertools.pairwise(self.entries):
            if b < a:
                raise ValueError(f"times must not decrease ({a} then {b})")
        unknown = {r for r, _ in self.entries} - set(self.labels)
        if unknown:
            raise ValueError(f"regions {sorted(unknown)} are not in the label map")

    def as_floats(self) -> list[tuple[str, float]]:
        """The run as ``[(region, seconds), ...]`` (the certifier's ``check_timed_run`` input)."""
        return [(r, float(t)) for r, t in self.entries]

    def label_lists(self) -> dict[str, list[str]]:
        return {k: list(v) for k, v in self.labels.items()}


@st.composite
def timed_runs(draw: st.DrawFn, labels: Mapping[str, tuple[str, ...]] | None = None, *, max_len: int = 6,
               quantum: Fraction = Fraction(1, 2), max_gap: int = 8, allow_repeats: bool = True,
               strictly_increasing: bool = True) -> TimedRun:
    """Finite timed runs over ``labels`` (drawn by ``label_maps()`` when None): the first entry at time 0,
    gaps ``k * quantum`` with k in [1, max_gap] (k >= 0 when not ``strictly_increasing``). Consecutive entries
    differ in region unless ``allow_repeats`` (a dwell observed as a new position)."""
    lab = dict(labels) if labels is not None else draw(label_maps())
    names = sorted(lab)
    length = draw(st.integers(1, max_len))
    entries: list[tuple[str, Fraction]] = [(draw(st.sampled_from(names)), Fraction(0))]
    t = Fraction(0)
    for _ in range(length - 1):
        prev = entries[-1][0]
        options = names if allow_repeats else [n for n in names if n != prev]
        if not options:
            break
        t += draw(st.integers(1 if strictly_increasing else 0, max_gap)) * quantum
        entries.append((draw(st.sampled_from(options)), t))
    return TimedRun(entries=tuple(entries), labels=lab)


# ---------------------------------------------------------------------------------------------------- trajectories
@dataclass(frozen=True, slots=True)
class Trajectory:
    """Sampled poses: ``t_s`` (seconds from time 0, increasing), ``xy_m`` (n x 2), ``yaw_rad`` (n)."""

    t_s: tuple[float, ...]
    xy_m: tuple[tuple[float, float], ...]
    yaw_rad: tuple[float, ...]

    def __post_init__(self) -> None:
        if not (len(self.t_s) == len(self.xy_m) == len(self.yaw_rad)) or not self.t_s:
            raise ValueError("t_s, xy_m and yaw_rad must have the same non-zero length")

    def arrays(self) -> tuple[FloatArray, FloatArray, FloatArray]:
        return np.array(self.t_s), np.array(self.xy_m, dtype=float).reshape(-1, 2), np.array(self.yaw_rad)


@st.composite
def trajectories(draw: st.DrawFn, *, rate_hz: float = 100.0, max_samples: int = 400, max_speed_mps: float = 0.2,
                 start: tuple[float, float] | None = None, box_m: float = 2.5) -> Trajectory:
    """Poses at ``rate_hz`` whose planar speed never exceeds ``max_speed_mps`` and which stay in
    ``[-box_m, box_m]^2``: piecewise-constant velocities (up to 6 segments), clipped at the box."""
    n = draw(st.integers(2, max_samples))
    dt = 1.0 / rate_hz
    x, y = start if start is not None else (draw(_centi(-box_m, box_m)), draw(_centi(-box_m, box_m)))
    yaw = draw(_centi(-3.14, 3.14))
    segments = draw(st.lists(st.tuples(_centi(-1.0, 1.0), _centi(-1.0, 1.0), _centi(-0.5, 0.5)), min_size=1,
                             max_size=6))
    ts, xys, yaws = [], [], []
    for i in range(n):
        ts.append(i * dt)
        xys.append((x, y))
        yaws.append(math.atan2(math.sin(yaw), math.cos(yaw)))
        vx, vy, wz = segments[i * len(segments) // n]
        norm = math.hypot(vx, vy)
        scale = max_speed_mps / max(norm, 1.0) if norm > 0 else 0.0
        x = min(max(x + vx * scale * dt, -box_m), box_m)
        y = min(max(y + vy * scale * dt, -box_m), box_m)
        yaw += wz * dt
    return Trajectory(t_s=tuple(ts), xy_m=tuple(xys), yaw_rad=tuple(yaws))


# ---------------------------------------------------------------------------------------------------- log faults
FaultKind = Literal["none", "truncate", "drop", "reorder", "nan", "zero_quaternion", "missing_topic",
                    "duplicate_stamp", "zero_stamps", "negative_stamp", "stamp_1970"]
FAULT_KINDS: tuple[FaultKind, ...] = ("none", "truncate", "drop", "reorder", "nan", "zero_quaternion",
                                      "missing_topic", "duplicate_stamp", "zero_stamps", "negative_stamp",
                                      "stamp_1970")
#: the header-stamp faults (the samples' positions are kept, except the moved duplicate)
STAMP_FAULTS: tuple[FaultKind, ...] = ("duplicate_stamp", "zero_stamps", "negative_stamp", "stamp_1970")


@dataclass(frozen=True, slots=True)
class LogFault:
    """Damage to a log, described, not applied.

    - ``truncate``: cut the file (or the storage file of a bag directory) to ``fraction`` of its bytes;
    - ``drop``: remove the pose samples with indices in [start, start + count);
    - ``reorder``: swap the *log order* of pose samples ``start`` and ``start + count`` (stamps unchanged);
    - ``nan``: set the position of pose samples [start, start + count) to NaN;
    - ``zero_quaternion``: set the orientation of pose samples [start, start + count) to (0, 0, 0, 0);
    - ``missing_topic``: omit ``topic`` (a role: ``pose``, ``cmd_vel`` or ``nominal``) from the log;
    - ``duplicate_stamp``: pose sample ``start + 1`` gets the header stamp of sample ``start`` and is moved to
      ``xy`` (when given): two different positions at one instant;
    - ``zero_stamps``: every header stamp is 0 (a publisher that never sets ``header.stamp``);
    - ``negative_stamp``: sample ``start``'s header stamp is -5 s (ROS2 only: ROS1 stamps are unsigned);
    - ``stamp_1970``: sample ``start``'s header stamp is 1 s after the epoch (a clock that was never set);
    - ``none``: an undamaged log.
    Indices are taken modulo the number of samples by ``apply_sample_fault``.
    """

    kind: FaultKind
    start: int = 0
    count: int = 1
    fraction: float = 1.0
    topic: Literal["pose", "cmd_vel", "nominal"] = "pose"
    xy: tuple[float, float] | None = None

    def __post_init__(self) -> None:
        if self.kind not in FAULT_KINDS:
            raise ValueError(f"kind={self.kind!r} is not one of {FAULT_KINDS}")
        if self.start < 0 or self.count < 1:
            raise ValueError(f"start={self.start!r} must be >= 0 and count={self.count!r} >= 1")
        if not 0 < self.fraction <= 1:
            raise ValueError(f"fraction={self.fraction!r} must lie in (0, 1]")

    @property
    def damages_samples(self) -> bool:
        return self.kind in ("drop", "reorder", "nan", "zero_quaternion", *STAMP_FAULTS)


@st.composite
def log_faults(draw: st.DrawFn, kinds: Sequence[FaultKind] = FAULT_KINDS, max_index: int = 400,
               places: Sequence[tuple[float, float]] = ()) -> LogFault:
    """Log faults of the given kinds with positions below ``max_index``; a ``duplicate_stamp`` moves its sample to
    one of ``places`` (e.g. obstacle centres) when given."""
    kind = draw(st.sampled_from(list(kinds)))
    xy = draw(st.sampled_from(list(places))) if places and kind == "duplicate_stamp" else None
    return LogFault(kind=kind, start=draw(st.integers(0, max_index - 1)), count=draw(st.integers(1, 50)),
                    fraction=draw(st.sampled_from([0.1, 0.3, 0.5, 0.7, 0.9, 0.99])),
                    topic=draw(st.sampled_from(["pose", "cmd_vel", "nominal"])), xy=xy)


def apply_sample_fault(fault: LogFault, stamps_ns: npt.NDArray[np.int64], xyz_m: FloatArray, quat_xyzw: FloatArray,
                       ) -> tuple[npt.NDArray[np.int64], FloatArray, FloatArray]:
    """Apply a sample-level fault (drop, reorder, nan, zero_quaternion, the stamp faults) to pose arrays, in log
    order.

    Returns new arrays (the inputs are not modified); other kinds return copies unchanged. ``reorder`` swaps two
    rows, stamps included, so the log order is no longer the stamp order.
    """
    n = len(stamps_ns)
    if not (xyz_m.shape == (n, 3) and quat_xyzw.shape == (n, 4)):
        raise ValueError(f"shapes stamps {stamps_ns.shape}, xyz {xyz_m.shape}, quat {quat_xyzw.shape} disagree")
    s, x, qt = stamps_ns.copy(), xyz_m.copy(), quat_xyzw.copy()
    if n == 0:
        return s, x, qt
    start = fault.start % n
    stop = min(start + fault.count, n)
    if fault.kind == "drop":
        keep = np.ones(n, dtype=bool)
        keep[start:stop] = False
        if not keep.any():
            keep[0] = True
        return s[keep], x[keep], qt[keep]
    if fault.kind == "reorder":
        other = (start + fault.count) % n
        if other == start:
            other = (start + 1) % n
        for arr in (s, x, qt):
            arr[[start, other]] = arr[[other, start]]
    elif fault.kind == "nan":
        x[start:stop, :2] = np.nan
    elif fault.kind == "zero_quaternion":
        qt[start:stop] = 0.0
    elif fault.kind == "duplicate_stamp" and n >= 2:
        k = min(start, n - 2)
        s[k + 1] = s[k]
        if fault.xy is not None:
            x[k + 1, :2] = fault.xy
    elif fault.kind == "zero_stamps":
        s[:] = 0
    elif fault.kind == "negative_stamp":
        s[start] = -5 * 10**9
    elif fault.kind == "stamp_1970":
        s[start] = 10**9
    return s, x, qt
