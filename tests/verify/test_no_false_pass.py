"""No false pass, round two: each finding of the second outside fault campaign as a regression test.

Outputs never written through symlinks, ``--out`` paths that cannot be made, stamp faults on every stream, one
topic with one type, ranges where numbers enter, the fast decoder against rosbags, signal data outside the pose's
span, unknown samples in the timed run, several components of a command.
"""

from __future__ import annotations

import os
from collections.abc import Callable
from pathlib import Path
from typing import Any

import pytest
from rosbags.serde import SerdeError

from verify.errors import VerifyError

from .support import FUZZ, one_line_error, run

ROOT = Path(__file__).resolve().parents[2]
REFUSED = (SerdeError, VerifyError)
SPEC = "G[0,inf) !(obs_1 | obs_2 | obs_3 | obs_4)"


@pytest.fixture(scope="module")
def seed_logs(tmp_path_factory: pytest.TempPathFactory) -> dict[tuple[str, bool], Path]:
    out: dict[tuple[str, bool], Path] = FUZZ.write_seeds(tmp_path_factory.mktemp("seeds"))
    return out


# ---- finding 9: outputs never written through symlinks ----------------------------------------------------------
@pytest.mark.parametrize("name", ["report.html", "certificate.json", "report.md", "junit.xml"])
def test_force_never_writes_through_a_symlink_in_the_output_folder(
        seed_logs: dict[tuple[str, bool], Path], tmp_path: Path, capsys: pytest.CaptureFixture[str],
        name: str) -> None:
    log = tmp_path / "run.bag"
    log.write_bytes(seed_logs["bag", False].read_bytes())
    before = log.read_bytes()
    out = tmp_path / "out"
    out.mkdir()
    (out / name).symlink_to(log)
    code, _, err = run(["certify", str(log), "--scenario", "nexus-sml", "--spec", SPEC, "--out", str(out),
                        "--force"], capsys)
    assert code == 3, err
    one_line_error(err, name, "symbolic link")
    assert log.read_bytes() == before
    assert (out / name).is_symlink()
    (out / name).unlink()  # the session's schema check reads every certificate.json left in a test folder


def test_force_never_writes_into_a_figures_symlink(seed_logs: dict[tuple[str, bool], Path], tmp_path: Path,
                                                   capsys: pytest.CaptureFixture[str]) -> None:
    elsewhere = tmp_path / "elsewhere"
    elsewhere.mkdir()
    out = tmp_path / "out"
    out.mkdir()
    (out / "figures").symlink_to(elsewhere)
    code, _, err = run(["certify", str(seed_logs["bag", False]), "--scenario", "nexus-sml", "--spec", SPEC,
                        "--out", str(out), "--force"], capsys)
    assert code == 3, err
    one_line_error(err, "figures", "symbolic link")
    assert list(elsewhere.iterdir()) == []


def test_force_replaces_a_hard_link_without_touching_the_input(seed_logs: dict[tuple[str, bool], Path],
                                                               tmp_path: Path,
                                                               capsys: pytest.CaptureFixture[str]) -> None:
    log = tmp_path / "run.bag"
    log.write_bytes(seed_logs["bag", False].read_bytes())
    before = log.read_bytes()
    out = tmp_path / "out"
    out.mkdir()
    os.link(log, out / "report.html")
    code, _, err = run(["certify", str(log), "--scenario", "nexus-sml", "--spec", SPEC, "--out", str(out),
                        "--force"], capsys)
    assert code == 0, err
    assert log.read_bytes() == before
    assert (out / "report.html").read_text().lstrip().lower().startswith("<!doctype html")


# ---- finding 13: --out paths that cannot be made ----------------------------------------------------------------
def test_out_paths_that_cannot_be_made_are_exit_3(seed_logs: dict[tuple[str, bool], Path], tmp_path: Path,
                                                  capsys: pytest.CaptureFixture[str]) -> None:
    loop = tmp_path / "loop"
    loop.symlink_to(loop)
    cases = [(str(loop), "symlink loop"), (str(loop / "report"), "--out"),
             (str(tmp_path / ("n" * 300)), "longer than the file system allows"),
             (str(tmp_path / "/".join(["d" * 200] * 30)), "")]  # over PATH_MAX: the line elides the path
    for out, words in cases:
        code, _, err = run(["certify", str(seed_logs["bag", False]), "--scenario", "nexus-sml", "--spec", SPEC,
                            "--out", out], capsys)
        assert code == 3, (out, err)
        one_line_error(err, words)


