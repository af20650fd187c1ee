"""certify and watch read a log under one set of rules (``verify.ingest.rules``): the same time base (``auto``
decided on the whole pose stream), the same stream problems, the same clock corrections, and watch states the
certificate's one-sentence reasons."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from tubempc.scenario import builtin_scenario
from verify import certify_log
from verify.ingest import read_log
from verify.ingest.rules import ReadingRules
from verify.online import OnlineMonitor
from verify.online.follow import open_follower
from verify.online.watch import AUTO_PROBE, _Feeder, watch_log

from ..verify.support import FUZZ, run  # noqa: TID252  (the shared helpers; tests is not a package)

ROOT = Path(__file__).resolve().parents[2]
LOGS = ROOT / "logs"
SPEC = "G[0,inf) !(obs_1 | obs_2 | obs_3 | obs_4)"


def _late_zero_stamps(tmp_path: Path, fmt: str = "mcap", *, violating: bool = False) -> Path:
    """A run whose first pose stamps are good and whose later stamps are unset (0): more than 5 % of the stream, so
    ``auto`` on the whole stream is log time, on the first ``AUTO_PROBE`` messages header time."""
    run0 = FUZZ.base_run(violating=violating)
    n = run0.stamp_ns.size
    run0.stamp_ns[2 * AUTO_PROBE: 2 * AUTO_PROBE + n // 5] = 0
    return FUZZ.write_run(run0, tmp_path / f"late_zero{FUZZ.SUFFIX[fmt]}", fmt)


def test_certify_and_watch_take_each_stream_time_from_the_one_rules_object(tmp_path: Path,
                                                                         monkeypatch: pytest.MonkeyPatch) -> None:
    calls: list[tuple[str, str]] = []
    pose_times, stream_times = ReadingRules.pose_times, ReadingRules.stream_times

    def spy_pose(self: ReadingRules, topic: str, *a: object, **k: object) -> object:
        calls.append(("pose", topic))
        return pose_times(self, topic, *a, **k)  # type: ignore[arg-type]

    def spy_stream(self: ReadingRules, topic: str, *a: object, **k: object) -> object:
        calls.append(("stream", topic))
        return stream_times(self, topic, *a, **k)  # type: ignore[arg-type]

    monkeypatch.setattr(ReadingRules, "pose_times", spy_pose)
    monkeypatch.setattr(ReadingRules, "stream_times", spy_stream)
    sc = builtin_scenario()
    read_log(LOGS / "demo.mcap", sc)
    offline = sorted(set(calls))
    calls.clear()
    watch_log(LOGS / "demo.mcap", OnlineMonitor(sc), time_base="auto")
    online = sorted(set(calls))
    assert ("pose", sc.topics.pose) in offline
    assert ("stream", sc.topics.cmd_vel) in offline
    assert offline == online


def test_rules_pose_topic_and_missing_topic_line() -> None:
    sc = builtin_scenario()
    rules = ReadingRules.of(sc)
    assert rules.pose_topic({sc.topics.pose, "/tf"}) == sc.topics.pose
    assert rules.pose_topic({"/tf"}) is None  # the built-in scenario names no tf_child_frame
    err = rules.missing_pose({"/tf", "/odom"}, "x.mcap")
    assert "tf_child_frame" in err.reason and "/odom" in err.reason
    with pytest.raises(Exception, match="time_base"):
        ReadingRules.of(sc, "wall")


@pytest.mark.parametrize("fmt", ["mcap", "bag"])
def test_watch_decides_auto_on_the_whole_pose_stream_as_certify(tmp_path: Path, fmt: str) -> None:
    log = _late_zero_stamps(tmp_path, fmt, violating=True)
    sc = builtin_scenario()
    cert = certify_log(log, sc, spec=SPEC, checks=("spec",), time_base="auto").certificate
    assert cert["time_base"] == "log"
    res = watch_log(log, OnlineMonitor(sc, spec=SPEC, checks=("spec",)), time_base="auto")
    assert any("auto: log time, chosen on the whole pose stream" in n for n in res.notes), res.notes
    assert res.result.verdict == cert["verdict"]
    assert [c.verdict for c in res.result.checks] == [c["verdict"] for c in cert["checks"]]


def test_following_a_log_whose_later_stamps_change_the_time_base_is_never_a_verdict(tmp_path: Path) -> None:
    """With --follow the base is chosen on the first messages; when the whole stream makes certify choose the other
    base, watch's verdict is inconclusive and a note says why."""
    log = _late_zero_stamps(tmp_path)
    sc = builtin_scenario()
    msgs = open_follower(log).poll()
    pose_at = [k for k, m in enumerate(msgs) if m.topic == sc.topics.pose]
    cut = pose_at[AUTO_PROBE] + 1
    monitor = OnlineMonitor(sc, spec=SPEC, checks=("spec",))
    feeder = _Feeder(monitor, ReadingRules.of(sc, "auto"), False, log, probe=AUTO_PROBE)
    feeder.feed(msgs[:cut])
    assert feeder.time_base == "header"  # the first messages' stamps order them
    feeder.feed(msgs[cut:], final=True)
    why = feeder.base_mismatch()
    assert why is not None and "certify chooses log time" in why
    # complete from the start: chosen on the whole stream, nothing to say
    whole = _Feeder(OnlineMonitor(sc, spec=SPEC, checks=("spec",)), ReadingRules.of(sc, "auto"), False, log,
                    probe=AUTO_PROBE)
    whole.feed(msgs, final=True)
    assert whole.time_base == "log" and whole.base_mismatch() is None


