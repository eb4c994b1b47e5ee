"""The figures a campaign's logs give: jitter and control energy per run, and the
comparison the operator wants after a campaign - per group (a base motion), each value
compared (a design) absolute and relative to a baseline ("Design #2 cuts jitter by 60 %
and energy by 95 % vs Design #1 under BM1").

    metrics = campaign_metrics(report, campaign)        # every recording's logs scored
    write_metrics(metrics, report, "logs/NAME/report.json")

`campaign_metrics` scores every log of every recording of a CampaignReport with
`groundstation.analysis.analyze_log`, over the window the campaign's [analysis] table
asks for (from a mark step, for duration_s; see AnalysisSpec), and compares them.  The
reference metrics the table names (`metrics = ["step"]`: step, frf, hysteresis,
friction_velocity) are computed per log over the same window (reference_metrics.py;
their figures join the row's, a failure is the row's `reference_error`).  A log that
cannot be scored is a row with its error, never an exception.  `write_metrics`
writes beside the report:

    NAME.metrics.csv     one row per log: run, its matrix values, the window, the figures
    NAME.metrics.json    the same rows (nested), the comparison, the settings
    NAME.jitter.png      bar charts (report_figures.py, matplotlib Agg)
    NAME.energy.png
    NAME.relative.png    relative to the baseline (only with a comparison)
    NAME.step.png, NAME.frf_*.png, NAME.hysteresis.png, NAME.slope_table.png,
    NAME.friction_velocity.png     the reference metrics' figures (reference_figures.py)
    NAME.slope_table.LOG.csv       each log's identified DB-DHM slope table (hysteresis)
    NAME.html            all of it in one self-contained page (the PNGs embedded)
    NAME.txt             the report's summary, then the comparison in words

The pieces: scoring.py scores one log (its window, from a mark step, and its row),
comparison.py compares the rows, metrics_words.py says it all in words; this module
collects the rows of a report and writes the outputs.
"""

from __future__ import annotations

import csv
import io
import json
from dataclasses import dataclass, field
from pathlib import Path
from typing import TYPE_CHECKING, Any

from .comparison import cell_text, compare
from .metrics_words import (csv_variable, describe, group_text, invalid_reason, label,
                            mode_sentence, mode_text, row_valid, seconds, unit,
                            validity_sentence, verdict)
from .model import AnalysisSpec, Campaign
from .report import CampaignReport
from .scoring import make_row, score_log_with_results

if TYPE_CHECKING:
    from .scoring_behind import ScoringBehind


