"""Regression suite files -> validated ``Suite`` values and the list of runs they stand for.

input: a suite YAML (scenarios with their runs x seeds x disturbance models, tolerances per metric, and optional
falsification cases) -> output: a frozen ``Suite`` and, by ``expand_suite``, one ``RunCase`` per (scenario, run,
disturbance, seed); by ``expand_falsify``, one ``FalsifyCase`` per falsification case (a search with its budget).
Scenario references are built-in names (``nexus-sml``) or paths relative to the suite file. Every problem raises
``SuiteError`` naming the file and the field.
"""

from __future__ import annotations

import hashlib
import json
from dataclasses import dataclass
from importlib import resources
from pathlib import Path
from typing import Annotated, Any, Literal

import yaml
from pydantic import BaseModel, ConfigDict, Field, ValidationError, field_validator, model_validator

from tubempc.control.disturbance import DISTURBANCE_MODELS
from tubempc.errors import SuiteError
from tubempc.mitl import parse
from tubempc.scenario import Scenario, load_scenario
from tubempc.scenario.transition import derived_spec

__all__ = [
    "DEFAULT_SUITE",
    "FalsifyCase",
    "FalsifySpec",
    "RunCase",
    "RunSpec",
    "Suite",
    "SuiteError",
    "SuiteScenario",
    "TargetSpec",
    "Tolerance",
    "Tolerances",
    "default_suite_path",
    "expand_falsify",
    "expand_suite",
    "load_suite",
]

DEFAULT_SUITE = "default-suite.yaml"
SCENARIO_SPEC = "scenario"  # a run's ``spec: scenario`` certifies against the scenario's own formula
_NAME = r"^[A-Za-z0-9][A-Za-z0-9_.-]*$"


class _Frozen(BaseModel):
    model_config = ConfigDict(frozen=True, extra="forbid")


class Tolerance(_Frozen):
    """Allowed worsening: ``abs + rel * |baseline|`` (in the metric's unit). A bare number in YAML is ``abs``."""

    abs: Annotated[float, Field(ge=0, allow_inf_nan=False)] = 0.0
    rel: Annotated[float, Field(ge=0, allow_inf_nan=False)] = 0.0

    @model_validator(mode="before")
    @classmethod
    def _number_is_abs(cls, data: Any) -> Any:
        if isinstance(data, int | float) and not isinstance(data, bool):
            return {"abs": data}
        return data

    def allowed(self, baseline: float) -> float:
        return self.abs + self.rel * abs(baseline)


class Tolerances(_Frozen):
    """Per-metric tolerances. Verdicts have none: any worsening (pass -> inconclusive -> fail) regresses."""

    t_ij_s: Tolerance = Tolerance(abs=0.3)  # transition time (Algorithm 1), s; slower is worse
    tube_ratio: Tolerance = Tolerance(abs=0.05)  # max |x - x_hat| / r_q; larger is worse
    max_tube_error_m: Tolerance = Tolerance(abs=0.002)
    min_clearance_m: Tolerance = Tolerance(abs=0.01)  # robot disc to the nearest unsafe region; smaller is worse
    input_margin: Tolerance = Tolerance(abs=0.01)  # min over time and axes of max_abs_i - |u_i|; smaller is worse
    workspace_margin_m: Tolerance = Tolerance(abs=0.01)
    check_margin: Tolerance = Tolerance(abs=0.01)  # every certificate check's margin; smaller is worse
    solver_failures: Tolerance = Tolerance(abs=0)
    solver_backups: Tolerance = Tolerance(abs=0)
    # solve times depend on the machine and its load (a loaded 2-core runner showed 3-5x): by default only a gross
    # slow-down (> 5x + a few ms) fails; tighten on a dedicated runner
    solve_time_p50_ms: Tolerance = Tolerance(abs=5.0, rel=4.0)
    solve_time_p95_ms: Tolerance = Tolerance(abs=10.0, rel=4.0)


class TargetSpec(_Frozen):
    """A controller target: a region, and optionally the time until which the robot holds there."""

    region: str
    depart_after_s: Annotated[float, Field(ge=0, allow_inf_nan=False)] | None = None

    @model_validator(mode="before")
    @classmethod
    def _bare_name(cls, data: Any) -> Any:
        return {"region": data} if isinstance(data, str) else data


