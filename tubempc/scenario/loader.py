"""Scenario files -> ``Scenario`` values; the built-in scenarios shipped with the package.

input: a YAML path, YAML text or a mapping -> output: a validated ``Scenario``; any problem raises
``ScenarioError`` naming the file, the field path and what is wrong (never a raw YAML or pydantic traceback).

Limits (refused with ``ScenarioError`` before any quadratic work): files up to ``MAX_SCENARIO_BYTES`` bytes and
``MAX_REGIONS`` regions; YAML nested too deeply is refused too.
"""

from __future__ import annotations

import difflib
from importlib import resources
from pathlib import Path
from typing import Any, get_args

import yaml
from pydantic import BaseModel, ValidationError

from tubempc.errors import ScenarioError
from tubempc.scenario.model import Scenario

__all__ = ["BUILTIN_SCENARIOS", "builtin_scenario", "builtin_scenario_text", "dump_scenario", "load_scenario",
           "scenario_from_dict"]

BUILTIN_SCENARIOS = ("nexus-sml",)
#: largest scenario file read (bytes): a hand-written or generated lab description is far below it
MAX_SCENARIO_BYTES = 256 * 1024
#: most regions in one scenario (region checks compare pairs of regions)
MAX_REGIONS = 2000
_BaseLoader: Any = getattr(yaml, "CSafeLoader", yaml.SafeLoader)  # libyaml when built in: ~10x faster


class _SafeLoader(_BaseLoader):  # type: ignore[misc]  # libyaml's loader is untyped
    """The safe loader, with integers Python cannot convert (more than ``sys.get_int_max_str_digits()`` digits)
    refused as a YAML error at their line and column (PyYAML lets that ``ValueError`` escape)."""


def _construct_int(loader: Any, node: yaml.ScalarNode) -> int:
    try:
        return int(yaml.constructor.SafeConstructor.construct_yaml_int(loader, node))
    except ValueError:
        digits = sum(c.isdigit() for c in str(node.value))
        raise yaml.constructor.ConstructorError(None, None, f"an integer of {digits} digits is out of range",
                                                node.start_mark) from None


_SafeLoader.add_constructor("tag:yaml.org,2002:int", _construct_int)


def _field_path(loc: tuple[int | str, ...], data: Any = None) -> str:
    """``("regions", 3, "radius")`` -> ``regions[3] (name).radius``: a region is named when the data names it."""
    out = ""
    node = data
    for part in loc:
        if isinstance(part, int):
            out += f"[{part}]"
            node = node[part] if isinstance(node, list) and 0 <= part < len(node) else None
            name = node.get("name") if isinstance(node, dict) else None
            if out.startswith("regions[") and isinstance(name, str) and out.count("[") == 1:
                out += f" ({name})"
        else:
            out += ("." if out else "") + part
            node = node.get(part) if isinstance(node, dict) else None
    return out


def _model_at(loc: tuple[int | str, ...]) -> type[BaseModel] | None:
    """The model class whose fields sit at ``loc`` inside a ``Scenario`` (None when it is not a model)."""
    model: type[BaseModel] = Scenario
    for part in loc:
        if isinstance(part, int):
            continue
        field = next((f for name, f in model.model_fields.items() if part in (name, f.alias)), None)
        if field is None:  # a key of a mapping (a signal's name): the model stays the mapping's value type
            continue
        found = _models_in(field.annotation)
        if not found:
            return None
        model = found[0]
    return model


def _models_in(annotation: Any) -> list[type[BaseModel]]:
    if isinstance(annotation, type) and issubclass(annotation, BaseModel):
        return [annotation]
    return [m for arg in get_args(annotation) for m in _models_in(arg)]


def _unknown_field(loc: tuple[int | str, ...]) -> str:
    """An unknown key, with the closest known one and the keys its block takes."""
    model = _model_at(loc[:-1])
    if model is None:
        return "unknown field (check the spelling)"
    known = [f.alias or name for name, f in model.model_fields.items()]
    close = difflib.get_close_matches(str(loc[-1]), known, n=1, cutoff=0.6)
    hint = f"did you mean {close[0]}? " if close else ""
    where = _field_path(loc[:-1]) or "the top level"
    return f"unknown field ({hint}{where} takes: {', '.join(known)})"


def _problem(error: Any, data: Any) -> tuple[str | None, str]:
    loc = tuple(error["loc"])
    msg = str(error["msg"]).removeprefix("Value error, ")
    if error["type"] == "missing":
        msg = "required field is missing"
    elif error["type"] == "extra_forbidden":
        msg = _unknown_field(loc)
    return _field_path(loc, data) or None, msg


def scenario_from_dict(data: Any, *, source: str = "<scenario>") -> Scenario:
    """Validate a mapping (as read from YAML) into a ``Scenario``; a ``ScenarioError`` lists every problem found
    (unknown keys first: a misspelt key is the likely cause of a "missing" one), ``field`` names the first."""
    if not isinstance(data, dict):
        raise ScenarioError(f"expected a mapping at the top level, got {type(data).__name__}", source=source)
    regions = data.get("regions")
    if isinstance(regions, list) and len(regions) > MAX_REGIONS:
        raise ScenarioError(f"{len(regions)} regions: at most {MAX_REGIONS} are accepted", source=source,
                            field="regions")
    try:
        return Scenario.model_validate(data)
    except ValidationError as err:
        errors = sorted(err.errors(), key=lambda e: e["type"] != "extra_forbidden")
        problems = [_problem(e, data) for e in errors]
    first_field = _field_path(tuple(errors[0]["loc"])) or None
    if len(problems) == 1:
        field, msg = problems[0]
        error = ScenarioError(msg, source=source, field=field)
    else:
        listed = "; ".join(f"{f}: {m}" if f else m for f, m in problems)
        error = ScenarioError(f"{len(problems)} problems: {listed}", source=source)
    error.field = first_field  # the path alone (regions[3].radius), for programs
    raise error from None


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
        field = _key_path_at(text, mark.index) if isinstance(err, yaml.constructor.ConstructorError) and mark else None
        raise ScenarioError(f"{where}invalid YAML ({problem})", source=source, field=field) from None
    except RecursionError:
        raise ScenarioError("invalid YAML (nested too deeply)", source=source) from None
    try:
        return scenario_from_dict(data, source=source)
    except RecursionError:
        raise ScenarioError("a value is nested too deeply", source=source) from None


def _key_path_at(text: str, index: int) -> str | None:
    """The key path (``mocap.rate_hz``, ``regions[2].radius``) of the YAML value that starts at ``index``."""

    def walk(node: yaml.Node, path: str) -> str | None:
        if node.start_mark.index == index and isinstance(node, yaml.ScalarNode):
            return path
        if isinstance(node, yaml.MappingNode):
            for key, value in node.value:
                name = str(key.value) if isinstance(key, yaml.ScalarNode) else "?"
                found = walk(value, f"{path}.{name}" if path else name)
                if found is not None:
                    return found
        elif isinstance(node, yaml.SequenceNode):
            for k, item in enumerate(node.value):
                found = walk(item, f"{path}[{k}]")
                if found is not None:
                    return found
        return None

    try:
        root = yaml.compose(text, Loader=_BaseLoader)
    except (yaml.YAMLError, RecursionError):
        return None
    return None if root is None else walk(root, "") or None


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
