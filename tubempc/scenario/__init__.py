"""Scenario model and built-in scenarios (shared by the planner and the certifier)."""

from tubempc.errors import ScenarioError
from tubempc.scenario.loader import (
    BUILTIN_SCENARIOS,
    builtin_scenario,
    builtin_scenario_text,
    dump_scenario,
    load_scenario,
    scenario_from_dict,
)
from tubempc.scenario.model import (
    CHECK_NAMES,
    DEFAULT_TOPICS,
    DisturbanceSpec,
    DynamicsSpec,
    InputLimits,
    MocapSpec,
    MpcSpec,
    Region,
    RobotSpec,
    Scenario,
    SignalSpec,
    Topics,
    TubeSpec,
    Workspace,
)

__all__ = [
    "BUILTIN_SCENARIOS",
    "CHECK_NAMES",
    "DEFAULT_TOPICS",
    "DisturbanceSpec",
    "DynamicsSpec",
    "InputLimits",
    "MocapSpec",
    "MpcSpec",
    "Region",
    "RobotSpec",
    "Scenario",
    "ScenarioError",
    "SignalSpec",
    "Topics",
    "TubeSpec",
    "Workspace",
    "builtin_scenario",
    "builtin_scenario_text",
    "dump_scenario",
    "load_scenario",
    "scenario_from_dict",
]
