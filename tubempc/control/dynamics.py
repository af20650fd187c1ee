"""Dynamics models ``x' = f(x) + g(x) u + delta`` for the state (x, y, theta) and input (u1, u2, u3).

input: a scenario's ``dynamics`` section, or user-supplied f and g with stated constants -> output: a frozen
``DynamicsModel`` holding CasADi functions f, g, the constants L_f, L_g, g_min of the tube lemma, the frame in which
the input is expressed (``world``: the robot's body-frame command is ``R(theta)^T u``; ``body``: ``u`` is the
command) and an optional heading restriction ``|theta| <= theta_max_rad``.

User models are spot-checked by sampling: a stated constant contradicted by the samples raises ``DesignError``.
"""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass
from typing import Literal

import casadi as ca
import numpy as np

from tubempc.errors import DesignError
from tubempc.scenario import Scenario

__all__ = [
    "DynamicsModel",
    "body_model",
    "model_for",
    "user_model",
    "world_model",
]

STATE_DIM = 3
InputFrame = Literal["world", "body"]
ModelFunction = ca.Function | Callable[[ca.SX], ca.SX]


@dataclass(frozen=True, slots=True)
class DynamicsModel:
    """``x' = f(x) + g(x) u``; ``f: R^3 -> R^3`` and ``g: R^3 -> R^{3x3}`` as CasADi functions."""

    name: str
    f: ca.Function
    g: ca.Function
    l_f: float
    l_g: float
    g_min: float
    input_frame: InputFrame
    theta_max_rad: float | None = None
    linear_world: bool = False  # f = 0, g = I: exact discretisation x+ = x + dt * u

    def __post_init__(self) -> None:
        for name in ("l_f", "l_g"):
            value = getattr(self, name)
            if not (math.isfinite(value) and value >= 0):
                raise DesignError(f"dynamics {self.name!r}: {name}={value!r} must be a finite non-negative number")
        if not (math.isfinite(self.g_min) and self.g_min > 0):
            raise DesignError(f"dynamics {self.name!r}: g_min={self.g_min!r} must be positive (Assumption 2)")
        if self.theta_max_rad is not None and not 0 < self.theta_max_rad <= math.pi:
            raise DesignError(f"dynamics {self.name!r}: theta_max_rad={self.theta_max_rad!r} must be in (0, pi]")

    @property
    def cache_key(self) -> str:
        if self.name in ("world", "body"):
            return f"{self.name}:{self.theta_max_rad!r}"
        return f"user:{id(self.f)}:{id(self.g)}"

    def xdot(self, x: np.ndarray, u: np.ndarray) -> np.ndarray:
        """Nominal vector field ``f(x) + g(x) u`` at one state (numpy in, numpy out)."""
        if self.linear_world:
            out: np.ndarray = np.array(u, dtype=float)
            return out
        fx = np.asarray(self.f(x), dtype=float).reshape(STATE_DIM)
        gx = np.asarray(self.g(x), dtype=float).reshape(STATE_DIM, STATE_DIM)
        xdot: np.ndarray = fx + gx @ np.asarray(u, dtype=float)
        return xdot

    def body_command(self, x: np.ndarray, u: np.ndarray) -> np.ndarray:
        """The command the robot receives on cmd_vel: ``R(theta)^T u[:2]``, ``u3`` (world inputs) or ``u`` (body)."""
        u = np.asarray(u, dtype=float)
        if self.input_frame == "body":
            return u.copy()
        c, s = math.cos(float(x[2])), math.sin(float(x[2]))
        return np.array([c * u[0] + s * u[1], -s * u[0] + c * u[1], u[2]])


def _functions(f_expr: ca.SX, g_expr: ca.SX, x: ca.SX) -> tuple[ca.Function, ca.Function]:
    return ca.Function("f", [x], [f_expr]), ca.Function("g", [x], [g_expr])


def world_model() -> DynamicsModel:
    """Nexus with world-frame velocity inputs: f = 0, g = I (L_f = L_g = 0, g_min = 1)."""
    x = ca.SX.sym("x", STATE_DIM)
    f, g = _functions(ca.SX.zeros(STATE_DIM), ca.SX.eye(STATE_DIM), x)
    return DynamicsModel(name="world", f=f, g=g, l_f=0.0, l_g=0.0, g_min=1.0, input_frame="world",
                         linear_world=True)


def body_model(theta_max_rad: float) -> DynamicsModel:
    """Nexus with body-frame inputs: g = blockdiag(R(theta), 1), valid for |theta| <= theta_max < pi/2.

    ``sym(g) = diag(cos theta, cos theta, 1)`` so g_min = cos(theta_max); ``|R(a) - R(b)|_2 = 2|sin((a-b)/2)|``
    gives L_g = 1; f = 0 gives L_f = 0.
    """
    if not 0 < theta_max_rad < math.pi / 2:
        raise DesignError(f"dynamics.theta_max={theta_max_rad!r} must lie in (0, pi/2) for the body-frame model")
    x = ca.SX.sym("x", STATE_DIM)
    c, s = ca.cos(x[2]), ca.sin(x[2])
    g_expr = ca.vertcat(ca.horzcat(c, -s, 0), ca.horzcat(s, c, 0), ca.horzcat(0, 0, 1))
    f, g = _functions(ca.SX.zeros(STATE_DIM), g_expr, x)
    return DynamicsModel(name="body", f=f, g=g, l_f=0.0, l_g=1.0, g_min=math.cos(theta_max_rad),
                         input_frame="body", theta_max_rad=theta_max_rad)