# ---- finding 4: the fast decoders accept only what rosbags accepts --------------------------------------------------
def _serialized(ros1: bool, msgtype: str, **fields: object) -> bytes:
    from rosbags.typesys import Stores, get_typestore

    store = get_typestore(Stores.ROS1_NOETIC if ros1 else Stores.ROS2_HUMBLE)
    ty = store.types
    hdr = ty["std_msgs/msg/Header"](**({"seq": 0} if ros1 else {}),
                                   stamp=ty["builtin_interfaces/msg/Time"](sec=5, nanosec=0), frame_id="map")
    point = ty["geometry_msgs/msg/Point"](x=1.0, y=2.0, z=0.0)
    quat = ty["geometry_msgs/msg/Quaternion"](x=0.0, y=0.0, z=0.0, w=1.0)
    pose = ty["geometry_msgs/msg/Pose"](position=point, orientation=quat)
    v3 = ty["geometry_msgs/msg/Vector3"](x=0.5, y=0.0, z=0.0)
    twist = ty["geometry_msgs/msg/Twist"](linear=v3, angular=v3)
    if msgtype == "geometry_msgs/msg/PoseStamped":
        msg = ty[msgtype](header=hdr, pose=pose)
    elif msgtype == "nav_msgs/msg/Odometry":
        import numpy as np

        msg = ty[msgtype](header=hdr, child_frame_id="base_link",
                          pose=ty["geometry_msgs/msg/PoseWithCovariance"](pose=pose, covariance=np.zeros(36)),
                          twist=ty["geometry_msgs/msg/TwistWithCovariance"](twist=twist, covariance=np.zeros(36)))
    else:
        msg = ty[msgtype](header=hdr, twist=twist)
    ser = store.serialize_ros1 if ros1 else store.serialize_cdr
    return bytes(ser(msg, msgtype))


@pytest.mark.parametrize("msgtype", ["geometry_msgs/msg/PoseStamped", "nav_msgs/msg/Odometry",
                                     "geometry_msgs/msg/TwistStamped"])
@pytest.mark.parametrize("damage", ["terminator", "trailing"])
def test_fast_decoders_refuse_what_rosbags_refuses(msgtype: str, damage: str) -> None:
    from verify.ingest.decode import decode_pose, decode_twist
    from verify.ingest.fields import decode_field
    from verify.ingest.raw import RawTopic

    good = _serialized(False, msgtype)
    if damage == "terminator":  # the NUL after header.frame_id ("map\0" at bytes 16..19) flipped
        assert good[19] == 0
        bad = good[:19] + b"X" + good[20:]
    else:  # eight bytes the layout does not explain
        bad = good + b"\0" * 8
    payloads = [good, bad, good, good]
    raw = RawTopic("/t", msgtype, True, [1, 2, 3, 4], payloads)
    decode = decode_twist if msgtype.endswith("TwistStamped") else decode_pose
    for fast in (True, False):
        with pytest.raises(REFUSED, match=r"terminator|mismatch"):
            decode(raw, False, fast=fast)  # type: ignore[operator]
    field = "twist.linear.x" if msgtype.endswith("TwistStamped") else "header.stamp.sec"
    for fast in (True, False):
        with pytest.raises(REFUSED, match=r"terminator|mismatch"):
            decode_field(raw, False, field, fast=fast)


@pytest.mark.parametrize("ros1", [True, False])
@pytest.mark.parametrize("msgtype", ["geometry_msgs/msg/PoseStamped", "nav_msgs/msg/Odometry",
                                     "geometry_msgs/msg/TwistStamped"])
