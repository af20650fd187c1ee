"""Test doubles for the report and batch tests: a CertifyResult-shaped value built from synthetic arrays."""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass, field
from typing import Any

import numpy as np
import pandas as pd
import pytest

from tubempc.scenario import Scenario, builtin_scenario
from verify.certificate import CERTIFICATE_VERSION

EVIL = '<script>alert("x")</script><img src="http://evil.example/x.png">&'


@dataclass(frozen=True)
class FakeResult:
    """Has exactly the attributes of the certifier's ``CertifyResult`` contract."""

    certificate: dict[str, Any]
    exit_code: int
    trajectory: pd.DataFrame
    nominal: pd.DataFrame | None = None
    inputs: pd.DataFrame | None = None
    robustness: pd.DataFrame | None = None
    extra: dict[str, Any] = field(default_factory=dict)


def _frames(n: int = 2000, rate_hz: float = 100.0) -> tuple[pd.DataFrame, pd.DataFrame, pd.DataFrame, pd.DataFrame]:
    rng = np.random.default_rng(7)
    t = np.arange(n) / rate_hz
    s = t / t[-1]
    x = -1.99 + s * (0.16 + 1.99)
    y = -1.78 + s * (0.40 + 1.78)
    theta = 0.1 * np.sin(t)
    traj = pd.DataFrame({"t_s": t, "x_m": x + rng.normal(0, 0.002, n), "y_m": y + rng.normal(0, 0.002, n),
                         "theta_rad": theta})
    # a dropout of 0.5 s, so that the sampling figure has an anomaly to show
    traj = traj.drop(index=range(500, 550)).reset_index(drop=True)
    nom = pd.DataFrame({"t_s": t, "x_m": x, "y_m": y, "theta_rad": theta})
    u = pd.DataFrame({"t_s": t, "u1": np.full(n, 0.11), "u2": np.full(n, 0.11), "u3": 0.1 * np.cos(t)})
    rho = pd.DataFrame({"t_s": t, "rho_m": 0.3 - 0.02 * t})
    return traj, nom, u, rho


def make_certificate(*, verdict: str = "fail", evil: bool = False) -> dict[str, Any]:
    """A certificate that the model (``verify.certificate``) accepts, with a failed, an inconclusive and passing
    checks (``evil``: strings that must be escaped in every report)."""
    name = EVIL if evil else "clearance"
    return {
        "certificate_version": CERTIFICATE_VERSION,
        "verdict": verdict,
        "checks": [
            {"name": "mitl_timed_run", "verdict": "pass", "margin": 0.12, "margin_unit": "m",
             "first_violation_time": None},
            {"name": "tube", "verdict": "fail" if verdict == "fail" else "pass", "margin": -0.004, "margin_unit": "m",
             "first_violation_time": 12.5 if verdict == "fail" else None, "subformula": "|p - p_hat| <= r_q"},
            {"name": "inputs", "verdict": "inconclusive" if verdict != "pass" else "pass", "margin": None,
             "margin_unit": "m/s or rad/s", "first_violation_time": None, "reason": "cmd_vel topic missing"},
            {"name": name, "verdict": "pass", "margin": 0.31, "margin_unit": "m", "first_violation_time": None},
        ],
        "obligations": [{"formula": "G[0,inf) !(obs_1 | obs_2 | obs_3 | obs_4)", "role": "formula", "verdict": "pass",
                         "margin": 0.31, "margin_unit": "m", "margin_atom": "obs_1", "margin_time": 3.0,
                         "margin_reason": None, "first_violation_time": None, "decided_at": 19.99,
                         "subformula": None, "reason": None, "unknown": None, "window": [0.0, None],
                         "explanation": None}],
        "timed_run": [{"region": "R1", "time": 0.0}, {"region": "R3", "time": 19.2}],
        "data_quality": {"dropouts": {"count": 1, "longest_gap_s": 0.51},
                         "topics": {EVIL if evil else "/qualisys/nexus/pose": {"rate_hz": 99.8}},
                         "findings": ["one dropout of 0.51 s"]},
        "formula": "G[0,inf) !(obs_1 | obs_2 | obs_3 | obs_4)",
        "scenario": "nexus-sml",
        "scenario_sha256": "ab" * 32,
        "log": EVIL if evil else "run.mcap",
        "log_format": "mcap",
        "log_digest": "cd" * 32,
        "log_digest_algorithm": "sha256",
        "log_sha256": "cd" * 32,
        "partial": False,
        "time_base": "header",
        "time0_ns": 0,
        "duration_s": 19.99,
        "judged_span_s": [0.0, 19.99],
        "samples": {"pose": {"read": 1950, "judged": 1950}},
        "pose_source": {"topic": "/qualisys/nexus/pose", "type": "geometry_msgs/msg/PoseStamped"},
        "speed_bound_mps": 0.283,
        "robot_radius_m": 0.27,
        "tube": {"radius_m": 0.01, "noise_tolerance_m": 0.0, "noise_tolerance_rule": "3 * scenario.mocap.noise_std"},
        "input_model": "holonomic",
        "checks_selected": ["spec", "tube", "input_box", "workspace", "obstacle_clearance"],
        "checks_source": "default",
        "not_checked": [{"name": "signals", "reason": "the scenario names no signal"}],
        "scenario_warnings": [],
    }


@pytest.fixture
def scenario() -> Scenario:
    return builtin_scenario()


@pytest.fixture(scope="session")
def make_result() -> Callable[..., FakeResult]:
    def build(*, verdict: str = "fail", evil: bool = False, with_optional: bool = True) -> FakeResult:
        traj, nom, u, rho = _frames()
        code = {"pass": 0, "fail": 1, "inconclusive": 2}[verdict]
        if not with_optional:
            return FakeResult(make_certificate(verdict=verdict, evil=evil), code, traj)
        return FakeResult(make_certificate(verdict=verdict, evil=evil), code, traj, nom, u, rho)

    return build
