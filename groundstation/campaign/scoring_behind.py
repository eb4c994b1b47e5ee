"""A campaign's logs scored while the next run records: each recording is handed over as
soon as it ends (CampaignRunner's `on_recording`), and one worker thread scores its logs
(scoring.py, exactly as at the end) behind the runs; `campaign_metrics` then takes each
row from here instead of scoring it again.

    behind = ScoringBehind(campaign)
    runner = CampaignRunner(campaign, tb, on_recording=behind.submit)
    report = runner.run()
    metrics = campaign_metrics(report, campaign, scored=behind)
    behind.close()

Why a thread, not a process: the campaign process has imported numpy and h5py already,
the thread imports the rest (scipy.signal, the analysis) as soon as it is made - while
the session starts and waits for the simulator's child - and a log's scoring is mostly
numpy and HDF5 reads, which let the recording's own thread run; a process would pay a
fresh interpreter's imports (about a CPU-second) for tens of milliseconds of work per log.

A row is scored with its run's status left empty (it is known only when the campaign
ends); `take` hands back the row and its reference results and the caller fills the
status in.  A log whose scoring here failed in a way scoring.py does not turn into a
row is scored again at the end; a log the report lists but that never came through
here (a resumed campaign's earlier runs) is scored at the end too.  After the last
recording the campaign makes, the thread also imports matplotlib's Agg canvas, which the
charts at the end need, while the session closes (not earlier: an import holds the
interpreter's lock for a fifth of a second, which would stall a run).
"""

from __future__ import annotations

import contextlib
import json
import logging
from concurrent.futures import Future, ThreadPoolExecutor
from pathlib import Path
from typing import Any

from .model import Campaign
from .scoring import score_log_with_results

log = logging.getLogger(__name__)

Key = tuple[str, int, str, "int | None", str]


def row_key(path: str | Path, run: int, variables: dict[str, Any], recording: str,
            part: int | None) -> Key:
    """What identifies one scored log: its file, its run and matrix values, its recording
    and part (the values as JSON, so that a list or a float compares as written)."""
    return (str(path), int(run), str(recording), part,
            json.dumps(variables, sort_keys=True, default=str))


class ScoringBehind:
    """One worker thread scoring a campaign's logs as their recordings end."""

    def __init__(self, campaign: Campaign):
        self._spec = campaign.analysis
        self._campaign = campaign.name
        self._design_dir = campaign.path.parent
        self._pool: ThreadPoolExecutor | None = ThreadPoolExecutor(
            1, thread_name_prefix="campaign-scoring")
        self._scored: dict[Key, Future] = {}
        #: recordings still to come before the charts' imports are worth doing: they hold
        #: the interpreter's lock for a fifth of a second, which would stall a run
        self._recordings_to_come = sum(s.action == "start_recording" for s in campaign.steps)
        #: how many rows `take` handed back scored here (the rest were scored at the end)
        self.taken = 0
        # scoring's imports (scipy.signal, the analysis, the log reader: 0.4 s) at once,
        # while the session starts and waits for the simulator's child; the first log
        # handed over would otherwise pay them in the middle of the next run
        self._pool.submit(import_scoring)

    def submit(self, recording: dict[str, Any]) -> None:
        """A recording that ended, as the report will list it (files, name, run,
        variables): its logs queued for scoring.  Never raises: what cannot be queued
        is scored at the end."""
        pool = self._pool
        if pool is None:
            return
        files = [str(f) for f in recording.get("files", [])]
        run = int(recording.get("run", 0) or 0)
        variables = dict(recording.get("variables", {}))
        name = str(recording.get("name", ""))
        try:
            for part, f in enumerate(files, 1):
                numbered = part if len(files) > 1 else None
                key = row_key(f, run, variables, name, numbered)
                self._scored[key] = pool.submit(
                    score_log_with_results, f, self._spec, self._campaign, run, variables,
                    recording=name, part=numbered, run_status="", design_dir=self._design_dir)
            self._recordings_to_come -= 1
            if self._recordings_to_come == 0:
                pool.submit(_import_charts)
        except RuntimeError:                 # the pool shut down under us: scored at the end
            log.debug("scoring behind: %s not queued", files)

    def take(self, path: str | Path, run: int, variables: dict[str, Any], recording: str,
             part: int | None) -> tuple[dict[str, Any], dict[str, Any]] | None:
        """(row, reference results) of a log scored here (waiting for it if it is still
        being scored), its run status empty; None when it was not, or failed here."""
        future = self._scored.pop(row_key(path, run, variables, recording, part), None)
        if future is None:
            return None
        try:
            scored = future.result()
        except Exception:                    # scored again at the end, where it is said
            log.exception("scoring %s behind the campaign", path)
            return None
        self.taken += 1
        return scored

    def close(self) -> None:
        """Drop what is still queued and let the log being scored finish (tens of
        milliseconds; a long log's a few seconds).  Idempotent."""
        pool, self._pool = self._pool, None
        self._scored.clear()
        if pool is not None:
            pool.shutdown(wait=True, cancel_futures=True)


def import_scoring() -> None:
    """What scoring.py imports when it scores a log; a failure here is scoring's own, said
    where a log is scored."""
    with contextlib.suppress(ImportError):
        from ..analysis import analyze_log  # noqa: F401
        from ..logs import LogReader  # noqa: F401


def _import_charts() -> None:
    """The charts' imports (report_figures draws on matplotlib's Agg canvas), done while
    the campaign still runs; a failure here is the charts' own, said where they are drawn."""
    with contextlib.suppress(ImportError):
        import matplotlib.backends.backend_agg  # noqa: F401
        import matplotlib.figure  # noqa: F401


__all__ = ["ScoringBehind", "row_key"]
