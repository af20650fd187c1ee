"""Any formula of the grammar on any log gives a valid certificate (issue 22, item 4; issue 29, items 11 and 14), and
every front-end says what the certificate says.

Formulas: every operator (X, U, nested windows, windows past the log's end, ``true``/``false``) over the example
scenario's region labels (polygons and a disc) and signal atoms. Logs: a few samples, with duplicate instants for
the per-sample checks, gaps, NaN, infinite and huge positions, signal values and commands. The certificate must
validate (a failed check without a finite margin says why; an undecided obligation says what is unknown), and the
Markdown and HTML tables, the JUnit cases and the ``certify -v`` lines must show the certificate's verdicts,
margins and times.
"""

from __future__ import annotations

import html
import math
import re
import xml.etree.ElementTree as ET
from fractions import Fraction
from pathlib import Path
from typing import Any

import numpy as np
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from tubempc.mitl import Formula
from tubempc.scenario import load_scenario
from tubempc.strategies import formulas, intervals
from verify import certify_data
from verify.certificate import Certificate, Verdict
from verify.certify import check_lines
from verify.ingest import LogData, PoseStream
from verify.ingest.fields import SignalStream
from verify.junit import certificate_suite, suite_element
from verify.report import check_row, fmt_margin, fmt_time, html_report, markdown_report, obligation_row

ROOT = Path(__file__).resolve().parents[1]
_ROOM = load_scenario(ROOT / "docs" / "examples" / "diffdrive-room.yaml")
SC = _ROOM.model_copy(update={"topics": _ROOM.topics.model_copy(update={"cmd_vel": "/cmd_vel"})})
ATOMS = ("in_room", "table", "dock", "slow", "crawl")
T0 = 1_700_000_000 * 10**9
#: positions: inside the room, at the table, at the dock, outside, and damaged values
XS = (0.5, 1.6, 4.4, 3.6, math.nan, math.inf, -math.inf, 1e308)
YS = (0.5, 1.4, 3.3, 3.0, math.nan, math.inf, 1e308)
VALUES = (0.1, 0.4, 0.6, math.nan, -math.inf, math.inf)


def formula_strategy() -> st.SearchStrategy[Formula]:
    return formulas(st.sampled_from(ATOMS), max_depth=3,
                    interval_strategy=intervals(max_s=4, quantum=Fraction(1, 2)))


@st.composite
def logs(draw: st.DrawFn) -> LogData:
    n = draw(st.integers(1, 25))
    steps = draw(st.lists(st.sampled_from((1, 2, 50_000_000, 100_000_000, 100_000_000, 700_000_000)),
                          min_size=n - 1, max_size=n - 1))
    t = T0 + np.concatenate(([0], np.cumsum(steps, dtype=np.int64))).astype(np.int64)
    x = np.array(draw(st.lists(st.sampled_from(XS), min_size=n, max_size=n)), dtype=np.float64)
    y = np.array(draw(st.lists(st.sampled_from(YS), min_size=n, max_size=n)), dtype=np.float64)
    pose = PoseStream(t, x, y, np.zeros(n))
    every = pose
    dups = draw(st.lists(st.integers(0, n - 1), max_size=3))
    if dups:  # disagreeing duplicates: unknown to the formula, judged by the per-sample checks
        k = np.sort(np.array(dups, dtype=np.int64))
        et = np.insert(t, k + 1, t[k])
        ex = np.insert(x, k + 1, x[k] + 0.3)
        ey = np.insert(y, k + 1, y[k])
        every = PoseStream(et, ex, ey, np.zeros(et.size))
        xx = x.copy()
        xx[k] = np.nan
        pose = PoseStream(t, xx, y, np.zeros(n))
    signals: dict[str, SignalStream] = {}
    m = draw(st.integers(0, 12))
    if m:
        st_ns = np.unique(T0 + np.array(draw(st.lists(st.integers(-300, 3000), min_size=m, max_size=m)),
                                        dtype=np.int64) * 1_000_000)
        vals = np.array(draw(st.lists(st.sampled_from(VALUES), min_size=st_ns.size, max_size=st_ns.size)))
        for name in ("slow", "crawl"):
            signals[name] = SignalStream(name, SC.signals[name], st_ns, vals.copy(), 100_000_000, "header")
    cmd_t = cmd_u = None
    if draw(st.booleans()):
        cmd_t = t.copy()
        cmd_u = np.array(draw(st.lists(st.tuples(*[st.sampled_from((0.1, 2.0, math.nan, math.inf))] * 3),
                                       min_size=n, max_size=n)), dtype=np.float64).reshape(n, 3)
    counts = {"read": n, "judged": n, "merged_duplicates": 0, "conflicting_duplicates": len(dups)}
    return LogData("<random log>", "in-memory", "0" * 64, "sha256", "header", T0, pose,
                   {"topic": "/odom", "type": "nav_msgs/msg/Odometry"}, None, cmd_t, cmd_u, (), None,
                   {"notes": [], "missing_definitions": []}, False, pose_samples=every, time_base_requested="header",
                   samples={"pose": {**counts, "retimed": 0}}, signals=signals)


