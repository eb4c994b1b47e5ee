"""Many logs, one row each: the per-log task of `groundstation analyze FOLDER --table OUT`.

    paths = find_logs(["logs/inertial_bm", "logs/2026-*/*.h5"])
    known = campaign_index(paths)                  # campaign reports beside the logs
    rows = run_serial(paths, BatchOptions())       # or batch_dask.run_dask(...)

`analyze_one(path, options, known)` is the whole task: it opens the log with h5py (through
LogReader, in bounded chunks: never the whole file), reads who the run was (campaign,
design, base motion, seed) and computes the metrics with the same adapters and the same
row code as the single-log CLI (batch_rows.py).  It never raises: a log that is corrupt,
half-written or not a log becomes a row whose `error` says why, so one bad file of
thousands costs one row, not the job.  The serial loop and the Dask workers call this
same function with the same arguments, which is what makes their tables equal.
"""

from __future__ import annotations

import contextlib
import glob
import json
import logging
import os
import re
from dataclasses import dataclass
from pathlib import Path
from typing import Any, Callable, Iterable

from ..core.errors import GroundStationError
from .batch_rows import EXTRA_METRICS, ROW_KEYS, extra_results, log_row
from .validity import MAX_EXCLUDED_FRACTION

log = logging.getLogger(__name__)

#: who the run was; `bytes` is the file's size (what a year of logs costs on disk)
IDENTITY_KEYS = ["path", "log", "bytes", "campaign", "campaign_run", "test_name", "run",
                 "design", "base_motion", "profiles", "seed", "created_utc", "clean_close"]
#: the columns of the batch table: identity, then the figures of the single-log CLI
TABLE_KEYS = IDENTITY_KEYS + [k for k in ROW_KEYS if k not in IDENTITY_KEYS]

_SEED_IN_TEXT = re.compile(r"\bseed\s*[=:]?\s*(\d+)\b", re.IGNORECASE)
_BASE_MOTION_ON = re.compile(r"^base motion (\S+) on$")


@dataclass(frozen=True)
class BatchOptions:
    """What to compute for every log (the `groundstation analyze` options that apply)."""

    metrics: tuple[str, ...] = ("jitter", "energy", "psd")
    start_s: float | None = None
    stop_s: float | None = None
    sensor: str = "autocollimator"
    integration_period_s: float = 1.0
    psd_segment_s: float = 10.0
    #: a testbed file overriding each log's own (a path: workers load it themselves)
    testbed: str | None = None
    frf_input: str = "current_coarse"
    frf_output: str = "encoder_outer"
    #: a window with more than this excluded is not valid (analysis/validity.py)
    max_excluded_fraction: float = MAX_EXCLUDED_FRACTION
    #: the mode check's design: "auto" (the log's last upload), a file, None (no check)
    design: str | None = "auto"


# ------------------------------------------------------------------------ which logs
def find_logs(patterns: Iterable[str | Path]) -> list[Path]:
    """The .h5 files named by `patterns`: a folder (its logs, recursively), a glob (its
    .h5 matches), or a file (as named); each once, sorted, absolute (a remote worker
    must be able to open them)."""
    found: set[Path] = set()
    for pattern in patterns:
        p = Path(pattern)
        if p.is_dir():
            found.update(q for q in p.rglob("*.h5") if q.is_file())
        elif glob.has_magic(str(pattern)):
            for name in glob.glob(str(pattern), recursive=True):
                q = Path(name)
                # a glob's matches that are not logs (report.json beside them) are skipped
                found.update(q.rglob("*.h5") if q.is_dir() else [q] if q.suffix == ".h5" else [])
        else:
            found.add(p)                 # even if missing: its row will say so
    return sorted(q.absolute() for q in found)


def campaign_index(paths: Iterable[Path]) -> dict[str, dict[str, Any]]:
    """{log path: {campaign, campaign_run, design, base_motion, seed}}: campaign_reports()
    without the files it skipped."""
    return campaign_reports(paths)[0]


def campaign_reports(paths: Iterable[Path]
                     ) -> tuple[dict[str, dict[str, Any]], list[tuple[Path, str]]]:
    """({log path: {campaign, campaign_run, design, base_motion, seed}}, skipped) from the
    campaign reports (`campaign run` writes report.json beside its logs) in the logs'
    folders; `skipped` is each other .json file there with why it is not a report, for
    the caller to note (a folder of logs holds other JSON too - exports, notes, tools').

    A log does not record which campaign it belongs to, nor the matrix values of its run;
    the report does.  Read once in the driver, passed to each task (a few hundred bytes)."""
    index: dict[str, dict[str, Any]] = {}
    skipped: list[tuple[Path, str]] = []
    for folder in sorted({Path(p).parent for p in paths}):
        for report in sorted(folder.glob("*.json")):
            try:
                entries = _report_entries(report)
            except _NotAReport as exc:
                skipped.append((report, str(exc)))
                continue
            for name, ident in entries:
                # a report lists where the log was written; the folder may have moved
                index[str(folder / name)] = ident
    return index, skipped


