"""Falsification: the search space stays admissible, each method finds a planted violation, none on the correct design.

Planted faults (the scenario's claims stay those of the built-in scenario: r_q = 0.01 m for sigma_low = 2):
the controller run with ``tube.sigma_low=0.5`` (its tube settles at 4 r_q under a constant full-bound push), and
a controller whose tightening ignores the tube (``disturbance.bound=0``: it plans at the robot radius from the
obstacle). Runs are the R4 -> R5 transition (~20 s, around obs_4 where the obstacle constraint is active).
"""

from __future__ import annotations

import json
import math
import shlex
from pathlib import Path

import numpy as np
import pytest

from tubempc.cli import main
from tubempc.falsify import (
    FalsifyError,
    FalsifyRequest,
    OverrideError,
    apply_overrides,
    make_space,
    prepare,
    run_falsify,
    write_outcome,
)
from tubempc.falsify.signals import StepSignal, SwitchSignal
from tubempc.scenario import builtin_scenario

SC = builtin_scenario()


def _request(**kw: object) -> FalsifyRequest:
    base: dict[str, object] = {"scenario_ref": "nexus-sml", "source": "R4", "target": "R5", "budget": 6, "seed": 0}
    base.update(kw)
    return FalsifyRequest(**base)  # type: ignore[arg-type]


# ---- the search space ------------------------------------------------------------------------------------------
@pytest.mark.parametrize("family", ["steps", "sine", "switch"])
def test_every_point_of_the_cube_is_an_admissible_perturbation(family: str) -> None:
    space = make_space(SC, "R1", family=family, knots=5, switches=3, horizon_s=30.0)  # type: ignore[arg-type]
    rng = np.random.default_rng(3)
    t = np.linspace(0.0, 40.0, 4001)
    centre = np.array(space.start_center)
    axes = np.array(space.start_semi_axes)
    corners = [np.ones(space.dim), -np.ones(space.dim)]
    for z in [*corners, *rng.uniform(-1, 1, size=(30, space.dim))]:
        cand = space.decode(z)
        delta = cand.signal.batch(t)
        assert np.max(np.linalg.norm(delta, axis=1)) <= SC.disturbance.bound * (1 + 1e-12)
        e = (np.array(cand.start_pose) - centre) / axes  # inside the terminal set |e|_P <= eps
        assert float(np.linalg.norm(e)) <= 1 + 1e-12
        assert cand.noise_std_m == 0.0  # the scenario states no MoCap noise


def test_the_centre_of_the_cube_is_the_unperturbed_run() -> None:
    space = make_space(SC, "R2", family="steps", knots=3, horizon_s=10.0)
    cand = space.decode(np.zeros(space.dim))
    assert not cand.signal.batch(np.linspace(0, 20, 50)).any()
    region = SC.region("R2")
    assert cand.start_pose == (region.center[0], region.center[1], SC.initial_heading)


def test_full_magnitude_corners_reach_the_bound_and_steps_hold_their_segments() -> None:
    space = make_space(SC, "R1", family="steps", knots=2, horizon_s=10.0, vary_start=False)
    z = np.array([1.0, 0.0, 0.0, -1.0, -1.0, -1.0])
    sig = space.decode(z).signal
    assert isinstance(sig, StepSignal)
    d = sig.batch(np.array([0.0, 4.99, 5.0, 12.0]))
    assert np.allclose(d[0], [SC.disturbance.bound, 0, 0]) and np.allclose(d[1], d[0])
    assert math.isclose(float(np.linalg.norm(d[2])), SC.disturbance.bound) and np.allclose(d[3], d[2])


def test_switching_times_fall_on_mpc_steps_and_alternate_the_outward_push() -> None:
    space = make_space(SC, "R1", family="switch", switches=2, horizon_s=10.0, vary_start=False)
    z = np.zeros(space.dim)
    z[:2] = [-0.5, 0.5]  # fractions 0.25 and 0.75 of 10 s
    z[2] = 1.0  # first interval outward
    sig = space.decode(z).signal
    assert isinstance(sig, SwitchSignal)
    assert sig.switch_s == (2.5, 7.5)
    assert [sig.worst_at(t) for t in (0.0, 2.4, 2.5, 7.4, 7.5, 9.0)] == [True, True, False, False, True, True]


