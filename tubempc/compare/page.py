"""A ``CompareOutcome`` -> ``compare.html``: the outcome, one before/after distribution plot per regressed or notable
metric (matplotlib, embedded as PNG), and the table of every metric.

input: the outcome -> output: one self-contained HTML page (``write_page``). Notable: regressed, improved, or
cannot tell with a median change beyond the tolerance. Numbers: a box per side with every run as a dot (paired runs
joined by a line), the tolerance drawn as a band around the before median on the worse side; verdicts: runs per
verdict on each side. Every string that comes from a file name or a certificate is escaped.
"""

from __future__ import annotations

import base64
import html
import io
from pathlib import Path

from tubempc.compare.outcome import CompareOutcome, describe
from tubempc.compare.stats import STATUS_ORDER, MetricResult, Status

__all__ = ["write_page"]

_COLOURS = {"regressed": "#d62728", "cannot_tell": "#ff7f0e", "improved": "#2ca02c", "ok": "#555",
            "not_judged": "#999"}
_NOTABLE: tuple[Status, ...] = ("regressed", "cannot_tell", "improved")
_VERDICTS = ("pass", "inconclusive", "fail")


def _notable(m: MetricResult) -> bool:
    """Regressed, improved, or undecided with a median change beyond the tolerance (or without a number)."""
    if m.status in ("regressed", "improved"):
        return True
    if m.status != "cannot_tell":
        return False
    return m.worse_by is None or m.tolerance is None or abs(m.worse_by) > m.tolerance