class _NotAReport(Exception):
    """A .json file beside the logs that is not a campaign report (the message says why)."""


def _report_entries(report: Path) -> list[tuple[str, dict[str, Any]]]:
    """(log file name, identity) of each log a campaign report lists; _NotAReport if the
    file is not one.  The layout is campaign/report.py's CampaignReport (asdict): this
    checks the fields read here, with their types, since anything may sit in a folder
    of logs.  (The analysis package does not import campaign/: campaign imports it.)"""
    try:
        data = json.loads(report.read_text())
    except OSError as exc:
        raise _NotAReport(f"cannot be read ({exc.strerror or exc})") from None
    except (ValueError, RecursionError) as exc:     # not UTF-8, not JSON, absurdly nested
        raise _NotAReport(f"not JSON ({str(exc)[:80]})") from None
    if not isinstance(data, dict):
        raise _NotAReport(f"a JSON {type(data).__name__}, not a campaign report's object")
    missing = [k for k in ("campaign", "file", "started", "recordings") if k not in data]
    if missing:
        raise _NotAReport(f"no {', '.join(repr(k) for k in missing)}: not a campaign report")
    if not isinstance(data["campaign"], str) or not isinstance(data["recordings"], list):
        raise _NotAReport("'campaign' is not text or 'recordings' not a list: not a campaign "
                          "report")
    # the simulator's seed of the whole campaign (report.setup, written by `campaign run`)
    # when the matrix does not vary it: the table's seed column was all NA without it
    setup = data.get("setup") if isinstance(data.get("setup"), dict) else {}
    campaign_seed = setup.get("seed")
    entries = []
    for i, rec in enumerate(data["recordings"], 1):
        files = rec.get("files", []) if isinstance(rec, dict) else None
        variables = (rec.get("variables") or {}) if isinstance(rec, dict) else None
        run = rec.get("run") if isinstance(rec, dict) else None
        if (not isinstance(files, list) or not all(isinstance(f, str) for f in files)
                or not isinstance(variables, dict)
                or not (run is None or isinstance(run, int) and not isinstance(run, bool))):
            raise _NotAReport(f"recording {i} is not a campaign report's (a run number, "
                              f"its files' names, its variables)")
        v = variables
        seed = v.get("seed", campaign_seed)
        ident = {"campaign": data["campaign"], "campaign_run": run,
                 "design": _text_or_none(v.get("design_stem", v.get("design"))),
                 "base_motion": _text_or_none(v.get("base_motion_stem", v.get("base_motion"))),
                 "seed": seed if isinstance(seed, int) and not isinstance(seed, bool) else None}
        entries += [(Path(f).name, ident) for f in files]
    return entries


def _text_or_none(value: Any) -> str | None:
    """A matrix value as the table's text column holds it (a report's value is a name)."""
    return None if value is None else str(value)


# ------------------------------------------------------------------------ one log
def run_identity(path: str | Path, known: dict[str, Any] | None = None) -> dict[str, Any]:
    """Who the run of the log at `path` was, from its root attributes and journal; a
    campaign report's values (`known`) win where the log cannot say (campaign, run) or
    where the log's own record is ambiguous (a settle step may upload a recentring
    design before the run's own; an open-loop run uploads none).  Raises LogError."""
    from ..logs import LogReader
    from ..logs.opening import attr_text

    known = known or {}
    with LogReader(path) as r:
        a = r.attrs
        design = base_motion = seed = None
        profiles: list[str] = []
        for rec in r.journal(["parameter_table", "event", "profile"]):
            d = rec.data if isinstance(rec.data, dict) else {}
            # the source of an upload names its design file, then notes in parentheses
            source = str(d.get("source", "")).split(" (")[0]
            if rec.kind == "parameter_table" and source.endswith(".toml"):
                design = Path(source).stem                         # the last design uploaded
            elif rec.kind == "event" and d.get("source") == "generator":
                m = _BASE_MOTION_ON.match(str(d.get("text", "")))
                base_motion = m.group(1) if m else base_motion
            elif rec.kind == "profile" and d.get("action") == "played":
                profiles.append(str(d.get("name", "")))
            if isinstance(d.get("seed"), int):
                seed = d["seed"]
        notes = attr_text(a.get("notes", ""))
        if seed is None and (m := _SEED_IN_TEXT.search(notes)):
            seed = int(m.group(1))                      # a seed stated in the notes
        return {
            "campaign": known.get("campaign") or "",
            "campaign_run": known.get("campaign_run"),
            "test_name": attr_text(a.get("test_name", "")),
            "run": int(a.get("run", 0)),
            "design": known.get("design") or design or "",
            "base_motion": known.get("base_motion") or base_motion or "",
            "profiles": ",".join(dict.fromkeys(profiles)),
            "seed": known.get("seed") if known.get("seed") is not None else seed,
            "created_utc": attr_text(a.get("created_utc", "")),
            "clean_close": bool(a.get("clean_close", False)),
        }


