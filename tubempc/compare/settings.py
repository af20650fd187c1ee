"""Tolerances and confidence of ``compare`` -> a frozen ``CompareSettings``, from a small YAML and the command line.

input: an optional YAML file (``--tolerances FILE``, else ``<scenario>.compare.yaml`` beside a scenario file), and
command-line overrides -> output: ``CompareSettings`` (``tolerance(metric, before_median)``, ``confidence``).

The file::

    confidence: 0.95            # of the one-sided tests (default 0.95)
    tolerances:                 # allowed worsening: a number (abs) or {abs: A, rel: R} -> A + R * |median before|
      check_margin: 0.01        # a family (every check.<name>.margin) ...
      check.tube.margin: 0.002  # ... or one metric by name (wins over its family)
      entry_s: {abs: 0.5, rel: 0.02}

Families and their defaults (the units of the metric): ``check_margin`` 0.01 (the check's margin unit),
``min_clearance_m`` 0.01 m, ``workspace_margin_m`` 0.01 m, ``tube_ratio`` 0.05, ``input_usage`` 0.05,
``entry_s`` 0.5 s, ``transition_s`` 0.5 s. Verdicts have no tolerance; ``duration_s`` is never judged.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import yaml

from tubempc.compare.metrics import metric_info
from tubempc.errors import CompareInputError

__all__ = ["DEFAULT_CONFIDENCE", "DEFAULT_TOLERANCES", "CompareSettings", "Tolerance", "load_settings",
           "settings_path_for"]

DEFAULT_CONFIDENCE = 0.95


@dataclass(frozen=True, slots=True)
class Tolerance:
    """Allowed worsening ``abs + rel * |median before|`` in the metric's unit."""

    abs: float = 0.0
    rel: float = 0.0

    def __post_init__(self) -> None:
        for name in ("abs", "rel"):
            value = getattr(self, name)
            if not (math.isfinite(value) and value >= 0):
                raise ValueError(f"{name}={value!r} must be a finite number >= 0")

    def allowed(self, before_median: float) -> float:
        return self.abs + self.rel * abs(before_median)


DEFAULT_TOLERANCES: dict[str, Tolerance] = {
    "check_margin": Tolerance(0.01),
    "min_clearance_m": Tolerance(0.01),
    "workspace_margin_m": Tolerance(0.01),
    "tube_ratio": Tolerance(0.05),
    "input_usage": Tolerance(0.05),
    "entry_s": Tolerance(0.5),
    "transition_s": Tolerance(0.5),
}


@dataclass(frozen=True, slots=True)
class CompareSettings:
    """Tolerances per family or metric name, and the confidence of the one-sided tests; ``source`` says where
    they came from (for the report)."""

    tolerances: dict[str, Tolerance] = field(default_factory=lambda: dict(DEFAULT_TOLERANCES))
    confidence: float = DEFAULT_CONFIDENCE
    source: str = "defaults"

    def __post_init__(self) -> None:
        if not (0.5 <= self.confidence < 1):
            raise ValueError(f"confidence={self.confidence!r} must be in [0.5, 1)")

    @property
    def alpha(self) -> float:
        return round(1.0 - self.confidence, 12)  # 1 - 0.95 is 0.05000000000000004 in binary

    def tolerance(self, metric: str, family: str) -> Tolerance:
        """The metric's own tolerance, else its family's, else none (zero)."""
        return self.tolerances.get(metric) or self.tolerances.get(family) or Tolerance()


def settings_path_for(scenario: str) -> Path | None:
    """``<scenario stem>.compare.yaml`` beside a scenario file, when it exists (built-in names have none)."""
    path = Path(scenario)
    if not path.is_file():
        return None
    beside = path.with_name(f"{path.stem}.compare.yaml")
    return beside if beside.is_file() else None


