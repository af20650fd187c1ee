"""Options shared by several ``tubempc`` commands, defined once so that they read and resolve alike.

``--scenario REF``: a scenario YAML file or a built-in scenario's name, resolved by ``load_scenario`` (every
command): **a file path first** (an existing file of that name wins), **then a built-in name** (``tubempc scenario
list``); neither is one line naming the value and the built-in names (exit 3).
"""

from __future__ import annotations

from collections.abc import Callable
from typing import TYPE_CHECKING, Any, TypeVar

import click

if TYPE_CHECKING:
    from tubempc.scenario import Scenario

__all__ = ["SCENARIO_HELP", "load_scenario_ref", "scenario_option"]

F = TypeVar("F", bound=Callable[..., Any])

#: what every command's ``--scenario`` help says about the value (the resolution order above)
SCENARIO_HELP = "A scenario YAML file or a built-in scenario name (a file of that name first, then a built-in)."


def scenario_option(*, required: bool = False, default: str | None = "nexus-sml", extra: str = "") -> Callable[[F], F]:
    """The ``--scenario`` option (its value in the command's ``scenario`` parameter, a string)."""
    text = SCENARIO_HELP + (f" {extra}" if extra else "")
    if required:
        return click.option("--scenario", "scenario", required=True, help=text)
    return click.option("--scenario", "scenario", default=default, show_default=default is not None, help=text)


def load_scenario_ref(ref: str) -> Scenario:
    """The scenario ``--scenario REF`` names (file first, then built-in name: ``tubempc.scenario.load_scenario``)."""
    from tubempc.scenario import load_scenario

    return load_scenario(ref)
