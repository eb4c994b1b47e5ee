"""The function-generator controller's worker: one thread runs the queued jobs one at a
time, in the order asked (a VISA session is not thread-safe, and the instrument must see
settings in the order the operator gave them).  No Qt and no instrument here.

A job is `job(epoch)`: a callable given the abort count at the time it was queued.
* `submit` queues a job behind the others (ignored once the queue is closing);
* `preempt` jumps the queue: every job not started yet is dropped (an "output on" queued
  before an abort must never run after it), a job under way stops at its next `guard`,
  and the given job runs next;
* `close` drops what is queued, runs one last job and stops the thread, bounded in time.

What a job's run has to say goes to three callbacks given at construction (the
controller wires them to its signals): `busy(action)` ("" when idle), `info(text)` and
`failed(action, message)`.
"""

from __future__ import annotations

import itertools
import logging
import queue
import threading
from typing import Callable

from ...core.errors import GroundStationError

# the controller's logger, as the worker's messages always were
log = logging.getLogger("groundstation.gui.generator.controller")

Job = Callable[[int], None]


class _Cancelled(Exception):
    """An abort came while the job waited or between two of its steps."""


class JobQueue:
    def __init__(self, *, busy: Callable[[str], None], info: Callable[[str], None],
                 failed: Callable[[str, str], None]):
        self._busy, self._info, self._failed = busy, info, failed
        #: held for every change of the queue, the epoch and `closing` (the controller's
        #: resource listing takes it too)
        self.lock = threading.Lock()
        self._queue: queue.PriorityQueue = queue.PriorityQueue()
        self._order = itertools.count()
        self.epoch = 0                       # incremented by every abort
        self.closing = False
        self._worker: threading.Thread | None = None
        self._pending = 0                    # jobs queued or under way

    def submit(self, action: str, job: Job) -> None:
        with self.lock:
            if self.closing:
                return
            self._put((1, next(self._order), self.epoch, action, job))
            self._ensure_worker()

    def preempt(self, action: str, job: Job, *, even_closing: bool = False) -> None:
        """Drop every job not started yet, make a job under way stop at its next guard,
        and run `job` next (once closing, only if `even_closing`)."""
        with self.lock:
            self.epoch += 1
            self._drain()
            if self.closing and not even_closing:
                return
            self._put((0, next(self._order), self.epoch, action, job))
            self._ensure_worker()

    def close(self, action: str, job: Job, timeout: float) -> None:
        """Take no more jobs, drop those not started, run `job` last (if the worker
        runs) and wait up to `timeout` for the worker to finish."""
        with self.lock:
            self.closing = True
            self.epoch += 1
            self._drain()
            worker = self._worker
            if worker is not None and worker.is_alive():
                self._put((0, next(self._order), self.epoch, action, job))
                self._put((9, next(self._order), self.epoch, "stop", None))
        if worker is not None:
            worker.join(timeout)
            if worker.is_alive():
                log.error("generator: the worker did not finish within %g s", timeout)

    def _put(self, item: tuple) -> None:
        """Queue a job (caller holds self.lock); counted until it has run or been dropped."""
        if item[4] is not None:
            self._pending += 1
        self._queue.put(item)

    def idle(self) -> bool:
        """Nothing queued and nothing under way (for scripts and tests)."""
        with self.lock:
            return self._pending == 0

    def _ensure_worker(self) -> None:
        if self._worker is None or not self._worker.is_alive():
            self._worker = threading.Thread(target=self._run, name="gs-fg", daemon=True)
            self._worker.start()

    def _run(self) -> None:
        while True:
            priority, _, epoch, action, job = self._queue.get()
            if job is None:
                return
            try:
                if priority > 0 and epoch != self.epoch:
                    log.info("generator: %s dropped (aborted before it started)", action)
                    continue
                self._busy(action)
                try:
                    job(epoch)
                except _Cancelled:
                    self._info(f"{action} stopped by the abort")
                except GroundStationError as exc:
                    self._failed(action, str(exc))
                except Exception as exc:   # a backend's own exception: report, keep serving
                    log.exception("generator job %s", action)
                    self._failed(action, f"{type(exc).__name__}: {exc}")
                finally:
                    self._busy("")
            finally:
                with self.lock:
                    self._pending -= 1

    def guard(self, epoch: int) -> None:
        """Between the steps of a job: stop if an abort came meanwhile."""
        if epoch != self.epoch:
            raise _Cancelled()

    def _drain(self) -> None:
        """Drop every job not started yet (caller holds self.lock)."""
        while True:
            try:
                item = self._queue.get_nowait()
            except queue.Empty:
                return
            if item[4] is not None:
                self._pending -= 1
