"""The MITL language shared by the planner and the certifier: text <-> frozen AST.

``parse(text)`` returns a hashable formula; ``str(formula)`` is canonical text that parses back to an equal formula.
"""

from tubempc.errors import SpecSyntaxError
from tubempc.mitl.ast import (
    FALSE,
    TRUE,
    UNBOUNDED,
    Always,
    And,
    Atom,
    Const,
    Eventually,
    Formula,
    Implies,
    Interval,
    Next,
    Not,
    Or,
    Until,
    atoms,
    format_seconds,
    subformulas,
    to_fraction,
)
from tubempc.mitl.parser import parse

__all__ = [
    "FALSE",
    "TRUE",
    "UNBOUNDED",
    "Always",
    "And",
    "Atom",
    "Const",
    "Eventually",
    "Formula",
    "Implies",
    "Interval",
    "Next",
    "Not",
    "Or",
    "SpecSyntaxError",
    "Until",
    "atoms",
    "format_seconds",
    "parse",
    "subformulas",
    "to_fraction",
]
