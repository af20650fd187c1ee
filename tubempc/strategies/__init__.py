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
- ``signal_messages``: the (time, value) messages of a signal atom's topic, with jitter, silences and duplicates;
- ``log_faults``: a description of damage to a log (truncation, dropped samples, reordering, NaN, zero quaternion,
  missing topic) and ``apply_sample_fault`` to apply the sample-level ones to arrays.

Import as ``from tubempc import strategies``: one module per kind of value (``mitl``, ``workspaces``, ``dynamics``,
``runs``, ``trajectories``, ``signals``, ``faults``), all re-exported here. Every value is frozen and prints
readably, so a shrunk counterexample can be pasted into ``@example(...)``.
"""

from __future__ import annotations

from tubempc.strategies.dynamics import (
    ControlAffineDynamics,
    DisturbanceSignal,
    NominalInput,
    disturbances,
    dynamics,
    nominal_inputs,
)
from tubempc.strategies.faults import FAULT_KINDS, STAMP_FAULTS, LogFault, apply_sample_fault, log_faults
from tubempc.strategies.mitl import atom_names, formulas, intervals
from tubempc.strategies.runs import TimedRun, label_maps, timed_runs
from tubempc.strategies.signals import SIGNAL_LEVELS, signal_messages
from tubempc.strategies.trajectories import Trajectory, trajectories
from tubempc.strategies.workspaces import robot_radii, scenarios

__all__ = [
    "FAULT_KINDS",
    "SIGNAL_LEVELS",
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
    "signal_messages",
    "timed_runs",
    "trajectories",
]
