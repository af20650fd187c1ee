"""Which checks a certification runs: scenario (+ an explicit list) -> ``Selection`` (selected, not checked + why).

input: a scenario and the checks asked for (``--checks``, else the scenario's ``checks:``, else none) -> output: the
checks to run and, for every other check, the reason it is not run. A check whose data the scenario does not name
is *not selected* (``tube`` without ``topics.nominal``, ``input_box`` without ``topics.cmd_vel``); asking for it
explicitly anyway, or for a check that does not exist, is unusable input (exit 3). A selected check whose topic the
log lacks is judged and comes out inconclusive (never a pass).
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

from tubempc.scenario import CHECK_NAMES, Scenario, ScenarioError
from verify.errors import ScenarioInputError

__all__ = ["CHECK_NAMES", "Selection", "parse_check_list", "select_checks"]


@dataclass(frozen=True, slots=True)
class Selection:
    selected: tuple[str, ...]
    not_checked: tuple[tuple[str, str], ...]  # (check, reason)
    source: str  # "--checks", "scenario checks", or "default"

    def __contains__(self, name: object) -> bool:
        return name in self.selected


def parse_check_list(text: str) -> tuple[str, ...]:
    """``"spec,workspace"`` -> ``("spec", "workspace")``; unknown or repeated names raise ``ScenarioInputError``."""
    names = tuple(n.strip() for n in text.split(",") if n.strip())
    if not names:
        raise ScenarioInputError(f"--checks: no check named in {text!r} (choose from {', '.join(CHECK_NAMES)})")
    unknown = [n for n in names if n not in CHECK_NAMES]
    if unknown:
        raise ScenarioInputError(f"--checks: unknown check(s) {', '.join(unknown)} (choose from "
                                 f"{', '.join(CHECK_NAMES)})")
    if len(set(names)) != len(names):
        raise ScenarioInputError(f"--checks: a check is listed twice in {text!r}")
    return names


def _missing_data(sc: Scenario, name: str) -> str | None:
    """Why the scenario cannot support check ``name`` (None: it can)."""
    if name == "tube":
        if sc.topics.nominal is None:
            return "the scenario names no nominal-state topic (topics.nominal)"
        try:
            _ = sc.tube_radius_m
        except ScenarioError as err:
            return f"the tube radius is unknown ({err.field}: {err.reason}; give tube.radius)"
    if name == "input_box" and sc.topics.cmd_vel is None:
        return "the scenario names no command topic (topics.cmd_vel)"
    return None


def select_checks(sc: Scenario, requested: Sequence[str] | None = None) -> Selection:
    """The checks to run: ``requested`` (the command line) wins over the scenario's ``checks:``; without either,
    every check whose data the scenario names."""
    if requested is not None:
        chosen, source = tuple(requested), "--checks"
    elif sc.checks is not None:
        chosen, source = tuple(sc.checks), "scenario checks"
    else:
        chosen, source = (), "default"
    unknown = [n for n in chosen if n not in CHECK_NAMES]
    if unknown:
        raise ScenarioInputError(f"{source}: unknown check(s) {', '.join(unknown)} (choose from "
                                 f"{', '.join(CHECK_NAMES)})")
    selected: list[str] = []
    not_checked: list[tuple[str, str]] = []
    for name in CHECK_NAMES:
        missing = _missing_data(sc, name)
        if source != "default":
            if name not in chosen:
                not_checked.append((name, f"not selected ({source}: {', '.join(chosen)})"))
            elif missing is not None:
                raise ScenarioInputError(f"scenario {sc.name!r}: check {name} was asked for ({source}) but {missing}")
            else:
                selected.append(name)
        elif missing is not None:
            not_checked.append((name, f"not selected: {missing}"))
        else:
            selected.append(name)
    return Selection(tuple(selected), tuple(not_checked), source)
