"""The online monitor's decisions and final lines say what the certificate says: regressions found by the
cross-front-end property (``property_tests/test_any_formula.py``, watch and online decisions on the full grammar)."""

from __future__ import annotations

import numpy as np

from tubempc.scenario import SignalSpec, builtin_scenario
from verify import certify_data
from verify.certificate import Certificate
from verify.ingest import LogData, PoseStream
from verify.online import OnlineMonitor

SC = builtin_scenario()
SC_SIGNAL = SC.model_copy(update={"signals": {"calm": SignalSpec(topic="/speed", field="data", op="<=", value=0.5,
                                                                  unit="m/s", rate_hz=10.0)}})
T0 = 1_700_000_000 * 10**9
MISSION_1 = SC.region("R1").center  # the region labelled mission_1


def _log(t_rel_ns: list[int], x: float, y: float) -> LogData:
    t = T0 + np.array(t_rel_ns, dtype=np.int64)
    n = t.size
    pose = PoseStream(t, np.full(n, x), np.full(n, y), np.zeros(n))
    return LogData("<memory>", "in-memory", "0" * 64, "sha256", "header", T0, pose, {}, None, None, None, (), None,
                   {"notes": [], "missing_definitions": []}, False, pose_samples=pose)


def _certificate(log: LogData, spec: str, sc=SC) -> Certificate:  # type: ignore[no-untyped-def]
    return Certificate.model_validate(certify_data(log, sc, spec=spec, checks=["spec"]).certificate)


def _online(t_rel_ns: list[int], x: float, y: float, spec: str, sc=SC):  # type: ignore[no-untyped-def]
    mon = OnlineMonitor(sc, spec=spec, checks=["spec"])
    decisions = []
    for t in t_rel_ns:
        mon.push_pose(T0 + t, x, y)
        decisions += mon.update()
    mon.close()
    return mon, decisions + mon.final_decisions


def test_a_signal_atom_without_a_stream_is_unknown_not_false() -> None:
    """certify_data on samples without the formula's signal: inconclusive (it was a fail: the signal was taken for
    a region label no region has), as the online monitor holds a signal before its first message."""
    log = _log([0, 100_000_000], *MISSION_1)
    cert = _certificate(log, "calm", SC_SIGNAL)
    assert cert.check("spec_trajectory").verdict.value == "inconclusive"  # type: ignore[union-attr]
    unknown = cert.panels[0].unknown
    assert unknown is not None and (unknown.atom, unknown.cause, unknown.decide) == (
        "calm", "no message of /speed before 0.00 s (it has none)", "a message of /speed by 0.00 s would decide it")
    mon, _ = _online([0, 100_000_000], *MISSION_1, "calm", SC_SIGNAL)
    assert mon.close().checks[0].verdict == "inconclusive"


def test_a_command_decided_before_the_first_pose_is_judged_is_timed_from_it() -> None:
    """A violating command while the first pose sample is still buffered (it waits for the formula's signal): the
    decision states its first violation, timed from that pose sample (it said none)."""
    mon = OnlineMonitor(SC_SIGNAL, spec="calm", checks=["spec", "input_box"])
    mon.push_pose(T0, *MISSION_1)
    assert mon.update() == []
    mon.push_cmd(T0, 9.0, 0.0, 0.0)
    (d,) = [d for d in mon.update() if d.name == "input_box"]
    assert (d.verdict, d.time_s, d.first_violation_s) == ("fail", 0.0, 0.0)


def test_the_obligations_are_the_certificates_conjuncts() -> None:
    """``p & p`` (no temporal operator) and ``p & X p`` are two obligations each, as in the certificate (they were
    one, named by the whole formula)."""
    for spec in ("mission_1 & mission_1", "mission_1 & X mission_1"):
        cert = _certificate(_log([0, 10**8], *MISSION_1), spec)
        mon, _ = _online([0, 10**8], *MISSION_1, spec)
        assert [o.name for o in mon.state().obligations] == [o.formula for o in cert.panels]


def test_next_and_a_constant_over_a_gap_are_decided_when_the_data_decides_them() -> None:
    """``X`` is judged at close but decided by the second sample; ``G(0,inf) false`` by the gap after the first
    sample, known when the sample after it arrives (the certificate said at its start, the monitor at the end)."""
    t = [0, 1, 50_000_000, 50_000_001]
    cases = {"X(0,inf) mission_1": 1e-9, "G(0,inf) false": 1e-9}
    gap = [0, 50_000_000, 50_000_001]
    for spec, when in cases.items():
        cert = _certificate(_log(t, *MISSION_1), spec)
        _, decisions = _online(t, *MISSION_1, spec)
        (d,) = [d for d in decisions if d.name == cert.panels[0].formula]
        assert d.time_s == cert.panels[0].decided_at == when
    cert = _certificate(_log(gap, *MISSION_1), "G(0,inf) false")
    _, decisions = _online(gap, *MISSION_1, "G(0,inf) false")
    (d,) = [d for d in decisions if d.name == "G(0,inf) false"]
    assert d.time_s == cert.panels[0].decided_at == 0.05


def test_a_late_disagreeing_duplicate_leaves_no_obligation_passing() -> None:
    """A duplicate stamp with other values after its sample was judged: spec_trajectory is inconclusive, and so is
    the obligation's final line (it said PASS)."""
    mon = OnlineMonitor(SC, spec="mission_1", checks=["spec"], max_pending=1)
    mon.push_pose(T0, *MISSION_1)
    mon.update()
    mon.push_pose(T0, MISSION_1[0] + 0.01, MISSION_1[1])
    result = mon.close()
    assert result.checks[0].verdict == "inconclusive"
    assert [o.verdict for o in mon.state().obligations] == ["inconclusive"]
