"""``verify.info`` (``tubempc info``) and the starting scenario it feeds (``tubempc scenario init``): every format,
every pose type, and only the pose and command topics read whole."""

from __future__ import annotations

import math
from collections.abc import Callable
from pathlib import Path
from typing import Any

import numpy as np
import pytest

import verify.info
from tubempc.scaffold import scenario_text
from tubempc.scenario import Scenario
from tubempc.scenario.loader import scenario_from_dict
from verify.certify import certify_log
from verify.errors import LogReadError
from verify.info import info_dict, log_info

MakeLog = Callable[..., Path]


@pytest.mark.parametrize("fmt", ["bag", "mcap", "db3", "dir-mcap", "dir-sqlite3"])
def test_every_format_gives_the_same_description(fmt: str, make_log: MakeLog, paper_traj: Callable[..., Any],
                                                 scenario: Scenario) -> None:
    traj = paper_traj(scenario, rate_hz=20.0, end_s=30.0)
    info = log_info(make_log(fmt, traj))
    topics = {t.topic: t for t in info.topics}
    pose = topics[scenario.topics.pose]
    assert pose.count == traj.t_s.shape[0] and pose.time == "header" and pose.clock == "wall"
    assert math.isclose(pose.rate_hz or 0.0, 20.0, rel_tol=1e-6) and pose.dropouts == 0
    cmd = topics[scenario.topics.cmd_vel or ""]
    assert cmd.time == "log" and cmd.header_first_s is None  # Twist has no header
    (p,) = [p for p in info.poses if p.topic == scenario.topics.pose]
    assert math.isclose(p.x_min_m, float(traj.x.min())) and math.isclose(p.y_max_m, float(traj.y.max()))
    step = np.hypot(np.diff(traj.x), np.diff(traj.y)) / np.diff(traj.t_s)
    assert math.isclose(p.speed_max_mps or 0.0, float(step.max()), abs_tol=1e-6)  # rounded to 1 um/s
    (c,) = info.commands
    assert math.isclose(c.max_abs_linear_x, float(np.abs(traj.cmd[:, 0]).max()))
    assert info_dict(info)["info_version"] == 1


def test_tf_child_frames_are_separate_streams_and_init_can_pick_one(make_log: MakeLog, paper_traj: Callable[..., Any],
                                                                    scenario: Scenario) -> None:
    traj = paper_traj(scenario, rate_hz=10.0, end_s=20.0)
    info = log_info(make_log("mcap", traj, pose_type="TF", tf_child="base_link"))
    frames = {p.child_frame: p for p in info.poses if p.topic == "/tf"}
    assert set(frames) == {"base_link", "other_robot"}
    assert math.isclose(frames["other_robot"].x_min_m - frames["base_link"].x_min_m, 0.5)
    sc = scenario_from_dict(__import__("yaml").safe_load(scenario_text(info, pose_topic="/tf#base_link")))
    assert sc.topics.pose == "/tf" and sc.topics.tf_child_frame == "base_link"
    with pytest.raises(ValueError, match="not a pose-like topic"):
        scenario_text(info, pose_topic="/tf#nobody")


def test_only_pose_and_command_topics_are_read_whole(make_log: MakeLog, paper_traj: Callable[..., Any],
                                                     scenario: Scenario, monkeypatch: pytest.MonkeyPatch) -> None:
    """Bounded memory: the status strings and metadata (any other topic: a camera) are streamed, times only."""
    asked: list[set[str]] = []
    real = verify.info.read_raw

    def spy(path: Any, topics: Any, **kw: Any) -> Any:
        asked.append(set(topics))
        return real(path, topics, **kw)

    monkeypatch.setattr(verify.info, "read_raw", spy)
    info = log_info(make_log("bag", paper_traj(scenario, end_s=10.0)))
    assert asked == [{scenario.topics.pose, scenario.topics.nominal, scenario.topics.cmd_vel}]
    assert {t.topic for t in info.topics} >= {scenario.topics.solver, scenario.topics.metadata}


def test_the_starting_scenario_certifies_before_any_edit(make_log: MakeLog, paper_traj: Callable[..., Any],
                                                         scenario: Scenario) -> None:
    log = make_log("mcap", paper_traj(scenario, end_s=40.0))
    sc = scenario_from_dict(__import__("yaml").safe_load(scenario_text(log_info(log))))
    assert sc.topics.pose == scenario.topics.pose and sc.topics.cmd_vel == scenario.topics.cmd_vel
    assert sc.inputs.model == "holonomic"  # the paper's commands move sideways
    assert certify_log(log, sc).verdict == "pass"


def test_an_unreadable_log_is_one_error_naming_it(tmp_path: Path) -> None:
    bad = tmp_path / "x.bag"
    bad.write_bytes(b"#ROSBAG V2.0\n" + b"\0" * 100)
    with pytest.raises(LogReadError, match=str(bad)):
        log_info(bad)


def test_a_truncated_log_names_salvage_and_salvage_describes_what_remains() -> None:
    log = Path(__file__).resolve().parents[2] / "logs" / "truncated.bag"
    with pytest.raises(LogReadError, match="--salvage"):
        log_info(log)
    info = log_info(log, salvage=True)
    assert info.partial and info.notes and info.notes[0].startswith("salvaged: truncated.bag: stopped at")
    pose = next(t for t in info.topics if t.topic == "/qualisys/nexus/pose")
    assert pose.count > 0 and pose.time == "header" and any(p.topic == pose.topic for p in info.poses)


ROOT = Path(__file__).resolve().parents[2]


def test_info_json_validates_against_the_published_schema(make_log: MakeLog, paper_traj: Callable[..., Any],
                                                          scenario: Scenario) -> None:
    """``info --json`` is a typed output: its published schema (docs/info.schema.json, ``tubempc schema info``) is
    the dataclasses', and what ``info --json`` prints validates against it (TF child frames, commands and gaps
    included); a field the schema does not name, or a wrong version, is refused."""
    import json
    import subprocess
    import sys

    import jsonschema

    from verify.info import info_schema

    published = json.loads((ROOT / "docs" / "info.schema.json").read_text())
    assert published == info_schema(), "regenerate: tubempc schema info > docs/info.schema.json"
    traj = paper_traj(scenario, rate_hz=10.0, end_s=20.0)
    log = make_log("mcap", traj, pose_type="TF", tf_child="base_link")
    cli = subprocess.run([sys.executable, "-m", "tubempc", "info", str(log), "--json"], capture_output=True,
                         text=True, check=True, timeout=300)
    printed = json.loads(cli.stdout)
    validator = jsonschema.Draft202012Validator(published)
    assert not list(validator.iter_errors(printed))
    assert printed["poses"] and printed["commands"] and printed["topics"][0]["largest_gaps"]
    assert list(validator.iter_errors({**printed, "surprise": 1}))
    assert list(validator.iter_errors({**printed, "info_version": 2}))
    topic = {**printed["topics"][0], "rate": 1.0}
    assert list(validator.iter_errors({**printed, "topics": [topic]}))
    schema_cli = subprocess.run([sys.executable, "-m", "tubempc", "schema", "info"], capture_output=True, text=True,
                                check=True, timeout=120)
    assert json.loads(schema_cli.stdout) == published
