"""The identification as one self-contained HTML page, and the report folder that holds it
beside the text, the JSON and the PNGs.

    page = html_page(result, written_to, pngs)          # pngs: figures.figures(result)
    paths = write_report(result, "reports/rig", written_to)

The page follows the campaign report's: one file, the figures embedded as base64 data:
URIs, no script, no style sheet or image fetched from anywhere, every text escaped.  Its
figures are report.as_json's, so the page, the JSON and the text never disagree.
"""

from __future__ import annotations

import base64
import json
from pathlib import Path
from typing import Any

from ..core.html_page import BASE_STYLE, cell, escaped
from .figures import TITLES, figures, write_figures
from .report import as_json, as_text

#: the report folder's files besides the figures (figures.figure_path names those)
TEXT_NAME, JSON_NAME, PAGE_NAME = "identification.txt", "identification.json", "identification.html"

_STYLE = BASE_STYLE + """
tr.held td { background: #f2f2f2; color: #666; font-style: italic; }
tr.unused td { background: #fff8e0; color: #666; }
"""


def _num(x: float | None) -> str:
    return "" if x is None else f"{x:.6g}"


def _table(head: list[str], rows: list[tuple[str, list[str]]]) -> str:
    """A table of already-escaped cells; each row with its class ('' for none)."""
    lines = ["<table><tr>" + "".join(f"<th>{escaped(h)}</th>" for h in head) + "</tr>"]
    for cls, cells in rows:
        attribute = f' class="{cls}"' if cls else ""
        lines.append(f"<tr{attribute}>" + "".join(cells) + "</tr>")
    lines.append("</table>")
    return "\n".join(lines)


def _parameter_table(parameters: list[dict[str, Any]]) -> str:
    """Every parameter; a held one (its base value kept, the status says why) greyed."""
    rows = []
    for p in parameters:
        ci = (f"[{_num(p['ci95'][0])}, {_num(p['ci95'][1])}]" if p["ci95"] is not None else "")
        change = f"{p['change_pct']:+.2f} %" if p["change_pct"] is not None else ""
        cells = [cell(p["name"], True), cell(p["units"], True), cell(_num(p["base"])),
                 cell(_num(p["value"])), cell(change), cell(ci), cell(p["status"], True),
                 cell(p["reason"], True), cell(", ".join(p["sources"]), True)]
        rows.append(("held" if str(p["status"]).startswith("held") else "", cells))
    return _table(["parameter", "units", "base", "identified", "change", "95 % interval",
                   "status", "reason", "sources"], rows)


def _logs_table(logs: list[dict[str, Any]]) -> str:
    """Every log given, used or not and why; a friction log (a position profile, no
    current excitation) says so instead of a current."""
    rows = []
    for u in logs:
        friction = u.get("purpose") == "friction"
        excited = "friction (position profile)" if friction else u["input"]
        current = f"{u['current_rms_a']:.3g}" if u["input"] and not friction else ""
        rows.append(("" if u["used"] else "unused",
                     [cell(Path(u["path"]).name, True),
                      cell("used" if u["used"] else "not used", True), cell(excited, True),
                      cell(current), cell(u["note"], True)]))
    return _table(["log", "", "excited", "current (A RMS)", "note"], rows)


def _fit_table(figures_json: dict[str, Any]) -> str:
    mag, phase = figures_json["rms_magnitude_db"], figures_json["rms_phase_deg"]
    rows = [("", [cell(f"{which} model", True), cell(f"{mag[which]:.3f}"),
                  cell(f"{phase[which]:.2f}")]) for which in ("base", "identified")]
    return _table(["model vs measured", "RMS magnitude (dB)", "RMS phase (deg)"], rows)


def _figure_sections(pngs: dict[str, bytes]) -> list[str]:
    out = []
    for name, png in pngs.items():
        title = TITLES.get(name, name)
        data = base64.b64encode(png).decode("ascii")
        out.append(f"<h3>{escaped(title)}</h3>"
                   f'<img alt="{escaped(title)}" src="data:image/png;base64,{data}">')
    return out


def _header(doc: dict[str, Any]) -> list[str]:
    base = Path(doc["base"])
    used = sum(1 for u in doc["logs"] if u["used"])
    lo, hi = doc["band_hz"]
    return ["<!DOCTYPE html>", '<html lang="en"><head><meta charset="utf-8">',
            f"<title>identification of {escaped(base.name)}</title>",
            f"<style>{_STYLE}</style></head><body>",
            f"<h1>Identification from {escaped(base.name)}</h1>",
            f"<p>base file {escaped(base)}<br>"
            f"written: {escaped(doc['written'] or 'no testbed file written')}<br>"
            f"{used} of {len(doc['logs'])} log(s) used; {doc['bins_used']} bins with coherence "
            f"&ge; {doc['min_coherence']:g} in {lo:g}-{hi:g} Hz</p>"]


def html_page(result: Any, written_to: str = "", pngs: dict[str, bytes] | None = None) -> str:
    """One page, nothing outside it: the files, the parameters with their provenance, the
    logs, the fit's quality, the notes, the figures (`pngs`, by figures.TITLES name) and
    the text report."""
    doc = as_json(result, written_to)
    out = _header(doc)
    out += ["<h2>Parameters</h2>", _parameter_table(doc["parameters"]),
            "<h2>Logs</h2>", _logs_table(doc["logs"]),
            "<h2>Fit quality</h2>", _fit_table(doc),
            f"<p>over the {doc['bins_used']} fitted bins; reduced chi-square "
            f"{doc['reduced_chi_square']:.3g} (1: the model explains the data as well as "
            f"their noise allows)</p>"]
    if doc["notes"]:
        out.append("<h2>Notes</h2><ul>" + "".join(f"<li>{escaped(n)}</li>" for n in doc["notes"])
                   + "</ul>")
    if pngs:
        out.append("<h2>Figures</h2>")
        out += _figure_sections(pngs)
    out += ["<h2>Report</h2>", f"<pre>{escaped(as_text(result, written_to))}</pre>", "</body></html>"]
    return "\n".join(out) + "\n"


def write_report(result: Any, folder: str | Path, written_to: str = "") -> list[Path]:
    """Write the report into `folder` (made if missing; OSError if it cannot be): the
    text, the JSON, every figure as PNG and the page embedding them.  Returns the paths,
    the page last."""
    pngs = figures(result)                  # drawn first: a drawing that fails leaves no folder
    folder = Path(folder)
    folder.mkdir(parents=True, exist_ok=True)
    text_path, json_path, page_path = folder / TEXT_NAME, folder / JSON_NAME, folder / PAGE_NAME
    text_path.write_text(as_text(result, written_to) + "\n", encoding="utf-8")
    json_path.write_text(json.dumps(as_json(result, written_to), indent=2) + "\n",
                         encoding="utf-8")
    paths = [text_path, json_path, *write_figures(result, folder, pngs)]
    page_path.write_text(html_page(result, written_to, pngs), encoding="utf-8")
    return paths + [page_path]


__all__ = ["JSON_NAME", "PAGE_NAME", "TEXT_NAME", "html_page", "write_report"]
