"""No false pass, round two: each finding of the second outside fault campaign as a regression test.

Outputs never written through symlinks, ``--out`` paths that cannot be made, stamp faults on every stream, one
topic with one type, ranges where numbers enter, the fast decoder against rosbags, signal data outside the pose's
span, unknown samples in the timed run, several components of a command.
"""

from __future__ import annotations

import importlib.util
import os
import sys
from pathlib import Path
from types import ModuleType

import pytest
from rosbags.serde import SerdeError

from tubempc.cli import main
from verify.errors import VerifyError

ROOT = Path(__file__).resolve().parents[2]
REFUSED = (SerdeError, VerifyError)
SPEC = "G[0,inf) !(obs_1 | obs_2 | obs_3 | obs_4)"


def _fuzz() -> ModuleType:
    spec = importlib.util.spec_from_file_location("fuzz_certify", ROOT / "benchmarks" / "fuzz_certify.py")
    assert spec is not None and spec.loader is not None
    module = importlib.util.module_from_spec(spec)
    sys.modules.setdefault("fuzz_certify", module)
    spec.loader.exec_module(module)
    return module


FUZZ = _fuzz()


def run(argv: list[str], capsys: pytest.CaptureFixture[str]) -> tuple[int, str, str]:
    with pytest.raises(SystemExit) as exc:
        main(argv)
    out, err = capsys.readouterr()
    code = exc.value.code
    return (code if isinstance(code, int) else 0), out, err


def one_line_error(err: str, *needles: str) -> None:
    lines = [ln for ln in err.splitlines() if ln.strip()]
    assert len(lines) == 1, err
    assert lines[0].startswith("tubempc: error: "), err
    for needle in needles:
        assert needle in lines[0], (needle, err)


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
