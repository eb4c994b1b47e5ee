"""The Analysis dock's worker: reading logs and computing their figures off the GUI
thread, the results back as typed Qt signals (one per event).  No widgets here.

Each kind of job (metrics, frf, hysteresis, step, identify, folder) runs on a thread of
its own, one at a time per kind: `start` refuses a second one of the same kind while the
first runs (the panel's button is off meanwhile), so a result always answers the last
request of its kind.  Metrics, FRF, hysteresis and step work through a batch of logs in
turn; a log that fails only fails its entry (the batch lists it with the reason).
Identify takes the logs together (one plant is fitted to all of them), so the logs fail
together too: pipeline.identify's IdentificationError says which and why.  A metrics
batch may also hold the live window: an analysis_live.LiveSnapshot, copied from the
window's store on the GUI thread when the job was asked for, and computed here like
the logs (live_metrics: analyze_log's code on one chunk).  A job ends with exactly one
signal: its result (sig_metrics_done, sig_frf_done, sig_hysteresis_done,
sig_step_done: a Batch; sig_identify_done: an IdentifyResult; sig_logs_found) or
sig_failed(job, message) - or, when cancelled, sig_cancelled(job) and nothing after
it.  The message of a GroundStationError is shown as it is; anything else is a bug,
logged with its traceback to the Python log and reported in one line.

Cancelling.  `cancel(job)` answers at once on the GUI thread: the kind is free again (a
new job of it may start) and whatever the cancelled job still sends is dropped.  Every
worker signal passes through the GUI thread (`_deliver`), which lets through only those
of the job currently holding the kind - so no stale result can arrive, however the
threads interleave.  The worker itself stops at its next check: between logs of a
batch, and for metrics after each chunk analyze_log reads (its on_progress hook); an
FRF, loop or step of one log in flight is computed to its end and thrown away, and so
is an identification (the pipeline has no hook to stop at).
"""

from __future__ import annotations

import logging
import threading
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Callable

import numpy as np
from PySide6.QtCore import QObject, Signal

from ...analysis import log_frf, log_hysteresis, log_window
from ...analysis.log_metrics import analyze_log
from ...analysis.log_step import LogStep, step_from_log
from ...core.errors import GroundStationError
from ...identification.curves import ResponseCurves, response_curves
from ...identification import pipeline
from ...identification.report import as_text, parameter_rows
from ...logs import LogReader
from .live import LiveSnapshot, live_metrics

log = logging.getLogger(__name__)

JOBS = ("metrics", "frf", "hysteresis", "step", "identify", "folder")
#: the kinds that work on the ticked logs (and that Cancel stops): all but identify
#: through a batch, a log at a time; identify on all of them at once
BATCH_JOBS = ("metrics", "frf", "hysteresis", "step", "identify")


class Cancelled(Exception):
    """Raised inside a job's work once its cancel was asked (never leaves this module)."""


@dataclass(frozen=True)
class Batch:
    """The results of the logs asked for, in their order: those computed (and the index
    of each in `requested`, which keeps a log's colour when one before it fails) and
    those that could not be (path, reason).  A metrics batch's entries may be the live
    window (a LiveSnapshot, named by its `.name` as a path is) instead of a path."""

    results: tuple[Any, ...]                  # LogMetrics, LogFrf, LogHysteresis, StepResult
    failures: tuple[tuple[Path | LiveSnapshot, str], ...]
    requested: tuple[Path | LiveSnapshot, ...]
    order: tuple[int, ...] = ()

    def indices(self) -> tuple[int, ...]:
        return self.order or tuple(range(len(self.results)))


MetricsBatch = Batch           # the name the metrics' batch had first


@dataclass(frozen=True, eq=False)
class StepResult:
    """A log's step figures and what to draw: reference and response against the time
    from the step (s), the reference's units (rad)."""

    step: LogStep
    time_s: np.ndarray
    reference: np.ndarray
    response: np.ndarray
    path: Path = field(init=False)

    def __post_init__(self) -> None:
        object.__setattr__(self, "path", self.step.path)


def step_trace(path: Path, step: LogStep, start_s: float | None,
               stop_s: float | None) -> StepResult:
    """The reference and the response (reference - error_angle, as step_from_log takes it)
    over the same window, the time counted from the step."""
    with LogReader(path) as r:
        i0, i1 = r.index_range(log_window.PACKET, start_s, stop_s, relative=True)
        d = r.read_rows(log_window.PACKET, ["reference", "error_angle"], i0, i1)
        origin = r.origin("device")
    ref = np.asarray(d["reference"], dtype=np.float64)
    t = np.asarray(d["device_time"], dtype=np.float64) - origin - step.step_time_s
    return StepResult(step, t, ref, ref - np.asarray(d["error_angle"], dtype=np.float64))


