"""A user's controller in the loop: the protocol's loader, the kinematic plants, and the pure-pursuit examples
through simulate, regress and falsify."""

from __future__ import annotations

import math
import re
from collections.abc import Sequence
from pathlib import Path

import numpy as np
import pytest

from tubempc.cli import main
from tubempc.control import Target
from tubempc.control.user import ControllerPlan, Reference, checked_controller, load_controller, run_controller
from tubempc.errors import ControllerError
from tubempc.rosio.memory import in_memory_log
from tubempc.scenario import Scenario, load_scenario
from verify import certify_data

ROOT = Path(__file__).resolve().parents[2]
LAB = ROOT / "examples" / "controllers" / "unicycle-lab.yaml"
GOOD = "examples.controllers.pure_pursuit:pure_pursuit"
FAULTY = "examples.controllers.pure_pursuit:corner_cutter"


class Constant:
    """Always the same command (for the plant tests)."""

    def __init__(self, model: str, command: Sequence[float]) -> None:
        self.input_model = model
        self.command = tuple(command)

    def reset(self, scenario: Scenario, plan: ControllerPlan) -> None:
        self.plan = plan

    def step(self, t_s: float, state: np.ndarray, reference: Reference) -> Sequence[float]:
        return self.command


def constant_unicycle() -> Constant:
    return Constant("unicycle", (0.2, 0.5))


def not_a_controller() -> object:
    return object()


@pytest.mark.parametrize(("spec", "words"), [
    ("examples.controllers.pure_pursuit", "expected package.module:factory"),
    ("no_such_package.module:factory", "cannot import no_such_package.module"),
    ("examples.controllers.pure_pursuit:nothing_here", "has no callable 'nothing_here'"),
    (f"{__name__}:not_a_controller", "lacks input_model, reset(scenario, plan) or step"),
])
def test_a_controller_that_cannot_be_loaded_is_named(spec: str, words: str) -> None:
    with pytest.raises(ControllerError, match=re.escape(words)):
        load_controller(spec)


def test_input_model_must_be_the_scenarios() -> None:
    with pytest.raises(ControllerError, match="its input model is unicycle, scenario 'nexus-sml' has holonomic"):
        checked_controller(GOOD, load_scenario("nexus-sml"))


def test_unicycle_plant_follows_the_arc_of_a_constant_command() -> None:
    lab = load_scenario(LAB)
    run = run_controller(lab, constant_unicycle(), [Target("B")], start_region="A", disturbance="none",
                         t_end_s=4.0)
    v, w = 0.2, 0.5
    x0, y0, th0 = *lab.region("A").center, lab.initial_heading
    t = run.t_s
    # the exact solution of x' = v cos th, y' = v sin th, th' = w (RK4 per sample: error far below 1e-9 m)
    x = x0 + v / w * (np.sin(th0 + w * t) - math.sin(th0))
    y = y0 - v / w * (np.cos(th0 + w * t) - math.cos(th0))
    assert np.max(np.hypot(run.x[:, 0] - x, run.x[:, 1] - y)) < 1e-9
    assert np.allclose(run.u_body, [[v, 0.0, w]])  # logged as Twist (linear.x, linear.y, angular.z)
    assert np.all(np.isnan(run.x_hat))  # no nominal claimed: the tube check cannot pass on it


def test_holonomic_plant_turns_the_body_command_with_the_heading() -> None:
    sc = load_scenario("nexus-sml")
    run = run_controller(sc, Constant("holonomic", (0.1, 0.0, 0.2)), [Target("R2")], start_region="R1",
                         disturbance="none", t_end_s=2.0)
    th = sc.initial_heading + 0.2 * run.t_s
    velocity = np.diff(run.x[:, :2], axis=0) / np.diff(run.t_s)[:, None]
    mid = 0.5 * (th[1:] + th[:-1])
    assert np.allclose(velocity, 0.1 * np.column_stack([np.cos(mid), np.sin(mid)]), atol=1e-6)


