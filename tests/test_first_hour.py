"""A lab's first hour with the CLI: ``info``, ``scenario init``, ``scenario validate --log``, ``certify``.

The log is written here in the style of a field robot's bag (a Clearpath Husky): ROS1, bz2 chunks, Odometry only
(10 Hz) beside an IMU (50 Hz) and ``/clock``, a simulated clock that starts at 100 s, and one 0.2 s dropout.
"""

from __future__ import annotations

import json
import math
import subprocess
import sys
from pathlib import Path
from typing import Any

import numpy as np
import pytest
from rosbags.rosbag1 import Writer
from rosbags.typesys import Stores, get_typestore

from scripts import make_any_robot_logs
from tubempc.cli import EXIT_UNUSABLE

SIM_T0_NS = 100 * 10**9  # a simulated clock: near 1970
ODOM = "/husky_velocity_controller/odom"


def _imu_and_clock(t_end_s: float, store: Any) -> list[tuple[str, str, int, Any]]:
    T = store.types
    out: list[tuple[str, str, int, Any]] = []
    V3, Q = T["geometry_msgs/msg/Vector3"], T["geometry_msgs/msg/Quaternion"]
    for k in range(int(t_end_s * 50) + 1):
        t_ns = SIM_T0_NS + k * 20_000_000
        stamp = T["builtin_interfaces/msg/Time"](sec=t_ns // 10**9, nanosec=t_ns % 10**9)
        header = T["std_msgs/msg/Header"](seq=k, stamp=stamp, frame_id="imu_link")
        imu = T["sensor_msgs/msg/Imu"](header=header, orientation=Q(x=0.0, y=0.0, z=0.0, w=1.0),
                                       orientation_covariance=np.zeros(9), angular_velocity=V3(x=0.0, y=0.0, z=0.1),
                                       angular_velocity_covariance=np.zeros(9),
                                       linear_acceleration=V3(x=0.0, y=0.0, z=9.81),
                                       linear_acceleration_covariance=np.zeros(9))
        out.append(("/imu/data", "sensor_msgs/msg/Imu", t_ns, imu))
        if k % 5 == 0:
            out.append(("/clock", "rosgraph_msgs/msg/Clock", t_ns, T["rosgraph_msgs/msg/Clock"](clock=stamp)))
    return out


def husky_like_bag(path: Path, *, drop_at_s: float = 12.0) -> Path:
    """The bag described in the module docstring; the Odometry message at ``drop_at_s`` is missing (0.2 s gap)."""
    kit = make_any_robot_logs
    run = kit.unicycle_run(((0.0, 0.0), (8.0, 0.0), (8.0, 5.0), (2.0, 5.0)), v_mps=0.8, w_radps=0.6, rate_hz=10.0)
    store = get_typestore(Stores.ROS1_NOETIC)
    odom = [m for m in kit.odometry_messages(run, ODOM, ros1=True, time0_ns=SIM_T0_NS)
            if abs((m[2] - SIM_T0_NS) * 1e-9 - drop_at_s) > 1e-6]
    messages = sorted(odom + _imu_and_clock(float(run.t_s[-1]), store), key=lambda m: m[2])
    w = Writer(path)
    w.set_compression(Writer.CompressionFormat.BZ2)
    with w:
        conns: dict[str, Any] = {}
        for topic, typ, t_ns, msg in messages:
            if topic not in conns:
                conns[topic] = w.add_connection(topic, typ, typestore=store)
            w.write(conns[topic], t_ns, store.serialize_ros1(msg, typ))
    return path


def run(*args: str | Path) -> subprocess.CompletedProcess[str]:
    return subprocess.run([sys.executable, "-m", "tubempc", *map(str, args)], capture_output=True, text=True,
                          timeout=300, check=False)


@pytest.fixture(scope="module")
def husky(tmp_path_factory: pytest.TempPathFactory) -> Path:
    return husky_like_bag(tmp_path_factory.mktemp("husky") / "husky.bag")


def test_info_describes_topics_rates_dropout_clock_and_where_the_robot_went(husky: Path) -> None:
    out = run("info", husky, "--json")
    assert out.returncode == 0, out.stderr
    doc = json.loads(out.stdout)
    assert doc["info_version"] == 1 and doc["format"] == "ros1" and doc["log_clock"] == "simulated"
    topics = {t["topic"]: t for t in doc["topics"]}
    assert set(topics) == {ODOM, "/imu/data", "/clock"}
    odom, imu = topics[ODOM], topics["/imu/data"]
    assert odom["msgtype"] == "nav_msgs/msg/Odometry" and odom["time"] == "header"
    assert math.isclose(odom["rate_hz"], 10.0, rel_tol=1e-6) and math.isclose(imu["rate_hz"], 50.0, rel_tol=1e-6)
    assert odom["dropouts"] == 1
    assert math.isclose(odom["largest_gaps"][0]["gap_s"], 0.2, abs_tol=1e-6)
    assert math.isclose(odom["largest_gaps"][0]["after_s"], 11.9, abs_tol=1e-6)
    assert odom["clock"] == "simulated" and math.isclose(odom["header_first_s"], 100.0)
    (pose,) = doc["poses"]
    assert pose["topic"] == ODOM
    assert math.isclose(pose["x_min_m"], 0.0, abs_tol=1e-9) and math.isclose(pose["x_max_m"], 8.0, abs_tol=1e-6)
    assert math.isclose(pose["y_max_m"], 5.0, abs_tol=1e-6)
    assert math.isclose(pose["speed_max_mps"], 0.8, rel_tol=1e-6)
    text = run("info", husky)
    assert text.returncode == 0 and "clock: simulated" in text.stdout
    assert "1 dropout (gaps > 1.5 periods)" in text.stdout


def test_a_certificate_in_five_commands(husky: Path, tmp_path: Path) -> None:
    """info, scenario init, edit, scenario validate --log, certify."""
    assert run("info", husky).returncode == 0
    init = run("scenario", "init", husky)
    assert init.returncode == 0, init.stderr
    scenario = tmp_path / "my-lab.yaml"
    scenario.write_text(init.stdout)
    # before any edit it validates and certifies (pass or inconclusive, never an error)
    assert run("scenario", "validate", scenario, "--log", husky).returncode == 0
    assert run("certify", husky, "--scenario", scenario).returncode in (0, 2)
    # the edit: the Husky's radius; the placeholder region and formula replaced by a goal at the far corner
    lines = init.stdout.replace("radius: 0.3 ", "radius: 0.55 ").splitlines(keepends=True)
    text = "".join(line for line in lines if not line.startswith(("  - name: lab", "    polygon:", "    labels:",
                                                                  "spec:")))
    text += "  - name: corner\n    center: [8.0, 5.0]\n    radius: 0.9\n    labels: [goal]\nspec: F[0,60] goal\n"
    scenario.write_text(text)
    checked = run("scenario", "validate", scenario, "--log", husky)
    assert checked.returncode == 0, checked.stderr
    assert f"ok with {husky}" in checked.stdout and "warning" not in checked.stdout
    cert = run("certify", husky, "--scenario", scenario, "--json")
    assert cert.returncode == 0, cert.stderr
    doc = json.loads(cert.stdout)
    assert doc["verdict"] == "pass" and doc["pose_source"]["topic"] == ODOM


def test_validate_with_log_lists_every_problem_with_the_log(husky: Path, tmp_path: Path) -> None:
    scenario = tmp_path / "s.yaml"
    scenario.write_text(run("scenario", "init", husky).stdout.replace(
        f"  pose: {ODOM}\n", f"  pose: {ODOM}\n  cmd_vel: /imu/data\n") + "signals:\n  spin:\n    topic: /imu/data\n"
        "    field: angular_velocity.q\n    op: <\n    value: 1.0\n")
    out = run("scenario", "validate", scenario, "--log", husky)
    assert out.returncode == EXIT_UNUSABLE and out.stderr.count("\n") == 1
    assert "topics.cmd_vel: /imu/data is a sensor_msgs/msg/Imu" in out.stderr
    assert "signals.spin.field" in out.stderr and "'q'" in out.stderr


def test_data_outside_the_workspace_is_named_by_validate_and_in_the_certificate(husky: Path, tmp_path: Path
                                                                                ) -> None:
    scenario = tmp_path / "s.yaml"
    scenario.write_text(run("scenario", "init", husky).stdout.replace("  x: [-1, 9]", "  x: [-1, 6]"))
    out = run("scenario", "validate", scenario, "--log", husky)
    assert out.returncode == 0, out.stderr
    assert "warning: workspace:" in out.stdout and "outside the workspace box" in out.stdout
    cert = json.loads(run("certify", husky, "--scenario", scenario, "--json").stdout)
    assert any("outside the workspace box" in w for w in cert["scenario_warnings"])
