"""Certification result + scenario -> human and CI reports next to ``certificate.json``.

input: a ``CertifyResult`` (certificate dict plus trajectory/nominal/inputs/robustness frames) and the scenario
-> output: ``report.md`` (figures as files under ``figures/``), a self-contained ``report.html`` (figures embedded
as base64 PNG, inline CSS, no script, no network), and ``junit.xml`` (``verify.junit``: one test case per check and per
obligation, a ``failure`` for a failed one and, by default, for an inconclusive one) so that CI systems show them
natively. The reports read the certificate (and the curves the judging code computed with it); they never judge:
every verdict, margin, time and explanation shown is the certificate's, and the text of each comes from one
formatter here (``check_row``, ``obligation_row``) shared by the Markdown and the HTML.

Every string that comes from a log or a scenario is escaped: ``html.escape`` in HTML, entity and backslash escapes
in Markdown, ElementTree (plus removal of characters XML 1.0 cannot carry) in JUnit.
"""

from __future__ import annotations

import base64
import html
import json
import math
import re
import xml.etree.ElementTree as ET
from collections.abc import Iterator, Mapping, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any, Protocol

import pandas as pd

from runkit.outputs import output_subdir, write_output_file
from tubempc.scenario import Scenario
from verify.certificate import Certificate, CheckEntry, ObligationEntry, TimedRunEntry
from verify.errors import ReportWriteError
from verify.figures import FigureSpec, render_figures
from verify.junit import InconclusiveAs, certificate_suite, suite_element, write_junit

__all__ = [
    "CertifyResultLike",
    "ReportSection",
    "ReportWriteError",
    "check_row",
    "html_report",
    "junit_xml",
    "markdown_report",
    "obligation_row",
    "write_junit",
    "write_reports",
]

_VERDICT_COLOURS = {"pass": "#2ca02c", "fail": "#d62728", "inconclusive": "#ff7f0e"}
_MD_ENTITY = re.compile(r"&(?=#?\w+;)")  # only an '&' that would start an entity is escaped: 'a & b' stays
_MD_SPECIAL = re.compile(r"([\\`*\[\]|~]|(?<!\w)_|_(?!\w))")  # links, emphasis, code, tables; not intraword _


class CertifyResultLike(Protocol):
    """What the reports need from ``verify.CertifyResult`` (any object with these attributes will do)."""

    @property
    def certificate(self) -> dict[str, Any]: ...
    @property
    def exit_code(self) -> int: ...
    @property
    def trajectory(self) -> pd.DataFrame: ...
    @property
    def nominal(self) -> pd.DataFrame | None: ...
    @property
    def inputs(self) -> pd.DataFrame | None: ...
    @property
    def robustness(self) -> pd.DataFrame | None: ...


# ---- value formatting (pure text; escaping happens per output format) -------------------------------------------
def _fmt(value: Any) -> str:
    if value is None:
        return "-"
    if isinstance(value, bool):
        return "yes" if value else "no"
    if isinstance(value, float):
        if math.isnan(value):
            return "NaN"
        if math.isinf(value):
            return "inf" if value > 0 else "-inf"
        return f"{value:.6g}"
    if isinstance(value, int | str):
        return str(value)
    text = json.dumps(value, default=str, sort_keys=True)
    return text if len(text) <= 300 else text[:297] + "..."


def _flatten(data: Any, prefix: str = "") -> Iterator[tuple[str, Any]]:
    """Nested mappings -> ("a.b.c", leaf) rows; lists and scalars are leaves."""
    if isinstance(data, Mapping):
        if not data and prefix:
            yield prefix, "{}"
        for key in sorted(data, key=str):
            yield from _flatten(data[key], f"{prefix}.{key}" if prefix else str(key))
    else:
        yield prefix or "value", data


def typed(result: CertifyResultLike) -> Certificate:
    """The result's certificate as the typed model (``verify.certificate``): what every report reads."""
    return Certificate.model_validate(result.certificate)


def _detail(key: str, value: Any) -> str:
    """One detail of a check; the per-atom margins as ``name [min, max] unit`` (the full values are in the
    certificate)."""
    if key == "atom_margins" and isinstance(value, dict):
        return "atom margins (min, max): " + ", ".join(f"{name} {_range(m)}" for name, m in value.items())
    return f"{key}: {_fmt(value)}"