# ---- overrides -------------------------------------------------------------------------------------------------
def test_overrides_change_the_controller_scenario_only() -> None:
    ctrl = apply_overrides(SC, ["tube.sigma_low=0.5", "regions.5.radius=0.4"])
    assert ctrl.tube.sigma_low == 0.5 and ctrl.regions[5].radius == 0.4
    assert SC.tube.sigma_low == 2.0 and SC.regions[5].radius == 0.45
    with pytest.raises(OverrideError, match=r"no field 'tube\.sigma'"):
        apply_overrides(SC, ["tube.sigma=1"])
    with pytest.raises(OverrideError, match="sigma_low"):
        apply_overrides(SC, ["tube.sigma_low=-1"])
    with pytest.raises(OverrideError, match="key=value"):
        apply_overrides(SC, ["tube.sigma_low"])


def test_a_request_needs_exactly_one_run_and_known_checks() -> None:
    with pytest.raises(FalsifyError, match="--to REGION"):
        FalsifyRequest("nexus-sml", source="R1")
    with pytest.raises(FalsifyError, match="unknown check"):
        FalsifyRequest("nexus-sml", target="R2", checks=("tube", "speed"))


# ---- the objective is the certifier's ------------------------------------------------------------------------
def test_in_memory_judgement_equals_the_certificate_of_the_written_log(tmp_path: Path) -> None:
    req = _request(overrides=("tube.sigma_low=0.5",), budget=1, method="random", seed=4)
    outcome = write_outcome(run_falsify(req, SC, workers=1), tmp_path)
    worst = outcome.files["worst"]
    assert worst["certificate_verdict"] == "fail"
    assert worst["margin_from_log"] == pytest.approx(worst["margin_in_memory"], abs=1e-9)
    cert = json.loads(Path(worst["certificate"]).read_text())
    assert cert["tube"]["radius_m"] == pytest.approx(SC.tube_radius_m)  # the claim, not the controller's 0.04 m
    data = json.loads((tmp_path / "falsify.json").read_text())
    assert data["verdict"] == "fail" and data["exit_code"] == 1
    assert data["controller_overrides"] == ["tube.sigma_low=0.5"]


# ---- each method finds a planted violation --------------------------------------------------------------------
@pytest.mark.parametrize("method", ["random", "targeted", "optimizer"])
def test_each_method_finds_the_planted_sigma_low_fault(method: str) -> None:
    outcome = run_falsify(_request(method=method, overrides=("tube.sigma_low=0.5",), budget=5, stop_at_first=True),
                          SC, workers=1)
    assert outcome.verdict == "fail"
    assert outcome.result.first_violation is not None and outcome.result.first_violation <= 5
    worst = outcome.result.worst
    assert worst is not None and worst.violated and worst.checks["tube"]["verdict"] == "fail"
    assert outcome.reference.margin > 0  # the unperturbed run itself is fine: the search found the breaking input


@pytest.mark.parametrize("method", ["random", "targeted", "optimizer"])
def test_no_method_reports_a_violation_on_the_correct_design(method: str) -> None:
    outcome = run_falsify(_request(method=method, budget=5, shrink_budget=0), SC, workers=1)
    assert outcome.verdict == "no_violation_found", outcome.to_json()["worst"]
    worst = outcome.result.worst
    assert worst is not None and 0 <= worst.margin < outcome.reference.margin


def test_targeted_shrinks_the_counterexample_towards_no_perturbation() -> None:
    outcome = run_falsify(_request(method="targeted", overrides=("disturbance.bound=0",), budget=8, shrink_budget=8),
                          SC, workers=1)
    assert outcome.verdict == "fail"
    minimal = outcome.result.minimal
    assert minimal is not None and minimal.violated
    first = next(e for e in outcome.result.evaluations if e.violated)
    assert np.linalg.norm(minimal.z) <= np.linalg.norm(first.z)


# ---- the command -------------------------------------------------------------------------------------------------
def test_cli_replays_a_point_exactly_and_exits_1_on_a_violation(tmp_path: Path, capsys: pytest.CaptureFixture[str]
                                                                ) -> None:
    req = _request(overrides=("tube.sigma_low=0.5",), budget=2, method="random", seed=1)
    outcome = write_outcome(run_falsify(req, SC, workers=1), tmp_path / "search")
    data = outcome.to_json()
    replay = shlex.split(data["worst"]["replay"])
    assert replay[:2] == ["tubempc", "falsify"]
    with pytest.raises(SystemExit) as exc:
        main([*replay[1:], "--out", str(tmp_path / "replay")])
    assert exc.value.code == 1
    out = capsys.readouterr().out
    assert f"margin {data['worst']['margin']:.9g}" in out
    cert = json.loads((tmp_path / "replay" / "certificate.json").read_text())
    assert cert["verdict"] == "fail"


