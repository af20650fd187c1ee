"""Test outcomes -> ``junit.xml``: the one JUnit writer of ``certify``, batch certification and ``regress``.

input: ``JUnitSuite`` values (one per log, or one per regression suite) -> output: ``<testsuites>`` XML on disk.

An *inconclusive* check is not a pass, and CI dashboards paint ``<skipped>`` green or grey: by default it is written
as ``<failure type="inconclusive">`` (counted in ``failures``), so a run that could not be decided turns the
pipeline red like a violation does (``type="violation"``). ``inconclusive="skipped"`` keeps the older form for a
CI that must stay green on undecided runs. Every string is made XML 1.0-safe (characters XML cannot carry become
U+FFFD; ElementTree escapes the rest).
"""

from __future__ import annotations

import math
import re
import xml.etree.ElementTree as ET
from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Literal

from runkit.outputs import write_output_file
from verify.certificate import Certificate, Verdict

__all__ = ["INCONCLUSIVE_AS", "InconclusiveAs", "JUnitCase", "JUnitSuite", "certificate_suite", "suite_element",
           "write_junit"]

Outcome = Literal["passed", "failure", "error", "skipped"]
InconclusiveAs = Literal["failure", "skipped"]
INCONCLUSIVE_AS: tuple[InconclusiveAs, ...] = ("failure", "skipped")
_XML_INVALID = re.compile("[\x00-\x08\x0b\x0c\x0e-\x1f\ud800-\udfff\ufffe\uffff]")


def _x(value: object) -> str:
    return _XML_INVALID.sub("\ufffd", str(value))


@dataclass(frozen=True, slots=True)
class JUnitCase:
    """One ``<testcase>``: ``outcome`` picks the child element (none for ``passed``)."""

    name: str
    classname: str
    outcome: Outcome = "passed"
    type: str = ""
    message: str = ""
    text: str = ""
    time_s: float = 0.0


@dataclass(frozen=True, slots=True)
class JUnitSuite:
    """One ``<testsuite>`` with its cases and ``<properties>`` (name, value pairs)."""

    name: str
    cases: tuple[JUnitCase, ...]
    properties: tuple[tuple[str, str], ...] = ()
    time_s: float = 0.0

    def count(self, outcome: Outcome) -> int:
        return sum(1 for c in self.cases if c.outcome == outcome)


def suite_element(suite: JUnitSuite) -> ET.Element:
    """The ``<testsuite>`` element of ``suite``."""
    node = ET.Element("testsuite", {
        "name": _x(suite.name), "tests": str(len(suite.cases)), "failures": str(suite.count("failure")),
        "errors": str(suite.count("error")), "skipped": str(suite.count("skipped")), "time": f"{suite.time_s:.3f}"})
    if suite.properties:
        props = ET.SubElement(node, "properties")
        for key, value in suite.properties:
            ET.SubElement(props, "property", {"name": _x(key), "value": _x(value)})
    for case in suite.cases:
        elem = ET.SubElement(node, "testcase", {"classname": _x(case.classname), "name": _x(case.name),
                                                "time": f"{case.time_s:.3f}"})
        if case.outcome == "skipped":
            ET.SubElement(elem, "skipped", {"message": _x(case.message)})
        elif case.outcome in ("failure", "error"):
            child = ET.SubElement(elem, case.outcome, {"message": _x(case.message), "type": _x(case.type)})
            if case.text:
                child.text = _x(case.text)
    return node


def write_junit(suites: Sequence[JUnitSuite], path: str | Path) -> Path:
    """Write ``<testsuites>`` around the given suites (one per log in a batch, one per regression suite)."""
    root = ET.Element("testsuites", {
        "tests": str(sum(len(s.cases) for s in suites)),
        "failures": str(sum(s.count("failure") for s in suites)),
        "errors": str(sum(s.count("error") for s in suites)),
        "skipped": str(sum(s.count("skipped") for s in suites)),
        "time": f"{sum(s.time_s for s in suites):.3f}"})
    root.extend(suite_element(s) for s in suites)
    ET.indent(root)
    return write_output_file(path, ET.tostring(root, encoding="utf-8", xml_declaration=True))


def _num(value: float | None, unit: str = "") -> str:
    return f"{value:.4g}{unit}" if value is not None and math.isfinite(value) else "-"


def _case(name: str, classname: str, verdict: Verdict, *, summary: str, details: str,
          inconclusive: InconclusiveAs) -> JUnitCase:
    if verdict is Verdict.PASS:
        return JUnitCase(name, classname)
    if verdict is Verdict.FAIL:
        return JUnitCase(name, classname, "failure", "violation", summary, details or summary)
    if inconclusive == "skipped":
        return JUnitCase(name, classname, "skipped", message=summary)
    return JUnitCase(name, classname, "failure", "inconclusive", f"{summary} (could not be decided: not a pass)",
                     details or summary)


def certificate_suite(certificate: Certificate, *, suite_name: str,
                      inconclusive: InconclusiveAs = "failure") -> JUnitSuite:
    """One test case per check and one per obligation of the formula (classname ``<suite>.obligations``; the
    whole formula and each top-level conjunct) of a certificate: a failed one is a ``failure`` of type
    ``violation``; an inconclusive one a ``failure`` of type ``inconclusive`` (or ``skipped``). The message states
    the certificate's verdict, margin, first violation and its one-sentence explanation; properties carry the
    verdict, the formula and the hashes."""
    if inconclusive not in INCONCLUSIVE_AS:
        raise ValueError(f"inconclusive={inconclusive!r} is not one of {INCONCLUSIVE_AS}")
    cases = []
    for check in certificate.checks:
        unit = f" {check.margin_unit}" if check.margin_unit else ""
        summary = (f"{check.verdict.value}: margin {_num(check.margin, unit)}, first violation at "
                   f"{_num(check.first_violation_time, ' s')}" + (f": {check.explanation}" if check.explanation
                                                                     else ""))
        details = "; ".join(f"{k}: {v}" for k, v in check.details.items())
        cases.append(_case(check.name, suite_name, check.verdict, summary=summary, details=details,
                           inconclusive=inconclusive))
    for ob in certificate.obligations:
        unit = f" {ob.margin_unit}" if ob.margin_unit else ""
        summary = (f"{ob.verdict.value}: margin {_num(ob.margin, unit)}, first violation at "
                   f"{_num(ob.first_violation_time, ' s')}, decided at {_num(ob.decided_at, ' s')}"
                   + (f": {ob.explanation}" if ob.explanation else ""))
        name = ob.formula if ob.role == "conjunct" else f"{ob.formula} (whole formula)"
        cases.append(_case(name, f"{suite_name}.obligations", ob.verdict, summary=summary, details=summary,
                           inconclusive=inconclusive))
    props = [("verdict", certificate.verdict.value), ("formula", certificate.formula),
             ("scenario_sha256", certificate.scenario_sha256), ("log_digest", certificate.log_digest),
             ("log_digest_algorithm", certificate.log_digest_algorithm)]
    if certificate.log_sha256 is not None:
        props.append(("log_sha256", certificate.log_sha256))
    props.append(("partial", str(certificate.partial)))
    return JUnitSuite(suite_name, tuple(cases), tuple(props))