@dataclass
class CampaignMetrics:
    """Every log's row and the comparison, with the settings that made them."""

    campaign: str
    report_file: str
    analysis: AnalysisSpec
    matrix: dict[str, list[Any]]
    rows: list[dict[str, Any]]
    comparison: list[dict[str, Any]] = field(default_factory=list)
    notes: list[str] = field(default_factory=list)
    #: what the reference metrics say across the logs (reference_metrics.campaign_summary)
    reference_summary: dict[str, Any] = field(default_factory=dict)
    #: row index -> metric -> its result and traces, for the figures (not in the JSON)
    reference_data: dict[int, dict[str, Any]] = field(default_factory=dict, repr=False)

    # ------------------------------------------------------------------ derived
    @property
    def compared(self) -> bool:
        return bool(self.comparison)

    def groups(self) -> list[str]:
        return list(dict.fromkeys(c["group"] for c in self.comparison))

    def compared_labels(self) -> list[str]:
        return list(dict.fromkeys(c["compare"] for c in self.comparison))

    def baseline_label(self) -> str:
        return label(self.analysis.baseline) if self.analysis.compare else ""

    def cell(self, group: str, compared: str) -> dict[str, Any] | None:
        return next((c for c in self.comparison if c["group"] == group and c["compare"] == compared), None)

    def window_text(self) -> str:
        a = self.analysis
        where = f"from the mark '{a.start_after_mark}'" if a.start_after_mark else "from the log's start"
        span = f" for {a.duration_s:g} s" if a.duration_s is not None else " to the log's end"
        return (f"sensor {a.sensor}, window {where}{span}, integration period "
                f"{a.integration_period_s:g} s")

    # ------------------------------------------------------------------ outputs
    def _columns(self) -> tuple[list[str], list[str], list[str], list[str]]:
        """(head, matrix keys, window, figures) columns of the CSV."""
        head = ["run", "run_status", "recording", "file", "part"]
        names = list(dict.fromkeys(k for r in self.rows for k in r["variables"]))
        window = ["window_start", "mark"]
        figures = [k for k in dict.fromkeys(k for r in self.rows for k in r["metrics"])
                   if k not in ("notes", "error")]
        return head, names, window, figures

    def csv_text(self) -> str:
        """One line per log; a matrix key that is also a column's name is 'matrix_KEY'."""
        head, names, window, figures = self._columns()
        fixed = set(head) | set(window) | set(figures) | {"notes", "error"}
        columns = (head + [csv_variable(k, fixed) for k in names] + window + figures
                   + ["notes", "error", "reference_error"])
        out = io.StringIO()
        w = csv.writer(out, lineterminator="\n")
        w.writerow(columns)
        for r in self.rows:
            flat = {"run": r["run"], "run_status": r["run_status"], "recording": r["recording"],
                    "file": r["file"], "part": r["part"], "window_start": r["window"]["start"],
                    "mark": r["window"]["mark"], **r["metrics"], "notes": r["notes"], "error": r["error"],
                    "reference_error": r.get("reference_error", "")}
            flat.update({csv_variable(k, fixed): v for k, v in r["variables"].items()})
            w.writerow(["" if flat.get(c) is None else flat[c] for c in columns])
        return out.getvalue()

    def as_json(self) -> dict[str, Any]:
        return {"campaign": self.campaign, "report": self.report_file,
                "analysis": self.analysis.as_dict(), "window": self.window_text(),
                "matrix": self.matrix, "rows": self.rows, "comparison": self.comparison,
                "reference_summary": self.reference_summary, "notes": self.notes}

    def text(self) -> str:
        """The rows and the comparison in words, for report.txt and the terminal."""
        from .reference_metrics import row_lines, summary_lines

        lines = [f"metrics ({self.window_text()}):"]
        for r in self.rows:
            head = f"  run {r['run']}" + (f" ({describe(r['variables'])})" if r["variables"] else "")
            head += f" {Path(r['file']).name}"
            if r["error"]:
                lines.append(f"{head}: ERROR {r['error']}")
                lines += row_lines(r, self.analysis.metrics)
                continue
            m = r["metrics"]
            lines.append(f"{head}: jitter std {unit(m.get('std_urad'), 'urad')}, high-pass "
                         f"{unit(m.get('highpass_rms_urad'), 'urad')}, energy "
                         f"{unit(m.get('energy_total_j'), 'J')} over {seconds(r)} s"
                         + (f" [{r['run_status']}]" if r["run_status"] not in ("completed", "") else "")
                         + ("" if row_valid(r) else f" - NOT VALID: {invalid_reason(r)}"))
            said = mode_text(m)
            if said:
                lines.append(f"    {'MODE: ' if m.get('mode_dominates') else ''}{said}")
            lines += row_lines(r, self.analysis.metrics)
            if r["notes"]:
                lines.append(f"    note: {r['notes']}")
        lines += summary_lines(self.reference_summary)
        if self.comparison:
            a = self.analysis
            lines.append(f"comparison of {a.compare}" + (f" by {a.group_by}" if a.group_by else "")
                         + f", relative to {self.baseline_label()}:")
            for g in self.groups():
                lines.append(f"  {group_text(a, g)}:")
                for c in self.compared_labels():
                    cell = self.cell(g, c)
                    if cell is not None:
                        lines.append(f"    {c}: {cell_text(cell)}")
                for c in self.compared_labels():
                    cell = self.cell(g, c)
                    if cell is None:
                        continue
                    where = group_text(a, g, under=True)
                    sentence = (validity_sentence(cell, self.baseline_label(), where)
                                or ("" if cell["baseline"] else verdict(cell, self.baseline_label(), where)))
                    if sentence:
                        lines.append(f"    => {sentence}")
                    flagged = mode_sentence(cell, where)
                    if flagged:
                        lines.append(f"    => {flagged}")
        lines += [f"note: {n}" for n in self.notes]
        return "\n".join(lines)


