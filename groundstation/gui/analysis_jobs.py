"""The Analysis dock's worker: reading logs and computing their figures off the GUI
thread, the results back as typed Qt signals (one per event).  No widgets here.

Each kind of job (metrics, frf, hysteresis, folder) runs on a thread of its own, one at
a time per kind: `start` refuses a second one of the same kind while the first runs
(the panel's button is off meanwhile), so a result always answers the last request of
its kind.  A job ends with exactly one signal: its result (sig_metrics_done,
sig_frf_done, sig_hysteresis_done, sig_logs_found) or sig_failed(job, message).  The
message of a GroundStationError is shown as it is; anything else is a bug, logged with
its traceback to the Python log and reported in one line.
"""

from __future__ import annotations

import logging
import threading
from dataclasses import dataclass
from pathlib import Path
from typing import Any, Callable

from PySide6.QtCore import QObject, Signal

from ..analysis import log_identification as ident
from ..errors import GroundStationError

log = logging.getLogger(__name__)

JOBS = ("metrics", "frf", "hysteresis", "folder")


@dataclass(frozen=True)
class MetricsBatch:
    """The metrics of the logs asked for, in their order: those computed and those that
    could not be (path, reason)."""

    results: tuple[Any, ...]                  # LogMetrics
    failures: tuple[tuple[Path, str], ...]
    requested: tuple[Path, ...]


class AnalysisJobs(QObject):
    sig_progress = Signal(str, str)           # job, what it does now ("metrics 1/2: a.h5")
    sig_metrics_done = Signal(object)         # MetricsBatch
    sig_frf_done = Signal(object)             # log_identification.LogFrf
    sig_hysteresis_done = Signal(object)      # log_identification.LogHysteresis
    sig_logs_found = Signal(str, object)      # folder, list[Path] of its logs
    sig_failed = Signal(str, str)             # job, why (the error's own message)

    def __init__(self, parent: QObject | None = None):
        super().__init__(parent)
        self._threads: dict[str, threading.Thread] = {}
        #: the kinds under way; a job leaves it just before its last signal, so the slot
        #: that signal reaches may start the next one of its kind at once
        self._running: dict[str, threading.Thread] = {}
        self._lock = threading.Lock()
        self._closing = False

    # ------------------------------------------------------------------ state
    def busy(self, job: str) -> bool:
        with self._lock:
            return job in self._running

    def idle(self) -> bool:
        return not any(self.busy(job) for job in JOBS)

    def shutdown(self, timeout: float = 5.0) -> None:
        """No more signals; wait (bounded) for the jobs under way to end."""
        self._closing = True
        for t in list(self._threads.values()):
            t.join(timeout)

    # ------------------------------------------------------------------ the jobs
    def metrics(self, paths: list[Path], **options) -> bool:
        """analyze_log on each path in turn (options: sensor, integration_period_s,
        start_s, stop_s); one MetricsBatch at the end, a log that fails only fails its row."""
        paths = [Path(p) for p in paths]

        def work() -> None:
            from ..analysis import analyze_log
            results, failures = [], []
            for i, path in enumerate(paths, 1):
                self._emit(self.sig_progress, "metrics", f"{i}/{len(paths)}: {path.name}")
                try:
                    results.append(analyze_log(path, **options))
                except GroundStationError as exc:
                    failures.append((path, str(exc)))
                except Exception as exc:       # a bug: said for this log, the rest go on
                    log.exception("metrics of %s", path)
                    failures.append((path, f"{type(exc).__name__}: {exc}"))
            self._finish("metrics", self.sig_metrics_done,
                         MetricsBatch(tuple(results), tuple(failures), tuple(paths)))
        return self._start("metrics", work)

    def frf(self, path: Path, **options) -> bool:
        """log_identification.frf_from_log (options: its keyword arguments)."""
        return self._start("frf", self._single("frf", self.sig_frf_done,
                                               lambda: ident.frf_from_log(path, **options), path))

    def hysteresis(self, path: Path, **options) -> bool:
        """log_identification.hysteresis_from_log (options: its keyword arguments)."""
        return self._start("hysteresis", self._single(
            "hysteresis", self.sig_hysteresis_done,
            lambda: ident.hysteresis_from_log(path, **options), path))

    def folder(self, folder: Path) -> bool:
        """The logs in a folder and below (a campaign's), as sig_logs_found."""
        def work() -> None:
            try:
                found = ident.find_logs(folder)
            except GroundStationError as exc:
                self._finish("folder", self.sig_failed, "folder", str(exc))
                return
            self._finish("folder", self.sig_logs_found, str(folder), found)
        return self._start("folder", work)

    # ------------------------------------------------------------------ plumbing
    def _single(self, job: str, done: Signal, compute: Callable[[], Any], path: Path):
        def work() -> None:
            self._emit(self.sig_progress, job, f"{Path(path).name}")
            try:
                result = compute()
            except GroundStationError as exc:
                self._finish(job, self.sig_failed, job, str(exc))
            except Exception as exc:
                log.exception("%s of %s", job, path)
                self._finish(job, self.sig_failed, job, f"{type(exc).__name__}: {exc}")
            else:
                self._finish(job, done, result)
        return work

    def _start(self, job: str, work: Callable[[], None]) -> bool:
        """Run `work` on a thread of its own; False (nothing started) while a job of the
        same kind runs or after shutdown."""
        def run() -> None:
            try:
                work()
            finally:
                self._release(job)          # whatever happened, the kind is free again

        with self._lock:
            if self._closing or job in self._running:
                return False
            t = threading.Thread(target=run, name=f"gs-analysis-{job}", daemon=True)
            self._running[job] = t
            self._threads[job] = t
        t.start()
        return True

    def _release(self, job: str) -> None:
        """Called on the job's own thread: the kind is free (unless a newer job of the
        kind already holds it)."""
        with self._lock:
            if self._running.get(job) is threading.current_thread():
                del self._running[job]

    def _finish(self, job: str, signal, *args) -> None:
        """The job's last signal, after it has released its kind."""
        self._release(job)
        self._emit(signal, *args)

    def _emit(self, signal, *args) -> None:
        if self._closing:
            return
        try:
            signal.emit(*args)
        except RuntimeError:        # the panel (and this object) went while the job ran
            pass


__all__ = ["AnalysisJobs", "JOBS", "MetricsBatch"]
