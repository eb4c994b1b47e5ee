"""The recorder: telemetry and journal records to HDF5, written by its own process.

Subscribing it to a client (`client.subscribe(recorder)`) costs the link one
`put_nowait` of the frame bytes per block: the disk never slows the link.  The writer
process (writer.py) batches what arrived and writes + flushes every `flush_interval_s`
(0.25 s: at most that much is lost in a crash, half the 0.5 s the log promises).  A
failed write (disk full, file too large, device gone) stops the recording with a
message that says what happened; the file keeps everything up to the last flush, and
the link and everything else go on.
"""

from __future__ import annotations

import contextlib
import errno
import logging
import multiprocessing as mp
import queue
import shutil
import signal
import tempfile
import threading
import time
from dataclasses import dataclass, field
from datetime import datetime
from pathlib import Path
from typing import TYPE_CHECKING, Any, Callable

import numpy as np

from ..codec import TelemetryBlock
from ..core.dictionary import Dictionary
from ..core.errors import GroundStationError
from .atomic import create_new
from .messages import Closed, Failed, Flushed, Frames, JournalEntry, Started, StartFailed, Stop, Stopped
from .schema import JOURNAL_KINDS
from .writer import writer_main

if TYPE_CHECKING:
    from .standby import SpareWriter, WriterStandby

log = logging.getLogger(__name__)

DEFAULT_TEMPLATE = "{date}_{time}_{test}_run{run:03d}.h5"
#: run numbers tried for a free file name before giving up
MAX_RUNS = 10000


class RecorderError(GroundStationError):
    """A recording could not be started or had to stop (the message says why)."""


@dataclass
class RecorderStatus:
    state: str                  # "idle", "recording", "stopped", "failed"
    path: Path | None
    frames: int
    bytes: int
    error: str
    discarded_blocks: int       # blocks that could not be queued (writer too slow or failed)
    files: list[Path]
    removed: list[Path] = field(default_factory=list)   # files of a recording that got nothing
    note: str = ""              # what the operator should know of the files (their removal)


def _file_name(template: str, test_name: str, run: int, now: datetime) -> str:
    safe = "".join(c if c.isalnum() or c in "-_" else "-" for c in test_name) or "test"
    return template.format(date=now.strftime("%Y%m%d"), time=now.strftime("%H%M%S"),
                           test=safe, run=run)


def log_path(folder: str | Path, test_name: str = "test", template: str = DEFAULT_TEMPLATE,
             run: int | None = None) -> tuple[Path, int]:
    """The next file name from the template that is free at this moment (the run number
    counts up from 1).  Only a proposal: another program may take the name a moment
    later - a recording takes its file with reserve_log_path(), which creates it."""
    folder = Path(folder)
    now = datetime.now()
    start = run or 1
    for n in range(start, start + MAX_RUNS):
        path = folder / _file_name(template, test_name, n, now)
        if not path.exists():
            return path, n
    raise RecorderError(f"no free file name for '{template}' in {folder}")


def reserve_log_path(folder: str | Path, test_name: str = "test",
                     template: str = DEFAULT_TEMPLATE, run: int | None = None,
                     now: datetime | None = None) -> tuple[Path, int]:
    """Create the next free log file of the template, empty, and return (path, run).

    The file is created with O_CREAT | O_EXCL, so that of two programs that choose the
    same name at the same moment (two `record --name same` started together: same
    second, same run number) exactly one gets it and the other goes on to the next run
    number.  Checking that a name is free and creating the file later is not enough:
    HDF5 creates with truncation, and its file lock is released once a log switches to
    SWMR mode, so the second program would silently truncate - and corrupt - the log
    the first one is writing.  The empty file belongs to the caller, which turns it
    into the log (LogFile truncates its own empty file) or removes it."""
    folder = Path(folder)
    now = now or datetime.now()
    start = run or 1
    previous = None
    for n in range(start, start + MAX_RUNS):
        path = folder / _file_name(template, test_name, n, now)
        if path == previous:
            # a template without {run}: every run number gives this one taken name
            break
        previous = path
        try:
            if create_new(path):
                return path, n
        except OSError as exc:
            raise RecorderError(f"cannot create the log file: {explain_error(exc, path)}") from None
    raise RecorderError(f"no free file name for '{template}' in {folder}: "
                        f"{_file_name(template, test_name, start, now)} and the names after "
                        "it are taken - choose another --name or folder")