def analyze_one(path: str | Path, options: BatchOptions = BatchOptions(),
                known: dict[str, Any] | None = None) -> dict[str, Any]:
    """The table row of one log (TABLE_KEYS): its identity and its figures, or its
    error.  Never raises: the batch must outlive any one bad file."""
    from .log_metrics import analyze_log

    path = Path(path)
    row: dict[str, Any] = dict.fromkeys(TABLE_KEYS)
    row.update(path=str(path), log=path.name, notes="", error="")
    try:
        with contextlib.suppress(OSError):      # a missing file: LogReader says it better
            row["bytes"] = path.stat().st_size
        row.update(run_identity(path, known))
        metrics = tuple(m for m in options.metrics if m not in EXTRA_METRICS)
        extras = tuple(m for m in options.metrics if m in EXTRA_METRICS)
        m, error = None, ""
        if metrics:
            try:
                m = analyze_log(path, metrics=metrics, start_s=options.start_s,
                                stop_s=options.stop_s, sensor=options.sensor,
                                integration_period_s=options.integration_period_s,
                                testbed=options.testbed, psd_segment_s=options.psd_segment_s,
                                design=options.design)
            except GroundStationError as exc:
                error = str(exc)
        ex = {} if error else extra_results(path, extras, start_s=options.start_s,
                                            stop_s=options.stop_s, frf_input=options.frf_input,
                                            frf_output=options.frf_output,
                                            testbed=options.testbed)
        figures = log_row(path, m, error, ex, max_excluded_fraction=options.max_excluded_fraction)
        if m is not None and m.missing_metrics:          # as the CLI's exit status 1
            figures["error"] = "; ".join(filter(None, [
                figures["error"], f"not computed: {', '.join(m.missing_metrics)} (see notes)"]))
        for k, v in figures.items():
            if k not in ("path", "log") and (k not in IDENTITY_KEYS or row[k] is None):
                row[k] = v
    # a damaged file can fail in h5py or numpy with anything, not only our LogError; the
    # row keeps the type so an unexpected failure is told from a known damage
    except GroundStationError as exc:
        row["error"] = str(exc)
    except Exception as exc:                             # noqa: BLE001 (see above)
        log.debug("analysing %s failed", path, exc_info=True)
        row["error"] = f"{type(exc).__name__}: {exc}"
    return row


def error_row(path: str | Path, error: str) -> dict[str, Any]:
    """The row of a log whose task could not run at all (its worker died)."""
    path = Path(path)
    row: dict[str, Any] = dict.fromkeys(TABLE_KEYS)
    row.update(path=str(path), log=path.name, notes="", error=error)
    return row


def run_serial(paths: list[Path], options: BatchOptions = BatchOptions(),
               known: dict[str, dict[str, Any]] | None = None,
               progress: Callable[[int, int], None] | None = None) -> list[dict[str, Any]]:
    """Every log's row, in the order of `paths`, one after the other in this process
    (with glibc's allocator set for it: analysis/allocator.py)."""
    from .allocator import tune_for_batch

    tune_for_batch()
    known = known or {}
    rows = []
    for i, p in enumerate(paths, 1):
        rows.append(analyze_one(p, options, known.get(str(p))))
        if progress is not None:
            progress(i, len(paths))
    return rows


def default_workers() -> int:
    """Local worker processes when none are asked for: one per core (the task is
    single-threaded numpy over compressed HDF5 chunks)."""
    return max(1, os.cpu_count() or 1)


__all__ = ["BatchOptions", "IDENTITY_KEYS", "TABLE_KEYS", "analyze_one", "campaign_index",
           "campaign_reports", "default_workers", "error_row", "find_logs", "run_identity",
           "run_serial"]
