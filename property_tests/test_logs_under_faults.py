"""Logs under faults: random runs written with rosbags (the log contract) to every format, then damaged.

For every drawn run, format (ROS1 ``.bag``, bare ``.mcap``, ROS2 bag directory with sqlite3 storage) and fault
(``tubempc.strategies.log_faults``, header-stamp faults included), each fault kind has its allowed outcomes:
- only a truncated log or a log without its pose topic may be unusable input (exit 3); every other fault leaves a
  usable log (a verdict), and the certifier never crashes;
- it never says "pass" for a run that violates its constraints (a written sample whose robot disc meets an obstacle
  or leaves the workspace, or a command outside the box), nor for a log the damage leaves unverifiable (truncated,
  salvaged, NaN positions, or missing the nominal or command topic);
- a clean run (no violation) whose margins exceed the between-sample bound passes when the fault leaves every
  sample and its time usable (no fault, a zero quaternion, reordered or outlier / 1970 / all-zero header stamps);
- a repeated stamp that moves a sample into an obstacle is a fail (the sample is judged, never dropped);
- an undamaged log reads back exactly: stamps and positions bit for bit, yaw to 1e-12 rad (the yaw goes through a
  quaternion: sin/cos then atan2, a few ulps).
The formula is ``G !(obs_1 | ... | obs_4)`` on the built-in scenario, so a violation of clearance is a violation of
the spec too; runs are drawn at the MoCap rate with the scenario's speed bound, so gaps can be bounded.
"""

from __future__ import annotations

import dataclasses
import math
import tempfile
from pathlib import Path
from typing import Any, Literal

import numpy as np
import numpy.typing as npt
from hypothesis import HealthCheck, event, example, given, settings
from hypothesis import strategies as st
from rosbags.rosbag1 import Writer as Writer1
from rosbags.rosbag2 import StoragePlugin
from rosbags.rosbag2 import Writer as Writer2
from rosbags.typesys import Stores, get_typestore

from tubempc import strategies
from tubempc.scenario import Scenario, builtin_scenario
from tubempc.strategies import LogFault, Trajectory, apply_sample_fault
from verify import UnusableInputError, certify_log
from verify.geometry import containing_region
from verify.ingest import read_log

Format = Literal["bag", "mcap", "sqlite3"]
FORMATS: tuple[Format, ...] = ("bag", "mcap", "sqlite3")
TIME0_NS = 1_767_225_600 * 10**9  # the log contract's time 0 for simulated runs
SCENARIO = builtin_scenario()
SPEC = "G[0,inf) !(obs_1 | obs_2 | obs_3 | obs_4)"
OBSTACLE_CENTRES = [tuple(r.center) for r in SCENARIO.unsafe_regions]
YAW_TOL_RAD = 1e-12  # see the module docstring


def _paths(root: Path, fmt: Format) -> Path:
    return {"bag": root / "run.bag", "mcap": root / "run.mcap", "sqlite3": root / "run_bag"}[fmt]


