"""Log round trip: a written log read back with plain rosbags, and with the certifier's reader (its own fast readers
and, with ``TUBEMPC_FAST_INGEST=0``, plain rosbags), gives the simulated arrays (every format)."""

from __future__ import annotations

import json
import math
from pathlib import Path

import numpy as np
import pytest
from rosbags.highlevel import AnyReader
from rosbags.typesys import Stores, get_typestore

from tubempc.control import ClosedLoopResult, Target, run_closed_loop
from tubempc.errors import LogWriteError
from tubempc.rosio import TIME0_NS, write_log
from tubempc.scenario import builtin_scenario

SCENARIO = builtin_scenario()


@pytest.fixture(scope="module")
def result() -> ClosedLoopResult:
    return run_closed_loop(SCENARIO, [Target("R3")], disturbance="random", seed=9, t_end_s=4.0, mocap_noise_m=0.001)


def _read(path: Path) -> dict[str, list[tuple[int, object]]]:
    out: dict[str, list[tuple[int, object]]] = {}
    with AnyReader([path], default_typestore=get_typestore(Stores.ROS2_HUMBLE)) as reader:
        for conn, stamp, raw in reader.messages():
            out.setdefault(conn.topic, []).append((stamp, reader.deserialize(raw, conn.msgtype)))
    return out


def _yaw(msg: object) -> float:
    q = msg.pose.orientation  # type: ignore[attr-defined]
    return 2.0 * math.atan2(q.z, q.w)


@pytest.mark.parametrize("name", ["run.mcap", "run.bag", "run.db3", "run_dir"])
def test_round_trip(tmp_path: Path, result: ClosedLoopResult, name: str) -> None:
    path = write_log(result, SCENARIO, tmp_path / name, metadata={"formula": SCENARIO.spec})
    topics = _read(path)
    t = SCENARIO.topics
    assert set(topics) == {t.pose, t.cmd_vel, t.nominal, t.solver, t.metadata}
    stamps = TIME0_NS + np.rint(result.t_s * 1e9).astype(np.int64)
    poses = topics[t.pose]
    assert [s for s, _ in poses] == stamps.tolist()
    assert [m.header.stamp.sec * 10**9 + m.header.stamp.nanosec for _, m in poses] == stamps.tolist()  # type: ignore[attr-defined]
    assert poses[0][1].header.frame_id == "world"  # type: ignore[attr-defined]
    xy = np.array([[m.pose.position.x, m.pose.position.y] for _, m in poses])  # type: ignore[attr-defined]
    yaw = np.array([_yaw(m) for _, m in poses])
    # float64 values round-trip exactly; the yaw goes through a quaternion (atan2 of sin/cos: ~1 ulp)
    assert np.array_equal(xy, result.x_measured[:, :2])
    assert np.allclose(yaw, result.x_measured[:, 2], atol=1e-12)
    nominal = np.array([[m.pose.position.x, m.pose.position.y] for _, m in topics[t.nominal]])  # type: ignore[attr-defined]
    assert np.array_equal(nominal, result.x_hat[:, :2])
    cmd = np.array([[m.linear.x, m.linear.y, m.angular.z] for _, m in topics[t.cmd_vel]])  # type: ignore[attr-defined]
    assert np.array_equal(cmd, result.u_body)
    assert [s for s, _ in topics[t.cmd_vel]] == stamps.tolist()
    status = [json.loads(m.data) for _, m in topics[t.solver]]  # type: ignore[attr-defined]
    assert len(status) == len(result.solver)
    assert status[0] == {"t_s": 0.0, "status": result.solver[0].status, "success": True,
                         "iterations": result.solver[0].iterations, "solve_time_s": result.solver[0].solve_time_s,
                         "backup": False, "target": "R3"}
    (meta_stamp, meta_msg), = topics[t.metadata]
    meta = json.loads(meta_msg.data)  # type: ignore[attr-defined]
    assert meta_stamp == TIME0_NS == meta["time0_ns"]
    assert meta["scenario_sha256"] == SCENARIO.sha256() and meta["seed"] == 9
    assert meta["disturbance"]["model"] == "random" and meta["disturbance"]["mocap_noise_m"] == 0.001
    assert meta["tube"] == {"sigma": result.sigma, "radius_m": result.tube_radius_m}
    assert meta["targets"] == [{"region": "R3", "depart_after_s": None}]
    assert meta["generator"].startswith("tubempc ") and meta["formula"] == SCENARIO.spec
    assert "regions:" in meta["scenario_yaml"]


@pytest.mark.parametrize("name", ["run.mcap", "run.bag", "run.db3", "run_dir"])
def test_round_trip_through_the_certifiers_reader(tmp_path: Path, result: ClosedLoopResult, name: str,
                                                  ingest_path: str) -> None:
    from verify.ingest import read_log

    path = write_log(result, SCENARIO, tmp_path / name)
    log = read_log(path, SCENARIO)
    stamps = TIME0_NS + np.rint(result.t_s * 1e9).astype(np.int64)
    assert log.time_base == "header" and log.time0_ns == TIME0_NS
    assert np.array_equal(log.pose.t_ns, stamps)
    assert np.array_equal(np.column_stack([log.pose.x_m, log.pose.y_m]), result.x_measured[:, :2])
    assert np.allclose(log.pose.theta_rad, result.x_measured[:, 2], atol=1e-12)
    assert log.nominal is not None and np.array_equal(log.nominal.x_m, result.x_hat[:, 0])
    assert log.cmd_t_ns is not None and log.cmd_u is not None
    assert np.array_equal(log.cmd_t_ns, stamps) and np.array_equal(log.cmd_u, result.u_body)
    assert len(log.statuses) == len(result.solver) and log.metadata is not None
    assert log.metadata["seed"] == 9
    assert log.data_quality["pose"]["fast_decode"] is (ingest_path == "fast")


def test_existing_path_and_reserved_key_are_refused(tmp_path: Path, result: ClosedLoopResult) -> None:
    path = write_log(result, SCENARIO, tmp_path / "a.mcap")
    with pytest.raises(LogWriteError, match="exists already"):
        write_log(result, SCENARIO, path)
    with pytest.raises(LogWriteError, match="reserved"):
        write_log(result, SCENARIO, tmp_path / "b.mcap", metadata={"time0_ns": 0})
    with pytest.raises(LogWriteError, match="does not exist"):
        write_log(result, SCENARIO, tmp_path / "missing" / "c.mcap")