def _tolerance(value: Any, where: str) -> Tolerance:
    try:
        if isinstance(value, int | float) and not isinstance(value, bool):
            return Tolerance(float(value))
        if isinstance(value, dict) and set(value) <= {"abs", "rel"} and all(
                isinstance(v, int | float) and not isinstance(v, bool) for v in value.values()):
            return Tolerance(float(value.get("abs", 0.0)), float(value.get("rel", 0.0)))
    except ValueError as err:
        raise CompareInputError(f"{where}: {err}") from None
    raise CompareInputError(f"{where}: expected a number (abs) or {{abs: A, rel: R}}, got {value!r}")


def _check_name(name: str, where: str) -> str:
    """A tolerance must name a family or a judged numeric metric (a typo would otherwise be silently ignored)."""
    info = metric_info(name)
    if name in DEFAULT_TOLERANCES or (info.kind == "number" and info.direction != "neutral"):
        return name
    what = "verdicts have no tolerance" if info.kind == "verdict" else "names no judged metric or family"
    raise CompareInputError(f"{where}: {name!r} {what} (families: {', '.join(DEFAULT_TOLERANCES)}; or a metric "
                            f"such as check.tube.margin)")


def parse_override(text: str) -> tuple[str, Tolerance]:
    """``--tol NAME=ABS`` or ``NAME=ABS+RELx`` (e.g. ``entry_s=0.5+0.02x``) -> (name, tolerance)."""
    name, sep, value = text.partition("=")
    abs_text, plus, rel_text = value.partition("+")
    try:
        abs_v = float(abs_text)
        rel_v = float(rel_text.removesuffix("x")) if plus else 0.0
        if not sep or not name.strip():
            raise ValueError(text)
        return name.strip(), Tolerance(abs_v, rel_v)
    except ValueError:
        raise CompareInputError(f"--tol {text!r}: expected NAME=ABS or NAME=ABS+RELx with numbers >= 0, "
                                f"e.g. check_margin=0.01 or entry_s=0.5+0.02x") from None


def load_settings(path: str | Path | None, *, overrides: tuple[str, ...] = (),
                  confidence: float | None = None) -> CompareSettings:
    """Defaults, then the YAML at ``path`` (if any), then the command line's ``--tol`` and ``--confidence``."""
    tolerances = dict(DEFAULT_TOLERANCES)
    conf = DEFAULT_CONFIDENCE
    source = "defaults"
    if path is not None:
        p = Path(path)
        try:
            data = yaml.safe_load(p.read_text(encoding="utf-8"))
        except OSError as err:
            raise CompareInputError(f"{p}: cannot read the tolerances ({err.strerror or err})") from None
        except (UnicodeDecodeError, yaml.YAMLError) as err:
            raise CompareInputError(f"{p}: not a YAML file ({err.__class__.__name__})") from None
        data = {} if data is None else data
        if not isinstance(data, dict) or not set(data) <= {"confidence", "tolerances"}:
            raise CompareInputError(f"{p}: expected a mapping with 'confidence' and/or 'tolerances'")
        raw = data.get("tolerances") or {}
        if not isinstance(raw, dict):
            raise CompareInputError(f"{p}: tolerances: expected a mapping of metric or family names")
        for name, value in raw.items():
            tolerances[_check_name(str(name), f"{p}: tolerances")] = _tolerance(value, f"{p}: tolerances.{name}")
        if "confidence" in data:
            value = data["confidence"]
            if isinstance(value, bool) or not isinstance(value, int | float) or not 0.5 <= value < 1:
                raise CompareInputError(f"{p}: confidence: expected a number in [0.5, 1), got {value!r}")
            conf = float(value)
        source = str(p)
    for text in overrides:
        name, tol = parse_override(text)
        tolerances[_check_name(name, f"--tol {text!r}")] = tol
    if confidence is not None:
        if not 0.5 <= confidence < 1:
            raise CompareInputError(f"--confidence {confidence!r}: expected a number in [0.5, 1)")
        conf = confidence
    if overrides or confidence is not None:
        source = f"{source} + command line"
    return CompareSettings(tolerances, conf, source)