def remove_own_file(path: Path) -> None:
    """Remove a file this recording created (never one another program made: a
    recording's files all come from reserve_log_path)."""
    with contextlib.suppress(FileNotFoundError):
        path.unlink()


def explain_error(exc: BaseException, path: Path) -> str:
    err = getattr(exc, "errno", None)
    text = str(exc)
    if err in (errno.ENOSPC, errno.EDQUOT) or "No space left" in text:
        return f"disk full while writing {path}"
    if err == errno.EFBIG or "File too large" in text:
        return f"file size limit reached while writing {path}"
    if err in (errno.EACCES, errno.EPERM) or "ermission denied" in text:
        return f"permission denied writing {path}"
    if err == errno.ENOENT or "No such file" in text:
        return f"{path.parent} does not exist"
    if err == errno.ENOTDIR or "Not a directory" in text:
        return f"{path.parent} is not a folder (a file of that name is in the way)"
    if err == errno.EROFS:
        return f"{path.parent} is on a read-only file system"
    return f"write to {path} failed ({type(exc).__name__}: {text})"


class Recorder:
    """Records telemetry blocks (call it with each block) and journal records to HDF5.

    The file is written by a separate process (writer.py); this object only queues.
    Callbacks `on_flush(status, last_host_time)` and `on_failure(message)` run in a
    small status thread of this process."""

    def __init__(self, dictionary: Dictionary, folder: str | Path, *, test_name: str = "test",
                 template: str = DEFAULT_TEMPLATE, notes: str = "", testbed_text: str = "",
                 testbed_name: str = "", testbed_path: str = "", flush_interval_s: float = 0.25,
                 rollover_bytes: int | None = None, rollover_seconds: float | None = None,
                 queue_blocks: int = 20000, link_stats: Callable[[], Any] | None = None,
                 on_failure: Callable[[str], None] | None = None,
                 on_flush: Callable[["RecorderStatus", float | None], None] | None = None,
                 compression: dict | None = None, chunk_rows: int | None = None,
                 writer_niceness: int = 0, standby: "WriterStandby | None" = None):
        """`chunk_rows`: rows per HDF5 chunk of the per-frame datasets (None: the
        schema's CHUNK_ROWS, sized for a live link; a fast campaign passes
        schema.FAST_CHUNK_ROWS).  `writer_niceness` (>= 0) lowers the writer process's
        scheduling priority by that much (os.nice): a fast campaign's simulator then
        wins a contended core, and the writer works in what it leaves; the fast clock
        still waits for the writer's queue, so nothing is discarded."""
        if writer_niceness < 0:
            raise ValueError(f"writer_niceness must be >= 0, not {writer_niceness!r}")
        #: a WriterStandby (standby.py) whose spare writer, already started, this
        #: recording takes instead of starting one (a campaign's runs: no wait at start)
        self.standby = standby
        self.d = dictionary
        self.folder = Path(folder)
        self.test_name = test_name
        self.config = {"test_name": test_name, "template": template, "notes": notes,
                       "testbed_text": testbed_text, "testbed_name": testbed_name,
                       "testbed_path": testbed_path, "flush_interval_s": flush_interval_s,
                       "rollover_bytes": rollover_bytes, "rollover_seconds": rollover_seconds,
                       "folder": str(self.folder), "compression": compression,
                       "chunk_rows": chunk_rows, "writer_niceness": writer_niceness}
        self.queue_blocks = queue_blocks
        self.link_stats = link_stats
        self.on_failure = on_failure
        self.on_flush = on_flush
        self.state = "idle"
        self.error = ""
        self.discarded_blocks = 0
        self.refused_blocks = 0        # blocks of packets a log does not hold (COMMAND)
        self.stop_reason = ""
        self.files: list[Path] = []
        self.removed: list[Path] = []
        self.removal_note = ""
        self.path: Path | None = None
        self._journaled = 0            # journal records queued (the recording's content)
        self._frames_closed = 0        # frames in files already rolled over
        self._frames = 0
        self._bytes = 0
        self.last_flushed_host_time: float | None = None
        self._proc = None
        self._inbox = None
        #: the standby's writer this recording took, and whether it has reported this
        #: recording's clean end ("stopped"): then it goes back to the standby
        self._spare: "SpareWriter | None" = None
        self._ended_cleanly = False
        # puts to the writer happen under this lock and only while _accepting: after the
        # Stop nothing more enters the queue, so what is in it is exactly what the writer
        # reads, and its feeder thread can be joined (see _release)
        self._put_lock = threading.Lock()
        self._accepting = False
        self._outbox = None
        self._status_thread: threading.Thread | None = None
        self._stopped = threading.Event()
        self._tmpdir: Path | None = None

    # ------------------------------------------------------------------ control
    def start(self, timeout: float = 60.0) -> Path:
        """Create the first file (reserved here, written by the writer process); raises
        RecorderError if it cannot.  A start that fails leaves nothing behind: no file,
        no writer process, no queue, no temporary folder."""
        if self.state == "recording":
            raise RecorderError("already recording")
        if not self.folder.is_dir():
            try:
                self.folder.mkdir(parents=True, exist_ok=True)
            except OSError as exc:
                raise RecorderError(f"cannot create the log folder: "
                                    f"{explain_error(exc, self.folder / 'x')}") from None
        # created here, exclusively: this recording's own file from the first instant
        path, run = reserve_log_path(self.folder, self.test_name, self.config["template"])
        try:
            msg = self._start_writer(path, run, timeout)
        except BaseException:
            # (a Ctrl-C too) no waiting for a writer that failed: _release kills it, and
            # then nobody has the file open
            self._release(timeout=0.0)
            remove_own_file(path)
            raise
        self.path = Path(msg.path)
        self.files.append(self.path)
        self._journaled = 0
        self.removed = []
        self.removal_note = ""
        self._accepting = True
        self.state = "recording"
        self._stopped.clear()
        self._status_thread = threading.Thread(target=self._watch, name="gs-recorder-status",
                                               daemon=True)
        self._status_thread.start()
        if self.standby is not None:
            # the spare for the next recording, spawned only now that this one has started
            self.standby.prepare()
        return self.path

    def _start_writer(self, path: Path, run: int, timeout: float) -> Started:
        """Spawn the writer on the reserved `path` (or hand it to the standby's spare)
        and wait for its Started."""
        config = {**self.config, "path": str(path), "run": run}
        self._ended_cleanly = False
        protocol_dir = str(self._protocol_dir())
        spare = self.standby.take(self.queue_blocks) if self.standby is not None else None
        if spare is not None:
            try:
                spare.orders.send((protocol_dir, config))
                self._proc, self._inbox, self._outbox = spare.proc, spare.inbox, spare.outbox
                self._spare = spare
            except OSError:                 # it died after take() looked: start one anew
                spare.discard()
                spare = None
        if spare is None:
            ctx = mp.get_context("spawn")
            self._inbox = ctx.Queue(maxsize=self.queue_blocks)
            self._outbox = ctx.Queue()
            self._proc = ctx.Process(target=writer_main, name="gs-log-writer", daemon=True,
                                     args=(self._inbox, self._outbox, protocol_dir, config))
            with _terminal_interrupt_held():        # the child starts with SIGINT held
                self._proc.start()
        deadline = time.monotonic() + timeout
        while True:
            try:
                msg = self._outbox.get(timeout=0.2)
                break
            except queue.Empty:
                pass
            if not self._proc.is_alive():
                code = self._proc.exitcode
                # the usual cause: a script without a main guard, which the writer's
                # spawned interpreter runs again while importing it
                raise RecorderError(
                    f"the log writer process ended at start (exit code {code}); in a script, "
                    "put the code under `if __name__ == \"__main__\":` (Python's rule for "
                    "programs that start processes)") from None
            if time.monotonic() > deadline:
                raise RecorderError(f"the log writer did not start within {timeout} s") from None
        if not isinstance(msg, Started):
            raise RecorderError(msg.message if isinstance(msg, StartFailed) else repr(msg))
        return msg

    def _protocol_dir(self) -> Path:
        """The dictionary's TOML files, as the writer must decode with the same ones."""
        tmp = Path(tempfile.mkdtemp(prefix="gs-protocol-"))
        self._tmpdir = tmp
        for name, text in self.d.source_texts.items():
            (tmp / name).write_text(text, encoding="utf-8")
        return tmp

    def __call__(self, block: TelemetryBlock) -> None:
        """Subscriber entry point: never blocks, never raises."""
        if self.state != "recording" or not len(block):
            return
        if block.packet.direction != "device_to_host":
            # a host-to-device packet (COMMAND) has no place in the log: the link should
            # never pass one on, and if it does the writer must not fall over it
            self.refused_blocks += 1
            return
        if block.raw is not None:
            data: Any = block.raw.tobytes()
        else:
            data = list(block.frames)
        host = np.ascontiguousarray(np.broadcast_to(block.host_time, (len(block),)), dtype=np.float64)
        try:
            self._put(Frames(block.packet.id, data, host))
        except queue.Full:
            self.discarded_blocks += 1

    def _put(self, msg) -> bool:
        """Queue `msg` for the writer without blocking; False once the recording is
        stopping (queue.Full when the writer is behind)."""
        with self._put_lock:
            if not self._accepting:
                return False
            self._inbox.put_nowait(msg)
            return True

    def queue_fill(self) -> float:
        """The share of the queue to the writer in use (0..1; 0 when not recording): a
        producer that can wait (the fast simulator's clock) waits while it is high, so
        no block is ever discarded for a full queue."""
        inbox = self._inbox
        if self.state != "recording" or inbox is None:
            return 0.0
        try:
            return inbox.qsize() / self.queue_blocks
        except (NotImplementedError, OSError, ValueError):  # no sem_getvalue (macOS), closed
            return 0.0

    def record(self, kind: str, record: dict[str, Any], blob: bytes = b"",
               at: float | None = None) -> None:
        """A journal record (command, parameter table, profile, note, ...), any thread."""
        if kind not in JOURNAL_KINDS:
            raise ValueError(f"unknown journal kind {kind!r} (known: {', '.join(JOURNAL_KINDS)})")
        if self.state != "recording":
            return
        try:
            if self._put(JournalEntry(at if at is not None else time.time(), kind,
                                      record, bytes(blob))):
                self._journaled += 1
        except queue.Full:
            self.discarded_blocks += 1

    def note(self, text: str) -> None:
        self.record("note", {"text": text})

    def stop(self, timeout: float = 30.0, reason: str = "") -> RecorderStatus:
        """Write what is queued, close the file cleanly, return the final status.  The
        writer is waited for as long as it makes progress; `timeout` is how long it may
        make none before it is given up on (then the state says so).

        `reason` (e.g. "interrupted by the operator (Ctrl-C)", "session taken over by
        ...") goes into the log's closing journal record, so the file says why it ends.

        A recording that received nothing - no frame, no journal record (a `record`
        whose device refused the connection) - keeps no file: its files are removed,
        and `status().note` (also logged as a warning) says so."""
        was_recording = self.state == "recording"
        if was_recording:
            self.stop_reason = reason
            with self._put_lock:        # a put under way finishes first; none follows
                self._accepting = False
            if self._while_writing(timeout, lambda: self._queue_stop(reason)):
                self._while_writing(timeout, lambda: self._stopped.wait(1.0))
        self._release(timeout)
        if was_recording and self.state == "stopped":
            self._remove_if_empty()
        return self.status()

    def _queue_stop(self, reason: str) -> bool:
        try:
            self._inbox.put(Stop(reason), timeout=1.0)
            return True
        except queue.Full:
            return False

    def _while_writing(self, timeout: float, attempt: Callable[[], bool]) -> bool:
        """Call `attempt` until it returns True; False once the writer has made no
        progress (no block taken off its queue, no frames flushed) for `timeout` s, or
        has ended.  A writer with a long backlog on a busy machine is slow, not stuck:
        a fixed timeout killed one that had half an hour of a one-hour log still to
        write, and that half hour was lost (a 1 h fast recording at load 8)."""
        seen = None
        deadline = time.monotonic() + timeout
        while not attempt():
            if self._stopped.is_set():
                return True
            if self._proc is None or not self._proc.is_alive():
                return False
            progress = (self._frames, self._queued())
            if progress != seen:
                seen, deadline = progress, time.monotonic() + timeout
            elif time.monotonic() >= deadline:
                log.warning("the log writer made no progress for %.0f s: stopping it", timeout)
                return False
        return True

    def _queued(self) -> int:
        """Blocks waiting for the writer; -1 where the queue cannot say (no sem_getvalue
        on macOS, or closed): progress is then judged by the frames flushed alone."""
        try:
            return self._inbox.qsize() if self._inbox is not None else 0
        except (NotImplementedError, OSError, ValueError):
            return -1

    def _release(self, timeout: float) -> None:
        """End the writer process and the status thread, close the queues and remove
        the temporary protocol folder: on every way out, start failures included.
        Dropping the queues frees their named semaphores now (their finalizers unlink
        them), not only at the interpreter's exit."""
        if self._status_thread is not None:
            if self._status_thread is not threading.current_thread():
                self._status_thread.join(timeout)
            self._status_thread = None
        if self._hand_back():
            return
        spare, self._spare = self._spare, None
        if spare is not None:           # ends with its recording: it hears no more orders
            with contextlib.suppress(OSError):
                spare.orders.close()
        if self._proc is not None:
            if self._proc.pid is not None:          # started (a failed start() may not be)
                self._proc.join(timeout)
                self._kill()
            # its sentinel pipe closed now, not left to the GC (ValueError: it survived
            # the kill - then the GC closes it once the process is reaped)
            with contextlib.suppress(ValueError):
                self._proc.close()
            self._proc = None
        with self._put_lock:
            self._accepting = False
        for q in (self._inbox, self._outbox):
            if q is None:
                continue
            q.close()
            if self.state == "stopped":
                # The writer read everything up to the Stop, and nothing followed it: the
                # feeder thread has nothing left to send and ends at once.  Joined here,
                # it drops its references to the queue's semaphores before we drop ours,
                # so they are unlinked and unregistered now, in this thread.  Left to
                # end on its own, the feeder could be the last holder and unlink one
                # while the interpreter exits, before telling multiprocessing's
                # resource tracker: "leaked semaphore" warnings at exit.
                q.join_thread()
            else:
                # a writer that failed or never started may have left the pipe full,
                # and a feeder blocked on it would never end: not waited for
                q.cancel_join_thread()
        self._inbox = self._outbox = None
        self._remove_protocol_dir()

    def _remove_protocol_dir(self) -> None:
        if self._tmpdir is not None:
            shutil.rmtree(self._tmpdir, ignore_errors=True)
            self._tmpdir = None

    def _hand_back(self) -> bool:
        """The standby's writer back to it, waiting for the next recording, when this
        one ended cleanly (its file closed, "stopped" reported: everything put was read
        and nothing follows).  True when handed back; then the queues stay open."""
        spare = self._spare
        if (spare is None or self.standby is None or not self._ended_cleanly
                or not self._proc.is_alive()):
            return False
        with self._put_lock:
            self._accepting = False
        self._spare = self._proc = self._inbox = self._outbox = None
        self._remove_protocol_dir()      # the writer read the dictionary when it started
        self.standby.give_back(spare)
        return True

    def _remove_if_empty(self) -> None:
        """Remove the files of a recording that received nothing (see stop): an empty
        log says only that something else failed, which the caller reports anyway."""
        if self._frames_closed + self._frames or self._journaled:
            return
        for path in self.files:
            remove_own_file(path)
        self.removed = list(self.files)
        self.removal_note = (f"removed {', '.join(str(p) for p in self.files)}: nothing was "
                             "recorded, so no log is kept")
        # info, not warning: every caller shows the note itself (it was printed twice)
        log.info(self.removal_note)

    def _kill(self) -> None:
        if self._proc is not None and self._proc.is_alive():
            self._proc.kill()
            self._proc.join(5)

    def status(self) -> RecorderStatus:
        return RecorderStatus(self.state, self.path, self._frames_closed + self._frames,
                              self._bytes, self.error, self.discarded_blocks, list(self.files),
                              list(self.removed), self.removal_note)

    # ------------------------------------------------------------------ status thread
    def _watch(self) -> None:
        next_stats = time.monotonic() + 1.0
        while True:
            if self.link_stats is not None and time.monotonic() >= next_stats:
                next_stats = time.monotonic() + 1.0
                self.record("link", _link_record(self.link_stats()))
            outbox = self._outbox
            if outbox is None:        # released: a stop that gave up on its writer
                return
            try:
                msg = outbox.get(timeout=0.2)
            except queue.Empty:
                if self._proc is None or self._proc.is_alive():
                    continue
                # It ended.  What it sent first is in the pipe already (a writer flushes
                # its queue before it exits: Stopped, or Failed on a full disk), and may
                # have landed after the wait above gave up: read that before calling the
                # end unexpected
                try:
                    msg = outbox.get(timeout=0.2)
                except (queue.Empty, EOFError, OSError, ValueError):
                    self._failed(f"the log writer process ended unexpectedly (exit code "
                                 f"{self._proc.exitcode})", self.last_flushed_host_time)
                    return
            except (EOFError, OSError, ValueError):     # ValueError: closed meanwhile
                return
            if isinstance(msg, Flushed):
                self._frames, self._bytes, self.last_flushed_host_time = msg.frames, msg.size_bytes, msg.last_host_time
                if self.on_flush is not None:
                    self.on_flush(self.status(), self.last_flushed_host_time)
            elif isinstance(msg, Closed):
                self._frames_closed += msg.frames
                self._frames = 0
            elif isinstance(msg, Started):
                self.path = Path(msg.path)
                self.files.append(self.path)
            elif isinstance(msg, Stopped):
                self._frames = msg.frames
                self._ended_cleanly = True
                self.state = "stopped"
                self._stopped.set()
                return
            elif isinstance(msg, Failed):
                self._failed(msg.message, msg.last_host_time)
                return

    def _failed(self, why: str, last: float | None) -> None:
        when = datetime.fromtimestamp(last).strftime("%H:%M:%S.%f")[:-3] if last else "the start"
        self.error = (f"recording stopped: {why}. The file keeps what was flushed up to "
                      f"{when}; free space or choose another folder and start a new recording "
                      f"- the link is unaffected.")
        self.state = "failed"
        log.error(self.error)
        self._stopped.set()
        if self.on_failure is not None:
            self.on_failure(self.error)


@contextlib.contextmanager
def _terminal_interrupt_held():
    """Block SIGINT in this thread while the writer process is spawned: the child
    inherits the blocked mask, so a Ctrl-C reaches it only once the writer has set SIGINT
    to ignored (writer.ignore_terminal_interrupt unblocks it after that), and never
    interrupts its start-up.  Blocking, not ignoring: a SIGINT that arrives meanwhile is
    held for this process (or taken by another of its threads) and raises
    KeyboardInterrupt once the spawn is done - with SIG_IGN here it was thrown away."""
    held = {signal.SIGINT}
    previous = signal.pthread_sigmask(signal.SIG_BLOCK, held)
    try:
        yield
    finally:
        if signal.SIGINT not in previous:
            signal.pthread_sigmask(signal.SIG_UNBLOCK, held)


def _link_record(snap) -> dict[str, Any]:
    return {"packets": {k: {"frames": v.frames, "dropped": v.dropped, "rate_hz": v.rate_hz}
                        for k, v in snap.packets.items()},
            "framing": snap.framing, "latency_ms_mean": snap.latency_ms_mean,
            "gaps": snap.gap_events[-50:]}