def _range(margins: Any) -> str:
    if not isinstance(margins, dict):
        return _fmt(margins)

    def num(v: Any) -> str:
        return f"{v:.4g}" if isinstance(v, int | float) else "-"

    return f"[{num(margins.get('min'))}, {num(margins.get('max'))}] {margins.get('unit', '')}".rstrip()


def fmt_time(value: Any) -> str:
    """A time in seconds for people: ``54.80 s`` (hundredths), ``-`` when absent."""
    if isinstance(value, int | float) and not isinstance(value, bool) and math.isfinite(value):
        return f"{value:.2f} s"
    return "-"


def fmt_margin(check: CheckEntry | ObligationEntry) -> str:
    """A margin with 4 significant digits and its unit (``-0.004 m``), ``-`` when absent; a formula's names the
    atom it is the value of (``-0.405 m (obs_3)``)."""
    if check.margin is None or not math.isfinite(check.margin):
        return "-"
    text = f"{check.margin:.4g} {check.margin_unit}" if check.margin_unit else f"{check.margin:.4g}"
    atom = check.margin_atom if isinstance(check, ObligationEntry) else check.details.get("margin_atom")
    return f"{text} ({atom})" if isinstance(atom, str) and atom else text


#: the columns of the checks table and of the obligations table (the same in Markdown and HTML)
CHECK_COLUMNS = ("check", "verdict", "margin", "first violation", "decided at", "why", "details")
OBLIGATION_COLUMNS = ("obligation", "verdict", "margin", "first violation", "decided at", "why")

#: detail fields shown elsewhere (their own columns) or too long for the table (in the certificate)
_HIDDEN_DETAILS = ("margin_atom", "margin_time", "explanation", "decided_at", "margin_reason")


def check_row(check: CheckEntry) -> tuple[str, ...]:
    """One row of the checks table, as text: the certificate's values, formatted once for every report."""
    details = "; ".join(_detail(str(k), v) for k, v in sorted(check.details.items(), key=lambda kv: str(kv[0]))
                        if k not in _HIDDEN_DETAILS)
    return (check.name, check.verdict.value, fmt_margin(check), fmt_time(check.first_violation_time),
            fmt_time(check.decided_at), check.explanation or ("-" if check.margin_reason is None
                                                               else check.margin_reason), details)


def obligation_row(ob: ObligationEntry) -> tuple[str, ...]:
    """One row of the obligations table (the whole formula first, then each conjunct)."""
    name = ob.formula if ob.role == "conjunct" else f"{ob.formula} (whole formula)"
    return (name, ob.verdict.value, fmt_margin(ob), fmt_time(ob.first_violation_time), fmt_time(ob.decided_at),
            ob.explanation or "-")


def _summary_rows(cert: Certificate) -> list[tuple[str, str]]:
    """The few facts a reader needs beside the verdict; everything else is under "Certificate details"."""
    rows = [("formula", cert.formula), ("scenario", cert.scenario), ("log", cert.log),
            ("duration", fmt_time(cert.duration_s))]
    if cert.verdict_reason:
        rows.append(("verdict reason", cert.verdict_reason))
    return rows


_MAIN_FIELDS = ("verdict", "checks", "obligations", "timed_run", "data_quality")


def _meta_rows(cert: Certificate, scenario: Scenario) -> list[tuple[str, str]]:
    data = cert.to_json_dict()
    rows = [(key, _fmt(data[key])) for key in sorted(data) if key not in _MAIN_FIELDS]
    if cert.tube is not None:
        rows.append(("tube radius r_q (scenario)", f"{cert.tube.radius_m:.6g} m"))
    return rows


def _top_lines(cert: Certificate) -> list[str]:
    """Which checks made the verdict, and findings a reader must see first (clock offsets between topics)."""
    lines = [f"Verdict over the checks: {', '.join(cert.checks_selected) or 'none'}."]
    lines += [f"Finding: {text}" for text in cert.clock_findings or []]
    return lines


def _not_run_notes(cert: Certificate) -> list[str]:
    """Checks that did not run and scenario warnings: said under the checks table, where a reader looks."""
    notes = [f"not checked: {n.name} ({n.reason})" for n in cert.not_checked]
    return notes + [f"scenario warning: {w}" for w in cert.scenario_warnings]


