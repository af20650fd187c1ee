"""The tube MPC as an implementation of the controller protocol (``tubempc.control.user.Controller``).

input: ``reset(scenario, plan)``, then ``step(t_s, state, reference)`` at every MoCap sample -> output: the
body-frame command ``(vx, vy, wz)``; ``nominal()`` gives the nominal state of the last step.

The control law is ``run_closed_loop``'s: every ``mpc.h`` (every ``h / dt``-th call) the warm-started FHOCP is solved
from the nominal state ``x_hat`` (never reset to the measurement), with the references of the current leg's guide
path and the obstacle slots in reach; its first input ``u_hat`` is held over h, and at every sample the ancillary
law ``u = u_hat - sigma (x_meas - x_hat)`` is applied. The nominal over one MPC step is computed as that loop
computes it (closed form ``x_hat + k dt u_hat`` for the linear world model, the RK4 of the sample block
otherwise), so that a replay of a ``run_closed_loop`` trajectory gives its nominal states, its solves and its
inputs (``tests/control/test_tube_controller.py``).

A new ``reference.index`` starts a new leg (guide path from the nominal) at the next MPC step. Algorithm 1's check
(the nominal in the terminal ball of the current target, at the MPC steps) is recorded in ``entered_terminal_s``
and offered as ``arrived(t_s, reference)``; every solve is a ``SolverRecord`` in ``records``.
"""

from __future__ import annotations

import math

import numpy as np

from tubempc.control.closed_loop import (
    LOOKAHEAD_M,
    MIN_OBSTACLE_SLOTS,
    SolverRecord,
    Target,
    _block_function,
    _Leg,
    _slots,
    _start_leg,
)
from tubempc.control.dynamics import STATE_DIM, DynamicsModel, model_for
from tubempc.control.fhocp import FhocpProblem, NominalMPC, build_fhocp
from tubempc.control.guide import references
from tubempc.control.tube import TubeDesign, design_tube
from tubempc.control.user import ControllerPlan, InputModel, Reference
from tubempc.errors import DesignError
from tubempc.scenario import Scenario

__all__ = ["TubeMPC", "tube_mpc"]