def model_for(scenario: Scenario) -> DynamicsModel:
    """The model named by ``scenario.dynamics.model``."""
    if scenario.dynamics.model == "body":
        return body_model(scenario.dynamics.theta_max)
    return world_model()


def _as_function(name: str, fn: ModelFunction, x: ca.SX, shape: tuple[int, int]) -> ca.Function:
    try:
        expr = ca.SX(fn(x))
    except Exception as err:  # user code: any failure is reported as a design problem
        raise DesignError(f"user dynamics: {name}(x) cannot be evaluated on a CasADi symbol "
                          f"({err.__class__.__name__}: {err})") from err
    if expr.shape != shape and not (shape[1] == 1 and expr.shape == (1, shape[0])):
        raise DesignError(f"user dynamics: {name}(x) has shape {expr.shape}, expected {shape}")
    return ca.Function(name, [x], [ca.reshape(expr, *shape)])


def user_model(f: ModelFunction, g: ModelFunction, *, l_f: float, l_g: float, g_min: float,
               input_frame: InputFrame = "body", theta_max_rad: float | None = None,
               sample_box: tuple[tuple[float, float], tuple[float, float]] = ((-2.5, 2.5), (-2.5, 2.5)),
               samples: int = 400, rng: np.random.Generator | None = None, name: str = "user") -> DynamicsModel:
    """A user model from CasADi functions or callables on a CasADi symbol, spot-checked by sampling.

    The check draws ``samples`` states (x, y in ``sample_box``, theta within the heading restriction or
    [-pi, pi]) and pairs of states; it raises ``DesignError`` naming the constant when a sample shows
    ``lambda_min(sym g(x)) < g_min``, ``|f(a) - f(b)| > L_f |a - b|`` or ``|g(a) - g(b)|_2 > L_g |a - b|``.
    Sampling can only refute a constant, never prove it.
    """
    x = ca.SX.sym("x", STATE_DIM)
    f_fn = _as_function("f", f, x, (STATE_DIM, 1))
    g_fn = _as_function("g", g, x, (STATE_DIM, STATE_DIM))
    model = DynamicsModel(name=name, f=f_fn, g=g_fn, l_f=l_f, l_g=l_g, g_min=g_min, input_frame=input_frame,
                          theta_max_rad=theta_max_rad)
    spot_check(model, sample_box=sample_box, samples=samples, rng=rng or np.random.default_rng(0))
    return model


def _sample_states(rng: np.random.Generator, n: int, box: tuple[tuple[float, float], tuple[float, float]],
                   theta_max: float) -> np.ndarray:
    return np.column_stack([rng.uniform(*box[0], n), rng.uniform(*box[1], n), rng.uniform(-theta_max, theta_max, n)])


def spot_check(model: DynamicsModel, *, sample_box: tuple[tuple[float, float], tuple[float, float]],
               samples: int, rng: np.random.Generator) -> None:
    """Refute stated constants of ``model`` by sampling (relative slack 1e-9 for rounding)."""
    theta_max = model.theta_max_rad if model.theta_max_rad is not None else math.pi
    a = _sample_states(rng, samples, sample_box, theta_max)
    # pairs at mixed distances: far pairs and close pairs (Lipschitz ratios are largest at small steps)
    b = a + rng.normal(scale=rng.choice([1e-3, 1e-1, 1.0], size=(samples, 1)), size=a.shape)
    b[:, 2] = np.clip(b[:, 2], -theta_max, theta_max)
    fa = np.asarray(model.f.map(samples)(a.T), dtype=float).T
    fb = np.asarray(model.f.map(samples)(b.T), dtype=float).T
    ga = [np.asarray(model.g(s), dtype=float) for s in a]
    gb = [np.asarray(model.g(s), dtype=float) for s in b]
    slack = 1e-9
    for i in range(samples):
        lam = float(np.linalg.eigvalsh(0.5 * (ga[i] + ga[i].T))[0])
        if lam < model.g_min * (1 - slack) - slack:
            raise DesignError(f"user dynamics {model.name!r}: g_min={model.g_min!r} is contradicted at "
                              f"x={a[i].tolist()} where lambda_min(sym g) = {lam:.6g}")
        dist = float(np.linalg.norm(a[i] - b[i]))
        if dist == 0:
            continue
        df = float(np.linalg.norm(fa[i] - fb[i]))
        if df > model.l_f * dist * (1 + slack) + slack:
            raise DesignError(f"user dynamics {model.name!r}: L_f={model.l_f!r} is contradicted: |f(a)-f(b)|/|a-b| = "
                              f"{df / dist:.6g} at a={a[i].tolist()}")
        dg = float(np.linalg.norm(ga[i] - gb[i], 2))
        if dg > model.l_g * dist * (1 + slack) + slack:
            raise DesignError(f"user dynamics {model.name!r}: L_g={model.l_g!r} is contradicted: |g(a)-g(b)|/|a-b| = "
                              f"{dg / dist:.6g} at a={a[i].tolist()}")
