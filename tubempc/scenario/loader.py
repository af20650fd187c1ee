"""Scenario files -> ``Scenario`` values; the built-in scenarios shipped with the package.

input: a YAML path, YAML text or a mapping -> output: a validated ``Scenario``; any problem raises
``ScenarioError`` naming the file, the field path and what is wrong (never a raw YAML or pydantic traceback).

Limits (refused with ``ScenarioError`` before any quadratic work): files up to ``MAX_SCENARIO_BYTES`` bytes and
``MAX_REGIONS`` regions; YAML nested too deeply is refused too.
"""

from __future__ import annotations

from importlib import resources
from pathlib import Path
from typing import Any

import yaml
from pydantic import ValidationError

from tubempc.errors import ScenarioError
from tubempc.scenario.model import Scenario

__all__ = ["BUILTIN_SCENARIOS", "builtin_scenario", "builtin_scenario_text", "dump_scenario", "load_scenario",
           "scenario_from_dict"]

BUILTIN_SCENARIOS = ("nexus-sml",)
#: largest scenario file read (bytes): a hand-written or generated lab description is far below it
MAX_SCENARIO_BYTES = 256 * 1024
#: most regions in one scenario (region checks compare pairs of regions)
MAX_REGIONS = 2000
_SafeLoader: Any = getattr(yaml, "CSafeLoader", yaml.SafeLoader)  # libyaml when built in: ~10x faster


def _field_path(loc: tuple[int | str, ...]) -> str:
    out = ""
    for part in loc:
        if isinstance(part, int):
            out += f"[{part}]"
        else:
            out += ("." if out else "") + part
    return out


def scenario_from_dict(data: Any, *, source: str = "<scenario>") -> Scenario:
    """Validate a mapping (as read from YAML) into a ``Scenario``."""
    if not isinstance(data, dict):
        raise ScenarioError(f"expected a mapping at the top level, got {type(data).__name__}", source=source)
    regions = data.get("regions")
    if isinstance(regions, list) and len(regions) > MAX_REGIONS:
        raise ScenarioError(f"{len(regions)} regions: at most {MAX_REGIONS} are accepted", source=source,
                            field="regions")
    try:
        return Scenario.model_validate(data)
    except ValidationError as err:
        first = err.errors()[0]
        field = _field_path(tuple(first["loc"])) or None
        msg = str(first["msg"]).removeprefix("Value error, ")
        if first["type"] == "missing":
            msg = "required field is missing"
        elif first["type"] == "extra_forbidden":
            msg = "unknown field (check the spelling)"
        more = len(err.errors()) - 1
        if more:
            msg += f" (and {more} more problem{'s' if more > 1 else ''})"
        raise ScenarioError(msg, source=source, field=field) from None


def load_scenario(path: str | Path) -> Scenario:
    """Read and validate a scenario YAML file, or a built-in scenario by name (``nexus-sml``)."""
    text_path = str(path)
    if text_path in BUILTIN_SCENARIOS and not Path(text_path).exists():
        return builtin_scenario(text_path)
    p = Path(path)
    try:
        size = p.stat().st_size
        if p.is_file() and size > MAX_SCENARIO_BYTES:
            raise ScenarioError(f"file of {size} bytes: scenario files are limited to {MAX_SCENARIO_BYTES} bytes",
                                source=str(p))
        if not p.is_file():
            raise ScenarioError("not a regular file", source=str(p))
        text = p.read_text(encoding="utf-8")
    except FileNotFoundError:
        raise ScenarioError(f"file not found, and not a built-in scenario name (built-in: "
                            f"{', '.join(sorted(BUILTIN_SCENARIOS))}; see `tubempc scenario list`)",
                            source=str(p)) from None
    except (OSError, UnicodeDecodeError) as err:
        raise ScenarioError(f"cannot read the file ({err.__class__.__name__}: {err})", source=str(p)) from None
    return _from_text(text, source=str(p))


def _from_text(text: str, *, source: str) -> Scenario:
    try:
        data = yaml.load(text, Loader=_SafeLoader)
    except yaml.YAMLError as err:
        mark = getattr(err, "problem_mark", None)
        where = f"line {mark.line + 1}, column {mark.column + 1}: " if mark is not None else ""
        problem = getattr(err, "problem", None) or str(err).splitlines()[0]
        raise ScenarioError(f"{where}invalid YAML ({problem})", source=source) from None
    except RecursionError:
        raise ScenarioError("invalid YAML (nested too deeply)", source=source) from None
    try:
        return scenario_from_dict(data, source=source)
    except RecursionError:
        raise ScenarioError("a value is nested too deeply", source=source) from None


def builtin_scenario_text(name: str = "nexus-sml") -> str:
    if name not in BUILTIN_SCENARIOS:
        raise ScenarioError(f"no built-in scenario named {name!r} (available: {', '.join(BUILTIN_SCENARIOS)})",
                            source=name)
    return resources.files("tubempc.scenario").joinpath("builtin", f"{name}.yaml").read_text(encoding="utf-8")


def builtin_scenario(name: str = "nexus-sml") -> Scenario:
    """The scenario shipped with the package (default: the paper's Nexus experiment)."""
    return _from_text(builtin_scenario_text(name), source=f"<builtin:{name}>")


def dump_scenario(scenario: Scenario) -> str:
    """YAML text that loads back to an equal scenario."""
    return yaml.safe_dump(scenario.to_dict(), sort_keys=False, default_flow_style=None, width=110)
