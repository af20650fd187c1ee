"""Options shared by several ``tubempc`` commands, defined once so that they read and resolve alike.

``--scenario REF``: a scenario YAML file or a built-in scenario's name, resolved by ``load_scenario`` (every
command): **a file path first** (an existing file of that name wins), **then a built-in name** (``tubempc scenario
list``); neither is one line naming the value and the built-in names (exit 3).

``certify`` and ``watch`` judge a log alike, so they share ``--checks`` (``checks_text``, parsed by
``verify.selection.parse_check_list``) and ``--clock-offset`` (``clock_offsets``, parsed by
``verify.ingest.clocks.parse_clock_offsets``).
"""

from __future__ import annotations

from collections.abc import Callable
from typing import TYPE_CHECKING, Any, TypeVar

import click

if TYPE_CHECKING:
    from tubempc.scenario import Scenario

__all__ = ["SCENARIO_HELP", "checks_option", "clock_offset_option", "load_scenario_ref", "scenario_option"]

F = TypeVar("F", bound=Callable[..., Any])

#: what every command's ``--scenario`` help says about the value (the resolution order above)
SCENARIO_HELP = "A scenario YAML file or a built-in scenario name (a file of that name first, then a built-in)."


def scenario_option(*, required: bool = False, default: str | None = "nexus-sml", extra: str = "") -> Callable[[F], F]:
    """The ``--scenario`` option (its value in the command's ``scenario`` parameter, a string)."""
    text = SCENARIO_HELP + (f" {extra}" if extra else "")
    if required:
        return click.option("--scenario", "scenario", required=True, help=text)
    return click.option("--scenario", "scenario", default=default, show_default=default is not None, help=text)


def checks_option() -> Callable[[F], F]:
    """``--checks NAME,...`` (its value in ``checks_text``; None: the scenario's ``checks:`` or every check whose
    data the scenario names)."""
    return click.option("--checks", "checks_text", default=None, metavar="NAME,...",
                        help="Checks to run: spec, obstacle_clearance, workspace, tube, input_box (default: the "
                             "scenario's checks:, else every check whose data the scenario names).")


def clock_offset_option() -> Callable[[F], F]:
    """``--clock-offset TOPIC=SECONDS``, repeatable (its values in ``clock_offsets``)."""
    return click.option("--clock-offset", "clock_offsets", multiple=True, metavar="TOPIC=SECONDS",
                        help="Add SECONDS to TOPIC's times (its clock runs behind the pose topic's by that much); "
                             "repeatable; extends the scenario's clock_offsets.")


def load_scenario_ref(ref: str) -> Scenario:
    """The scenario ``--scenario REF`` names (file first, then built-in name: ``tubempc.scenario.load_scenario``)."""
    from tubempc.scenario import load_scenario

    return load_scenario(ref)
