"""Recorded runs for the compare tests: one mission (R5 -> R3 past obstacle R9), written as ROS2 logs.

Each run is a straight path R5 -> R3 at 0.2 m/s with holds at both ends; the real state wobbles about it (a smooth
disturbance drawn from the seed), the MoCap adds Gaussian noise, the nominal state is the path. ``shift_m`` moves the
whole path towards R9 (the closest obstacle: 0.408 m clear of the path), as a changed controller would.
"""

from __future__ import annotations

from collections.abc import Callable, Sequence
from pathlib import Path

import numpy as np
import pytest

from tubempc.control.closed_loop import Arrival, ClosedLoopResult, Target
from tubempc.rosio import write_log
from tubempc.scenario import Scenario, builtin_scenario_text, load_scenario

START = np.array([2.02, -1.63])  # R5
GOAL = np.array([0.16, 0.40])  # R3
_DIR = (GOAL - START) / np.linalg.norm(GOAL - START)
TOWARDS_R9 = np.array([_DIR[1], -_DIR[0]])  # the path's normal on R9's side
SPEC = "G[0,inf) !(obs_1 | obs_2 | obs_3 | obs_4) & F[0,30] mission_2"
WriteRuns = Callable[..., list[Path]]


@pytest.fixture(scope="session")
def mission_scenario(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """The built-in scenario with the mission's formula and R5 as the initial region, as a file."""
    text = builtin_scenario_text("nexus-sml")
    text = text.replace("initial_region: R1", "initial_region: R5")
    text = "\n".join(f'spec: "{SPEC}"' if line.startswith("spec:") else line for line in text.splitlines()) + "\n"
    path = tmp_path_factory.mktemp("scenario") / "mission.yaml"
    path.write_text(text, encoding="utf-8")
    assert load_scenario(path).spec == SPEC
    return path


def run_result(seed: int, *, shift_m: float = 0.0, noise_m: float = 0.0005, wobble_m: float = 0.001,
               speed_mps: float = 0.2, rate_hz: float = 100.0) -> ClosedLoopResult:
    rng = np.random.default_rng(seed)
    length = float(np.linalg.norm(GOAL - START))
    t_move = length / speed_mps
    t_s = np.arange(0.0, 2.0 + t_move + 3.0, 1.0 / rate_hz)
    s = np.clip((t_s - 2.0) * speed_mps, 0.0, length)
    path = START + s[:, None] * _DIR + shift_m * TOWARDS_R9
    phase, freq = rng.uniform(0, 2 * np.pi, 2), rng.uniform(0.2, 0.5, 2)
    wobble = wobble_m * np.sin(2 * np.pi * freq[None, :] * t_s[:, None] + phase[None, :])
    x = np.column_stack([path + wobble, np.zeros_like(t_s)])
    measured = x.copy()
    measured[:, :2] += rng.normal(scale=noise_m, size=(t_s.size, 2))
    x_hat = np.column_stack([path, np.zeros_like(t_s)])
    moving = (t_s >= 2.0) & (s < length)
    u = np.zeros((t_s.size, 3))
    u[moving, :2] = speed_mps * _DIR
    inside = float(t_s[np.argmax(np.linalg.norm(path - GOAL, axis=1) <= 0.18)])
    return ClosedLoopResult(
        t_s=t_s, x=x, x_measured=measured, x_hat=x_hat, u_world=u, u_body=u, solver=(),
        arrivals=(Arrival("R3", 0.0, 2.0 + t_move, 2.0 + t_move, inside, None),), targets=(Target("R3"),),
        start_region="R5", tube_radius_m=0.01, sigma=2.0, seed=seed, disturbance="wobble",
        disturbance_params={"wobble_m": wobble_m}, mocap_noise_m=noise_m, ok=True, reason=None)


def _writer(mission_scenario: Path) -> WriteRuns:
    scenario: Scenario = load_scenario(mission_scenario)

    def write(folder: Path, seeds: Sequence[int], *, shift_m: float | Sequence[float] = 0.0,
              names: Sequence[str] | None = None) -> list[Path]:
        folder.mkdir(parents=True, exist_ok=True)
        shifts = [shift_m] * len(seeds) if isinstance(shift_m, int | float) else list(shift_m)
        out = []
        for k, (seed, shift) in enumerate(zip(seeds, shifts, strict=True)):
            name = names[k] if names is not None else f"mission{k}"
            out.append(write_log(run_result(seed, shift_m=shift), scenario, folder / f"{name}.mcap"))
        return out

    return write


@pytest.fixture
def write_runs(mission_scenario: Path) -> WriteRuns:
    """``write_runs(folder, seeds, shift_m=0.0, names=None)``: one ``mission<k>.mcap`` per seed in ``folder``."""
    return _writer(mission_scenario)


@pytest.fixture(scope="session")
def recorded(tmp_path_factory: pytest.TempPathFactory, mission_scenario: Path) -> dict[str, Path]:
    """Folders of recorded runs, written once per session: ``before`` (seeds 0-7), ``after`` (the same missions,
    other noise: seeds 100-107), ``moved`` (seeds 100-107, path 3 cm closer to R9), ``few`` (four runs, seeds
    200-203, path 1.5 cm closer to R9: beyond the 1 cm tolerance, too few runs to tell)."""
    root = tmp_path_factory.mktemp("recorded")
    write = _writer(mission_scenario)
    write(root / "before", range(8))
    write(root / "after", range(100, 108))
    write(root / "moved", range(100, 108), shift_m=0.03)
    write(root / "few", range(200, 204), shift_m=0.015)
    return {name: root / name for name in ("before", "after", "moved", "few")}


@pytest.fixture(scope="session")
def certified(tmp_path_factory: pytest.TempPathFactory, recorded: dict[str, Path],
              mission_scenario: Path) -> dict[str, Path]:
    """The recorded folders certified once (batch certification's output folders, certificates only)."""
    from verify.batch import certify_many, write_batch

    root = tmp_path_factory.mktemp("certified")
    scenario = load_scenario(mission_scenario)
    out = {}
    for name, folder in recorded.items():
        out[name] = root / name
        write_batch(certify_many([folder], scenario, workers=1, progress=False), out[name], reports=False,
                    workers=1, progress=False)
    return out
