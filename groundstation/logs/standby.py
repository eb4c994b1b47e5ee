"""A log writer process started before its recording: a campaign's next writer warms up
while the current run records.

Starting a writer costs a fresh interpreter importing numpy, h5py and the codec - about
as long as a whole short run on the fast simulator (docs/campaigns.md, "Whole
campaigns").  A `WriterStandby` keeps one spare writer spawned ahead: the process has
done its imports and waits for the recording it will write (the file's path and the
recording's settings, sent when the recording starts).  Each recording still has a
writer process of its own, as without a standby - the isolation that protects the link
and the operator's program from HDF5's failures is unchanged; only the wait moves out
of the way.

A spare whose parent disappears ends by itself (it checks its parent while waiting); a
spare found dead when wanted is replaced by an ordinary start.
"""

from __future__ import annotations

import contextlib
import multiprocessing as mp
import os
import threading
from dataclasses import dataclass
from typing import Any

#: how often a waiting spare looks whether its parent is still there, s
PARENT_CHECK_S = 0.5


@dataclass
class SpareWriter:
    """A spawned writer process waiting for its recording, with the queues it will use."""

    proc: Any
    inbox: Any
    outbox: Any
    orders: Any            # the sending end of the pipe its recording's settings go down
    queue_blocks: int

    def discard(self) -> None:
        """End the spare unused and free its queues.  Killed, not asked: it holds no
        file and no data, and may still be importing (it would read the request only
        after that), so nobody waits for it."""
        with contextlib.suppress(OSError):
            self.orders.close()
        if self.proc.pid is not None:
            if self.proc.is_alive():
                self.proc.kill()
            self.proc.join(5)
        for q in (self.inbox, self.outbox):
            q.close()
            q.cancel_join_thread()


class WriterStandby:
    """Keeps one spare writer spawned ahead.  `take()` hands it over (and spawns the
    next one); `close()` ends the one waiting.  Thread-safe."""

    def __init__(self, queue_blocks: int = 20000) -> None:
        self.queue_blocks = queue_blocks
        self._spare: SpareWriter | None = None
        self._lock = threading.Lock()
        self._closed = False
        #: spares spawned, and spares handed to a recording (figures for the tests and
        #: the benchmark)
        self.spawned = 0
        self.used = 0

    def prepare(self) -> None:
        """Spawn a spare now if none waits (returns at once: it warms up by itself)."""
        with self._lock:
            if self._spare is None and not self._closed:
                self._spare = self._spawn()

    def take(self, queue_blocks: int) -> SpareWriter | None:
        """The spare, if one waits, is alive and fits (its queue's size); a new spare is
        spawned for the recording after this one.  None: start a writer the usual way."""
        with self._lock:
            if self._closed:
                return None
            spare, self._spare = self._spare, None
            if spare is not None and (not spare.proc.is_alive() or spare.queue_blocks != queue_blocks):
                spare.discard()
                spare = None
            self._spare = self._spawn()
            if spare is not None:
                self.used += 1
            return spare

    def close(self) -> None:
        with self._lock:
            self._closed = True
            spare, self._spare = self._spare, None
        if spare is not None:
            spare.discard()

    def _spawn(self) -> SpareWriter:
        from .recorder import _terminal_interrupt_held
        from .writer import spare_writer_main

        ctx = mp.get_context("spawn")
        inbox = ctx.Queue(maxsize=self.queue_blocks)
        outbox = ctx.Queue()
        orders_in, orders_out = ctx.Pipe(duplex=False)
        proc = ctx.Process(target=spare_writer_main, name="gs-log-writer", daemon=True,
                           args=(inbox, outbox, orders_in, os.getpid()))
        with _terminal_interrupt_held():        # as every writer: SIGINT held until ignored
            proc.start()
        orders_in.close()                       # the child's end
        self.spawned += 1
        return SpareWriter(proc, inbox, outbox, orders_out, self.queue_blocks)
