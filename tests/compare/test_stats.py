"""The per-metric judgement: regressed / within tolerance / improved / cannot tell, and the metrics of a certificate."""

from __future__ import annotations

from collections.abc import Sequence
from pathlib import Path

import numpy as np
import pytest

from tubempc.compare import CompareSettings, MetricValue, Pairing, Run, certificate_metrics, compare_metrics, min_pairs
from tubempc.compare.metrics import metric_info
from verify import certify_log
from verify.certificate import Certificate, Verdict

ROOT = Path(__file__).resolve().parents[2]
TOL = 0.01  # the default tolerance of min_clearance_m


def _pairing(keys: Sequence[str], *, paired: bool = True) -> Pairing:
    blank = Certificate.model_construct()  # the judgement reads only the keys of the pairs
    pairs = tuple((Run(k, "b", blank), Run(k, "a", blank)) for k in keys) if paired else ()
    return Pairing(pairs, paired, (), (), "test")


def _judge(before: Sequence[float | None], after: Sequence[float | None], *, metric: str = "min_clearance_m",
           paired: bool = True, confidence: float = 0.95) -> tuple[str, str]:
    keys = [f"run{k}" for k in range(max(len(before), len(after)))]
    side_b = {k: {metric: MetricValue(number=v, unit="m")} if v is not None else {}
              for k, v in zip(keys, before, strict=False)}
    side_a = {k: {metric: MetricValue(number=v, unit="m")} if v is not None else {}
              for k, v in zip(keys, after, strict=False)}
    (result,) = compare_metrics(_pairing(keys, paired=paired), side_b, side_a, CompareSettings(confidence=confidence))
    return result.status, result.reason


def test_fewest_pairs_of_a_one_sided_signed_rank_test() -> None:
    assert min_pairs(0.05) == 5  # 2**-4 = 0.0625 cannot reach 0.05; 2**-5 = 0.031 can
    assert min_pairs(0.1) == 4
    assert min_pairs(0.01) == 7


def test_a_clear_shift_beyond_the_tolerance_regresses_from_five_pairs_on() -> None:
    rng = np.random.default_rng(0)
    before = 0.4 + rng.normal(scale=0.001, size=5)
    assert _judge(before, before - 3 * TOL)[0] == "regressed"
    status, reason = _judge(before[:4], before[:4] - 3 * TOL)
    assert status == "cannot_tell" and "too few runs to tell" in reason and "at least 5 pairs" in reason


def test_no_change_within_noise_is_shown_within_tolerance() -> None:
    rng = np.random.default_rng(1)
    before = 0.4 + rng.normal(scale=0.001, size=8)
    after = 0.4 + rng.normal(scale=0.001, size=8)
    assert _judge(before, after)[0] == "ok"
    assert _judge(before, after, paired=False)[0] == "ok"


def test_spread_too_wide_to_show_the_tolerance_holds_cannot_tell() -> None:
    rng = np.random.default_rng(2)
    before = 0.4 + rng.normal(scale=0.05, size=8)  # five tolerances of noise
    after = 0.4 + rng.normal(scale=0.05, size=8)
    status, reason = _judge(before, after)
    assert status == "cannot_tell" and "cannot show it stays within the tolerance" in reason


def test_shift_beyond_tolerance_but_not_significant_cannot_tell() -> None:
    before = [0.40, 0.40, 0.40, 0.40, 0.40, 0.40]
    after = [0.38, 0.38, 0.38, 0.38, 0.43, 0.43]  # median 2 cm worse, but two runs of six are 3 cm better
    status, reason = _judge(before, after)
    assert status == "cannot_tell" and "not significant" in reason


def test_clear_improvement_is_improved() -> None:
    before = 0.4 + np.linspace(0, 0.001, 8)
    assert _judge(before, before + 3 * TOL)[0] == "improved"
    assert _judge(before, before + 3 * TOL, paired=False)[0] == "improved"


def test_the_confidence_is_the_one_stated() -> None:
    before = 0.4 + np.linspace(0, 0.001, 4)
    assert _judge(before, before - 3 * TOL)[0] == "cannot_tell"  # 95 %: four pairs are too few
    assert _judge(before, before - 3 * TOL, confidence=0.9)[0] == "regressed"  # 90 %: 2**-4 < 0.1


def test_a_region_no_longer_reached_in_one_pair_regresses() -> None:
    status, reason = _judge([30.0, 30.1, 29.9], [30.0, None, 29.9], metric="entry_s.R3")
    assert status == "regressed" and "run1" in reason


def _verdicts(before: Sequence[Verdict], after: Sequence[Verdict], *, paired: bool) -> tuple[str, str]:
    keys = [f"run{k}" for k in range(len(before))]
    side_b = {k: {"verdict": MetricValue(verdict=v)} for k, v in zip(keys, before, strict=True)}
    side_a = {k: {"verdict": MetricValue(verdict=v)} for k, v in zip(keys, after, strict=True)}
    (result,) = compare_metrics(_pairing(keys, paired=paired), side_b, side_a, CompareSettings())
    return result.status, result.reason


def test_a_paired_pass_turning_inconclusive_regresses_even_with_two_runs() -> None:
    status, reason = _verdicts([Verdict.PASS, Verdict.PASS], [Verdict.PASS, Verdict.INCONCLUSIVE], paired=True)
    assert status == "regressed" and "run1: pass -> inconclusive" in reason
    assert _verdicts([Verdict.PASS] * 2, [Verdict.PASS] * 2, paired=True)[0] == "ok"


def test_unpaired_verdicts_by_the_share_of_runs_that_do_not_pass() -> None:
    ok, fail = Verdict.PASS, Verdict.FAIL
    assert _verdicts([ok] * 8, [fail] * 6 + [ok] * 2, paired=False)[0] == "regressed"
    assert _verdicts([ok] * 8, [fail] + [ok] * 7, paired=False)[0] == "cannot_tell"
    assert _verdicts([ok] * 3, [fail] * 3, paired=False)[0] == "cannot_tell"  # 1 / C(6, 3) = 0.05: too few


def test_metrics_of_a_certificate() -> None:
    cert = Certificate.model_validate(certify_log(ROOT / "logs" / "demo.mcap", "nexus-sml").certificate)
    metrics = certificate_metrics(cert)
    clearance = cert.check("obstacle_clearance")
    tube, box = cert.check("tube"), cert.check("input_box")
    assert clearance is not None and tube is not None and box is not None
    assert metrics["check.obstacle_clearance.margin"].number == clearance.margin
    assert metrics["min_clearance_m"].number == clearance.details["sample_margin_m"]  # sampled, not the bound
    assert metrics["tube_ratio"].number == pytest.approx(tube.details["max_deviation_m"] / tube.details["radius_m"])
    usage = max(1 - (m - box.details["tolerance"]) / 0.2 for m in box.details["component_margins"].values())
    assert metrics["input_usage"].number == pytest.approx(usage)
    run = [(e.region, e.time) for e in cert.timed_run]  # R1 at 0, R3, R1 again
    assert metrics["entry_s.R3"].number == run[1][1]
    assert "entry_s.R1" in metrics and metrics["entry_s.R1"].number == run[0][1]  # the first entry
    assert metrics["transition_s.R3->R1"].number == pytest.approx(run[2][1] - run[1][1])
    assert metrics["verdict"].verdict is Verdict.PASS
    assert metric_info("duration_s").direction == "neutral"
    assert metric_info("check.tube.margin", "m").direction == "higher_better"