def test_fast_and_plain_decoders_read_a_negative_stamp_alike(ros1: bool, msgtype: str) -> None:
    """A stamp second of -1 (written as int32 0xffffffff, as rosbags writes ROS1's time too): rosbags reads it back
    as -1 s; the fast decoders read ROS1's as 2106 (uint32), so a nominal stream with negative stamps was
    inconclusive on one path and failed on the other (the fault campaign's nominal stamp faults)."""
    import numpy as np

    from verify.ingest.decode import decode_pose, decode_twist
    from verify.ingest.raw import RawTopic

    good = _serialized(ros1, msgtype)
    at = 4  # the stamp second: after seq (ROS1) or after the encapsulation header (CDR)
    assert good[at : at + 4] == (5).to_bytes(4, "little")
    neg = good[:at] + (2**32 - 1).to_bytes(4, "little") + good[at + 4 :]
    raw = RawTopic("/t", msgtype, True, [1, 2, 3], [good, neg, good])
    decode = decode_twist if msgtype.endswith("TwistStamped") else decode_pose
    got = [decode(raw, ros1, fast=fast).stamp_ns for fast in (True, False)]  # type: ignore[operator]
    assert got[0] is not None and got[1] is not None
    assert np.array_equal(got[0], got[1]) and int(got[0][1]) == -10**9, got


# ---- finding 1: unset stamps on a signal topic ----------------------------------------------------------------------
SIGNAL_SPEC = "G[0,inf) motor_ok"


def _signal_log(tmp_path: Path, fmt: str, faulty: list[tuple[float, int | None, float]]) -> tuple[Path, Path]:
    """A clean pose run with a temperature signal (40 degC beside every pose sample) and ``faulty`` extra messages
    (log time s, header stamp ns or None for a good stamp, degC); and the scenario file with ``motor_ok``."""
    run = FUZZ.base_run(violating=False)
    run.extra = FUZZ.temperature_stream(run)
    for at_s, stamp, celsius in faulty:
        log_ns = FUZZ.TIME0_NS + round(at_s * 1e9)
        run.extra.append((log_ns, FUZZ.TEMP_TOPIC, FUZZ.TEMPERATURE,
                          FUZZ.temperature(log_ns if stamp is None else stamp, celsius)))
    log = FUZZ.write_run(run, tmp_path / f"run{FUZZ.SUFFIX[fmt]}", fmt)
    scenario = tmp_path / "scenario.yaml"
    scenario.write_text(FUZZ.signal_scenario_text())
    return log, scenario


@pytest.mark.parametrize("fmt", ["bag", "mcap", "db3"])
def test_unset_stamps_on_a_signal_topic_are_judged(tmp_path: Path, capsys: pytest.CaptureFixture[str],
                                                   fmt: str) -> None:
    # a second publisher that never sets its stamp reports 95 degC for 1 s in the middle of the run
    hot = [(10.0 + k / 10 - 0.002, 0, 95.0) for k in range(10)]  # held at the pose samples
    log, scenario = _signal_log(tmp_path, fmt, hot)
    for base in ("auto", "header", "log"):
        code, _, err = run(["certify", str(log), "--scenario", str(scenario), "--spec", SIGNAL_SPEC,
                            "--time-base", base], capsys)
        assert code == 1, (base, err)
        code, out, err = run(["watch", str(log), "--scenario", str(scenario), "--spec", SIGNAL_SPEC,
                              "--time-base", base], capsys)
        assert code == 1, (base, out, err)
    (tmp_path / "clean").mkdir()
    clean, scenario = _signal_log(tmp_path / "clean", fmt, [])
    assert run(["certify", str(clean), "--scenario", str(scenario), "--spec", SIGNAL_SPEC], capsys)[0] == 0