def _is_quiet(value: Any) -> bool:
    """A data-quality value that reports nothing (0, empty, false, none): listed after the findings."""
    return value in (0, 0.0, False, None, "", "{}", "[]") or (isinstance(value, list | dict) and not value)


#: data-quality fields that describe a stream or state a rule (counts read, rates, thresholds, conventions, bounds,
#: where a time came from) rather than report a problem: listed after the findings and not counted as findings.
#: Every other field that is not quiet is a finding (a new field counts until it is named here).
_DESCRIPTIVE_FIELDS = frozenset({
    "read", "judged", "messages", "rate_hz", "expected_rate_hz", "threshold_s", "longest_gap_s",
    "convention", "speed_bound_mps", "tolerance_m", "max_speed_mps", "median", "max_abs", "fast_decode",
    "time_base", "type", "topic", "pose_topic", "period_source", "unit", "field",
})


def _is_finding(key: str, value: Any) -> bool:
    """A data-quality row that reports something (a count of problems, a note), not a description. A stream's own
    ``count`` (``pose.count``: messages) describes it; a nested one (``pose.dropouts.count``) counts problems."""
    parts = key.split(".")
    if parts[-1] == "count":
        return not _is_quiet(value) and len(parts) > 2
    return not _is_quiet(value) and parts[-1] not in _DESCRIPTIVE_FIELDS


def _quality_rows(cert: Certificate) -> list[tuple[str, Any]]:
    """Flattened data-quality entries: the findings first, then what describes the streams, then the quiet ones
    (their order otherwise kept)."""
    rows = list(_flatten(cert.data_quality))
    findings = [r for r in rows if _is_finding(*r)]
    described = [r for r in rows if not _is_finding(*r) and not _is_quiet(r[1])]
    return findings + described + [r for r in rows if _is_quiet(r[1])]


def _quality_heading(rows: Sequence[tuple[str, Any]]) -> str:
    n = sum(1 for r in rows if _is_finding(*r))
    return (f"{n} finding(s) that report something, listed first; then what describes the streams" if n else
            "no finding reports a problem; the rows describe the streams")


def _figure_groups(figures: Sequence[FigureSpec]) -> dict[str, list[FigureSpec]]:
    groups: dict[str, list[FigureSpec]] = {"map": [], "states": [], "quality": []}
    for fig in figures:
        key = ("map" if fig.stem.startswith(("workspace", "obligations", "clearance", "separation")) else
               "quality" if fig.stem.startswith("sampling") else "states")
        groups[key].append(fig)
    return groups


@dataclass(frozen=True, slots=True)
class ReportSection:
    """An extra section appended to the reports (e.g. the demo's comparison with the paper): a titled table and
    notes. Every cell and note is escaped like any other string."""

    title: str
    columns: tuple[str, ...]
    rows: tuple[tuple[Any, ...], ...] = ()
    notes: tuple[str, ...] = ()

    def __post_init__(self) -> None:
        for i, row in enumerate(self.rows):
            if len(row) != len(self.columns):
                raise ValueError(f"rows[{i}] has {len(row)} cells for {len(self.columns)} columns")


# ---- Markdown -----------------------------------------------------------------------------------------------------
def _md(text: Any) -> str:
    """Escape for a Markdown table cell: tags and entity starts first, then Markdown punctuation, no line breaks."""
    raw = _fmt(text) if not isinstance(text, str) else text
    escaped = _MD_ENTITY.sub("&amp;", raw).replace("<", "&lt;").replace(">", "&gt;")
    escaped = _MD_SPECIAL.sub(r"\\\1", escaped)
    return escaped.replace("\r", " ").replace("\n", " ")


