"""The formula a single transition (or a chain of them) is judged by when no formula is given.

Used by ``tubempc falsify --to`` and by the regression suite's runs without a ``spec``: one rule, one place.
"""

from __future__ import annotations

from tubempc.scenario.model import Scenario

__all__ = ["derived_spec"]


def derived_spec(scenario: Scenario, last_target: str) -> str:
    """Safety from every unsafe label, and reaching the last target's labels (if it has any)."""
    unsafe = sorted({lab for r in scenario.unsafe_regions for lab in r.labels})
    parts = []
    if unsafe:
        parts.append(f"G[0,inf) !({' | '.join(unsafe)})")
    labels = scenario.region(last_target).labels
    if labels:
        parts.append(f"F[0,inf) {labels[0]}" if len(labels) == 1 else f"F[0,inf) ({' | '.join(labels)})")
    return " & ".join(parts) if parts else "true"