class RunSpec(_Frozen):
    """One closed-loop run: start region, targets, and the formula its log is certified against.

    ``spec``: MITL text; ``scenario`` for the scenario's own formula; absent for the derived formula (stay clear
    of every unsafe region, and eventually satisfy a label of the last target if it has one).
    """

    name: Annotated[str, Field(pattern=_NAME)]
    start: str
    targets: tuple[TargetSpec, ...] = Field(min_length=1)
    spec: str | None = None
    t_end_s: Annotated[float, Field(gt=0, allow_inf_nan=False)] | None = None

    @field_validator("spec")
    @classmethod
    def _spec_parses(cls, v: str | None) -> str | None:
        if v is not None and v != SCENARIO_SPEC:
            parse(v)
        return v


class SuiteScenario(_Frozen):
    name: Annotated[str, Field(pattern=_NAME)]
    scenario: str  # a built-in name or a path relative to the suite file
    runs: tuple[RunSpec, ...] = Field(min_length=1)


class FalsifySpec(_Frozen):
    """A falsification case: search one run of a suite scenario with a budget of simulations (``tubempc
    falsify``); the suite regresses when it finds a counterexample where the baseline found none."""

    name: Annotated[str, Field(pattern=_NAME)]
    scenario: str  # the name of one of the suite's scenarios
    start: str | None = None  # default: the scenario's initial region
    target: str | None = None  # one transition; or
    plan: bool = False  # the scenario's planned mission
    method: Literal["random", "targeted", "optimizer"] = "optimizer"
    budget: Annotated[int, Field(ge=1)] = 20
    seed: Annotated[int, Field(ge=0)] = 0
    family: Literal["steps", "sine", "switch"] = "steps"
    knots: Annotated[int, Field(ge=1)] = 4
    switches: Annotated[int, Field(ge=1)] = 3
    bound_scale: Annotated[float, Field(gt=0, allow_inf_nan=False)] = 1.0
    fixed_start: bool = False

    @model_validator(mode="after")
    def _one_run(self) -> FalsifySpec:
        if self.plan == (self.target is not None):
            raise ValueError("give either target (one transition) or plan: true")
        return self


class Suite(_Frozen):
    name: Annotated[str, Field(pattern=_NAME)]
    scenarios: tuple[SuiteScenario, ...] = Field(min_length=1)
    seeds: tuple[Annotated[int, Field(ge=0)], ...] = Field(min_length=1)
    disturbances: tuple[str, ...] = Field(min_length=1)
    mocap_noise_m: Annotated[float, Field(ge=0, allow_inf_nan=False)] = 0.0
    tolerances: Tolerances = Tolerances()
    falsify: tuple[FalsifySpec, ...] = ()

    @field_validator("disturbances")
    @classmethod
    def _known_models(cls, v: tuple[str, ...]) -> tuple[str, ...]:
        unknown = [d for d in v if d not in DISTURBANCE_MODELS]
        if unknown:
            raise ValueError(f"unknown disturbance model(s) {unknown} (known: {', '.join(DISTURBANCE_MODELS)})")
        return v

    @model_validator(mode="after")
    def _unique_names(self) -> Suite:
        names = [s.name for s in self.scenarios]
        if len(set(names)) != len(names):
            raise ValueError(f"scenarios: duplicate names in {names}")
        for s in self.scenarios:
            runs = [r.name for r in s.runs]
            if len(set(runs)) != len(runs):
                raise ValueError(f"scenarios ({s.name}): duplicate run names in {runs}")
        cases = [f.name for f in self.falsify]
        if len(set(cases)) != len(cases):
            raise ValueError(f"falsify: duplicate case names in {cases}")
        for f in self.falsify:
            if f.scenario not in names:
                raise ValueError(f"falsify ({f.name}): scenario {f.scenario!r} is not one of the suite's {names}")
        return self

    def sha256(self) -> str:
        data = self.model_dump(mode="json")
        if not data["falsify"]:
            del data["falsify"]  # suites without falsification cases keep the hash they had before the field
        blob = json.dumps(data, sort_keys=True, separators=(",", ":")).encode()
        return hashlib.sha256(blob).hexdigest()


def _field_path(loc: tuple[int | str, ...]) -> str:
    out = ""
    for part in loc:
        out += f"[{part}]" if isinstance(part, int) else ("." if out else "") + part
    return out


def default_suite_path() -> Path:
    """The suite shipped with the package (the built-in scenario, a few transitions, two disturbance models)."""
    return Path(str(resources.files("tubempc.regress").joinpath(DEFAULT_SUITE)))


@dataclass(frozen=True, slots=True)
class LoadedSuite:
    """A validated suite with its scenarios loaded (keyed by the suite's scenario names) and its source."""

    suite: Suite
    scenarios: dict[str, Scenario]
    source: str
    scenario_refs: dict[str, str] | None = None  # suite scenario name -> the file path or built-in name it loaded