def markdown_report(result: CertifyResultLike, scenario: Scenario, figures: list[FigureSpec], *,
                    figure_dir: str = "figures", sections: Sequence[ReportSection] = ()) -> str:
    """The report as Markdown, in the order a reader asks: verdict and checks, map and obligations, states and
    inputs, data quality, certificate details; figures are referenced as ``figure_dir/<stem>.png``."""
    cert = typed(result)
    groups = _figure_groups(figures)

    def figs(key: str) -> list[str]:
        out: list[str] = []
        for fig in groups[key]:
            out += [f"![{_md(fig.caption)}]({figure_dir}/{fig.stem}.png)", "", f"*{_md(fig.caption)}*", ""]
        return out

    lines = [f"# Certificate: {_md(cert.verdict.value).upper()}", "",
             f"Exit code {result.exit_code} (0 pass, 1 violation, 2 inconclusive).", ""]
    lines += [f"- {_md(t)}" for t in _top_lines(cert)] + [""]
    lines += ["| | |", "|---|---|"]
    lines += [f"| {_md(k)} | {_md(v)} |" for k, v in _summary_rows(cert)]
    lines += ["", "## Checks", "", "| " + " | ".join(CHECK_COLUMNS) + " |", "|" + "---|" * len(CHECK_COLUMNS)]
    lines += ["| " + " | ".join(_md(c) for c in check_row(check)) + " |" for check in cert.checks]
    lines += [""] + [f"- {_md(note)}" for note in _not_run_notes(cert)]
    lines += ["", "## Map and obligations", ""]
    if cert.obligations:
        lines += ["| " + " | ".join(OBLIGATION_COLUMNS) + " |", "|" + "---|" * len(OBLIGATION_COLUMNS)]
        lines += ["| " + " | ".join(_md(c) for c in obligation_row(ob)) + " |" for ob in cert.obligations]
        lines.append("")
    lines += [*figs("map"), "### Timed run", ""]
    run = cert.timed_run
    if run:
        if cert.robots:  # several robots: each entry names its robot
            lines += ["| # | robot | region | entered at |", "|---|---|---|---|"]
            lines += [f"| {i} | {_md(e.robot)} | {_md(e.region)} | {_md(fmt_time(e.time))} |"
                      for i, e in enumerate(run)]
        else:
            lines += ["| # | region | entered at |", "|---|---|---|"]
            lines += [f"| {i} | {_md(e.region)} | {_md(fmt_time(e.time))} |" for i, e in enumerate(run)]
    else:
        lines.append("The robot disc was never fully inside a region.")
    lines += ["", "## States and inputs", "", *figs("states"), "## Data quality", ""]
    dq = _quality_rows(cert)
    if dq:
        lines += [_md(_quality_heading(dq)[:1].upper() + _quality_heading(dq)[1:]) + ".", ""]
        lines += ["| finding | value |", "|---|---|"] + [f"| {_md(k)} | {_md(_fmt(v))} |" for k, v in dq]
    else:
        lines.append("No data-quality findings were reported.")
    lines += ["", *figs("quality"), "## Certificate details", "", "| field | value |", "|---|---|"]
    lines += [f"| {_md(k)} | {_md(v)} |" for k, v in _meta_rows(cert, scenario)]
    for sec in sections:
        lines += ["", f"## {_md(sec.title)}", ""]
        if sec.columns:
            lines += ["| " + " | ".join(_md(c) for c in sec.columns) + " |", "|" + "---|" * len(sec.columns)]
            lines += ["| " + " | ".join(_md(_fmt(v)) for v in row) + " |" for row in sec.rows]
        lines += [""] + [f"- {_md(n)}" for n in sec.notes]
    return "\n".join(lines).rstrip() + "\n"


# ---- HTML ---------------------------------------------------------------------------------------------------------
_CSS = """
body{font-family:system-ui,sans-serif;margin:2em auto;max-width:1100px;color:#222}
table{border-collapse:collapse;margin:0.5em 0 1.5em 0}td,th{border:1px solid #ccc;padding:3px 8px;text-align:left;
vertical-align:top;font-size:0.92em}th{background:#f3f3f3}.badge{color:#fff;padding:2px 10px;border-radius:4px}
figure{margin:1em 0}img{max-width:100%;border:1px solid #eee}code{background:#f6f6f6}
summary h2{display:inline}summary{cursor:pointer;margin:1em 0}
""".strip()


def _e(value: Any) -> str:
    return html.escape(_fmt(value) if not isinstance(value, str) else value, quote=True)


def _badge(verdict: str) -> str:
    colour = _VERDICT_COLOURS.get(verdict, "#555")
    return f'<span class="badge" style="background:{colour}">{_e(verdict)}</span>'