def write_run(path: Path, fmt: Format, scenario: Scenario, *, stamps_ns: npt.NDArray[np.int64],
              log_ns: npt.NDArray[np.int64], xyz_m: npt.NDArray[np.float64], quat_xyzw: npt.NDArray[np.float64],
              cmd_ns: npt.NDArray[np.int64], cmd_u: npt.NDArray[np.float64], topics: set[str]) -> Path:
    """Pose (and the nominal = the pose, and cmd_vel) per the log contract, with rosbags only."""
    ros1 = fmt == "bag"
    store = get_typestore(Stores.ROS1_NOETIC if ros1 else Stores.ROS2_HUMBLE)
    ser = store.serialize_ros1 if ros1 else store.serialize_cdr
    ty = store.types
    msgs: list[tuple[int, str, str, Any]] = []
    for i, stamp in enumerate(stamps_ns.tolist()):
        sec, nsec = divmod(int(stamp), 10**9)
        st_msg = ty["builtin_interfaces/msg/Time"](sec=sec, nanosec=nsec)
        header = (ty["std_msgs/msg/Header"](seq=i, stamp=st_msg, frame_id="world") if ros1 else
                  ty["std_msgs/msg/Header"](stamp=st_msg, frame_id="world"))
        x, y, z = (float(v) for v in xyz_m[i])
        qx, qy, qz, qw = (float(v) for v in quat_xyzw[i])
        pose = ty["geometry_msgs/msg/PoseStamped"](
            header=header, pose=ty["geometry_msgs/msg/Pose"](
                position=ty["geometry_msgs/msg/Point"](x=x, y=y, z=z),
                orientation=ty["geometry_msgs/msg/Quaternion"](x=qx, y=qy, z=qz, w=qw)))
        for role in ("pose", "nominal"):
            topic = getattr(scenario.topics, role)
            if role in topics:
                msgs.append((int(log_ns[i]), topic, "geometry_msgs/msg/PoseStamped", pose))
    if "cmd_vel" in topics:
        vec = ty["geometry_msgs/msg/Vector3"]
        for t, u in zip(cmd_ns.tolist(), cmd_u, strict=True):
            twist = ty["geometry_msgs/msg/Twist"](linear=vec(x=float(u[0]), y=float(u[1]), z=0.0),
                                                  angular=vec(x=0.0, y=0.0, z=float(u[2])))
            msgs.append((int(t), scenario.topics.cmd_vel, "geometry_msgs/msg/Twist", twist))
    msgs.sort(key=lambda m: m[0])

    def write_all(writer: Any) -> None:
        conns: dict[str, Any] = {}
        for _, topic, msgtype, _ in msgs:
            if topic not in conns:
                conns[topic] = writer.add_connection(topic, msgtype, typestore=store)
        for t, topic, msgtype, msg in msgs:
            writer.write(conns[topic], t, ser(msg, msgtype))

    if ros1:
        with Writer1(path) as w1:
            write_all(w1)
        return path
    if fmt == "mcap":
        bag_dir = path.parent / "mcap_dir"
        with Writer2(bag_dir, version=9, storage_plugin=StoragePlugin.MCAP) as w2:
            write_all(w2)
        (storage,) = [p for p in bag_dir.iterdir() if p.suffix == ".mcap"]
        storage.rename(path)
        return path
    with Writer2(path, version=9, storage_plugin=StoragePlugin.SQLITE3) as w2:
        write_all(w2)
    return path


def truncate(path: Path, fraction: float) -> None:
    """Cut the file (the storage file of a bag directory) to ``fraction`` of its bytes."""
    target = path if path.is_file() else next(p for p in path.iterdir() if p.suffix in (".db3", ".mcap"))
    data = target.read_bytes()
    target.write_bytes(data[: max(1, int(len(data) * fraction))])


def violates(xy: npt.NDArray[np.float64], cmd_u: npt.NDArray[np.float64], scenario: Scenario) -> bool:
    """Ground truth from the samples written: obstacle contact, workspace exit or a command outside the box."""
    return clean_margin(xy, scenario) < 0 or bool(np.any(np.abs(cmd_u) > np.asarray(scenario.inputs.max_abs)))


def clean_margin(xy: npt.NDArray[np.float64], scenario: Scenario) -> float:
    """The smallest sample margin (m) of the robot disc to every obstacle and to the workspace walls (NaN rows
    ignored)."""
    eta = scenario.robot.radius
    finite = xy[np.isfinite(xy).all(axis=1)]
    if finite.size == 0:
        return math.inf
    margins = [float(np.min(np.hypot(finite[:, 0] - r.center[0], finite[:, 1] - r.center[1]))) - r.radius - eta
               for r in scenario.unsafe_regions]
    ws = scenario.workspace
    margins += [float(np.min(finite[:, 0] - ws.x[0])) - eta, float(np.min(ws.x[1] - finite[:, 0])) - eta,
                float(np.min(finite[:, 1] - ws.y[0])) - eta, float(np.min(ws.y[1] - finite[:, 1])) - eta]
    return min(margins)