@pytest.mark.parametrize("fmt", ["mcap", "bag"])
def test_unusable_header_stamps_make_watch_inconclusive_as_certify(tmp_path: Path, fmt: str,
                                                                   capsys: pytest.CaptureFixture[str]) -> None:
    """--time-base header on unset stamps: certify cannot pass (the stamps cannot order the samples); watch
    neither."""
    run0 = FUZZ.base_run(violating=False)
    run0.stamp_ns[:] = 0
    log = FUZZ.write_run(run0, tmp_path / f"zero{FUZZ.SUFFIX[fmt]}", fmt)
    codes = [run([cmd, str(log), "--scenario", "nexus-sml", "--spec", SPEC, "--time-base", "header"], capsys)[0]
             for cmd in ("certify", "watch")]
    assert codes == [2, 2]


def _signal_log(tmp_path: Path) -> tuple[Path, Path]:
    run0 = FUZZ.base_run(violating=False)
    run0.extra = FUZZ.temperature_stream(run0)
    for k in range(10):  # 95 degC for 1 s in the middle of the run
        log_ns = FUZZ.TIME0_NS + round((10.0 + k / 10 - 0.002) * 1e9)
        run0.extra.append((log_ns, FUZZ.TEMP_TOPIC, FUZZ.TEMPERATURE, FUZZ.temperature(log_ns, 95.0)))
    log = FUZZ.write_run(run0, tmp_path / "run.mcap", "mcap")
    scenario = tmp_path / "scenario.yaml"
    scenario.write_text(FUZZ.signal_scenario_text())
    return log, scenario


@pytest.mark.parametrize("offset", ["0", "4e9", "1e12", "/motor/temperatur=0.02"])
def test_watch_takes_clock_offsets_as_certify(tmp_path: Path, capsys: pytest.CaptureFixture[str],
                                              offset: str) -> None:
    log, scenario = _signal_log(tmp_path)
    item = offset if offset.startswith("/") else f"{FUZZ.TEMP_TOPIC}={offset}"
    got = []
    for cmd in ("certify", "watch"):
        code, _out, err = run([cmd, str(log), "--scenario", str(scenario), "--spec", "G[0,inf) motor_ok",
                              "--clock-offset", item], capsys)
        got.append(code)
        if code == 3:
            assert "--clock-offset" in err and len(err.strip().splitlines()) == 1, err
    assert got[0] == got[1], (offset, got)
    assert got[0] == {"0": 1, "4e9": 2, "1e12": 3}.get(offset, 3)


def test_watch_moves_a_topic_by_its_clock_offset(tmp_path: Path) -> None:
    """A 1 s correction of the signal's clock moves its violation by 1 s in watch as in certify."""
    log, scenario_path = _signal_log(tmp_path)
    from tubempc.scenario import load_scenario

    sc = load_scenario(scenario_path)
    for shift in (0.0, 1.0):
        cert = certify_log(log, sc, spec="G[0,inf) motor_ok", clock_offsets={FUZZ.TEMP_TOPIC: shift}).certificate
        res = watch_log(log, OnlineMonitor(sc, spec="G[0,inf) motor_ok"), time_base="auto",
                        clock_offsets={FUZZ.TEMP_TOPIC: shift})
        spec = next(c for c in res.result.checks if c.name == "spec_trajectory")
        want = next(c for c in cert["checks"] if c["name"] == "spec_trajectory")
        assert spec.verdict == want["verdict"] == "fail"
        got_s = (spec.first_violation_ns - cert["time0_ns"]) * 1e-9  # type: ignore[operator]
        assert np.isclose(got_s, want["first_violation_time"], atol=1e-6), (shift, got_s, want)


def test_watch_says_why_without_out(capsys: pytest.CaptureFixture[str]) -> None:
    code, out, _ = run(["watch", str(LOGS / "obstacle_touch.bag"), "--scenario", "nexus-sml"], capsys)
    assert code == 1
    why = [ln for ln in out.splitlines() if ln.startswith("   why    ")]
    assert why and any("violated at" in ln for ln in why), out
    code, out, _ = run(["-q", "watch", str(LOGS / "obstacle_touch.bag"), "--scenario", "nexus-sml"], capsys)
    assert code == 1 and "   why    " not in out


def test_an_undecodable_nominal_stream_is_not_used_in_watch_as_in_certify(tmp_path: Path) -> None:
    """certify does not use an optional stream whose messages cannot be decoded (a finding); watch neither (it
    refused the whole log before)."""
    from dataclasses import replace

    log = FUZZ.write_run(FUZZ.base_run(violating=True), tmp_path / "run.mcap", "mcap")
    sc = builtin_scenario()
    msgs = open_follower(log).poll()
    k = next(i for i, m in enumerate(msgs) if m.topic == sc.topics.nominal)
    msgs[k] = replace(msgs[k], payload=b"\x00\x01\x00\x00\x07")
    monitor = OnlineMonitor(sc, spec=SPEC)
    feeder = _Feeder(monitor, ReadingRules.of(sc, "auto"), False, log, probe=None)
    feeder.feed(msgs, final=True)
    assert "nominal" in feeder.unused and "not used" in feeder.unused["nominal"]
    res = monitor.close(problems=feeder.problems)
    tube = next(c for c in res.checks if c.name == "tube")
    assert tube.verdict == "inconclusive" and res.verdict == "fail"