def html_report(result: CertifyResultLike, scenario: Scenario, figures: list[FigureSpec], *,
                sections: Sequence[ReportSection] = ()) -> str:
    """A self-contained HTML page: inline CSS, figures as ``data:image/png;base64`` URIs, no script, no links.
    Order: verdict and checks, map and obligations, states and inputs, then data quality and the certificate's
    details collapsed (``<details>``)."""
    cert = typed(result)
    verdict = cert.verdict.value
    groups = _figure_groups(figures)

    def figs(key: str) -> list[str]:
        out = []
        for fig in groups[key]:
            data = base64.b64encode(fig.png).decode("ascii")
            out.append(f'<figure id="fig-{_e(fig.stem)}"><img alt="{_e(fig.caption)}" '
                       f'src="data:image/png;base64,{data}"><figcaption>{_e(fig.caption)}</figcaption></figure>')
        return out

    parts = ["<!DOCTYPE html>", '<html lang="en"><head><meta charset="utf-8">',
             f"<title>Certificate {_e(verdict)}: {_e(scenario.name)}</title>", f"<style>{_CSS}</style></head><body>",
             f"<h1>Certificate {_badge(verdict)}</h1>",
             f"<p>Exit code {int(result.exit_code)} (0 pass, 1 violation, 2 inconclusive).</p>",
             *([("<ul>" + "".join(f"<li>{_e(t)}</li>" for t in _top_lines(cert)) + "</ul>")]
               if _top_lines(cert) else []),
             '<table class="summary">']
    parts += [f"<tr><th>{_e(k)}</th><td>{_e(v)}</td></tr>" for k, v in _summary_rows(cert)]
    parts += ["</table>", "<h2>Checks</h2>",
              '<table class="checks"><tr>' + "".join(f"<th>{_e(c)}</th>" for c in CHECK_COLUMNS) + "</tr>"]
    for check in cert.checks:
        row = check_row(check)
        parts.append(f"<tr><td>{_e(row[0])}</td><td>{_badge(row[1])}</td>"
                     + "".join(f"<td>{_e(c)}</td>" for c in row[2:5])
                     + f'<td class="why">{_e(row[5])}</td><td class="details">{_e(row[6])}</td></tr>')
    parts.append("</table>")
    notes = _not_run_notes(cert)
    if notes:
        parts.append('<ul class="not-run">' + "".join(f"<li>{_e(n)}</li>" for n in notes) + "</ul>")
    parts.append("<h2>Map and obligations</h2>")
    if cert.obligations:
        parts.append('<table class="obligations"><tr>' + "".join(f"<th>{_e(c)}</th>" for c in OBLIGATION_COLUMNS)
                     + "</tr>")
        for ob in cert.obligations:
            row = obligation_row(ob)
            parts.append(f'<tr class="{_e(ob.role)}"><td>{_e(row[0])}</td><td>{_badge(row[1])}</td>'
                         + "".join(f"<td>{_e(c)}</td>" for c in row[2:5]) + f'<td class="why">{_e(row[5])}</td></tr>')
        parts.append("</table>")
    parts += [*figs("map"), "<h3>Timed run</h3>"]
    run = cert.timed_run
    if run:
        def robot(e: TimedRunEntry) -> str:
            return f"<td>{_e(e.robot)}</td>" if cert.robots else ""

        parts.append('<table class="timed-run"><tr><th>#</th>' + ("<th>robot</th>" if cert.robots else "")
                     + "<th>region</th><th>entered at</th></tr>")
        parts += [f"<tr><td>{i}</td>{robot(e)}<td>{_e(e.region)}</td><td>{_e(fmt_time(e.time))}</td></tr>"
                  for i, e in enumerate(run)]
        parts.append("</table>")
    else:
        parts.append("<p>The robot disc was never fully inside a region.</p>")
    parts += ["<h2>States and inputs</h2>", *figs("states")]
    dq = _quality_rows(cert)
    parts.append(f"<details><summary><h2>Data quality</h2> ({_e(_quality_heading(dq))})</summary>")
    if dq:
        parts.append('<table class="data-quality"><tr><th>finding</th><th>value</th></tr>')
        parts += [f"<tr><td>{_e(k)}</td><td>{_e(v)}</td></tr>" for k, v in dq]
        parts.append("</table>")
    else:
        parts.append("<p>No data-quality findings were reported.</p>")
    parts += [*figs("quality"), "</details>", "<details><summary><h2>Certificate details</h2></summary>",
              '<table class="meta">']
    parts += [f"<tr><th>{_e(k)}</th><td>{_e(v)}</td></tr>" for k, v in _meta_rows(cert, scenario)]
    parts += ["</table>", "</details>"]
    for sec in sections:
        parts.append(f"<h2>{_e(sec.title)}</h2>")
        if sec.columns:
            parts.append('<table class="section"><tr>' + "".join(f"<th>{_e(c)}</th>" for c in sec.columns) + "</tr>")
            parts += ["<tr>" + "".join(f"<td>{_e(v)}</td>" for v in row) + "</tr>" for row in sec.rows]
            parts.append("</table>")
        if sec.notes:
            parts.append("<ul>" + "".join(f"<li>{_e(n)}</li>" for n in sec.notes) + "</ul>")
    parts.append("</body></html>")
    return "\n".join(parts) + "\n"


