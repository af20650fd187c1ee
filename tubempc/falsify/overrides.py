"""``--set key=value`` overrides -> the scenario the controller runs with (never the one it is judged against).

input: a scenario and ``key=value`` texts (dotted paths into the scenario, values in YAML: ``tube.sigma_low=0.5``,
``mpc.Q=[1, 1, 1]``) -> output: a validated copy of the scenario. An unknown key, a malformed value or a value the
scenario model refuses raises ``OverrideError`` naming the override.
"""

from __future__ import annotations

import copy
from collections.abc import Sequence
from typing import Any

import yaml
from pydantic import ValidationError

from tubempc.errors import OverrideError
from tubempc.scenario import Scenario

__all__ = ["OverrideError", "apply_overrides", "parse_override"]


def parse_override(text: str) -> tuple[list[str], Any]:
    """``"tube.sigma_low=0.5"`` -> (["tube", "sigma_low"], 0.5)."""
    key, sep, raw = text.partition("=")
    key = key.strip()
    if not sep or not key or any(not part for part in key.split(".")):
        raise OverrideError(f"--set {text!r}: expected key=value with a dotted key such as tube.sigma_low=0.5")
    try:
        value = yaml.safe_load(raw) if raw.strip() else None
    except yaml.YAMLError as err:
        raise OverrideError(f"--set {text!r}: the value is not valid YAML ({str(err).splitlines()[0]})") from None
    return key.split("."), value


def apply_overrides(scenario: Scenario, overrides: Sequence[str]) -> Scenario:
    """The scenario with every override applied (in order), validated like a scenario file."""
    if not overrides:
        return scenario
    data = copy.deepcopy(scenario.to_dict())
    for text in overrides:
        path, value = parse_override(text)
        node: Any = data
        for depth, part in enumerate(path):
            last = depth == len(path) - 1
            if isinstance(node, dict) and part in node:
                if last:
                    node[part] = value
                else:
                    node = node[part]
            elif isinstance(node, list) and part.isdigit() and int(part) < len(node):
                if last:
                    node[int(part)] = value
                else:
                    node = node[int(part)]
            else:
                where = ".".join(path[:depth + 1])
                raise OverrideError(f"--set {text!r}: the scenario has no field {where!r}")
    try:
        return Scenario.model_validate(data)
    except ValidationError as err:
        first = err.errors()[0]
        loc = ".".join(str(p) for p in first["loc"])
        msg = str(first["msg"]).removeprefix("Value error, ")
        raise OverrideError(f"--set {', '.join(overrides)}: {loc}: {msg}") from None
