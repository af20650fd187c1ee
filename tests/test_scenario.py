"""Scenario model: the built-in Nexus setup, YAML round trip, and errors that name the file and the field."""

from __future__ import annotations

import math
from pathlib import Path
from typing import Any

import pytest
import yaml

from tubempc.errors import ScenarioError
from tubempc.scenario import builtin_scenario, builtin_scenario_text, dump_scenario, load_scenario, scenario_from_dict

ISSUE_EXAMPLE = """
name: nexus-sml
workspace: {x: [-2.5, 2.5], y: [-2.5, 2.5]}          # metres
robot: {radius: 0.27}                                 # eta: the robot disc
inputs: {max_abs: [0.2, 0.2, 0.2]}                    # |u_i| bounds (vx, vy, wz)
disturbance: {bound: 0.02}                            # delta_bar
tube: {sigma_low: 2.0, radius: 0.01}                  # radius optional: derived from the model when absent
mpc: {h: 0.1, horizon: 1.2, Q: [0.5, 0.5, 0.5], R: [0.5, 0.5, 0.5], P: [0.5, 0.5, 0.5]}
regions:
  - {name: R1, center: [-1.99, -1.78], radius: 0.45, labels: [mission_1]}
  - {name: R6, center: [-1.11, 0.54], radius: 0.45, labels: [obs_1], unsafe: true}
initial_region: R1
spec: "G[0,inf) !(obs_1 | obs_2 | obs_3 | obs_4) & F[30,50] mission_2 & F[80,110] mission_1"
topics: {pose: /qualisys/nexus/pose, cmd_vel: /nexus/cmd_vel, nominal: /nexus/nominal_pose}
"""


def _example() -> dict[str, Any]:
    data: dict[str, Any] = yaml.safe_load(ISSUE_EXAMPLE)
    # the issue's excerpt names atoms of regions it leaves out: add them so the spec is consistent
    data["regions"] += [
        {"name": "R3", "center": [0.16, 0.40], "radius": 0.45, "labels": ["mission_2"]},
        {"name": "R7", "center": [0.79, 1.49], "radius": 0.45, "labels": ["obs_2"], "unsafe": True},
        {"name": "R8", "center": [0.16, -1.41], "radius": 0.45, "labels": ["obs_3"], "unsafe": True},
        {"name": "R9", "center": [2.02, 0.04], "radius": 0.45, "labels": ["obs_4"], "unsafe": True},
    ]
    return data


def test_issue_fields_are_accepted_exactly_as_written() -> None:
    s = scenario_from_dict(_example())
    assert s.tube.radius == 0.01
    assert s.mpc.steps == 12
    assert s.inputs.max_abs == (0.2, 0.2, 0.2)
    assert s.region("R6").unsafe and s.region("R6").labels == ("obs_1",)
    assert s.topics.pose == "/qualisys/nexus/pose"


def test_builtin_scenario_is_the_paper_setup() -> None:
    s = builtin_scenario()
    assert [r.name for r in s.regions] == [f"R{i}" for i in range(1, 10)]
    assert {r.name for r in s.unsafe_regions} == {"R6", "R7", "R8", "R9"}
    assert s.labels()["R1"] == ("mission_1",) and s.labels()["R3"] == ("mission_2",)
    assert s.mpc.Q == s.mpc.R == s.mpc.P == (0.5, 0.5, 0.5)
    assert s.mpc.horizon == pytest.approx(1.2)
    assert s.inputs.max_abs == (0.2, 0.2, 0.2)
    assert str(s.formula) == (
        "G[0,inf) !(obs_1 | obs_2 | obs_3 | obs_4) & F[30,50] mission_2 & F[80,110] mission_1")
    for r in s.regions:
        assert s.workspace.contains_disc(r.center, r.radius), r.name
        assert r.radius > s.robot.radius, r.name
    # the terminal ball plus a 1 cm tube keeps the robot disc inside every safe region
    assert s.mpc.terminal_radius_m + 0.01 + s.robot.radius < min(r.radius for r in s.safe_regions)