def load_suite(path: str | Path | None = None) -> LoadedSuite:
    """Read, validate and resolve a suite file (default: the shipped default suite)."""
    p = Path(path) if path is not None else default_suite_path()
    source = str(p)
    try:
        data = yaml.safe_load(p.read_text(encoding="utf-8"))
    except FileNotFoundError:
        raise SuiteError("file not found", source=source) from None
    except (OSError, UnicodeDecodeError) as err:
        raise SuiteError(f"cannot read the file ({err.__class__.__name__}: {err})", source=source) from None
    except yaml.YAMLError as err:
        raise SuiteError(f"invalid YAML ({str(err).splitlines()[0]})", source=source) from None
    if not isinstance(data, dict):
        raise SuiteError(f"expected a mapping at the top level, got {type(data).__name__}", source=source)
    try:
        suite = Suite.model_validate(data)
    except ValidationError as err:
        first = err.errors()[0]
        msg = str(first["msg"]).removeprefix("Value error, ")
        if first["type"] == "extra_forbidden":
            msg = "unknown field (check the spelling)"
        raise SuiteError(msg, source=source, field=_field_path(tuple(first["loc"])) or None) from None
    scenarios: dict[str, Scenario] = {}
    refs: dict[str, str] = {}
    for i, entry in enumerate(suite.scenarios):
        ref = entry.scenario
        candidate = p.parent / ref
        refs[entry.name] = str(candidate) if candidate.exists() else ref
        scenario = load_scenario(refs[entry.name])
        names = {r.name for r in scenario.regions}
        for j, run in enumerate(entry.runs):
            for where, region in [("start", run.start)] + [(f"targets[{k}]", t.region)
                                                           for k, t in enumerate(run.targets)]:
                if region not in names:
                    raise SuiteError(f"region {region!r} is not in scenario {scenario.name!r}", source=source,
                                     field=f"scenarios[{i}].runs[{j}].{where}")
        scenarios[entry.name] = scenario
    for i, case in enumerate(suite.falsify):
        names = {r.name for r in scenarios[case.scenario].regions}
        for where, maybe in (("start", case.start), ("target", case.target)):
            if maybe is not None and maybe not in names:
                raise SuiteError(f"region {maybe!r} is not in scenario {scenarios[case.scenario].name!r}",
                                 source=source, field=f"falsify[{i}].{where}")
    return LoadedSuite(suite, scenarios, source, refs)


@dataclass(frozen=True, slots=True)
class RunCase:
    """One run of the suite, ready to execute in any process (all fields picklable)."""

    run_id: str
    scenario: Scenario
    start: str
    targets: tuple[tuple[str, float | None], ...]
    spec: str
    disturbance: str
    seed: int
    t_end_s: float | None
    mocap_noise_m: float


def expand_suite(loaded: LoadedSuite) -> list[RunCase]:
    """scenario x run x disturbance x seed, in a stable order; ids ``<scenario>.<run>.<disturbance>.s<seed>``."""
    cases = []
    suite = loaded.suite
    for entry in suite.scenarios:
        scenario = loaded.scenarios[entry.name]
        for run in entry.runs:
            if run.spec is None:
                spec = derived_spec(scenario, run.targets[-1].region)
            else:
                spec = scenario.spec if run.spec == SCENARIO_SPEC else run.spec
            targets = tuple((t.region, t.depart_after_s) for t in run.targets)
            for disturbance in suite.disturbances:
                for seed in suite.seeds:
                    cases.append(RunCase(f"{entry.name}.{run.name}.{disturbance}.s{seed}", scenario, run.start,
                                         targets, spec, disturbance, seed, run.t_end_s, suite.mocap_noise_m))
    return cases


@dataclass(frozen=True, slots=True)
class FalsifyCase:
    """One falsification case of the suite, ready to run in any process (``spec`` as in ``FalsifySpec``)."""

    run_id: str
    scenario: Scenario
    scenario_ref: str
    spec: FalsifySpec


def expand_falsify(loaded: LoadedSuite) -> list[FalsifyCase]:
    """The suite's falsification cases, ids ``<scenario>.falsify.<case>``."""
    refs = loaded.scenario_refs or {}
    return [FalsifyCase(f"{f.scenario}.falsify.{f.name}", loaded.scenarios[f.scenario],
                        refs.get(f.scenario, loaded.scenarios[f.scenario].name), f) for f in loaded.suite.falsify]
