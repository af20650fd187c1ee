"""Falsification: search the admissible disturbances, start poses and MoCap noise for the run that breaks a check.

``make_space`` (the cube ``[-1, 1]^d`` -> ``Candidate``) -> ``evaluate`` (closed loop in process, judged by
``verify.certify_data``) -> ``search`` (random, targeted with hypothesis, differential evolution) -> ``run_falsify``
/ ``write_outcome`` (certificate-like JSON; log, certificate and report of the worst case). ``tubempc falsify`` is
the command-line front.
"""

from tubempc.falsify.objective import DEFAULT_CHECKS, Evaluation, FalsifySetup, evaluate, simulate
from tubempc.falsify.overrides import OverrideError, apply_overrides
from tubempc.falsify.run import (
    FALSIFY_FORMAT,
    FalsifyError,
    FalsifyOutcome,
    FalsifyRequest,
    prepare,
    replay_command,
    run_falsify,
    write_case,
    write_outcome,
)
from tubempc.falsify.search import METHODS, SearchResult, search
from tubempc.falsify.signals import SineSignal, StepSignal, SwitchSignal
from tubempc.falsify.space import FAMILIES, Candidate, SearchSpace, make_space

__all__ = [
    "DEFAULT_CHECKS",
    "FALSIFY_FORMAT",
    "FAMILIES",
    "METHODS",
    "Candidate",
    "Evaluation",
    "FalsifyError",
    "FalsifyOutcome",
    "FalsifyRequest",
    "FalsifySetup",
    "OverrideError",
    "SearchResult",
    "SearchSpace",
    "SineSignal",
    "StepSignal",
    "SwitchSignal",
    "apply_overrides",
    "evaluate",
    "make_space",
    "prepare",
    "replay_command",
    "run_falsify",
    "search",
    "simulate",
    "write_case",
    "write_outcome",
]
