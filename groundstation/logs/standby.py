"""Log writer processes kept ready between recordings: a campaign's next writer warms
up while the current run records, and a writer that ended its recording cleanly writes
the next one.

Starting a writer costs a fresh interpreter importing numpy, h5py and the codec - about
as long as a whole short run on the fast simulator, and a third of a second of CPU
(docs/campaigns.md, "Whole campaigns").  A `WriterStandby` keeps one spare writer
spawned ahead: the process has done its imports and waits for the recording it will
write (the file's path and the recording's settings, sent when the recording starts).

A writer whose recording ended cleanly (its file closed, every block written, the
"stopped" report sent) is handed back and waits for the next recording's settings, so a
campaign of many runs starts its writer processes once, not once a run.  What is not
reused: a writer whose recording failed (a full disk, a failed write: HDF5's state after
it is not trusted), one that was given up on or killed, one that ended.  Those end with
their recording, as without a standby, and the next recording takes a fresh spare - so
the isolation that protects the link and the operator's program from HDF5's failures is
unchanged.

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
#: writers kept waiting at most (the one spawned ahead and one handed back); one more
#: would only hold memory
MAX_WAITING = 2


@dataclass
class SpareWriter:
    """A spawned writer process waiting for its recording, with the queues it will use."""

    proc: Any
    inbox: Any
    outbox: Any
    orders: Any            # the sending end of the pipe its recording's settings go down
    queue_blocks: int
    #: recordings it has written to the end (a writer handed back after a clean stop)
    recordings: int = 0

    def discard(self) -> None:
        """End the waiting writer and free its queues.  Killed, not asked: it holds no
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
            if self.recordings:
                # A writer handed back had read everything up to its Stop, and nothing
                # was put after it: our feeder thread has nothing left and ends at once.
                # Joined, it lets go of the queue's semaphores now (see
                # Recorder._release: no "leaked semaphore" warning at exit).
                q.join_thread()
            else:
                q.cancel_join_thread()


class WriterStandby:
    """Keeps writers waiting for recordings: one spawned ahead, and those handed back
    after a clean stop.  `prepare()` spawns one when none waits, `take()` hands one
    over; `give_back()` returns one; `close()` ends those waiting.
    Thread-safe."""

    def __init__(self, queue_blocks: int = 20000) -> None:
        self.queue_blocks = queue_blocks
        self._waiting: list[SpareWriter] = []      # the newest last
        self._lock = threading.Lock()
        self._closed = False
        #: writers spawned, handed to a recording, and of those, handed over again after
        #: a recording (figures for the tests and the benchmark)
        self.spawned = 0
        self.used = 0
        self.reused = 0

    def waiting_pids(self) -> list[int]:
        """The process ids of the writers waiting, the one `take()` hands over last."""
        with self._lock:
            return [spare.proc.pid for spare in self._waiting]

    def prepare(self) -> None:
        """Spawn a spare now if none waits (returns at once: it warms up by itself)."""
        with self._lock:
            if not self._waiting and not self._closed:
                self._waiting.append(self._spawn())

    def take(self, queue_blocks: int) -> SpareWriter | None:
        """A waiting writer that is alive and fits (its queue's size), the one handed
        back last first: it has certainly finished its imports.  None: start a writer
        the usual way.  The spare for the recording after this one is spawned by
        `prepare()` once this one has started (Recorder.start): spawned here, its
        imports took the CPU the recording's own start was waiting for."""
        with self._lock:
            if self._closed:
                return None
            chosen = None
            while self._waiting and chosen is None:
                spare = self._waiting.pop()
                if spare.proc.is_alive() and spare.queue_blocks == queue_blocks:
                    chosen = spare
                else:
                    spare.discard()
            if chosen is not None:
                self.used += 1
                self.reused += bool(chosen.recordings)
            return chosen

    def give_back(self, spare: SpareWriter) -> None:
        """A writer whose recording has just ended cleanly (Recorder._release), waiting
        for the next one's settings.  Ended instead when the standby is closed or enough
        wait already."""
        spare.recordings += 1
        with self._lock:
            surplus = []
            if self._closed:
                surplus.append(spare)
            else:
                self._waiting.append(spare)
                while len(self._waiting) > MAX_WAITING:
                    surplus.append(self._waiting.pop(0))
        for extra in surplus:
            extra.discard()

    def close(self) -> None:
        with self._lock:
            self._closed = True
            waiting, self._waiting = self._waiting, []
        for spare in waiting:
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