# ---- JUnit --------------------------------------------------------------------------------------------------------
def junit_xml(result: CertifyResultLike, *, suite_name: str = "certify",
              inconclusive: InconclusiveAs = "failure") -> ET.Element:
    """``<testsuite>`` with one ``<testcase>`` per check and per obligation (``verify.junit``: a failed one is a
    ``failure`` of type ``violation``, an inconclusive one a ``failure`` of type ``inconclusive`` unless
    ``inconclusive="skipped"``)."""
    return suite_element(certificate_suite(typed(result), suite_name=suite_name, inconclusive=inconclusive))


# ---- writing ------------------------------------------------------------------------------------------------------
def write_reports(result: CertifyResultLike, scenario: Scenario, out_dir: str | Path, *,
                  suite_name: str = "certify", sections: Sequence[ReportSection] = (),
                  junit_inconclusive: InconclusiveAs = "failure", figure_workers: int | None = None
                  ) -> dict[str, Path]:
    """Write ``report.md``, ``report.html``, ``junit.xml`` and ``figures/*.png`` into ``out_dir`` (created).

    Returns the written paths keyed by their path relative to ``out_dir`` (``"report.html"``,
    ``"figures/workspace.png"``, ...). ``suite_name`` names the JUnit suite (a batch passes the log's name).
    ``sections`` are appended to both reports (the demo's comparison with the paper uses this).
    ``junit_inconclusive``: how ``junit.xml`` reports an inconclusive check (``verify.junit``).
    ``figure_workers``: processes drawing the figures (``verify.figures.render_figures``; a batch that already
    writes several logs at once passes 1).
    """
    out = Path(out_dir)
    cert = typed(result)
    if cert.robots:  # several robots: one path per robot, separation, per-robot panels (verify.fleet_figures)
        from verify.fleet_figures import render_fleet_figures

        figures = render_fleet_figures(cert, scenario, getattr(result, "columns", {}),
                                       judgement=getattr(result, "formula", None))
    else:
        figures = render_figures(cert, scenario, trajectory=result.trajectory, nominal=result.nominal,
                                 inputs=result.inputs, robustness=result.robustness,
                                 judgement=getattr(result, "formula", None), workers=figure_workers)
    written: dict[str, Path] = {}
    try:
        out.mkdir(parents=True, exist_ok=True)
        fig_dir = output_subdir(out, "figures")
        for fig in figures:
            written[f"figures/{fig.stem}.png"] = write_output_file(fig_dir / f"{fig.stem}.png", fig.png)
        written["report.md"] = write_output_file(out / "report.md",
                                                 markdown_report(result, scenario, figures, sections=sections))
        written["report.html"] = write_output_file(out / "report.html",
                                                   html_report(result, scenario, figures, sections=sections))
        suite = certificate_suite(cert, suite_name=suite_name, inconclusive=junit_inconclusive)
        written["junit.xml"] = write_junit([suite], out / "junit.xml")
    except OSError as err:
        raise ReportWriteError(f"{out}: cannot write the reports ({err.__class__.__name__}: {err})") from err
    return written
