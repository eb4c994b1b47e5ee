"""The design workbench's worker: the slow views (margins, verdict, linear responses) of
an edited design computed off the GUI thread, one at a time.  No widgets here.

`request(slot, generation, design)` asks for one slot's views; a request replaces any
still waiting for that slot, so a burst of edits computes the first and the last, not
each.  One job runs at a time.  The result comes back on the GUI thread as
sig_done(slot, generation, result, seconds) or sig_failed(slot, generation, message):
the generation says which edit it answers, and the workbench shows it only if that is
still the slot's latest (older answers are dropped; the views stay marked stale until
the latest one arrives).

Where the job runs.  By default in a worker *process* (one, started with "spawn" when
the jobs object is made, so that its imports are done before the first request): the
slow views are mostly small numpy operations that hold the GIL, and on a thread of this
process they slow the GUI thread's own redrawing by two to three times while they run
(benchmarks/bench_workbench.py measures both).  A process needs the design and the
result pickled (a few hundred microseconds).  `processes=False`, or a process that
cannot be started or dies, runs the jobs on a thread instead - the same answers.
"""

from __future__ import annotations

import logging
import multiprocessing
import threading
from concurrent.futures import Future, ProcessPoolExecutor
from concurrent.futures.process import BrokenProcessPool
from typing import Any

from PySide6.QtCore import QCoreApplication, QObject, Qt, Signal

from . import worker

log = logging.getLogger(__name__)


class SlowJobs(QObject):
    sig_done = Signal(int, int, object, float)      # slot, generation, result, seconds
    sig_failed = Signal(int, int, str)              # slot, generation, message
    _sig_result = Signal(int, int, object, str, float)   # any thread -> GUI thread

    def __init__(self, dictionary, parent: QObject | None = None, processes: bool = True):
        super().__init__(parent)
        self._dictionary = dictionary
        self._waiting: dict[int, tuple[int, Any]] = {}
        self._running = False
        self._thread: threading.Thread | None = None
        self._closed = False
        self._pool: ProcessPoolExecutor | None = None
        self._sig_result.connect(self._finished, Qt.ConnectionType.QueuedConnection)
        app = QCoreApplication.instance()
        if app is not None:
            app.aboutToQuit.connect(self.shutdown)
        if processes:
            try:
                self._pool = ProcessPoolExecutor(1, mp_context=multiprocessing.get_context("spawn"),
                                                 initializer=worker.start, initargs=(dictionary,))
                self._pool.submit(worker.ready)            # start it (imports) before the first job
            except (OSError, RuntimeError) as exc:
                log.warning("workbench: no worker process (%s); computing on a thread", exc)
                self._pool = None

    @property
    def uses_process(self) -> bool:
        return self._pool is not None

    @property
    def busy(self) -> bool:
        return self._running or bool(self._waiting)

    def request(self, slot: int, generation: int, design: Any) -> None:
        if self._closed:
            return
        self._waiting[slot] = (generation, design)
        self._start_next()

    def forget(self, slot: int) -> None:
        """Drop a waiting request of `slot` (its design was closed)."""
        self._waiting.pop(slot, None)

    def _start_next(self) -> None:
        if self._running or not self._waiting or self._closed:
            return
        slot = next(iter(self._waiting))
        generation, design = self._waiting.pop(slot)
        self._running = True
        if self._pool is not None:
            try:
                future = self._pool.submit(worker.compute, design)
            except (BrokenProcessPool, RuntimeError) as exc:
                self._lose_pool(exc)
            else:
                future.add_done_callback(lambda f: self._from_process(slot, generation, design, f))
                return
        self._thread = threading.Thread(target=self._on_thread, args=(slot, generation, design),
                                        name=f"workbench-slot{slot + 1}", daemon=True)
        self._thread.start()

    def _on_thread(self, slot: int, generation: int, design: Any) -> None:     # worker thread
        self._emit(slot, generation, *worker.compute(design, self._dictionary))

    def _from_process(self, slot: int, generation: int, design: Any, future: Future) -> None:
        try:
            result = future.result()
        except BrokenProcessPool as exc:        # the process died: this job again, on a thread
            self._emit(slot, generation, None, f"\0lost:{exc}", 0.0, design)
            return
        except Exception as exc:                # e.g. a result that could not be pickled
            result = (None, f"internal error: {type(exc).__name__}: {exc}", 0.0)
        self._emit(slot, generation, *result)

    def _emit(self, slot, generation, result, message, seconds, design=None) -> None:
        try:
            self._sig_result.emit(slot, generation, (result, design), message, seconds)
        except RuntimeError:                    # the object is gone (window closed)
            pass

    def _lose_pool(self, exc) -> None:
        log.warning("workbench: the worker process is gone (%s); computing on a thread", exc)
        pool, self._pool = self._pool, None
        if pool is not None:
            pool.shutdown(wait=False, cancel_futures=True)

    def _finished(self, slot: int, generation: int, payload, message: str, seconds: float) -> None:
        result, design = payload                  # GUI thread
        if self._thread is not None:
            self._thread.join()
            self._thread = None
        self._running = False
        if message.startswith("\0lost:"):
            self._lose_pool(message[6:])
            if slot not in self._waiting:
                self._waiting[slot] = (generation, design)
        elif not self._closed:
            if message:
                self.sig_failed.emit(slot, generation, message)
            else:
                self.sig_done.emit(slot, generation, result, seconds)
        self._start_next()

    def shutdown(self) -> None:
        """Nothing more starts; the job under way (if any) is waited for."""
        self._closed = True
        self._waiting.clear()
        if self._thread is not None:
            self._thread.join()
            self._thread = None
        if self._pool is not None:
            self._pool.shutdown(wait=True, cancel_futures=True)
            self._pool = None
