"""Regenerate the example logs in ``logs/`` (deterministic: fixed seeds). Run: ``python3 scripts/make_example_logs.py``.

input: the built-in scenario (and deliberately wrong variants of it for the faulty runs) -> output: the logs listed
in ``logs/README.md``. Every log is certified against the *built-in* scenario by ``tests/test_example_logs.py``.
"""

from __future__ import annotations

import argparse
import shutil
import tempfile
from pathlib import Path

from tubempc.control.closed_loop import Target, run_closed_loop
from tubempc.demo import run_demo
from tubempc.rosio import write_log
from tubempc.scenario import Scenario, builtin_scenario, scenario_from_dict

LOGS = Path(__file__).resolve().parent.parent / "logs"


def _variant(base: Scenario, **changes: object) -> Scenario:
    data = base.to_dict()
    for path, value in changes.items():
        target = data
        keys = path.split("__")
        for key in keys[:-1]:
            target = target[int(key)] if key.isdigit() else target[key]
        target[keys[-1]] = value
    return scenario_from_dict(data, source="<variant>")


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__)
    parser.add_argument("--out", type=Path, default=LOGS)
    out: Path = parser.parse_args().out
    out.mkdir(parents=True, exist_ok=True)
    base = builtin_scenario()

    # 1. the demo run: the plan for the paper's formula, executed under a bounded random disturbance -> pass
    with tempfile.TemporaryDirectory() as tmp:
        demo = run_demo(tmp, seed=7, disturbance="random")
        shutil.copy(demo.files["mcap"], out / "demo.mcap")

    # 2. a late mission: leave R1 at 40 s, so R3 is reached after the window [30, 50] closes -> fail at t = 50
    late = run_closed_loop(base, [Target("R1", 40.0), Target("R3")], disturbance="random", seed=3, t_end_s=60.0)
    write_log(late, base, out / "late_mission.mcap", metadata={"example": "late mission"})

    # 3. an obstacle touch: a controller told that R8 has radius 0.01 m drives R5 -> R1 straight through it -> fail
    blind = _variant(base, regions__7__radius=0.01)
    touch = run_closed_loop(blind, [Target("R1")], start_region="R5", disturbance="random", seed=4, t_end_s=26.0)
    write_log(touch, blind, out / "obstacle_touch.bag", metadata={"example": "obstacle touch (R8 shrunk)"})

    # 4. a tube breach: sigma_low = 0.5 gives a 4 cm tube under the worst-case disturbance; the scenario promises 1 cm
    weak = _variant(base, tube__sigma_low=0.5)
    breach = run_closed_loop(weak, [Target("R2")], disturbance="worst", seed=5, t_end_s=24.0)
    write_log(breach, weak, out / "tube_breach.mcap", metadata={"example": "tube breach (sigma_low 0.5)"})

    # 5. a truncated file: a good run's ROS1 bag cut at 60 % of its size -> unusable (exit 3); --salvage -> partial
    good = run_closed_loop(base, [Target("R1", 20.0), Target("R3")], disturbance="random", seed=6, t_end_s=45.0)
    with tempfile.TemporaryDirectory() as tmp:
        whole = write_log(good, base, Path(tmp) / "whole.bag")
        data = whole.read_bytes()
    (out / "truncated.bag").write_bytes(data[: int(len(data) * 0.6)])
    for path in sorted(out.iterdir()):
        if path.suffix in (".mcap", ".bag"):
            print(f"{path.name}: {path.stat().st_size / 1e6:.2f} MB")


if __name__ == "__main__":
    main()