def test_yaml_round_trip(tmp_path: Path) -> None:
    s = builtin_scenario()
    path = tmp_path / "s.yaml"
    path.write_text(dump_scenario(s))
    s2 = load_scenario(path)
    assert s2 == s and s2.sha256() == s.sha256()
    assert load_scenario("nexus-sml") == s
    assert "R9" in builtin_scenario_text()


def test_scenario_values_are_frozen() -> None:
    s = builtin_scenario()
    with pytest.raises(Exception, match="frozen"):
        s.name = "other"  # type: ignore[misc]
    assert hash(s) == hash(builtin_scenario())


def _broken(**changes: Any) -> dict[str, Any]:
    data = _example()
    for path, value in changes.items():
        target: Any = data
        keys = path.split("__")
        for k in keys[:-1]:
            target = target[int(k)] if k.isdigit() else target[k]
        last = keys[-1]
        if value is ...:
            del target[last]
        elif last.isdigit():
            target[int(last)] = value
        else:
            target[last] = value
    return data


@pytest.mark.parametrize(
    ("changes", "field", "fragment"),
    [
        ({"robot__radius": -0.1}, "robot.radius", "greater than 0"),
        ({"workspace__x": [1, -1]}, "workspace", "must be below"),
        ({"inputs__max_abs": [0.2, 0.2]}, "inputs", "holonomic model takes 3 bounds"),
        ({"inputs__model": "unicycle"}, "inputs", "unicycle model takes 2 bounds"),
        ({"mpc__h": 0.7}, "mpc", "not a whole number of steps"),
        ({"initial_region": "R42"}, None, "initial_region: 'R42' is not one of the regions"),
        ({"spec": "F[30,50 mission_2"}, "spec", "column 9"),
        ({"spec": "F[0,10] mission_9"}, None, "mission_9 label no region"),
        ({"robot__radiuss": 0.3}, "robot.radiuss", "unknown field"),
        ({"workspace__polygon": [[0, 0], [1, 0], [0, 1]]}, "workspace", "not both"),
        ({"regions__0__polygon": [[0, 0], [1, 0], [1, 1]]}, "regions[0]", "not both"),
        ({"regions__0__radius": ...}, "regions[0]", "give a disc"),
        ({"checks": ["spec", "speed"]}, "checks[1]", "Input should be"),
        ({"checks": []}, "checks", "at least one check"),
        ({"topics__pose": "no slash"}, "topics.pose", "must start with '/'"),
        ({"regions__0__name": "bad name"}, "regions[0].name", "pattern"),
        ({"regions__0__center": [float("nan"), 0.0]}, "regions[0].center[0]", "finite"),
    ],
)
def test_errors_name_file_and_field(changes: dict[str, Any], field: str | None, fragment: str) -> None:
    with pytest.raises(ScenarioError) as info:
        scenario_from_dict(_broken(**changes), source="lab.yaml")
    msg = str(info.value)
    assert msg.startswith("lab.yaml: "), msg
    assert isinstance(info.value, ValueError)
    if field is not None:
        assert info.value.field == field, msg
    assert fragment in msg


@pytest.mark.parametrize(
    ("changes", "field", "fragment"),
    [
        ({"regions__0__radius": 0.2}, "regions[0]", "cannot contain the robot disc"),
        ({"regions__0__center": [2.4, 0.0]}, "regions[0]", "does not fit inside the workspace"),
        ({"regions__1__center": [-1.99, -1.5]}, "regions", "overlap"),
        ({"disturbance": ...}, "disturbance", "required for planning"),
        ({"mpc": ...}, "mpc", "required for planning"),
        ({"tube": ...}, "tube", "required for planning"),
        ({"initial_region": ...}, "initial_region", "required for planning"),
        ({"inputs__model": "unicycle", "inputs__max_abs": [0.3, 1.0]}, "inputs.model", "fully actuated"),
        ({"regions__0__radius": ..., "regions__0__center": ..., "regions__0__polygon": [[-2.4, -2.4], [-1.4, -2.4],
                                                                                       [-1.4, -1.4]]},
         "regions[0]", "polygon"),
    ],
)
def test_certification_accepts_what_the_planner_refuses(changes: dict[str, Any], field: str, fragment: str) -> None:
    """Lenient for the certifier (the scenario loads), strict for the planner (ScenarioError naming the field)."""
    sc = scenario_from_dict(_broken(**changes), source="lab.yaml")
    with pytest.raises(ScenarioError) as info:
        sc.require_planning()
    assert info.value.field == field, str(info.value)
    assert fragment in str(info.value)
    assert builtin_scenario().planning_problems() == []


