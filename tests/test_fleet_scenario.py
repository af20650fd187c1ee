"""The scenario's ``robots:`` block: several robots share workspace, regions and formula; atoms are qualified."""

from __future__ import annotations

import subprocess
import sys
from pathlib import Path
from typing import Any

import pytest
import yaml

from tubempc.scenario import ScenarioError, load_scenario, scenario_from_dict

ROOT = Path(__file__).resolve().parents[1]
EXAMPLE = ROOT / "docs" / "examples" / "two-robots-warehouse.yaml"


def _data(**changes: Any) -> dict[str, Any]:
    data = yaml.safe_load(EXAMPLE.read_text())
    data.update(changes)
    return {k: v for k, v in data.items() if v is not None}


def test_example_loads_with_its_robots() -> None:
    sc = load_scenario(EXAMPLE)
    assert sc.robot_names == ("husky", "jackal")
    assert sc.robot.radius == 0.35  # the largest disc
    assert sc.separation is not None and sc.separation.min_m == 0.3
    assert set(sc.proximity) == {"close"}
    jackal = sc.robot_scenario("jackal")
    assert (jackal.topics.pose, jackal.robot.radius, set(jackal.signals)) == ("/jackal/odom", 0.25, {"slow"})
    assert not jackal.robots and jackal.spec == "true"
    assert sc.planning_problems()[0][0] == "robots"


def test_hash_is_canonical_and_depends_on_the_robots() -> None:
    a = scenario_from_dict(_data())
    assert a.sha256() == scenario_from_dict(yaml.safe_load(yaml.safe_dump(a.to_dict()))).sha256()
    robots = _data()["robots"]
    robots[1]["radius"] = 0.3
    assert scenario_from_dict(_data(robots=robots)).sha256() != a.sha256()


@pytest.mark.parametrize(("changes", "words"), [
    ({"spec": "G !door"}, "unqualified atom(s) door in a scenario with robots husky, jackal: name the robot "
                          "(husky.door or jackal.door)"),
    ({"spec": "F bob.dock"}, "bob is not one of the robots husky, jackal"),
    ({"spec": "F husky.slow"}, "slow labels no region and names no signal of husky"),
    ({"robot": {"radius": 0.2}}, "robot: a scenario with robots: gives these per robot"),
    ({"proximity": {"near": {"robots": ["husky", "bob"], "within_m": 1.0}}}, "'bob' is not one of the robots"),
    ({"proximity": {"door": {"robots": ["husky", "jackal"], "within_m": 1.0}}}, "door is also a region label"),
    ({"separation": {"min_m": 0.3, "pairs": [{"robots": ["husky", "husky"], "min_m": 1}]}}, "two different robots"),
])
def test_fleet_mistakes_are_named(changes: dict[str, Any], words: str) -> None:
    with pytest.raises(ScenarioError, match=None) as err:
        scenario_from_dict(_data(**changes))
    assert words in str(err.value)


def test_one_robot_scenario_refuses_fleet_fields_and_qualified_atoms() -> None:
    data = yaml.safe_load((ROOT / "docs" / "examples" / "diffdrive-room.yaml").read_text())
    with pytest.raises(ScenarioError, match="need a robots: block"):
        scenario_from_dict({**data, "separation": {"min_m": 0.5}})
    with pytest.raises(ScenarioError, match="qualified atom"):
        scenario_from_dict({**data, "spec": "F robot.dock"})


def test_a_robot_needs_its_pose_topic_and_a_fleet_two_robots() -> None:
    robots = _data()["robots"]
    robots[0]["topics"] = {"cmd_vel": "/husky/cmd_vel"}
    with pytest.raises(ScenarioError, match="pose topic"):
        scenario_from_dict(_data(robots=robots))
    with pytest.raises(ScenarioError, match="two robots or more"):
        scenario_from_dict(_data(robots=_data()["robots"][:1], spec="F husky.dock", proximity={}))


def _cli(*args: str) -> subprocess.CompletedProcess[str]:
    return subprocess.run([sys.executable, "-m", "tubempc", *args], capture_output=True, text=True, timeout=300,
                          check=False, cwd=ROOT)


def test_cli_unqualified_atom_is_one_line_exit_3() -> None:
    out = _cli("certify", "logs/two_robots.bag", "--scenario", str(EXAMPLE), "--spec", "F[0,40] dock")
    assert out.returncode == 3
    assert out.stderr.strip().count("\n") == 0 and "Traceback" not in out.stderr
    assert "unqualified atom(s) dock in a scenario with robots husky, jackal" in out.stderr


def test_cli_validate_with_the_log_checks_each_robot() -> None:
    out = _cli("scenario", "validate", str(EXAMPLE), "--log", "logs/two_robots.bag")
    assert out.returncode == 0, out.stderr
    assert "(robot husky): pose /husky/pose, 1501 samples" in out.stdout
    assert "(robot jackal): pose /jackal/odom, 601 samples" in out.stdout
    wrong = _cli("scenario", "validate", str(EXAMPLE), "--log", "logs/diffdrive_odom.bag")
    assert wrong.returncode == 3
    assert "robots.husky: topics.pose: /husky/pose is absent" in wrong.stderr