def commands(n: int) -> st.SearchStrategy[npt.NDArray[np.float64]]:
    """Body-frame commands: within the box, or (sometimes) one sample beyond it."""
    limit = SCENARIO.inputs.max_abs

    @st.composite
    def draw_cmds(draw: st.DrawFn) -> npt.NDArray[np.float64]:
        base = np.array([draw(st.integers(-100, 100)) / 100 * m for m in limit])
        u = np.tile(base, (n, 1))
        if draw(st.integers(0, 7)) == 0:
            k = draw(st.integers(0, n - 1))
            u[k, draw(st.integers(0, 2))] = 1.5 * max(limit)
        return u

    return draw_cmds()


@st.composite
def faulty_runs(draw: st.DrawFn) -> tuple[Trajectory, npt.NDArray[np.float64], Format, LogFault]:
    # start in a safe region (runs that should pass) or anywhere (runs that often meet an obstacle)
    starts = [r.center for r in SCENARIO.safe_regions]
    start = draw(st.one_of(st.sampled_from(starts), st.none()))
    traj = draw(strategies.trajectories(rate_hz=SCENARIO.mocap.rate_hz, max_samples=150, max_speed_mps=0.2,
                                        box_m=2.2, start=start))
    n = len(traj.t_s)
    return (traj, draw(commands(n)), draw(st.sampled_from(FORMATS)),
            draw(strategies.log_faults(max_index=n, places=OBSTACLE_CENTRES)))


def _arrays(traj: Trajectory) -> tuple[npt.NDArray[np.int64], npt.NDArray[np.float64], npt.NDArray[np.float64]]:
    t_s, xy, yaw = traj.arrays()
    stamps = TIME0_NS + np.rint(t_s * 1e9).astype(np.int64)
    xyz = np.column_stack([xy, np.zeros(len(t_s))])
    quat = np.column_stack([np.zeros(len(t_s)), np.zeros(len(t_s)), np.sin(yaw / 2), np.cos(yaw / 2)])
    return stamps, xyz, quat


def _write_damaged(root: Path, traj: Trajectory, cmd_u: npt.NDArray[np.float64], fmt: Format,
                   fault: LogFault) -> tuple[Path, npt.NDArray[np.float64]]:
    """The damaged log and the positions actually written (the ground truth of what the log holds)."""
    stamps, xyz, quat = _arrays(traj)
    cmd_ns = stamps.copy()
    s, x, q = apply_sample_fault(fault, stamps, xyz, quat)
    # log (arrival) order stays monotonic; a reorder fault swaps the header stamps only
    log_ns = np.sort(s) if fault.kind not in strategies.STAMP_FAULTS else stamps.copy()
    topics = {"pose", "nominal", "cmd_vel"}
    if fault.kind == "missing_topic":
        topics.discard(fault.topic)
    path = write_run(_paths(root, fmt), fmt, SCENARIO, stamps_ns=s, log_ns=log_ns, xyz_m=x, quat_xyzw=q,
                     cmd_ns=cmd_ns, cmd_u=cmd_u, topics=topics)
    if fault.kind == "truncate":
        truncate(path, fault.fraction)
    return path, x[:, :2]


Case = tuple[Trajectory, npt.NDArray[np.float64], Format, LogFault]
#: faults after which every sample and its time stay usable: a clean run with room to spare must pass
KEEPS_PASS = {"none", "zero_quaternion", "reorder", "zero_stamps", "negative_stamp", "stamp_1970"}