# ---- finding 3 and issue 24: clock offsets and rates checked where they enter ----------------------------------------
@pytest.mark.parametrize("seconds", ["7.6e9", "9.3e9", "1e12", "1e300", "-5e9"])
def test_clock_offsets_out_of_range_are_exit_3_naming_the_option(tmp_path: Path, capsys: pytest.CaptureFixture[str],
                                                                 seconds: str) -> None:
    hot = [(10.0 + k / 10 - 0.002, None, 95.0) for k in range(10)]  # a violation the offset could hide
    log, scenario = _signal_log(tmp_path, "mcap", hot)
    code, _, err = run(["certify", str(log), "--scenario", str(scenario), "--spec", SIGNAL_SPEC,
                        "--clock-offset", f"{FUZZ.TEMP_TOPIC}={seconds}"], capsys)
    assert code == 3, err
    one_line_error(err, "--clock-offset", "out of range")
    text = scenario.read_text() + f"clock_offsets: {{{FUZZ.TEMP_TOPIC}: {seconds}}}\n"
    scenario.write_text(text)
    code, _, err = run(["certify", str(log), "--scenario", str(scenario), "--spec", SIGNAL_SPEC], capsys)
    assert code == 3, err
    one_line_error(err, "clock_offsets", "out of range")


def test_clock_offset_at_the_limit_is_judged(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    hot = [(10.0 + k / 10 - 0.002, None, 95.0) for k in range(10)]
    log, scenario = _signal_log(tmp_path, "mcap", hot)
    code, _, err = run(["certify", str(log), "--scenario", str(scenario), "--spec", SIGNAL_SPEC,
                        "--clock-offset", f"{FUZZ.TEMP_TOPIC}=4e9"], capsys)
    assert code == 2, err  # the signal is moved 127 years away: unknown over the run, never a pass


def test_clock_offset_for_an_unknown_topic_lists_the_known_ones(tmp_path: Path,
                                                                capsys: pytest.CaptureFixture[str]) -> None:
    log, scenario = _signal_log(tmp_path, "mcap", [])
    code, _, err = run(["certify", str(log), "--scenario", str(scenario), "--spec", SIGNAL_SPEC,
                        "--clock-offset", "/motor/temperatur=0.02"], capsys)
    assert code == 3, err
    one_line_error(err, "--clock-offset", "/motor/temperatur,", FUZZ.TEMP_TOPIC, "/qualisys/nexus/pose")
    scenario.write_text(scenario.read_text() + "clock_offsets: {/imu/dat: 0.02}\n")
    code, _, err = run(["certify", str(log), "--scenario", str(scenario), "--spec", SIGNAL_SPEC], capsys)
    assert code == 3, err
    one_line_error(err, "clock_offsets", "/imu/dat", FUZZ.TEMP_TOPIC)


@pytest.mark.parametrize("rate", ["1e-300", "1e300"])
def test_signal_rate_out_of_range_names_the_field(tmp_path: Path, capsys: pytest.CaptureFixture[str],
                                                  rate: str) -> None:
    log, scenario = _signal_log(tmp_path, "mcap", [])
    scenario.write_text(FUZZ.signal_scenario_text(float(rate)))
    code, _, err = run(["certify", str(log), "--scenario", str(scenario), "--spec", SIGNAL_SPEC], capsys)
    assert code == 3, err
    one_line_error(err, "signals.motor_ok.rate_hz", "out of range")


# ---- issue 24 item 5: a signal on the pose topic shares the pose's samples ------------------------------------------
def _odometry(stamp_ns: int, x: float, y: float, vx: float) -> Callable[[Any, bool], Any]:
    """A builder of one nav_msgs/Odometry message (rosbags types of either ROS version)."""
    import numpy as np

    def build(ty: Any, ros1: bool) -> Any:
        sec, nsec = divmod(stamp_ns, 10**9)
        header = ty["std_msgs/msg/Header"](**({"seq": 0} if ros1 else {}),
                                           stamp=ty["builtin_interfaces/msg/Time"](sec=sec, nanosec=nsec),
                                           frame_id="odom")
        pose = ty["geometry_msgs/msg/Pose"](position=ty["geometry_msgs/msg/Point"](x=x, y=y, z=0.0),
                                            orientation=ty["geometry_msgs/msg/Quaternion"](x=0.0, y=0.0, z=0.0,
                                                                                          w=1.0))
        v3 = ty["geometry_msgs/msg/Vector3"]
        twist = ty["geometry_msgs/msg/Twist"](linear=v3(x=vx, y=0.0, z=0.0), angular=v3(x=0.0, y=0.0, z=0.0))
        return ty["nav_msgs/msg/Odometry"](
            header=header, child_frame_id="base_link",
            pose=ty["geometry_msgs/msg/PoseWithCovariance"](pose=pose, covariance=np.zeros(36)),
            twist=ty["geometry_msgs/msg/TwistWithCovariance"](twist=twist, covariance=np.zeros(36)))
    return build


@pytest.mark.parametrize("fmt", ["bag", "mcap"])
def test_a_signal_on_the_pose_topic_is_known_wherever_the_pose_is(tmp_path: Path,
                                                                  capsys: pytest.CaptureFixture[str],
                                                                  fmt: str) -> None:
    """A Husky-like log: Odometry at 10 Hz with 0.2 s dropouts every 3 s, a speed atom on its twist: the pose
    check bridges the dropouts with the speed bound, the atom with the pose's samples (pass); a fast sample fails."""
    run0 = FUZZ.base_run(violating=False)
    run0.topics = ("metadata",)
    r1 = FUZZ.SCENARIO.region("R1").center
    for fast in (False, True):
        extra = []
        for i, t_ns in enumerate(run0.t_ns.tolist()):
            if i % 30 == 15:
                continue  # a dropout: 0.2 s between two samples (2 periods)
            vx = 1.5 if fast and i == 200 else 0.05
            extra.append((t_ns, "/odom", "nav_msgs/msg/Odometry", _odometry(t_ns, r1[0], r1[1], vx)))
        run0.extra = extra
        folder = tmp_path / f"fast{fast}"
        folder.mkdir()
        log = FUZZ.write_run(run0, folder / f"husky{FUZZ.SUFFIX[fmt]}", fmt)
        scenario = folder / "husky.yaml"
        text = FUZZ.builtin_scenario_text("nexus-sml").replace(
            "topics: {pose: /qualisys/nexus/pose, cmd_vel: /nexus/cmd_vel, nominal: /nexus/nominal_pose}",
            "topics: {pose: /odom}")
        assert "topics: {pose: /odom}" in text
        scenario.write_text(text + "signals:\n  slow: {topic: /odom, field: twist.twist.linear.x, op: '<=', "
                                   "value: 1.0, unit: m/s}\n")
        for command in ("certify", "watch"):
            code, out, err = run([command, str(log), "--scenario", str(scenario), "--spec", "G[0,inf) slow",
                                  "--time-base", "auto"], capsys)
            assert code == (1 if fast else 0), (command, fast, out, err)


# ---- finding 2: one topic, one type -----------------------------------------------------------------------------
def _pose_stamped(stamp_ns: int, x: float, y: float) -> Callable[[Any, bool], Any]:
    def build(ty: Any, ros1: bool) -> Any:
        sec, nsec = divmod(stamp_ns, 10**9)
        header = ty["std_msgs/msg/Header"](**({"seq": 0} if ros1 else {}),
                                           stamp=ty["builtin_interfaces/msg/Time"](sec=sec, nanosec=nsec),
                                           frame_id="odom")
        return ty["geometry_msgs/msg/PoseStamped"](header=header, pose=ty["geometry_msgs/msg/Pose"](
            position=ty["geometry_msgs/msg/Point"](x=x, y=y, z=0.0),
            orientation=ty["geometry_msgs/msg/Quaternion"](x=0.0, y=0.0, z=0.0, w=1.0)))
    return build


@pytest.mark.parametrize("fmt", ["bag", "mcap", "db3", "dir"])
def test_one_topic_with_two_types_is_exit_3_naming_both(tmp_path: Path, capsys: pytest.CaptureFixture[str],
                                                        monkeypatch: pytest.MonkeyPatch, fmt: str) -> None:
    """One PoseStamped published on /odom before the robot's Odometry stream, which drives through an obstacle."""
    run0 = FUZZ.base_run(violating=True)
    run0.topics = ("metadata",)
    run0.extra = [(int(run0.t_ns[0]) - 1_000_000, "/odom", "geometry_msgs/msg/PoseStamped",
                   _pose_stamped(int(run0.t_ns[0]) - 1_000_000, *run0.xy[0]))]
    run0.extra += [(t_ns, "/odom", "nav_msgs/msg/Odometry", _odometry(t_ns, float(x), float(y), 0.0))
                   for t_ns, (x, y) in zip(run0.t_ns.tolist(), run0.xy, strict=True)]
    log = FUZZ.write_run(run0, tmp_path / f"two{FUZZ.SUFFIX[fmt]}", fmt)
    scenario = tmp_path / "odom.yaml"
    scenario.write_text(FUZZ.builtin_scenario_text("nexus-sml").replace(
        "topics: {pose: /qualisys/nexus/pose, cmd_vel: /nexus/cmd_vel, nominal: /nexus/nominal_pose}",
        "topics: {pose: /odom}"))
    for fast in ("0", "1"):
        monkeypatch.setenv("TUBEMPC_FAST_INGEST", fast)
        for argv in (["certify", str(log)], ["certify", str(log), "--salvage"], ["watch", str(log)]):
            if "--salvage" in argv and fmt in ("db3", "dir"):
                continue
            code, out, err = run([*argv, "--scenario", str(scenario), "--spec", SPEC], capsys)
            assert code == 3, (fast, argv, out, err)
            one_line_error(err, "/odom", "geometry_msgs/msg/PoseStamped", "nav_msgs/msg/Odometry")


# ---- findings 6 and 7: an unknown sample in the timed run; a command with one unknown component ----------------------
@pytest.mark.parametrize("fmt", ["bag", "mcap"])
@pytest.mark.parametrize("fault", ["conflicting duplicate", "NaN position"])
def test_an_unknown_sample_is_unknown_in_the_timed_run(tmp_path: Path, capsys: pytest.CaptureFixture[str], fmt: str,
                                                       fault: str) -> None:
    """The robot stays in R1; at t = 2 s its one sample in R3 (mission_2) is unknown: a second message with the same
    stamp elsewhere, or a NaN position. ``F[0,5] mission_2`` is undecided in both semantics, never failed."""
    run0 = FUZZ.base_run(violating=False)
    k = 20
    r3 = FUZZ.SCENARIO.region("R3").center
    if fault == "NaN position":
        run0.xy[k] = (float("nan"), r3[1])
    else:
        run0.xy[k] = r3
        run0.topics = ("nominal", "cmd_vel", "solver", "metadata")
        stamp = int(run0.stamp_ns[k])
        run0.extra = [(int(t), FUZZ.SCENARIO.topics.pose, FUZZ.POSE, _pose_stamped(int(s), float(x), float(y)))
                      for t, s, (x, y) in zip(run0.t_ns, run0.stamp_ns, run0.xy, strict=True)]
        r1 = FUZZ.SCENARIO.region("R1").center
        run0.extra.append((int(run0.t_ns[k]) + 1_000_000, FUZZ.SCENARIO.topics.pose, FUZZ.POSE,
                           _pose_stamped(stamp, r1[0], r1[1])))
    log = FUZZ.write_run(run0, tmp_path / f"unknown{FUZZ.SUFFIX[fmt]}", fmt)
    for command in ("certify", "watch"):
        code, out, err = run([command, str(log), "--scenario", "nexus-sml", "--spec", "F[0,5] mission_2",
                              "--checks", "spec", "--json"] if command == "certify" else
                             [command, str(log), "--scenario", "nexus-sml", "--spec", "F[0,5] mission_2",
                              "--checks", "spec"], capsys)
        assert code == 2, (command, out, err)
        if command == "certify":
            import json

            checks = {c["name"]: c["verdict"] for c in json.loads(out)["checks"]}
            assert checks == {"spec_trajectory": "inconclusive", "spec_timed_run": "inconclusive"}, checks


@pytest.mark.parametrize("fmt", ["bag", "mcap"])
def test_a_known_component_over_its_bound_fails_beside_a_nan_one(tmp_path: Path,
                                                                 capsys: pytest.CaptureFixture[str],
                                                                 fmt: str) -> None:
    run0 = FUZZ.base_run(violating=False)
    run0.cmd[50] = (5.0, 0.0, float("nan"))  # linear.x 5 m/s against 0.2; angular.z unknown
    log = FUZZ.write_run(run0, tmp_path / f"cmd{FUZZ.SUFFIX[fmt]}", fmt)
    for command in ("certify", "watch"):
        code, out, err = run([command, str(log), "--scenario", "nexus-sml", "--checks", "input_box"], capsys)
        assert code == 1, (command, out, err)
    run0.cmd[50] = (0.1, 0.0, float("nan"))  # only the unknown component: undecided
    log = FUZZ.write_run(run0, tmp_path / f"cmd2{FUZZ.SUFFIX[fmt]}", fmt)
    assert run(["certify", str(log), "--scenario", "nexus-sml", "--checks", "input_box"], capsys)[0] == 2


# ---- finding 5: signal data outside the pose's span -------------------------------------------------------------
@pytest.mark.parametrize("fmt", ["bag", "mcap"])
def test_a_signal_violation_after_the_pose_stream_ends_is_never_a_pass(tmp_path: Path,
                                                                        capsys: pytest.CaptureFixture[str],
                                                                        fmt: str) -> None:
    """The pose stops at 9.9 s, the temperature runs to 30 s and reads 95 degC at 20 s: not judged (the run is the
    pose's span), stated, and no pass; without the hot reading the late messages are only stated."""
    import json

    for hot in (True, False):
        run0 = FUZZ.base_run(violating=False)
        run0.extra = FUZZ.temperature_stream(run0)
        if hot:
            at = int(run0.t_ns[200]) - 2_000_000
            run0.extra.append((at, FUZZ.TEMP_TOPIC, FUZZ.TEMPERATURE, FUZZ.temperature(at, 95.0)))
        run0.topics = ("metadata",)
        run0.extra += [(int(t), FUZZ.SCENARIO.topics.pose, FUZZ.POSE, _pose_stamped(int(t), float(x), float(y)))
                       for t, (x, y) in zip(run0.t_ns[:100], run0.xy[:100], strict=True)]
        log = FUZZ.write_run(run0, tmp_path / f"span{hot}{FUZZ.SUFFIX[fmt]}", fmt)
        scenario = tmp_path / "signal.yaml"
        scenario.write_text(FUZZ.signal_scenario_text())
        code, out, err = run(["certify", str(log), "--scenario", str(scenario), "--spec", SIGNAL_SPEC, "--json",
                              "--checks", "spec"], capsys)
        cert = json.loads(out)
        assert code == (2 if hot else 0), (hot, err)
        assert cert["data_quality"]["signals"]["motor_ok"]["outside_pose_span"] >= 200
        assert any("outside the pose's span" in n for n in cert["data_quality"]["notes"])
        if hot:  # the checks and obligations judge the pose's span; the run cannot pass, and says why
            assert cert["verdict"] == "inconclusive"
            assert "outside the pose's span violate" in cert["verdict_reason"], cert["verdict_reason"]
        code, out, err = run(["watch", str(log), "--scenario", str(scenario), "--spec", SIGNAL_SPEC,
                              "--time-base", "auto", "--checks", "spec"], capsys)
        assert code == (2 if hot else 0), (hot, out, err)


# ---- finding 15: memory bounded by the log, not by the formula's window -------------------------------------------
def test_huge_windows_are_sized_by_the_log(seed_logs: dict[tuple[str, bool], Path],
                                           capsys: pytest.CaptureFixture[str]) -> None:
    import tracemalloc

    import numpy as np

    from verify.monitor.grid import sliding_clipped

    x = np.random.default_rng(3).normal(size=1000)
    for width in (999, 1000, 5000, 10**12):
        assert np.array_equal(sliding_clipped(x, width, np.minimum, np.inf), np.minimum.accumulate(x[::-1])[::-1])
    tracemalloc.start()
    try:
        for spec, want in (("G[0,99999999999] !obs_1", 2), ("G[0,10000000] !(obs_1 | obs_2)", 2),
                           ("F[0,99999999999] obs_1", 2), ("F[99999999999,99999999999] obs_1", 2)):
            code, _, err = run(["certify", str(seed_logs["mcap", False]), "--scenario", "nexus-sml", "--spec", spec,
                                "--checks", "spec"], capsys)
            assert code == want, (spec, err)
        _, peak = tracemalloc.get_traced_memory()
    finally:
        tracemalloc.stop()
    assert peak < 300 * 2**20, peak  # a 30 s log at 10 Hz; the window of 1e11 s asked 14.6 TiB before


# ---- finding 8: certify and watch under one time rule ----------------------------------------------------------------
@pytest.mark.parametrize("fmt", ["bag", "mcap"])
@pytest.mark.parametrize("fault", ["late pose in an obstacle", "three zero stamps"])
def test_certify_and_watch_agree_on_stamp_faults(tmp_path: Path, capsys: pytest.CaptureFixture[str], fmt: str,
                                                 fault: str) -> None:
    run0 = FUZZ.base_run(violating=False)
    run0.topics = ("nominal", "cmd_vel", "solver", "metadata")
    msgs = [(int(t), int(s), float(x), float(y)) for t, s, (x, y) in zip(run0.t_ns, run0.stamp_ns, run0.xy,
                                                                          strict=True)]
    if fault == "three zero stamps":
        for k in (40, 120, 200):
            msgs[k] = (msgs[k][0], 0, msgs[k][2], msgs[k][3])
        want = 0
    else:  # stamped at 5 s inside obstacle 1, delivered at 25 s
        obs = FUZZ.SCENARIO.unsafe_regions[0].center
        msgs.append((int(run0.t_ns[250]) + 1_000_000, int(run0.stamp_ns[50]) + 1_000_000, obs[0], obs[1]))
        want = 1
    run0.extra = [(t, FUZZ.SCENARIO.topics.pose, FUZZ.POSE, _pose_stamped(s, x, y)) for t, s, x, y in msgs]
    log = FUZZ.write_run(run0, tmp_path / f"stamps{FUZZ.SUFFIX[fmt]}", fmt)
    for base in ("header", "auto"):
        codes = []
        for command in ("certify", "watch"):
            code, _out, _err = run([command, str(log), "--scenario", "nexus-sml", "--spec", SPEC, "--checks", "spec",
                                  "--time-base", base], capsys)
            codes.append(code)
        assert codes == [want, want], (base, codes)


# ---- the speed bound checked against the data -------------------------------------------------------------------
@pytest.mark.parametrize("fmt", ["bag", "mcap"])
def test_a_step_faster_than_the_speed_bound_is_never_bridged_with_the_bound(tmp_path: Path,
                                                                            capsys: pytest.CaptureFixture[str],
                                                                            fmt: str) -> None:
    """The robot waits beside obstacle 1 and, between two samples 0.1 s apart, appears on its other side (1.8 m:
    18 m/s against the scenario's bound). The straight line crosses the obstacle: the gap is judged with the step
    the data shows (undecided), never with the contradicted bound (which would pass)."""
    import numpy as np

    run0 = FUZZ.base_run(violating=False)
    cx, cy = FUZZ.SCENARIO.region("R6").center
    half = run0.t_ns.size // 2
    run0.xy[:half] = (cx - 0.9, cy)
    run0.xy[half:] = (cx + 0.9, cy)
    assert 10 * FUZZ.SCENARIO.max_speed_mps * 0.1 < 1.8
    log = FUZZ.write_run(run0, tmp_path / f"jump{FUZZ.SUFFIX[fmt]}", fmt)
    argv = ["--scenario", "nexus-sml", "--spec", "G[0,inf) !obs_1", "--checks", "spec"]
    assert _trajectory_verdict(log, argv, capsys) == "inconclusive"
    code, out, err = run(["watch", str(log), *argv], capsys)
    assert code == 2, (out, err)
    run0.xy[half:] = (cx - 0.9, cy + 0.02)  # a small step within the bound: judged with the bound, a pass
    assert np.all(np.isfinite(run0.xy))
    log = FUZZ.write_run(run0, tmp_path / f"still{FUZZ.SUFFIX[fmt]}", fmt)
    assert _trajectory_verdict(log, argv, capsys) == "pass"


def _trajectory_verdict(log: Path, argv: list[str], capsys: pytest.CaptureFixture[str]) -> str:
    import json

    _, out, _ = run(["certify", str(log), *argv, "--json"], capsys)
    verdicts = {c["name"]: c["verdict"] for c in json.loads(out)["checks"]}
    return str(verdicts["spec_trajectory"])
