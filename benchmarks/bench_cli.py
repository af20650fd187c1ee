"""Benchmark: how fast the command line answers, against starting Python and against a plain rosbags read.

    python3 benchmarks/bench_cli.py [--repeat 5]

Writes a one-minute log at 50 Hz in the style of a Clearpath Jackal's (ROS1, nav_msgs/Odometry and sensor_msgs/Imu
at 50 Hz, a simulated clock) and a scenario for it (``tubempc scenario init``), then times, as fresh processes
(the median of ``--repeat`` runs, wall clock): ``python -c pass``; ``tubempc -V``; ``tubempc --help``;
``tubempc certify LOG --scenario S --json``; and a plain rosbags read of the same log (every message read and
deserialized, in a fresh process too). Each is printed with its ratio to ``python -c pass``; the last line is
``version_s= help_s= certify_json_s= rosbags_read_s=``. Run it on an idle machine: the times are wall clock. Each
row also prints the median CPU time (user + system) of its process: on a loaded machine the wall time measures the
load, the CPU time the work.

Every command runs once untimed first, with ``PYTHONDONTWRITEBYTECODE`` removed from its environment, so that
each is timed as an installed package runs (modules compiled once, their bytecode cached), not recompiling every
module of the source tree at each start.
"""

from __future__ import annotations

import argparse
import importlib.util
import os
import resource
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path
from typing import Any

ROOT = Path(__file__).resolve().parent.parent

ROSBAGS_READ = """
import sys
from pathlib import Path
from rosbags.highlevel import AnyReader
from rosbags.typesys import Stores, get_typestore
n = 0
with AnyReader([Path(sys.argv[1])], default_typestore=get_typestore(Stores.ROS1_NOETIC)) as reader:
    for conn, _, raw in reader.messages():
        reader.deserialize(raw, conn.msgtype)
        n += 1
print(n)
"""


def _kit() -> Any:
    path = ROOT / "scripts" / "make_any_robot_logs.py"
    spec = importlib.util.spec_from_file_location("any_robot_logs", path)
    if spec is None or spec.loader is None:
        raise RuntimeError(f"cannot load {path}")
    mod = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(mod)
    return mod


def jackal_like_log(path: Path) -> Path:
    """One minute at 50 Hz: Odometry of a unicycle driving a loop, and an IMU; the clock starts at 100 s."""
    from rosbags.typesys import Stores, get_typestore

    kit = _kit()
    t0_ns = 100 * 10**9
    run = kit.unicycle_run(((0.0, 0.0), (6.0, 0.0), (6.0, 4.0), (0.0, 4.0), (0.0, 0.5)), v_mps=0.5, w_radps=0.8,
                           rate_hz=50.0)
    messages = kit.odometry_messages(run, "/odometry/filtered", ros1=True, time0_ns=t0_ns)
    T = get_typestore(Stores.ROS1_NOETIC).types
    V3, Q = T["geometry_msgs/msg/Vector3"], T["geometry_msgs/msg/Quaternion"]
    zeros = __import__("numpy").zeros(9)
    for k in range(len(run.t_s)):
        t_ns = t0_ns + k * 20_000_000
        header = T["std_msgs/msg/Header"](seq=k, stamp=T["builtin_interfaces/msg/Time"](
            sec=t_ns // 10**9, nanosec=t_ns % 10**9), frame_id="imu_link")
        messages.append(("/imu/data", "sensor_msgs/msg/Imu", t_ns, T["sensor_msgs/msg/Imu"](
            header=header, orientation=Q(x=0.0, y=0.0, z=0.0, w=1.0), orientation_covariance=zeros,
            angular_velocity=V3(x=0.0, y=0.0, z=0.1), angular_velocity_covariance=zeros,
            linear_acceleration=V3(x=0.0, y=0.0, z=9.81), linear_acceleration_covariance=zeros)))
    return kit.write_messages(path, messages)  # type: ignore[no-any-return]


def _children_cpu_s() -> float:
    used = resource.getrusage(resource.RUSAGE_CHILDREN)
    return used.ru_utime + used.ru_stime


def timed(cmd: list[str], repeat: int) -> tuple[float, float]:
    """Median wall time and median CPU time of ``cmd`` as a fresh process (it must succeed or exit with a verdict
    code)."""
    env = {k: v for k, v in os.environ.items() if k != "PYTHONDONTWRITEBYTECODE"}
    times, cpus = [], []
    for i in range(repeat + 1):  # the first run caches the bytecode; it is not timed
        cpu = _children_cpu_s()
        start = time.perf_counter()
        done = subprocess.run(cmd, capture_output=True, text=True, check=False, cwd=ROOT, env=env)
        if i:
            times.append(time.perf_counter() - start)
            cpus.append(_children_cpu_s() - cpu)
        if done.returncode not in (0, 1, 2):
            raise RuntimeError(f"{' '.join(cmd)} exited {done.returncode}: {done.stderr.strip()}")
    return statistics.median(times), statistics.median(cpus)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--repeat", type=int, default=5, help="runs per measurement (the median is printed)")
    args = parser.parse_args()
    py = sys.executable
    with tempfile.TemporaryDirectory() as tmp:
        log = jackal_like_log(Path(tmp) / "jackal.bag")
        scenario = Path(tmp) / "jackal.yaml"
        init = subprocess.run([py, "-m", "tubempc", "scenario", "init", str(log)], capture_output=True, text=True,
                              check=True, cwd=ROOT)
        scenario.write_text(init.stdout)
        base, base_cpu = timed([py, "-c", "pass"], args.repeat)
        rows = {
            "version_s": timed([py, "-m", "tubempc", "-V"], args.repeat),
            "help_s": timed([py, "-m", "tubempc", "--help"], args.repeat),
            "certify_json_s": timed([py, "-m", "tubempc", "certify", str(log), "--scenario", str(scenario), "--json"],
                                    args.repeat),
            "rosbags_read_s": timed([py, "-c", ROSBAGS_READ, str(log)], args.repeat),
        }
    print(f"python -c pass: {base:.3f} s (baseline), CPU {base_cpu:.3f} s")
    for name, (value, cpu) in rows.items():
        print(f"{name.removesuffix('_s')}: {value:.3f} s ({value / base:.1f}x python -c pass), CPU {cpu:.3f} s")
    print(" ".join(f"{name}={value:.3f}" for name, (value, _) in rows.items()))


if __name__ == "__main__":
    main()
