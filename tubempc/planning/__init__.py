"""Planning: WTS abstraction (Algorithm 1 per region pair), MITL -> timed automaton, product search, plan.

``build_wts`` -> ``find_run`` (or ``plan_from_wts`` / ``plan_mission`` for the re-timed ``Plan``).
"""

from tubempc.planning.automaton import TimedAutomaton, compile_formula, tick_of
from tubempc.planning.plan import Plan, PlannedTarget, plan_from_wts, plan_mission
from tubempc.planning.reference_semantics import LassoRun, holds, truth_table
from tubempc.planning.retime import Retimed, retime
from tubempc.planning.search import SearchLimitError, SearchResult, export_dot, find_run
from tubempc.planning.wts import (
    AbstractionError,
    TransitionOracle,
    build_wts,
    make_wts,
    wts_all_labels,
    wts_edges,
    wts_failed,
    wts_labels,
    wts_weight,
)

__all__ = [
    "AbstractionError",
    "LassoRun",
    "Plan",
    "PlannedTarget",
    "Retimed",
    "SearchLimitError",
    "SearchResult",
    "TimedAutomaton",
    "TransitionOracle",
    "build_wts",
    "compile_formula",
    "export_dot",
    "find_run",
    "holds",
    "make_wts",
    "plan_from_wts",
    "plan_mission",
    "retime",
    "tick_of",
    "truth_table",
    "wts_all_labels",
    "wts_edges",
    "wts_failed",
    "wts_labels",
    "wts_weight",
]