class TubeMPC:
    """The warm-started nominal MPC plus the ancillary law, stepped at the MoCap rate (see the module docstring).

    ``model``: the dynamics (default: the scenario's); ``tube``: its design for the scenario (default: designed in
    ``reset``). ``closed_form_nominal``: compute the nominal over an MPC
    step in closed form (default: for the linear world model; ``run_closed_loop`` uses the RK4 block instead when
    the world model runs with the ``worst`` disturbance and MoCap noise).
    """

    input_model: InputModel = "holonomic"

    def __init__(self, model: DynamicsModel | None = None, *, tube: TubeDesign | None = None,
                 closed_form_nominal: bool | None = None) -> None:
        self._model_arg = model
        self._tube_arg = tube
        self._closed_form_arg = closed_form_nominal
        self.tube_radius_m: float | None = None
        self.period_s: float | None = None  # mpc.h after reset: the loop's decision period
        self.records: list[SolverRecord] = []
        self.entered_terminal_s: dict[int, float] = {}
        self._ready = False

    def reset(self, scenario: Scenario, plan: ControllerPlan) -> None:
        model = self._model_arg or model_for(scenario)
        tube = self._tube_arg or design_tube(scenario, model)
        h, dt = scenario.mpc.h, 1.0 / scenario.mocap.rate_hz
        per_step = round(h / dt)
        if per_step < 1 or abs(per_step * dt - h) > 1e-9:
            raise DesignError(f"mpc.h={h!r} s is not a whole number of MoCap samples (mocap.rate_hz="
                              f"{scenario.mocap.rate_hz!r})")
        self._scenario, self._model, self._tube = scenario, model, tube
        self._closed_form = model.linear_world if self._closed_form_arg is None else self._closed_form_arg
        self._plan = plan
        self._per_step, self._dt = per_step, dt
        self.period_s = h
        self._n_stages = scenario.mpc.steps
        self._reach = self._n_stages * h * tube.max_planar_speed_mps + 0.2
        self._step_m = tube.max_planar_speed_mps * h
        self._problem: FhocpProblem = build_fhocp(scenario, model, tube, MIN_OBSTACLE_SLOTS)
        self._mpc_by_slots: dict[int, NominalMPC] = {}
        self._k_dt = (np.arange(per_step + 1) * dt)[:, None]  # k dt, k = 0..m (as run_closed_loop)
        self._block = None if self._closed_form else _block_function(model, dt, per_step)
        self._x_hat = np.array(plan.start_pose, dtype=float)
        self._u_hat = np.zeros(STATE_DIM)
        self._nominal_block = self._x_hat[None, :].copy()
        self._calls = 0
        self._leg: _Leg | None = None
        self.tube_radius_m = tube.radius_m
        self.records = []
        self.entered_terminal_s = {}
        self._ready = True

    @property
    def tube(self) -> TubeDesign:
        return self._tube

    def nominal(self) -> np.ndarray:
        return self._x_hat.copy()

    def arrived(self, t_s: float, reference: Reference) -> bool:
        """Algorithm 1: the nominal has entered the terminal ball of ``reference`` (checked at the MPC steps: a call
        before the step at ``t_s`` checks the nominal state at ``t_s``)."""
        if self._ready:
            self._check(t_s, reference)
        return reference.index in self.entered_terminal_s

    def _check(self, t_s: float, reference: Reference) -> None:
        """At an MPC step: the nominal moves to the end of the previous step, and Algorithm 1 checks the current
        leg (the first leg starts here), before any switch to a new reference."""
        if self._calls % self._per_step:
            return
        if self._calls:
            self._x_hat = self._nominal_block[self._per_step]
        leg = self._leg if self._leg is not None else self._leg_for(reference, t_s)
        if leg.entered_s is None:
            to_goal = self._x_hat - leg.goal
            if math.sqrt(float(to_goal.dot(to_goal))) <= self._tube.terminal_radius_m:  # np.linalg.norm
                leg.entered_s = t_s
                self.entered_terminal_s[leg.index] = t_s

    def _leg_for(self, reference: Reference, t_s: float) -> _Leg:
        leg = self._leg
        if leg is not None and leg.index == reference.index:
            return leg
        source = self._plan.start_region if leg is None else leg.target.region
        if leg is not None:
            leg.departure_s = t_s
        new = _start_leg(self._scenario, self._tube, index=reference.index,
                         target=Target(reference.region, reference.depart_after_s), source=source, x_hat=self._x_hat,
                         t_s=t_s, chord_m=self._problem.chord_margin_m)
        self._leg = new
        return new

    def _solve(self, t_s: float, reference: Reference) -> None:
        self._check(t_s, reference)
        x_hat = self._x_hat
        leg = self._leg_for(reference, t_s)
        n_stages = self._n_stages
        leg.s_m = leg.path.project(x_hat[:2], leg.s_m, 1.0)
        refs = np.empty((n_stages + 1, 3))
        references(leg.path, leg.s_m, lookahead_m=LOOKAHEAD_M, step_m=self._step_m, stages=n_stages + 1, out=refs)
        refs[:, 2] = leg.goal[2]
        slots = _slots(leg, x_hat[:2], self._reach)
        m = slots.shape[1]
        if m not in self._mpc_by_slots:
            self._mpc_by_slots[m] = NominalMPC(build_fhocp(self._scenario, self._model, self._tube, m)
                                               if m != MIN_OBSTACLE_SLOTS else self._problem)
        out = self._mpc_by_slots[m].solve(x_hat, refs, slots)
        for other, ctrl in self._mpc_by_slots.items():  # keep every warm start current
            if other != m:
                ctrl.adopt(out)
        self.records.append(SolverRecord(t_s=t_s, status=out.status, success=out.success, iterations=out.iterations,
                                         solve_time_s=out.solve_time_s, backup=out.backup,
                                         target=leg.target.region))
        self._u_hat = u_hat = out.inputs[0].copy()
        if self._block is None:
            self._nominal_block = x_hat + self._k_dt * u_hat
        else:
            m_s = self._per_step
            zeros = np.zeros((STATE_DIM, m_s))
            _, nominal, _, _, end = self._block(x_hat, x_hat, u_hat, zeros, zeros, 0.0, 0.0, np.zeros(STATE_DIM),
                                                self._tube.sigma)
            self._nominal_block = np.vstack([np.asarray(nominal, dtype=float).T,
                                             np.asarray(end, dtype=float).ravel()[None, :]])

    def step(self, t_s: float, state: np.ndarray, reference: Reference) -> np.ndarray:
        if not self._ready:
            raise DesignError("TubeMPC.step before reset(scenario, plan)")
        j = self._calls % self._per_step
        if j == 0:
            self._solve(t_s, reference)
        self._x_hat = x_hat = self._nominal_block[j]
        self._calls += 1
        u: np.ndarray = self._u_hat - self._tube.sigma * (np.asarray(state, dtype=float) - x_hat)
        if self._model.input_frame != "world":
            return u
        c, s = np.cos(state[2]), np.sin(state[2])
        return np.array([c * u[0] + s * u[1], -s * u[0] + c * u[1], u[2]])


def tube_mpc() -> TubeMPC:
    """``--controller tubempc.control.tube_controller:tube_mpc``: the tube MPC through the protocol's loop."""
    return TubeMPC()