def _figure(m: MetricResult) -> str:
    """The metric's plot as a base64 PNG."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    import numpy as np

    fig, ax = plt.subplots(figsize=(6.4, 3.2), dpi=100)
    try:
        if m.kind == "verdict":
            x = np.arange(2)
            bottom = np.zeros(2)
            for rank, (name, colour) in enumerate(zip(_VERDICTS, ("#2ca02c", "#ff7f0e", "#d62728"), strict=True)):
                counts = np.array([sum(1 for v in m.values_before if v == rank),
                                   sum(1 for v in m.values_after if v == rank)], dtype=float)
                ax.bar(x, counts, 0.5, bottom=bottom, color=colour, label=name)
                bottom += counts
            ax.set_xticks(x, ["before", "after"])
            ax.set_ylabel("runs")
            ax.legend(loc="upper right", fontsize=8)
        else:
            before, after = np.asarray(m.values_before, float), np.asarray(m.values_after, float)
            data = [before, after] if before.size and after.size else [before if before.size else after]
            labels = ["before", "after"] if before.size and after.size else ["before" if before.size else "after"]
            ax.boxplot(data, positions=range(len(data)), widths=0.4, showfliers=False)
            ax.set_xticks(range(len(data)), labels)
            rng = np.random.default_rng(0)  # jitter of the dots only (fixed: the page is reproducible)
            xs = [pos + rng.uniform(-0.08, 0.08, values.size) for pos, values in enumerate(data)]
            if m.paired and before.size == after.size and len(data) == 2:
                for xb, xa, b, a in zip(xs[0], xs[1], before, after, strict=True):
                    ax.plot([xb, xa], [b, a], "-", color="#999", lw=0.6, alpha=0.6)
            for pos, values in enumerate(data):
                ax.plot(xs[pos], values, "o", ms=4, alpha=0.7, color=("#1f77b4", "#d62728")[pos])
            if m.tolerance is not None and m.before.median is not None:
                sign = -1.0 if m.direction == "higher_better" else 1.0
                edge = m.before.median + sign * m.tolerance
                ax.axhspan(min(m.before.median, edge), max(m.before.median, edge), color="#2ca02c", alpha=0.12,
                           label=f"tolerance {m.tolerance:.3g}")
                ax.legend(loc="best", fontsize=8)
            ax.set_ylabel(m.unit if m.unit and len(m.unit) <= 12 else "value")
            ax.grid(True, axis="y", alpha=0.3)
        ax.set_title(m.name if not m.unit or len(m.unit) <= 12 else f"{m.name} [{m.unit}]", fontsize=9)
        fig.tight_layout()
        buf = io.BytesIO()
        fig.savefig(buf, format="png")
    finally:
        plt.close(fig)
    return base64.b64encode(buf.getvalue()).decode("ascii")


def _e(value: object) -> str:
    text = "" if value is None else (f"{value:.4g}" if isinstance(value, float) else str(value))
    return html.escape(text, quote=True)


def _row(m: MetricResult) -> str:
    if m.kind == "verdict":
        b = ", ".join(f"{n} {v}" for v, n in m.before.verdicts)
        a = ", ".join(f"{n} {v}" for v, n in m.after.verdicts)
        cells: list[object] = [b, "", "", "", a, "", "", ""]
    else:
        cells = [m.before.median, m.before.p05, m.before.p95, m.before.worst,
                 m.after.median, m.after.p05, m.after.p95, m.after.worst]
    colour = _COLOURS[m.status]
    return (f"<tr><td>{_e(m.name)}</td><td>{_e(m.unit)}</td><td style=\"color:{colour}\">"
            f"{_e(m.status.replace('_', ' '))}</td><td>{_e(m.before.n)}</td>"
            + "".join(f"<td>{_e(c)}</td>" for c in cells[:4])
            + f"<td>{_e(m.after.n)}</td>" + "".join(f"<td>{_e(c)}</td>" for c in cells[4:])
            + f"<td>{_e(m.difference)}</td><td>{_e(m.tolerance)}</td><td>{_e(m.reason)}</td></tr>")


def page_html(outcome: CompareOutcome) -> str:
    o = outcome
    colour = {0: "#2ca02c", 1: "#d62728", 2: "#ff7f0e"}[o.exit_code]
    sections = []
    for m in (m for status in _NOTABLE for m in o.by_status(status) if _notable(m)):
        lines = "<br>".join(_e(line.strip()) for line in describe(m))
        sections.append(f"<section><h3 style=\"color:{_COLOURS[m.status]}\">{_e(m.status.replace('_', ' '))}: "
                        f"{_e(m.name)}</h3><p>{lines}</p><img alt=\"{_e(m.name)}: before and after\" "
                        f"src=\"data:image/png;base64,{_figure(m)}\"></section>")
    ordered = sorted(o.metrics, key=lambda m: (STATUS_ORDER.index(m.status), m.name))
    head = ("<tr><th rowspan=2>metric</th><th rowspan=2>unit</th><th rowspan=2>status</th><th colspan=5>before</th>"
            "<th colspan=5>after</th><th rowspan=2>difference</th><th rowspan=2>tolerance</th>"
            "<th rowspan=2>why</th></tr><tr>" + "<th>n</th><th>median</th><th>p05</th><th>p95</th><th>worst</th>" * 2
            + "</tr>")
    counts = ", ".join(f"{len(o.by_status(s))} {s.replace('_', ' ')}" for s in STATUS_ORDER if o.by_status(s))
    return ("<!DOCTYPE html>\n<html lang=\"en\"><head><meta charset=\"utf-8\"><title>Compare: before and after"
            "</title><style>body{font-family:system-ui,sans-serif;margin:2em;max-width:1400px}"
            "table{border-collapse:collapse;font-size:0.85em}td,th{border:1px solid #ccc;padding:2px 6px;"
            "text-align:left}section{margin:1.5em 0}img{max-width:100%}</style></head><body>"
            f"<h1 style=\"color:{colour}\">{_e(o.verdict.capitalize())} (exit code {o.exit_code})</h1>"
            f"<p>Before: {_e(o.before.label)} ({len(o.before.runs)} {_e(o.before.kind)}); after: "
            f"{_e(o.after.label)} ({len(o.after.runs)} {_e(o.after.kind)}). {_e(o.pairing.note)}. Confidence "
            f"{o.settings.confidence:g}; tolerances: {_e(o.settings.source)}. {len(o.metrics)} metrics: "
            f"{_e(counts)}.</p>"
            + ("<h2>Regressed and notable metrics</h2><p>Regressed, improved, and undecided metrics whose median "
               "moved beyond the tolerance; the others are in the table below.</p>" + "".join(sections)
               if sections else "<p>No metric regressed, improved, or moved beyond its tolerance.</p>")
            + f"<h2>Every metric</h2><table>{head}{''.join(_row(m) for m in ordered)}</table></body></html>\n")


def write_page(outcome: CompareOutcome, path: str | Path) -> Path:
    target = Path(path)
    target.write_text(page_html(outcome), encoding="utf-8")
    return target
