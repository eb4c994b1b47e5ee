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

Where the window starts.  A mark step writes an event (source "script") to the log's
journal, stamped with the host's clock; frames carry both clocks.  The window starts at
the device time of the last HIGH_RATE frame the host had received when the mark was
written - the device time the rig had reached at the mark (within one frame on the
simulator, within the link's latency on a rig).
"""

from __future__ import annotations

import csv
import io
import json
import logging
import math
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from ..core.errors import GroundStationError
from .model import AnalysisSpec, Campaign
from .reading import run_names
from .report import CampaignReport

log = logging.getLogger(__name__)

PACKET = "HIGH_RATE"
#: the figures compared: key in LogMetrics.row() -> (what it is, unit)
COMPARED = {"std_urad": ("jitter (std)", "urad"),
            "highpass_rms_urad": ("jitter (high-pass RMS)", "urad"),
            "energy_total_j": ("control energy", "J")}
#: a window this much shorter than the baseline's makes energies incomparable (said so)
WINDOW_TOLERANCE = 0.05


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
                     folder: str | Path | None = None) -> CampaignMetrics:
    """Score every log of every recording in `report` and compare them as `campaign`'s
    [analysis] table asks (None: whole logs, default sensor, no comparison).  A log no
    longer where the report says is looked for in `folder` (the report's own folder,
    moved with its logs)."""
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
            row, data[len(rows)] = _score(f, spec, report.campaign, run, variables,
                                          recording=str(rec.get("name", "")),
                                          part=part if len(files) > 1 else None,
                                          run_status=run_status(report, run),
                                          design_dir=campaign.path.parent if campaign else None)
            rows.append(row)
        if not files:
            rows.append(_row(str(rec.get("name", "")), "", None, run, variables, run_status(report, run),
                             error="the recording wrote no file"))
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


def _row(recording: str, file: str, part: int | None, run: int, variables: dict[str, Any],
         status: str, *, window: dict[str, Any] | None = None, metrics: dict[str, Any] | None = None,
         notes: str = "", error: str = "") -> dict[str, Any]:
    return {"run": run, "run_status": status, "recording": recording, "file": file, "part": part,
            "variables": variables,
            "window": window or {"start": "", "mark": "", "start_s": None, "stop_s": None},
            "metrics": metrics or {}, "notes": notes, "error": error, "reference": {},
            "reference_error": ""}


def score_log(path: str | Path, spec: AnalysisSpec, campaign: str = "", run: int = 0,
              variables: dict[str, Any] | None = None, *, recording: str = "",
              part: int | None = None, run_status: str = "",
              design_dir: Path | None = None) -> dict[str, Any]:
    """One log's row: its window found, `analyze_log` over it; whatever goes wrong is the
    row's `error` (the log unreadable, a channel missing, an empty window).  The
    reference metrics of `spec.metrics` join it (their failure: `reference_error`)."""
    return _score(path, spec, campaign, run, variables, recording=recording, part=part,
                  run_status=run_status, design_dir=design_dir)[0]


def _score(path: str | Path, spec: AnalysisSpec, campaign: str = "", run: int = 0,
           variables: dict[str, Any] | None = None, *, recording: str = "",
           part: int | None = None, run_status: str = "",
           design_dir: Path | None = None) -> tuple[dict[str, Any], dict[str, Any]]:
    """(the row, the reference metrics' results for the figures)."""
    row, unreadable = _score_jitter(path, spec, campaign, run, variables, recording=recording,
                                    part=part, run_status=run_status, design_dir=design_dir)
    if not spec.metrics or unreadable:
        return row, {}
    from .reference_metrics import add_to_row
    return row, add_to_row(row, path, spec.metrics)


def run_design(variables: dict[str, Any], design_dir: Path | None) -> str | Path | None:
    """The design whose loop a run closed, for the mode check: the matrix's `design`
    value when it names a design file (relative to the campaign file), None when it
    names none ("open_loop": no loop, no check), "auto" without a `design` key (the last
    design the log records uploading, if the loop was closed in the window)."""
    if "design" not in variables:
        return "auto"
    v = variables["design"]
    if not isinstance(v, str) or not v.endswith(".toml"):
        return None
    p = Path(v)
    return p if p.is_absolute() or design_dir is None else design_dir / p


def _score_jitter(path: str | Path, spec: AnalysisSpec, campaign: str = "", run: int = 0,
                  variables: dict[str, Any] | None = None, *, recording: str = "",
                  part: int | None = None, run_status: str = "",
                  design_dir: Path | None = None) -> tuple[dict[str, Any], bool]:
    """(the row of jitter and energy, whether the log could not be read at all)."""
    from ..analysis import analyze_log
    from ..logs import LogError

    variables = dict(variables or {})
    notes: list[str] = []
    window = {"start": "log start", "mark": "", "start_s": None, "stop_s": None}
    try:
        if spec.start_after_mark:
            target = mark_text(spec.start_after_mark, campaign, run, variables)
            start, found = mark_start(path, target)
            if start is None:
                notes.append(f"no mark '{target}' in the log: the whole log is scored")
                window["start"] = "log start (mark not found)"
            else:
                window.update(start="mark", mark=found, start_s=start,
                              stop_s=None if spec.duration_s is None else start + spec.duration_s)
        elif spec.duration_s is not None:
            window.update(start_s=0.0, stop_s=spec.duration_s)
        m = analyze_log(path, start_s=window["start_s"], stop_s=window["stop_s"], sensor=spec.sensor,
                        integration_period_s=spec.integration_period_s,
                        design=run_design(variables, design_dir))
    except GroundStationError as exc:
        return _row(recording, str(path), part, run, variables, run_status, window=window,
                    notes="; ".join(notes), error=str(exc).strip() or type(exc).__name__), \
            isinstance(exc, LogError)
    except Exception as exc:            # a log this code did not foresee: a row, not a crash
        log.exception("scoring %s", path)
        return _row(recording, str(path), part, run, variables, run_status, window=window,
                    notes="; ".join(notes), error=f"{type(exc).__name__}: {exc}"), True
    row = m.row(spec.excluded_limit())
    said = row.pop("notes", "")
    if said:
        notes.append(said)
    error = row.pop("error", "") or ""
    if window["stop_s"] is not None and window["start_s"] is not None:
        scored = m.window_to_s - m.window_from_s + 1.0 / m.rate_hz
        wanted = window["stop_s"] - window["start_s"]
        if scored < wanted * (1 - WINDOW_TOLERANCE):
            notes.append(f"the log ends {scored:.3g} s into the {wanted:g} s window")
    return _row(recording, str(path), part, run, variables, run_status, window=window,
                metrics=row, notes="; ".join(notes), error=error), False


def mark_text(text: str, campaign: str, run: int, variables: dict[str, Any]) -> str:
    """`start_after_mark` with the run's placeholders filled (as the mark step's were)."""
    names = run_names(campaign, run, {k: v for k, v in variables.items() if not k.endswith("_stem")})
    names.update(variables)
    try:
        return text.format(**names)
    except (KeyError, IndexError, ValueError):
        return text


def mark_start(path: str | Path, text: str) -> tuple[float | None, str]:
    """(seconds of device time from the log's start, the mark's text) of the first mark
    step whose text is `text` (else the first that contains it); (None, '') if none."""
    from ..logs import LogReader

    with LogReader(path) as r:
        marks = [e for e in r.journal("event")
                 if e.data.get("source") == "script" and isinstance(e.data.get("text"), str)]
        hit = next((e for e in marks if e.data["text"] == text), None) \
            or next((e for e in marks if text in e.data["text"]), None)
        if hit is None:
            return None, ""
        if PACKET not in r.packets() or not r.n_frames(PACKET):
            return 0.0, hit.data["text"]
        # rows whose host arrival time is at or before the mark: the last one is where
        # the rig was when the mark was written
        _, i1 = r.index_range(PACKET, None, hit.time, "host")
        if i1 == 0:
            return 0.0, hit.data["text"]
        t = r.read_rows(PACKET, ["device_time"], i1 - 1, i1, with_time=False)["device_time"]
        return float(t[0]) - r.origin("device"), hit.data["text"]


# ---------------------------------------------------------------------- comparison
def compare(rows: list[dict[str, Any]], spec: AnalysisSpec,
            matrix: dict[str, list[Any]]) -> tuple[list[dict[str, Any]], list[str]]:
    """One cell per (group value, compared value): the figures of its log and, relative
    to the baseline's cell of the same group, their ratio and change in %."""
    notes: list[str] = []
    tagged = [r for r in rows if r["run"]]

    def values(key: str) -> list[Any]:
        if key in matrix:
            return list(matrix[key])
        return list(dict.fromkeys(r["variables"].get(key) for r in tagged if key in r["variables"]))

    groups = values(spec.group_by) if spec.group_by else [None]
    compared = values(spec.compare)
    cells: list[dict[str, Any]] = []
    for g in groups:
        members = [r for r in tagged if g is None or r["variables"].get(spec.group_by) == g]
        chosen: dict[int, dict[str, Any] | None] = {}
        for i, c in enumerate(compared):
            mine = [r for r in members if r["variables"].get(spec.compare) == c]
            good = [r for r in mine if not r["error"]]
            # a valid log first: a repeat that clipped must not hide one that measured
            good.sort(key=lambda r: not row_valid(r))
            chosen[i] = good[0] if good else (mine[0] if mine else None)
            if len(mine) > 1:
                notes.append(f"{len(mine)} logs for {spec.compare} = {label(c)}"
                             + (f", {spec.group_by} = {label(g)}" if g is not None else "")
                             + f": the first {'readable ' if good else ''}one is compared")
        base_i = next((i for i, c in enumerate(compared) if c == spec.baseline), None)
        base = chosen.get(base_i) if base_i is not None else None
        for i, c in enumerate(compared):
            cells.append(_cell(chosen[i], base, g, c, i == base_i))
    return cells, notes


def _cell(row: dict[str, Any] | None, base: dict[str, Any] | None, group: Any, value: Any,
          is_baseline: bool) -> dict[str, Any]:
    cell: dict[str, Any] = {"group": label(group) if group is not None else "all",
                            "group_value": group, "compare": label(value), "compare_value": value,
                            "baseline": is_baseline, "run": None, "run_status": "", "log": "",
                            "window_s": None, "error": "", "valid": False, "invalid_reason": "",
                            "excluded_fraction": None, "baseline_valid": None,
                            "baseline_invalid_reason": ""}
    notes: list[str] = []
    if row is None:
        notes.append("no log")
        cell["invalid_reason"] = "no log"
    else:
        cell.update(run=row["run"], run_status=row["run_status"], log=Path(row["file"]).name,
                    window_s=window_seconds(row), error=row["error"], valid=row_valid(row),
                    invalid_reason=invalid_reason(row),
                    excluded_fraction=finite(row["metrics"].get("excluded_fraction")))
    if base is not None:
        cell.update(baseline_valid=row_valid(base), baseline_invalid_reason=invalid_reason(base))
    figures = row["metrics"] if row is not None and not row["error"] else {}
    basefig = base["metrics"] if base is not None and not base["error"] else {}
    # ratios only between two measurements: an invalid run (or baseline) is named, not ranked
    comparable = cell["valid"] and (is_baseline or bool(cell["baseline_valid"]))
    for key in COMPARED:
        v, b = finite(figures.get(key)), finite(basefig.get(key))
        cell[key] = v
        ratio = None
        if comparable and is_baseline and v is not None and v != 0:
            ratio = 1.0
        elif comparable and v is not None and b is not None and b != 0:
            ratio = v / b
        cell[f"{key}_ratio"] = ratio
        cell[f"{key}_change_pct"] = None if ratio is None else (ratio - 1.0) * 100.0
    missing = [what for key, (what, _) in COMPARED.items() if row is not None and not row["error"]
               and cell[key] is None]
    if missing:
        notes.append(f"no {', '.join(missing)} (the log's row says why)")
    if row is not None and not row["error"] and not cell["valid"]:
        notes.append(f"not valid: {cell['invalid_reason']} - not compared")
    elif not is_baseline and row is not None and not row["error"] and base is not None \
            and not base["error"] and not cell["baseline_valid"]:
        notes.append(f"the baseline's run is not valid ({cell['baseline_invalid_reason']}): "
                     f"no ratio")
    if not is_baseline and row is not None and not row["error"]:
        if base is None or base["error"]:
            notes.append("no baseline figures in this group: " + ("the baseline's log could not be "
                                                                   "scored" if base else "no baseline log"))
        else:
            lacking = [what for key, (what, _) in COMPARED.items()
                       if cell[key] is not None and finite(basefig.get(key)) in (None, 0.0)]
            if lacking:
                notes.append(f"the baseline has no (or a zero) {', '.join(lacking)}")
            w, wb = window_seconds(row), window_seconds(base)
            if w is not None and wb is not None and abs(w - wb) > WINDOW_TOLERANCE * max(w, wb):
                notes.append(f"windows differ ({w:.3g} s vs the baseline's {wb:.3g} s): energies "
                             f"are totals over unequal times")
    cell["mode_share"] = finite(figures.get("mode_share"))
    cell["mode_band_hz"] = figures.get("mode_band_hz")
    cell["mode_frequency_hz"] = finite(figures.get("mode_frequency_hz"))
    cell["mode_dominates"] = bool(figures.get("mode_dominates"))
    if cell["mode_dominates"]:
        notes.append(mode_text(cell))
    if row is not None and row["run_status"] not in ("completed", ""):
        notes.append(f"run {row['run']} {row['run_status'].split(':')[0]}")
    cell["note"] = "; ".join(notes)
    return cell


# ---------------------------------------------------------------------- words
def label(value: Any) -> str:
    """A matrix value as the tables show it: a file by its name without extension."""
    if isinstance(value, str):
        return Path(value).stem or value
    if isinstance(value, float) and value.is_integer():
        return f"{value:g}"
    return str(value)


def describe(variables: dict[str, Any]) -> str:
    shown = {k: v for k, v in variables.items() if not k.endswith("_stem")}
    return ", ".join(f"{k}={label(v)}" for k, v in shown.items())


def group_text(spec: AnalysisSpec, group: str, *, under: bool = False) -> str:
    if not spec.group_by:
        return "" if under else "all runs"
    return f"{'under ' if under else ''}{spec.group_by} {group}"


def csv_variable(key: str, fixed: set[str]) -> str:
    return f"matrix_{key}" if key in fixed else key


def finite(v: Any) -> float | None:
    return float(v) if isinstance(v, (int, float)) and not isinstance(v, bool) and math.isfinite(v) else None


def num(v: Any) -> str:
    return "n/a" if finite(v) is None else f"{v:.4g}"


def unit(v: Any, name: str) -> str:
    return "n/a" if finite(v) is None else f"{v:.4g} {name}"


def pct(v: Any) -> str:
    return "n/a" if finite(v) is None else f"{v:+.0f} %"


def window_seconds(row: dict[str, Any]) -> float | None:
    m = row["metrics"]
    a, b = finite(m.get("from_s")), finite(m.get("to_s"))
    return None if a is None or b is None else b - a


def seconds(row: dict[str, Any]) -> str:
    w = window_seconds(row)
    return "n/a" if w is None else f"{w:.3g}"


def cell_text(cell: dict[str, Any]) -> str:
    if cell["error"]:
        return f"ERROR {cell['error']}"
    if cell["note"] == "no log":
        return "no log"
    parts = []
    for key, (what, unit) in COMPARED.items():
        s = f"{what} {num(cell[key])}" + (f" {unit}" if cell[key] is not None else "")
        if not cell["baseline"] and cell[f"{key}_change_pct"] is not None:
            s += f" ({pct(cell[f'{key}_change_pct'])})"
        parts.append(s)
    text = ", ".join(parts) + (" (baseline)" if cell["baseline"] else "")
    return text + (f" - {cell['note']}" if cell["note"] else "")


def row_valid(row: dict[str, Any]) -> bool:
    """A row whose window is a measurement: scored without error and `valid` (its
    excluded fraction within the limit)."""
    return not row["error"] and row["metrics"].get("valid") is True


def invalid_reason(row: dict[str, Any]) -> str:
    """Why a row is not valid ('' if it is)."""
    if row["error"]:
        return f"not scored: {row['error']}"
    if row["metrics"].get("valid") is True:
        return ""
    return str(row["metrics"].get("invalid_reason") or "no validity figure")


def mode_text(figures: dict[str, Any]) -> str:
    """'jitter dominated by the loop's mode at 22.8 Hz (82 % of its variance in
    21.7-23.9 Hz)' from a row's figures or a cell ('' without a mode check)."""
    share, band, f = (finite(figures.get("mode_share")), figures.get("mode_band_hz"),
                      finite(figures.get("mode_frequency_hz")))
    if share is None or not band or f is None:
        return ""
    where = f"{share * 100:.0f} % of its variance in {band[0]:.3g}-{band[1]:.3g} Hz"
    if figures.get("mode_dominates"):
        return f"jitter dominated by the loop's lightly damped mode at {f:.3g} Hz ({where})"
    return f"mode check: {where} (the loop's mode at {f:.3g} Hz)"


def mode_sentence(cell: dict[str, Any], where: str) -> str:
    """'inertial_design1 under base_motion BM2: jitter dominated by ... - a limit cycle of
    the loop, not base-motion rejection' ('' when the mode does not dominate)."""
    if not cell.get("mode_dominates"):
        return ""
    return (f"{cell['compare']}" + (f" {where}" if where else "")
            + f": {mode_text(cell)} - a limit cycle of the loop, not base-motion rejection")


def validity_sentence(cell: dict[str, Any], baseline: str, where: str) -> str:
    """'open_loop under base_motion BM2: not valid, 52 % of the window off the
    autocollimator's range ...' for a cell left out of the comparison ('' otherwise)."""
    head = f"{cell['compare']}" + (f" {where}" if where else "")
    if cell["note"] == "no log" or cell["error"]:
        return ""
    if not cell["valid"]:
        return f"{head}: not valid, {cell['invalid_reason']} - not ranked"
    if not cell["baseline"] and cell["baseline_valid"] is False:
        return (f"{head}: no comparison, the baseline {baseline} is not valid "
                f"({cell['baseline_invalid_reason']})")
    return ""


def verdict(cell: dict[str, Any], baseline: str, where: str) -> str:
    """'relative_design2 cuts jitter by 80 % and energy by 97 % vs relative_design1 under
    ref 0.0001' ('' when a figure is missing, or either run is not valid).  Jitter is the
    reference's metric, the high-pass RMS over the integration period; the standard
    deviation (said so) only where the window has no settled high-pass figure."""
    j, e = cell.get("highpass_rms_urad_change_pct"), cell["energy_total_j_change_pct"]
    jitter = "jitter"
    if j is None:
        j, jitter = cell["std_urad_change_pct"], "jitter (std)"
    if j is None or e is None:
        return ""

    def verb(change: float) -> str:
        return "leaves" if round(change) == 0 else "cuts" if change < 0 else "raises"

    def what(change: float, name: str) -> str:
        return f"{name} unchanged (within 1 %)" if round(change) == 0 else f"{name} by {abs(change):.0f} %"
    if verb(j) == verb(e):              # "cuts jitter by 60 % and energy by 95 %"
        words = f"{verb(j)} {what(j, jitter)} and {what(e, 'energy')}"
    else:
        words = f"{verb(j)} {what(j, jitter)} and {verb(e)} {what(e, 'energy')}"
    return f"{cell['compare']} {words} vs {baseline}" + (f" {where}" if where else "")


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


__all__ = ["COMPARED", "CampaignMetrics", "campaign_metrics", "compare", "invalid_reason", "label",
           "mark_start", "mode_sentence", "mode_text", "output_paths", "row_valid", "run_design",
           "score_log", "validity_sentence", "write_metrics"]
