"""One campaign log scored: its window found (from a mark step, for a duration),
`analyze_log` over it, and the reference metrics the [analysis] table names; whatever
goes wrong is the row's error, never an exception.  A row is a dict: run, its status,
recording, file, part, matrix values, window, figures, notes, error (campaign_metrics
collects them; comparison.py compares them).

Where the window starts.  A mark step writes an event (source "script") to the log's
journal, stamped with the host's clock; frames carry both clocks.  The window starts at
the device time of the last HIGH_RATE frame the host had received when the mark was
written - the device time the rig had reached at the mark (within one frame on the
simulator, within the link's latency on a rig).
"""

from __future__ import annotations

import logging
from pathlib import Path
from typing import Any

from ..core.errors import GroundStationError
from .comparison import WINDOW_TOLERANCE
from .model import AnalysisSpec
from .reading import run_names

log = logging.getLogger(__name__)

PACKET = "HIGH_RATE"


def make_row(recording: str, file: str, part: int | None, run: int, variables: dict[str, Any],
             status: str, *, window: dict[str, Any] | None = None,
             metrics: dict[str, Any] | None = None, notes: str = "",
             error: str = "") -> dict[str, Any]:
    """A campaign-metrics row (the fields a row has, empty where not given)."""
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
    return score_log_with_results(path, spec, campaign, run, variables, recording=recording,
                                  part=part, run_status=run_status, design_dir=design_dir)[0]


def score_log_with_results(path: str | Path, spec: AnalysisSpec, campaign: str = "",
                           run: int = 0, variables: dict[str, Any] | None = None, *,
                           recording: str = "", part: int | None = None, run_status: str = "",
                           design_dir: Path | None = None
                           ) -> tuple[dict[str, Any], dict[str, Any]]:
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
        return make_row(recording, str(path), part, run, variables, run_status, window=window,
                        notes="; ".join(notes), error=str(exc).strip() or type(exc).__name__), \
            isinstance(exc, LogError)
    except Exception as exc:            # a log this code did not foresee: a row, not a crash
        log.exception("scoring %s", path)
        return make_row(recording, str(path), part, run, variables, run_status, window=window,
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
    return make_row(recording, str(path), part, run, variables, run_status, window=window,
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


__all__ = ["PACKET", "make_row", "mark_start", "mark_text", "run_design", "score_log",
           "score_log_with_results"]
