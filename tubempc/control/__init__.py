"""Dynamics, tube design, nominal FHOCP/MPC, closed-loop simulation and Algorithm 1."""

from tubempc.control.algorithm1 import TransitionResult, clearance_m, transition_time
from tubempc.control.closed_loop import (
    Arrival,
    ClosedLoopResult,
    SolverRecord,
    Target,
    hold_position,
    run_closed_loop,
)
from tubempc.control.disturbance import DISTURBANCE_MODELS, InvalidArgumentError
from tubempc.control.dynamics import DynamicsModel, body_model, model_for, user_model, world_model
from tubempc.control.guide import NoGuidePathError
from tubempc.control.tube import TubeDesign, design_tube

__all__ = [
    "DISTURBANCE_MODELS",
    "Arrival",
    "ClosedLoopResult",
    "DynamicsModel",
    "InvalidArgumentError",
    "NoGuidePathError",
    "SolverRecord",
    "Target",
    "TransitionResult",
    "TubeDesign",
    "body_model",
    "clearance_m",
    "design_tube",
    "hold_position",
    "model_for",
    "run_closed_loop",
    "transition_time",
    "user_model",
    "world_model",
]