def test_disturbance_stays_within_the_scenarios_bound() -> None:
    lab = load_scenario(LAB)
    still = Constant("unicycle", (0.0, 0.0))
    run = run_controller(lab, still, [Target("B")], start_region="A", disturbance="worst", t_end_s=3.0)
    speed = np.linalg.norm(np.diff(run.x, axis=0), axis=1) / np.diff(run.t_s)
    assert 0 < speed.max() <= lab.disturbance.bound * (1 + 1e-9)


def test_pure_pursuit_completes_the_mission_and_the_corner_cutter_hits_the_obstacle() -> None:
    lab = load_scenario(LAB)
    good = run_controller(lab, load_controller(GOOD), [Target("W"), Target("B")], disturbance="random", seed=3)
    assert good.ok
    cert = certify_data(in_memory_log(good, lab), lab)
    assert cert.verdict == "pass"
    faulty = run_controller(lab, load_controller(FAULTY), [Target("W"), Target("B")], disturbance="none",
                            t_end_s=30.0)
    cert = certify_data(in_memory_log(faulty, lab), lab).model
    clearance = cert.check("obstacle_clearance")
    assert clearance is not None and clearance.verdict.value == "fail" and clearance.margin is not None
    assert clearance.margin < -0.05  # it cuts the corner at W well into O


def test_simulate_controller_writes_a_log_that_certifies(tmp_path: Path, capsys: pytest.CaptureFixture[str]
                                                         ) -> None:
    out = tmp_path / "run.mcap"
    with pytest.raises(SystemExit) as exc:
        main(["simulate", "--scenario", str(LAB), "--controller", GOOD, "--to", "W,B", "--out", str(out)])
    assert exc.value.code == 0, capsys.readouterr()
    with pytest.raises(SystemExit) as exc:
        main(["certify", str(out), "--scenario", str(LAB)])
    assert exc.value.code == 0
    assert "pass" in capsys.readouterr().out


def test_simulate_with_a_bad_controller_is_one_line_exit_3(tmp_path: Path, capsys: pytest.CaptureFixture[str]
                                                           ) -> None:
    with pytest.raises(SystemExit) as exc:
        main(["simulate", "--scenario", "nexus-sml", "--controller", GOOD, "--to", "R2", "--out",
              str(tmp_path / "x.mcap")])
    err = capsys.readouterr().err
    assert exc.value.code == 3 and len(err.strip().splitlines()) == 1 and "input model" in err


def _regress(controller: str, capsys: pytest.CaptureFixture[str]) -> tuple[int, str]:
    suite = ROOT / "examples" / "controllers"
    with pytest.raises(SystemExit) as exc:
        main(["regress", "--suite", str(suite / "suite.yaml"), "--baseline", str(suite / "baseline.json"),
              "--controller", controller, "--workers", "1", "--no-progress"])
    return int(exc.value.code or 0), capsys.readouterr().out


@pytest.mark.slow
def test_regress_passes_the_example_and_catches_the_corner_cutter(capsys: pytest.CaptureFixture[str]) -> None:
    code, out = _regress(GOOD, capsys)
    assert code == 0, out
    code, out = _regress(FAULTY, capsys)
    assert code == 1
    assert "check.obstacle_clearance.verdict: pass -> fail" in out


@pytest.mark.slow
def test_falsify_finds_the_corner_cutters_violation_within_its_budget(tmp_path: Path,
                                                                      capsys: pytest.CaptureFixture[str]) -> None:
    with pytest.raises(SystemExit) as exc:
        main(["falsify", "--scenario", str(LAB), "--controller", FAULTY, "--to", "W,B", "--method", "random",
              "--budget", "2", "--workers", "1", "--horizon", "40", "--out", str(tmp_path / "f")])
    out = capsys.readouterr().out
    assert exc.value.code == 1, out
    # the corner cutter already violates without disturbance: that run is the counterexample, simulation 0
    assert "VIOLATION first found at simulation 0" in out and "(obstacle_clearance)" in out