def check_damaged(case: Case) -> None:
    traj, cmd_u, fmt, fault = case
    with tempfile.TemporaryDirectory() as tmp:
        path, written_xy = _write_damaged(Path(tmp), traj, cmd_u, fmt, fault)
        bad = violates(written_xy, cmd_u, SCENARIO)
        t_s, _, _ = traj.arrays()
        step_m = SCENARIO.max_speed_mps * (float(np.max(np.diff(t_s))) if len(t_s) > 1 else 0.0)
        # the timed run (paper semantics) is decided only when the robot starts inside a region
        starts_in_region = bool(containing_region(written_xy[:1, 0], written_xy[:1, 1], SCENARIO)[0] >= 0)
        roomy = not bad and starts_in_region and clean_margin(written_xy, SCENARIO) > step_m + 1e-9
        may_be_unusable = fault.kind == "truncate" or (fault.kind == "missing_topic" and fault.topic == "pose")
        for salvage in (False, True) if fault.kind == "truncate" else (False,):
            try:
                result = certify_log(path, SCENARIO, spec=SPEC, salvage=salvage)
            except UnusableInputError as err:
                event(f"{fault.kind}: unusable input")
                refused = str(err)
                assert may_be_unusable, (fault, fmt, f"usable log refused: {refused}")
                continue
            verdict = result.verdict
            event(f"{fault.kind}: {verdict} ({'violating' if bad else 'clean'} run)")
            assert not (fault.kind == "missing_topic" and fault.topic == "pose"), "a log without poses was judged"
            if bad:
                assert verdict != "pass", (fault, fmt, "a violating run passed")
            if fault.kind in ("truncate", "nan") or (fault.kind == "missing_topic" and fault.topic != "pose"):
                assert verdict != "pass", (fault, fmt, "an unverifiable log passed")
            if fault.kind == "duplicate_stamp" and fault.xy is not None and len(t_s) >= 2:
                assert verdict == "fail", (fault, fmt, "a repeated stamp hid a sample inside an obstacle")
            if roomy and fault.kind in KEEPS_PASS:
                assert verdict == "pass", (fault, fmt, result.certificate.get("verdict_reason"))


@given(faulty_runs())
@example((Trajectory(t_s=(0.0, 0.01), xy_m=((0.0, 0.0), (0.0, 0.0)), yaw_rad=(0.0, 0.0)),
          np.zeros((2, 3)), "mcap", LogFault(kind="missing_topic", topic="nominal")))
@example((Trajectory(t_s=tuple(k * 0.01 for k in range(40)), xy_m=((-1.99, -1.78),) * 40, yaw_rad=(0.0,) * 40),
          np.zeros((40, 3)), "mcap", LogFault(kind="duplicate_stamp", start=20, xy=(-1.11, 0.54))))
@example((Trajectory(t_s=tuple(k * 0.01 for k in range(40)), xy_m=((-1.99, -1.78),) * 40, yaw_rad=(0.0,) * 40),
          np.zeros((40, 3)), "bag", LogFault(kind="zero_stamps")))
@example((Trajectory(t_s=tuple(k * 0.01 for k in range(40)), xy_m=((-1.99, -1.78),) * 40, yaw_rad=(0.0,) * 40),
          np.zeros((40, 3)), "sqlite3", LogFault(kind="negative_stamp", start=7)))
@example((Trajectory(t_s=tuple(k * 0.01 for k in range(40)), xy_m=((-1.99, -1.78),) * 40, yaw_rad=(0.0,) * 40),
          np.zeros((40, 3)), "mcap", LogFault(kind="stamp_1970", start=0)))
@example((Trajectory(t_s=tuple(k * 0.01 for k in range(40)), xy_m=((-1.99, -1.78),) * 40, yaw_rad=(0.0,) * 40),
          np.zeros((40, 3)), "bag", LogFault(kind="none")))
@settings(deadline=None, suppress_health_check=[HealthCheck.too_slow, HealthCheck.data_too_large])
def test_damaged_logs_never_crash_and_never_pass_wrongly(case: Case) -> None:
    check_damaged(case)


# Found by the nightly profile (seed 79787955990689291046924142033752259217), shrunk: a ROS2 sqlite3 bag whose
# .db3 is cut to 90 % (or 99 %) of its bytes opens, then rosbags raises apsw.CorruptError ("database disk image is
# malformed") while iterating messages; the certifier crashed (exit 70) until verify/ingest/raw.py wrapped apsw
# errors as unusable input (exit 3). Pinned as a regression test.
TRUNCATED_SQLITE3: Case = (Trajectory(t_s=(0.0, 0.01), xy_m=((-1.99, -1.78), (-1.99, -1.78)), yaw_rad=(0.0, 0.0)),
                           np.zeros((2, 3)), "sqlite3", LogFault(kind="truncate", start=0, count=1, fraction=0.9))


