"""The campaign metrics drawn and laid out: PNG bar charts (matplotlib's Agg canvas,
imported here only, when a chart is drawn) and one self-contained HTML page.

    figures = bar_figures(metrics)            # {"jitter": PNG bytes, "energy": ..., "relative": ...}
    page = html_page(metrics, report, figures)

With a comparison the bars are grouped: one group per value of `group_by` (a base
motion), one bar per value of `compare` (a design); "relative" shows each design's
jitter and energy in % of the baseline's in the same group.  Without one, one bar per
log.  The page embeds the charts as data: URIs and references no other file; every text
in it is escaped.  Charts are drawn on a Figure of their own (no pyplot), so drawing on
a worker thread of the GUI does not touch its state.
"""

from __future__ import annotations

import base64
import io
import math
from pathlib import Path
from typing import Any, Callable

from ..core.html_page import BASE_STYLE, cell, escaped
from .comparison import COMPARED
from .metrics import CampaignMetrics
from .metrics_words import (describe, group_text, mode_sentence, num, pct, row_valid,
                            validity_sentence, verdict)
from .report import CampaignReport

FIGURE_TITLES = {"jitter": "Jitter", "energy": "Control energy", "relative": "Relative to the baseline"}


# ---------------------------------------------------------------------- charts
def bar_figures(metrics: CampaignMetrics) -> dict[str, bytes]:
    """The charts as PNG bytes, by name ('jitter', 'energy', and 'relative' when there
    is a comparison); {} when there is no log to draw."""
    if metrics.compared:
        groups = metrics.groups()
        names = metrics.compared_labels()

        def series(key: str, scale: float = 1.0) -> list[tuple[str, list[float | str | None]]]:
            out = []
            for name in names:
                values: list[float | str | None] = []
                for g in groups:
                    cell = metrics.cell(g, name)
                    v = cell.get(key) if cell is not None else None
                    # an invalid run is named on the chart, not drawn beside the others
                    if cell is not None and cell["note"] != "no log" and not cell["error"] \
                            and not cell["valid"]:
                        values.append("not valid")
                        continue
                    values.append(None if v is None else v * scale)
                out.append((name + (" (baseline)" if name == metrics.baseline_label() else ""), values))
            return out
        where = f"by {metrics.analysis.group_by}" if metrics.analysis.group_by else "all runs"
        sensor = metrics.analysis.sensor
        xlabel = metrics.analysis.group_by
        figs = {
            "jitter": _chart([(f"Jitter (std) of {sensor}, {where}", "urad", series("std_urad")),
                              (f"Jitter (high-pass RMS, {metrics.analysis.integration_period_s:g} s)",
                               "urad", series("highpass_rms_urad"))], groups, _fmt, xlabel=xlabel),
            "energy": _chart([(f"Control energy, {where}", "J", series("energy_total_j"))], groups, _fmt,
                             xlabel=xlabel),
            "relative": _chart([(f"Jitter (std), % of {metrics.baseline_label()}", "%",
                                 series("std_urad_ratio", 100.0)),
                                (f"Control energy, % of {metrics.baseline_label()}", "%",
                                 series("energy_total_j_ratio", 100.0))], groups,
                               lambda v: f"{v:.0f} %", reference=100.0, xlabel=xlabel),
        }
        return figs
    rows = metrics.rows
    if not rows:
        return {}
    ticks = [f"run {r['run']}" + (f"\n{Path(r['file']).stem[-24:]}" if len(rows) > 1 else "") for r in rows]

    def per_log(key: str) -> list[float | str | None]:
        return [None if r["error"] else r["metrics"].get(key) if row_valid(r) else "not valid"
                for r in rows]
    return {
        "jitter": _chart([(f"Jitter of {metrics.analysis.sensor}", "urad",
                           [("std", per_log("std_urad")), ("high-pass RMS", per_log("highpass_rms_urad"))])],
                         ticks, _fmt),
        "energy": _chart([("Control energy", "J", [("total", per_log("energy_total_j"))])], ticks, _fmt),
    }


def _fmt(v: float) -> str:
    return f"{v:.3g}"