@pytest.mark.parametrize("method", ["targeted", "random"])
def test_a_reference_run_that_violates_is_the_counterexample_at_simulation_0(
        method: str, tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    """Issue 22: with robot.radius=0.2 the controller plans too close to obs_4 and the unperturbed run touches it;
    falsify ran 0 simulations, wrote no_violation_found with exit code 0, then crashed formatting None (exit 70)."""
    with pytest.raises(SystemExit) as exc:
        main(["falsify", "--scenario", "nexus-sml", "--from", "R4", "--to", "R5", "--set", "robot.radius=0.2",
              "--method", method, "--budget", "5", "--seed", "0", "--workers", "1", "--out", str(tmp_path / "f")])
    assert exc.value.code == 1
    out = capsys.readouterr().out
    assert "VIOLATION first found at simulation 0" in out
    data = json.loads((tmp_path / "f" / "falsify.json").read_text())
    assert data["verdict"] == "fail" and data["exit_code"] == 1
    assert data["first_violation_sim"] == 0 and data["simulations"] == 0
    assert data["worst"]["sim"] == 0 and data["worst"]["violated"] and data["reference"]["violated"]
    assert data["files"]["worst"]["certificate_verdict"] == "fail"


def test_cli_bad_override_is_one_line_and_exit_3(capsys: pytest.CaptureFixture[str]) -> None:
    with pytest.raises(SystemExit) as exc:
        main(["falsify", "--to", "R2", "--set", "tube.sigma_lo=0.5", "--budget", "1"])
    assert exc.value.code == 3
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "tube.sigma_lo" in err[0]


def test_cli_impossible_controller_design_is_exit_3(capsys: pytest.CaptureFixture[str]) -> None:
    with pytest.raises(SystemExit) as exc:
        main(["falsify", "--to", "R2", "--set", "inputs.max_abs=[0.01, 0.01, 0.01]", "--budget", "1"])
    assert exc.value.code == 3
    assert "unperturbed run cannot be simulated" in capsys.readouterr().err


@pytest.mark.slow
def test_the_correct_design_approaches_the_tube_bound_without_crossing_it() -> None:
    """The lemma's worst case rides r_q: the optimizer gets within 1e-4 m of it and never across."""
    req = _request(method="optimizer", family="switch", budget=40, seed=2, checks=("tube",))
    outcome = run_falsify(req, SC, workers=1)
    assert outcome.verdict == "no_violation_found"
    worst = outcome.result.worst
    assert worst is not None and 0 <= worst.margin < 1e-4


def test_prepare_uses_the_unperturbed_run_length_as_horizon() -> None:
    setup, reference = prepare(_request(), SC)
    assert setup.space.horizon_s == pytest.approx(reference.duration_s)
    assert reference.margin > 0 and not reference.violated


@pytest.mark.slow  # starts a local Dask cluster
def test_random_search_on_dask_equals_inline() -> None:
    req = _request(method="random", budget=2, seed=5)
    inline = run_falsify(req, SC, workers=1).result.evaluations
    remote = run_falsify(req, SC, workers=2, dask="local").result.evaluations
    assert [(e.z, e.margin, e.violated) for e in remote] == [(e.z, e.margin, e.violated) for e in inline]


def test_mocap_noise_is_searched_within_its_std_and_runs_with_the_switching_push() -> None:
    noisy = apply_overrides(SC, ["mocap.noise_std=0.001"])
    space = make_space(noisy, "R4", family="switch", switches=2, horizon_s=19.0)
    assert space.names()[-2:] == ["noise.std", "noise.seed"]
    rng = np.random.default_rng(7)
    stds = [space.decode(z).noise_std_m for z in rng.uniform(-1, 1, size=(50, space.dim))]
    assert max(stds) <= 0.001 and min(stds) >= 0.0 and max(stds) > 0.0005
    # noise with an outward push takes the sampled (CasADi) path of the closed loop; judged like any run
    from tubempc.falsify import FalsifySetup, evaluate
    from tubempc.falsify.objective import DEFAULT_CHECKS

    setup = FalsifySetup(noisy, noisy, "R4", (("R5", None),), "G[0,inf) !obs_4", DEFAULT_CHECKS, space)
    z = rng.uniform(-1, 1, size=space.dim)
    z[2] = 1.0  # the first interval is the outward push
    ev = evaluate(setup, tuple(z))
    assert ev.error is None and math.isfinite(ev.margin)
    assert ev.checks["tube"]["verdict"] in ("pass", "fail")