def test_truncated_sqlite3_bag_is_unusable_input_not_a_crash() -> None:
    traj, cmd_u, _, fault = TRUNCATED_SQLITE3
    for fraction in (0.9, 0.99):
        with tempfile.TemporaryDirectory() as tmp:
            path, _ = _write_damaged(Path(tmp), traj, cmd_u, "sqlite3", dataclasses.replace(fault, fraction=fraction))
            for salvage in (False, True):
                try:
                    verdict = certify_log(path, SCENARIO, spec=SPEC, salvage=salvage).verdict
                except UnusableInputError:
                    continue
                assert verdict != "pass"


@given(strategies.trajectories(rate_hz=100.0, max_samples=120, max_speed_mps=0.2, box_m=2.2),
       st.sampled_from(FORMATS))
@settings(deadline=None, suppress_health_check=[HealthCheck.too_slow])
def test_undamaged_logs_round_trip_exactly(traj: Trajectory, fmt: Format) -> None:
    stamps, xyz, quat = _arrays(traj)
    _, xy, yaw = traj.arrays()
    with tempfile.TemporaryDirectory() as tmp:
        path = write_run(_paths(Path(tmp), fmt), fmt, SCENARIO, stamps_ns=stamps, log_ns=stamps, xyz_m=xyz,
                         quat_xyzw=quat, cmd_ns=stamps, cmd_u=np.zeros((len(stamps), 3)),
                         topics={"pose", "nominal", "cmd_vel"})
        log = read_log(path, SCENARIO)
    assert log.time0_ns == int(stamps[0])
    assert np.array_equal(log.pose.t_ns, stamps)
    assert np.array_equal(log.pose.x_m, xy[:, 0]) and np.array_equal(log.pose.y_m, xy[:, 1])
    dyaw = np.angle(np.exp(1j * (log.pose.theta_rad - yaw)))
    assert float(np.max(np.abs(dyaw))) <= YAW_TOL_RAD
    assert log.nominal is not None and np.array_equal(log.nominal.x_m, xy[:, 0])
    assert log.cmd_u is not None and np.array_equal(log.cmd_u, np.zeros((len(stamps), 3)))
    assert not log.partial
    assert math.isfinite(float(log.pose.x_m.sum()))


@given(strategies.trajectories(rate_hz=100.0, max_samples=120, max_speed_mps=0.2, box_m=2.2),
       st.sampled_from(FORMATS), strategies.log_faults(kinds=("reorder",), max_index=120))
@settings(deadline=None, suppress_health_check=[HealthCheck.too_slow])
def test_reordered_stamps_read_back_sorted_and_reported(traj: Trajectory, fmt: Format, fault: LogFault) -> None:
    """Header stamps out of log order (``time_base="header"``): the poses come back in stamp order, the count
    reported. (``auto`` would judge on log time when many stamps go backwards: see tests/verify/test_time_base.py.)"""
    stamps, xyz, quat = _arrays(traj)
    s, x, q = apply_sample_fault(fault, stamps, xyz, quat)
    with tempfile.TemporaryDirectory() as tmp:
        path = write_run(_paths(Path(tmp), fmt), fmt, SCENARIO, stamps_ns=s, log_ns=stamps, xyz_m=x, quat_xyzw=q,
                         cmd_ns=stamps, cmd_u=np.zeros((len(stamps), 3)), topics={"pose", "nominal", "cmd_vel"})
        log = read_log(path, SCENARIO, time_base="header")
    assert np.array_equal(log.pose.t_ns, stamps)
    assert np.array_equal(log.pose.x_m, xyz[:, 0]) and np.array_equal(log.pose.y_m, xyz[:, 1])
    swapped = int(np.count_nonzero(np.diff(s) < 0))
    assert log.data_quality["pose"]["out_of_order_stamps"] == swapped