def test_certification_warnings_name_the_field() -> None:
    poke = scenario_from_dict(_broken(regions__0__center=[-2.06, -1.78]), source="lab.yaml")  # 1 cm past the wall
    assert poke.certification_warnings() == ["regions[0] (R1): reaches outside the workspace box"]
    nested = _broken()
    nested["regions"].append({"name": "room", "polygon": [[-2.5, -2.5], [-1.0, -2.5], [-1.0, -1.0], [-2.5, -1.0]],
                              "labels": ["in_room"]})
    warnings = scenario_from_dict(nested).certification_warnings()
    k = len(nested["regions"]) - 1
    assert any(f"regions[0] (R1) and regions[{k}] (room) may overlap" in w for w in warnings), warnings
    assert builtin_scenario().certification_warnings() == []
    ell = _broken()
    ell["workspace"] = {"polygon": [[-2.5, -2.5], [2.5, -2.5], [2.5, 0.0], [0.0, 0.0], [0.0, 2.5], [-2.5, 2.5]]}
    # the L-shape lacks the quarter x > 0, y > 0: R7 lies in it, R3 and R9 straddle its edges, the others are inside
    outside = scenario_from_dict(ell).certification_warnings()
    assert [w for w in outside if "workspace" in w] == [
        f"regions[{k}] ({n}): reaches outside the workspace polygon" for k, n in ((2, "R3"), (3, "R7"), (5, "R9"))]


def test_optional_fields_keep_the_form_and_the_hash() -> None:
    sc = builtin_scenario()
    again = scenario_from_dict(sc.to_dict())
    assert again == sc and again.sha256() == sc.sha256()
    assert "checks" not in sc.to_dict() and "model" not in sc.to_dict()["inputs"]
    minimal = _broken(disturbance=..., tube=..., mpc=..., initial_region=..., topics={"pose": "/odom"})
    m = scenario_from_dict(minimal)
    assert m.topics.cmd_vel is None and m.topics.nominal is None
    assert scenario_from_dict(m.to_dict()) == m
    with pytest.raises(ScenarioError, match="mpc: required for planning"):
        _ = m.mpc


@pytest.mark.parametrize(
    "polygon",
    [
        [[0, 0], [1, 0]],  # too few
        [[0, 0], [1, 1], [1, 0], [0, 1]],  # bow tie (zero signed area: its edges cross)
        [[0, 0], [2, 2], [2, 0], [0, 1]],  # bow tie (edges cross)
        [[0, 0], [1, 0], [2, 0]],  # zero area
        [[0, 0], [1, 0], [1, 1], [0, 0]],  # repeated vertex
        [[0, 0], [2, 0], [1, 0], [1, 1]],  # folds back on itself
    ],
)
def test_non_simple_polygons_are_refused(polygon: list[list[float]]) -> None:
    data = _broken()
    data["regions"].append({"name": "bad", "polygon": polygon})
    with pytest.raises(ScenarioError) as info:
        scenario_from_dict(data, source="lab.yaml")
    assert info.value.field == f"regions[{len(data['regions']) - 1}]", str(info.value)


def test_file_errors(tmp_path: Path) -> None:
    with pytest.raises(ScenarioError, match="file not found"):
        load_scenario(tmp_path / "missing.yaml")
    bad = tmp_path / "bad.yaml"
    bad.write_text("name: [unclosed\n")
    with pytest.raises(ScenarioError, match=r"bad.yaml: line \d+, column \d+: invalid YAML"):
        load_scenario(bad)
    bad.write_text("- just a list\n")
    with pytest.raises(ScenarioError, match="expected a mapping"):
        load_scenario(bad)


def test_derived_quantities() -> None:
    s = builtin_scenario()
    assert s.max_speed_mps == pytest.approx(math.hypot(0.2, 0.2))
    assert s.mpc.terminal_radius_m == pytest.approx(0.07 / math.sqrt(0.5))