def _chart(panels: list[tuple[str, str, list[tuple[str, list[float | str | None]]]]], groups: list[str],
           fmt: Callable[[float], str], reference: float | None = None, xlabel: str = "") -> bytes:
    """Side-by-side panels of grouped bars: (title, unit, [(series name, one value per
    group)]); a missing value is drawn as 'n/a', a text (e.g. 'not valid') as itself."""
    from matplotlib.backends.backend_agg import FigureCanvasAgg
    from matplotlib.figure import Figure

    bars = len(groups) * max(1, len(panels[0][2]))
    width_in = min(18.0, len(panels) * max(5.0, 1.5 + 0.45 * bars))
    fig = Figure(figsize=(width_in, 4.2), dpi=100, layout="constrained")
    FigureCanvasAgg(fig)
    axes = fig.subplots(1, len(panels), squeeze=False)[0]
    for ax, (title, unit, series) in zip(axes, panels):
        n = max(1, len(series))
        width = 0.8 / n
        for i, (name, values) in enumerate(series):
            xs = [g - 0.4 + width * (i + 0.5) for g in range(len(groups))]
            heights = [math.nan if v is None or isinstance(v, str) else v for v in values]
            ax.bar(xs, heights, width, label=name, color=f"C{i % 10}")
            for x, v in zip(xs, values):
                shown = "n/a" if v is None else v if isinstance(v, str) else fmt(v)
                at = 0.0 if v is None or isinstance(v, str) else v
                ax.annotate(shown, (x, at),
                            xytext=(0, 2), textcoords="offset points", ha="center", va="bottom",
                            fontsize=7)
        if reference is not None:
            ax.axhline(reference, color="0.3", linewidth=0.8, linestyle="--")
        ax.set_xticks(range(len(groups)), groups, fontsize=8)
        ax.set_ylabel(unit.replace("urad", "µrad"))
        if xlabel:
            ax.set_xlabel(xlabel)
        ax.set_title(title, fontsize=9)
        ax.grid(axis="y", alpha=0.3)
        ax.set_axisbelow(True)
        ax.margins(y=0.15)
        if len(series) > 1 or reference is not None:
            ax.legend(fontsize=7)
    buf = io.BytesIO()
    fig.savefig(buf, format="png", metadata={"Software": None})
    return buf.getvalue()


# ---------------------------------------------------------------------- the page
_STYLE = BASE_STYLE + """
tr.baseline td { background: #f4f8ff; } tr.error td { background: #fff0f0; }
tr.invalid td { background: #fff8e0; color: #666; }
"""


def html_page(metrics: CampaignMetrics, report: CampaignReport, figures: dict[str, bytes],
              reference: dict[str, bytes] | None = None) -> str:
    """One page, nothing outside it: the settings, the comparison, the charts (base64
    data: URIs), the reference metrics' tables and charts (`reference`: PNGs of
    reference_figures.figures), every log's figures, the notes and the report's summary."""
    from .reference_figures import html_section

    a = metrics.analysis
    status = (f"{report.status}: {len(report.completed_runs)} run(s) complete, "
              f"{len(report.failed_runs)} failed; {len(metrics.rows)} log(s) scored")
    out = ["<!DOCTYPE html>", '<html lang="en"><head><meta charset="utf-8">',
           f"<title>campaign {escaped(metrics.campaign)}: metrics</title>",
           f"<style>{_STYLE}</style></head><body>",
           f"<h1>Campaign {escaped(metrics.campaign)}</h1>",
           f"<p>{escaped(status)}<br>campaign file {escaped(report.file)}<br>{escaped(metrics.window_text())}</p>"]
    if metrics.compared:
        title = f"Comparison of {a.compare}" + (f" by {a.group_by}" if a.group_by else "")
        out.append(f"<h2>{escaped(title)}</h2>")
        out.append(f"<p>relative to {escaped(metrics.baseline_label())} in each group</p>")
        out.append(_comparison_table(metrics))
        sentences = [validity_sentence(c, metrics.baseline_label(), group_text(a, c["group"], under=True))
                     or ("" if c["baseline"] else
                         verdict(c, metrics.baseline_label(), group_text(a, c["group"], under=True)))
                     for c in metrics.comparison]
        sentences += [mode_sentence(c, group_text(a, c["group"], under=True)) for c in metrics.comparison]
        sentences = [s for s in sentences if s]
        if sentences:
            out.append("<ul>" + "".join(f"<li>{escaped(s)}</li>" for s in sentences) + "</ul>")
    if figures:
        out.append("<h2>Figures</h2>")
        for name, png in figures.items():
            data = base64.b64encode(png).decode("ascii")
            out.append(f"<h3>{escaped(FIGURE_TITLES.get(name, name))}</h3>"
                       f'<img alt="{escaped(FIGURE_TITLES.get(name, name))}" src="data:image/png;base64,{data}">')
    section = html_section(metrics, reference or {})
    if section:
        out.append(section)
    out.append("<h2>Every log</h2>")
    out.append(_rows_table(metrics))
    if metrics.notes:
        out.append("<h2>Notes</h2><ul>" + "".join(f"<li>{escaped(n)}</li>" for n in metrics.notes) + "</ul>")
    out.append("<h2>Report</h2>")
    out.append(f"<pre>{escaped(report.summary())}\n\n{escaped(metrics.text())}</pre>")
    out.append("</body></html>")
    return "\n".join(out) + "\n"