@dataclass(frozen=True, eq=False)
class IdentifyResult:
    """An identification and what the window shows of it, all computed on the worker:
    the parameter rows (report.parameter_rows), the report's text, and each measured
    response with the base and identified models on its bins (curves.response_curves)."""

    identification: pipeline.Identification
    rows: tuple[dict[str, Any], ...]
    curves: tuple[ResponseCurves, ...]
    text: str
    base_path: Path

    @property
    def used_logs(self) -> tuple[Path, ...]:
        return tuple(u.path for u in self.identification.logs if u.used)


class _Job:
    """One job's token: its kind, its thread and whether it was cancelled."""

    def __init__(self, kind: str):
        self.kind = kind
        self.cancelled = threading.Event()
        self.thread: threading.Thread | None = None

    def check(self) -> None:
        if self.cancelled.is_set():
            raise Cancelled


class AnalysisJobs(QObject):
    sig_progress = Signal(str, int, int, str)  # job, logs done, logs in all, what now ("a.h5 40 %")
    sig_metrics_done = Signal(object)         # Batch of LogMetrics
    sig_frf_done = Signal(object)             # Batch of log_frf.LogFrf
    sig_hysteresis_done = Signal(object)      # Batch of log_hysteresis.LogHysteresis
    sig_step_done = Signal(object)            # Batch of StepResult
    sig_identify_done = Signal(object)        # IdentifyResult
    sig_logs_found = Signal(str, object)      # folder, list[Path] of its logs
    sig_failed = Signal(str, str)             # job, why (the error's own message)
    sig_cancelled = Signal(str)               # job
    #: worker -> GUI thread: (the _Job, the public signal's name, its arguments)
    _sig_event = Signal(object, str, object)

    def __init__(self, parent: QObject | None = None):
        super().__init__(parent)
        #: kind -> the job holding it; read and changed on the GUI thread only
        self._current: dict[str, _Job] = {}
        self._threads: list[threading.Thread] = []
        self._closing = False
        self._sig_event.connect(self._deliver)

    # ------------------------------------------------------------------ state
    def busy(self, job: str) -> bool:
        return job in self._current

    def idle(self) -> bool:
        return not self._current

    def running(self) -> tuple[str, ...]:
        return tuple(k for k in JOBS if k in self._current)

    def cancel(self, job: str) -> bool:
        """Stop the job of this kind (False: none runs); sig_cancelled(job) at once."""
        token = self._current.pop(job, None)
        if token is None:
            return False
        token.cancelled.set()
        self.sig_cancelled.emit(job)
        return True

    def join(self, timeout: float = 5.0) -> bool:
        """Wait (bounded) for every worker thread, cancelled ones too; True if all ended."""
        for t in list(self._threads):
            t.join(timeout)
        self._threads = [t for t in self._threads if t.is_alive()]
        return not self._threads

    def shutdown(self, timeout: float = 5.0) -> None:
        """No more signals; the jobs under way told to stop and waited for (bounded)."""
        self._closing = True
        for token in self._current.values():
            token.cancelled.set()
        self._current.clear()
        self.join(timeout)

    # ------------------------------------------------------------------ the jobs
    def metrics(self, paths: list[Path | LiveSnapshot], **options) -> bool:
        """analyze_log on each path in turn (options: sensor, integration_period_s,
        start_s, stop_s, testbed); progress after each chunk it reads.  A LiveSnapshot
        among them is the live window: live_metrics with the same sensor, period and
        testbed (its span is its own; start_s / stop_s are the logs')."""
        def compute(job: _Job, path, i: int, n: int):
            if isinstance(path, LiveSnapshot):
                return live_metrics(path, **{k: v for k, v in options.items() if k in (
                    "sensor", "integration_period_s", "testbed")})

            def progress(frames: int, total: int) -> None:
                job.check()
                self._post(job, "sig_progress", "metrics", i, n,
                           f"{path.name} {100 * frames // max(total, 1)} %")
            return analyze_log(path, on_progress=progress, **options)
        return self._batch("metrics", paths, compute)

    def frf(self, paths: list[Path], **options) -> bool:
        """log_frf.frf_from_log of each path (options: its keyword arguments)."""
        return self._batch("frf", paths, lambda job, p, i, n: log_frf.frf_from_log(p, **options))

    def hysteresis(self, paths: list[Path], **options) -> bool:
        """log_hysteresis.hysteresis_from_log of each path (options: its keyword arguments)."""
        return self._batch("hysteresis", paths,
                           lambda job, p, i, n: log_hysteresis.hysteresis_from_log(p, **options))

    def step(self, paths: list[Path], start_s: float | None = None,
             stop_s: float | None = None) -> bool:
        """log_step.step_from_log of each path, with its reference and response to draw."""
        def compute(job: _Job, path: Path, i: int, n: int) -> StepResult:
            res = step_from_log(path, start_s, stop_s)
            job.check()
            return step_trace(path, res, start_s, stop_s)
        return self._batch("step", paths, compute)

    def identify(self, paths: list[Path], base: Path, **options) -> bool:
        """pipeline.identify of the logs together on the base testbed file (options:
        band_hz, min_coherence), then the rows and curves the window draws."""
        paths = [Path(p) for p in paths]

        def work(job: _Job):
            self._post(job, "sig_progress", "identify", 0, len(paths),
                       f"responses of {len(paths)} log(s), plant fit on {Path(base).name}")
            try:
                result = pipeline.identify(paths, base, **options)
                job.check()
                self._post(job, "sig_progress", "identify", len(paths), len(paths),
                           "the models on the measured bins")
                curves = tuple(response_curves(result))
            except GroundStationError as exc:      # IdentificationError among them
                return "sig_failed", ("identify", str(exc))
            job.check()
            return "sig_identify_done", (IdentifyResult(
                result, tuple(parameter_rows(result)), curves, as_text(result), Path(base)),)
        return self._start("identify", work)

    def folder(self, folder: Path) -> bool:
        """The logs in a folder and below (a campaign's), as sig_logs_found."""
        def work(job: _Job):
            try:
                found = log_window.find_logs(folder)
            except GroundStationError as exc:
                return "sig_failed", ("folder", str(exc))
            return "sig_logs_found", (str(folder), found)
        return self._start("folder", work)

    # ------------------------------------------------------------------ plumbing
    def _batch(self, kind: str, paths, compute: Callable[[_Job, Path, int, int], Any]) -> bool:
        paths = tuple(p if isinstance(p, LiveSnapshot) else Path(p) for p in paths)
        done_signal = f"sig_{kind}_done"

        def work(job: _Job):
            results, order, failures = [], [], []
            n = len(paths)
            for i, path in enumerate(paths):
                job.check()
                self._post(job, "sig_progress", kind, i, n, path.name)
                try:
                    result = compute(job, path, i, n)
                except Cancelled:
                    raise
                except GroundStationError as exc:
                    failures.append((path, str(exc)))
                except Exception as exc:     # a bug: said for this log, the rest go on
                    log.exception("%s of %s", kind, path)
                    failures.append((path, f"{type(exc).__name__}: {exc}"))
                else:
                    results.append(result)
                    order.append(i)
            job.check()
            return done_signal, (Batch(tuple(results), tuple(failures), paths, tuple(order)),)
        return self._start(kind, work)

    def _start(self, kind: str, work: Callable[[_Job], tuple[str, tuple]]) -> bool:
        """Run `work` on a thread of its own; it returns the name and arguments of its
        last signal.  False (nothing started) while a job of the kind runs or after
        shutdown."""
        if self._closing or kind in self._current:
            return False
        job = _Job(kind)

        def run() -> None:
            try:
                name, args = work(job)
            except Cancelled:
                return
            except Exception as exc:          # a bug in the job itself
                log.exception("analysis job %s", kind)
                name, args = "sig_failed", (kind, f"{type(exc).__name__}: {exc}")
            self._post(job, name, *args)

        job.thread = threading.Thread(target=run, name=f"gs-analysis-{kind}", daemon=True)
        self._current[kind] = job
        self._threads = [t for t in self._threads if t.is_alive()] + [job.thread]
        job.thread.start()
        return True

    def _post(self, job: _Job, name: str, *args) -> None:
        """From a worker: one signal, to be delivered on the GUI thread if still wanted."""
        if self._closing or job.cancelled.is_set():
            return
        try:
            self._sig_event.emit(job, name, args)
        except RuntimeError:        # the panel (and this object) went while the job ran
            pass

    def _deliver(self, job: _Job, name: str, args: tuple) -> None:
        """On the GUI thread: only the job holding its kind speaks; its last signal frees
        the kind first, so the slot it reaches may start the next job of the kind."""
        if self._closing or self._current.get(job.kind) is not job:
            return
        if name != "sig_progress":
            del self._current[job.kind]
        getattr(self, name).emit(*args)


__all__ = ["AnalysisJobs", "BATCH_JOBS", "Batch", "IdentifyResult", "JOBS", "MetricsBatch",
           "StepResult", "step_trace"]