# ---------------------------------------------------------------------- scoring
def campaign_metrics(report: CampaignReport, campaign: Campaign | None = None, *,
                     folder: str | Path | None = None,
                     scored: "ScoringBehind | None" = None) -> CampaignMetrics:
    """Score every log of every recording in `report` and compare them as `campaign`'s
    [analysis] table asks (None: whole logs, default sensor, no comparison).  A log no
    longer where the report says is looked for in `folder` (the report's own folder,
    moved with its logs).  A log `scored` has scored already, while the campaign ran
    (scoring_behind.py, the same analysis), is taken from there."""
    spec = campaign.analysis if campaign is not None else AnalysisSpec()
    matrix = dict(campaign.matrix) if campaign is not None else {}
    rows: list[dict[str, Any]] = []
    data: dict[int, dict[str, Any]] = {}
    untagged = 0
    for rec in report.recordings:
        files = list(rec.get("files", []))
        if "run" not in rec:
            untagged += 1
        run = int(rec.get("run", 0) or 0)
        variables = dict(rec.get("variables", {}))
        for part, f in enumerate(files, 1):
            if folder is not None and not Path(f).exists() and (Path(folder) / Path(f).name).exists():
                f = str(Path(folder) / Path(f).name)
            name = str(rec.get("name", ""))
            numbered = part if len(files) > 1 else None
            status = run_status(report, run)
            ahead = scored.take(f, run, variables, name, numbered) if scored is not None else None
            if ahead is not None:
                row, data[len(rows)] = ahead
                row["run_status"] = status
            else:
                row, data[len(rows)] = score_log_with_results(
                    f, spec, report.campaign, run, variables, recording=name, part=numbered,
                    run_status=status, design_dir=campaign.path.parent if campaign else None)
            rows.append(row)
        if not files:
            rows.append(make_row(str(rec.get("name", "")), "", None, run, variables,
                                 run_status(report, run), error="the recording wrote no file"))
    notes = []
    if untagged:
        notes.append(f"{untagged} recording(s) in the report carry no run or matrix values (a report "
                     f"written before runs were tagged): their rows say run 0 and they are not compared")
    metrics = CampaignMetrics(report.campaign, report.report_file, spec, matrix, rows, notes=notes,
                              reference_data=data)
    if spec.metrics:
        from .reference_metrics import campaign_summary
        metrics.reference_summary = campaign_summary(rows, spec.metrics)
    if spec.compare:
        metrics.comparison, extra = compare(rows, spec, matrix)
        metrics.notes += extra
    return metrics


def run_status(report: CampaignReport, run: int) -> str:
    if not run:
        return ""
    if str(run) in report.failed_runs:
        return "failed: " + report.failed_runs[str(run)]
    if run in report.completed_runs:
        return "completed"
    if report.failed_run == run:
        return f"{report.status}: {report.reason.splitlines()[0] if report.reason else ''}".rstrip(": ")
    return "incomplete"


# ---------------------------------------------------------------------- files
def output_paths(report_path: str | Path) -> dict[str, Path]:
    base = Path(report_path)
    stem = base.with_suffix("")
    return {"csv": Path(f"{stem}.metrics.csv"), "json": Path(f"{stem}.metrics.json"),
            "jitter": Path(f"{stem}.jitter.png"), "energy": Path(f"{stem}.energy.png"),
            "relative": Path(f"{stem}.relative.png"), "html": Path(f"{stem}.html"),
            "txt": base.with_suffix(".txt")}


def write_metrics(metrics: CampaignMetrics, report: CampaignReport, report_path: str | Path, *,
                  html_only: bool = False) -> list[Path]:
    """Write the outputs beside `report_path` (see the module docstring); returns the
    files written.  `html_only`: the page alone (its figures embedded)."""
    from . import reference_figures, report_figures

    paths = output_paths(report_path)
    paths["html"].parent.mkdir(parents=True, exist_ok=True)
    written: list[Path] = []
    figures = report_figures.bar_figures(metrics)
    reference = reference_figures.figures(metrics)
    if not html_only:
        written += reference_figures.write_slope_tables(metrics, report_path)
        for name, png in reference.items():
            paths[name] = Path(f"{Path(report_path).with_suffix('')}.{name}.png")
            paths[name].write_bytes(png)
            written.append(paths[name])
        paths["csv"].write_text(metrics.csv_text())
        paths["json"].write_text(json.dumps(metrics.as_json(), indent=2, default=str) + "\n")
        written += [paths["csv"], paths["json"]]
        for name, png in figures.items():
            paths[name].write_bytes(png)
            written.append(paths[name])
        paths["txt"].write_text(report.summary() + "\n\n" + metrics.text() + "\n")
        written.append(paths["txt"])
    paths["html"].write_text(report_figures.html_page(metrics, report, figures, reference),
                             encoding="utf-8")
    written.append(paths["html"])
    return written


__all__ = ["CampaignMetrics", "campaign_metrics", "output_paths", "run_status", "write_metrics"]
