"""tubempc: tube-based MPC under MITL specifications, and the planning pipeline of the Nexus experiment.

Subpackages: ``mitl`` (the specification language), ``scenario`` (workspace and mission model), ``control``
(dynamics, tube design, MPC, closed loop, Algorithm 1), ``planning`` (WTS abstraction, MITL automaton, product
search), ``rosio`` (ROS log writing). The certifier lives in the sibling package ``verify``.
"""

from tubempc.errors import (
    DesignError,
    LogWriteError,
    NoAcceptingRunError,
    NotAvailableError,
    ScenarioError,
    SearchLimitError,
    SolverError,
    SpecSyntaxError,
    TubeMPCError,
)

__version__ = "0.1.0"

__all__ = [
    "DesignError",
    "LogWriteError",
    "NoAcceptingRunError",
    "NotAvailableError",
    "ScenarioError",
    "SearchLimitError",
    "SolverError",
    "SpecSyntaxError",
    "TubeMPCError",
    "__version__",
]