def _num(text: str) -> str:
    return text.replace("\\", "")


def _certify(log: LogData, formula: Formula) -> Any:
    checks = ["spec", "workspace", "obstacle_clearance"] + (["input_box"] if log.cmd_t_ns is not None else [])
    return certify_data(log, SC, spec=str(formula), checks=checks)


@settings(deadline=None, suppress_health_check=[HealthCheck.too_slow, HealthCheck.data_too_large])
@given(log=logs(), formula=formula_strategy())
def test_every_formula_on_every_log_gives_a_valid_certificate(log: LogData, formula: Formula) -> None:
    result = _certify(log, formula)  # raises (exit 70) on a certificate the model refuses
    cert = Certificate.model_validate(result.certificate)
    assert result.exit_code in (0, 1, 2)
    assert cert.obligations[0].role == "formula" and cert.obligations[0].formula == cert.formula
    spec = cert.check("spec_trajectory")
    assert spec is not None
    whole = cert.obligations[0]
    # the spec_trajectory check is the whole formula's obligation: one judgement, told twice
    assert (spec.verdict, spec.margin, spec.first_violation_time, spec.decided_at, spec.explanation) == (
        whole.verdict, whole.margin, whole.first_violation_time, whole.decided_at, whole.explanation)
    for entry in (*cert.checks, *cert.obligations):
        if entry.verdict is Verdict.FAIL:
            assert entry.first_violation_time is not None
            assert entry.margin is not None or entry.margin_reason
            assert entry.margin is None or entry.margin <= 0
        if entry.verdict is not Verdict.PASS:
            assert entry.explanation
    for ob in cert.obligations:
        if ob.verdict is Verdict.INCONCLUSIVE:
            assert ob.unknown is not None and ob.unknown.cause and ob.unknown.decide
        if ob.verdict is Verdict.FAIL:
            assert ob.decided_at is not None and ob.decided_at >= 0


def _html_rows(page: str, table: str) -> list[list[str]]:
    body = page.split(f'<table class="{table}">', 1)[1].split("</table>", 1)[0]
    rows = []
    for row in re.findall(r"<tr[^>]*>(.*?)</tr>", body, flags=re.S)[1:]:
        cells = re.findall(r"<td[^>]*>(.*?)</td>", row, flags=re.S)
        rows.append([html.unescape(re.sub(r"<[^>]+>", "", c)) for c in cells])
    return rows


@settings(deadline=None, max_examples=40, suppress_health_check=[HealthCheck.too_slow, HealthCheck.data_too_large])
@given(log=logs(), formula=formula_strategy())
def test_every_front_end_shows_the_certificates_values(log: LogData, formula: Formula) -> None:
    """report.html and report.md (their tables), junit.xml and the ``-v`` lines show each check's and each
    obligation's verdict, margin, first violation, decision time and explanation exactly as the certificate."""
    result = _certify(log, formula)
    cert = Certificate.model_validate(result.certificate)
    page = html_report(result, SC, [])
    md = markdown_report(result, SC, [])
    want_checks = [list(check_row(c)) for c in cert.checks]
    want_obl = [list(obligation_row(o)) for o in cert.obligations]
    got_checks = _html_rows(page, "checks")
    assert [r[:6] for r in got_checks] == [r[:6] for r in want_checks]
    assert _html_rows(page, "obligations") == want_obl
    md_rows = [[_num(html.unescape(c.strip())) for c in line.strip("|").split(" | ")]
               for line in md.splitlines() if line.startswith("| ") and " | " in line]
    for row in want_obl:
        assert any(r[1:] == [_num(c) for c in row[1:]] for r in md_rows), row
    for c in cert.checks:  # the certificate's values, as every report formats them
        row = check_row(c)
        assert row[2] == fmt_margin(c) and row[3] == fmt_time(c.first_violation_time)
    suite = suite_element(certificate_suite(cert, suite_name="log"))
    cases = {(c.get("classname"), c.get("name")): c for c in suite.iter("testcase")}
    assert len(cases) == len(cert.checks) + len(cert.obligations)
    for ob in cert.obligations:
        name = ob.formula if ob.role == "conjunct" else f"{ob.formula} (whole formula)"
        case = cases[("log.obligations", name)]
        child = next(iter(case), None)
        assert (child is None) == (ob.verdict is Verdict.PASS)
        if child is not None and ob.explanation:
            assert ob.explanation in (child.get("message") or "")
    lines = "\n".join(check_lines(result.certificate))
    for entry in (*cert.checks, *cert.obligations):
        if entry.explanation:
            assert f"why: {entry.explanation}" in lines
        if entry.first_violation_time is not None:
            assert f"first violation at t={entry.first_violation_time:.2f} s" in lines
    ET.fromstring(ET.tostring(suite))  # well-formed