def _comparison_table(metrics: CampaignMetrics) -> str:
    a = metrics.analysis
    head = [a.group_by or "group", a.compare, "run"]
    for what, unit in COMPARED.values():
        head += [f"{what} ({unit.replace('urad', 'µrad')})", "vs baseline"]
    head += ["window (s)", "note"]
    lines = ["<table><tr>" + "".join(f"<th>{escaped(h)}</th>" for h in head) + "</tr>"]
    for c in metrics.comparison:
        cls = (' class="error"' if c["error"] else
               ' class="invalid"' if c["note"] != "no log" and not c["valid"] else
               ' class="baseline"' if c["baseline"] else "")
        cells = [cell(c["group"], True), cell(c["compare"], True), cell(c["run"])]
        for key in COMPARED:
            cells.append(cell(num(c[key])))
            cells.append(cell("baseline" if c["baseline"] else
                             f"{pct(c[f'{key}_change_pct'])} (x{num(c[f'{key}_ratio'])})"
                             if c[f"{key}_ratio"] is not None else "n/a"))
        cells.append(cell(num(c["window_s"])))
        cells.append(cell(c["error"] or c["note"], True))
        lines.append(f"<tr{cls}>" + "".join(cells) + "</tr>")
    lines.append("</table>")
    return "\n".join(lines)


_ROW_FIGURES = [("from_s", "from (s)"), ("to_s", "to (s)"), ("frames", "frames"),
                ("missing_frames", "missing"), ("excluded_pct", "excluded (%)"),
                ("valid", "valid"), ("mean_urad", "mean (µrad)"),
                ("std_urad", "std (µrad)"), ("highpass_rms_urad", "high-pass RMS (µrad)"),
                ("rms_urad", "RMS (µrad)"), ("energy_total_j", "energy (J)"),
                ("energy_coarse_j", "coarse (J)"), ("energy_fine_j", "fine (J)"),
                ("saturated_coarse_pct", "coarse sat. (%)"), ("saturated_fine_pct", "fine sat. (%)"),
                ("mode_share_pct", "mode share (%)"), ("mode_band", "mode band (Hz)")]


def _rows_table(metrics: CampaignMetrics) -> str:
    head = ["run", "status", "matrix", "log", "window"] + [h for _, h in _ROW_FIGURES] + ["notes / error"]
    lines = ["<table><tr>" + "".join(f"<th>{escaped(h)}</th>" for h in head) + "</tr>"]
    for r in metrics.rows:
        w = r["window"]
        start = f"mark '{w['mark']}'" if w["start"] == "mark" else w["start"]
        cells = [cell(r["run"]), cell(r["run_status"], True), cell(describe(r["variables"]), True),
                 cell(Path(r["file"]).name, True), cell(start, True)]
        shown = dict(r["metrics"])
        if isinstance(shown.get("excluded_fraction"), float):
            shown["excluded_pct"] = 100.0 * shown["excluded_fraction"]
        shown["valid"] = "yes" if row_valid(r) else "NO"
        if isinstance(shown.get("mode_share"), float):
            shown["mode_share_pct"] = 100.0 * shown["mode_share"]
            lo, hi = shown["mode_band_hz"]
            shown["mode_band"] = f"{lo:.3g}-{hi:.3g}" + (" DOMINATES" if shown.get("mode_dominates") else "")
        cells += [cell(num(shown.get(k)) if isinstance(shown.get(k), float)
                      else shown.get(k)) for k, _ in _ROW_FIGURES]
        said = [("ERROR " + r["error"]) if r["error"] else
                "; ".join(x for x in [r["notes"], "" if row_valid(r) else
                                      "not valid: " + str(r["metrics"].get("invalid_reason", ""))] if x)]
        if r.get("reference_error"):
            said.append("reference metric: " + r["reference_error"])
        cells.append(cell("; ".join(x for x in said if x), True))
        cls = ' class="error"' if r["error"] else "" if row_valid(r) else ' class="invalid"'
        lines.append(f"<tr{cls}>" + "".join(cells) + "</tr>")
    lines.append("</table>")
    return "\n".join(lines)


__all__ = ["FIGURE_TITLES", "bar_figures", "html_page"]
