"""The log writer process: receives frames and journal records, writes the HDF5 file.

Why a process and not a thread: HDF5 does all its work under the interpreter lock, and
after a failed write (disk full, file too large, device gone) its library state is not
trustworthy - we have seen it crash the interpreter on the way out.  In its own process
the writer cannot stall the link or the GUI, and whatever happens to it, the operator's
program keeps running; what it flushed stays valid on disk (SWMR ordering).

Frames travel as the bytes received (78 bytes a HIGH_RATE frame) and are decoded here
with the same codec, so nothing heavier than the wire format crosses the pipe.
"""

from __future__ import annotations

import contextlib
import os
import queue
import resource
import shutil
import signal
import time
from pathlib import Path
from typing import Any

import numpy as np

from ..codec import FrameCodec
from ..core.dictionary import load_dictionary
from .h5file import LogFile
from .messages import (Closed, Failed, Flushed, Frames, JournalEntry, Started, StartFailed, Stop,
                       Stopped)


def ignore_terminal_interrupt() -> None:
    """SIGINT and SIGTERM ignored in this process (the writer: see writer_main).  The
    recorder spawns the writer with SIGINT blocked (recorder._terminal_interrupt_held);
    it is unblocked here, once ignored, so a Ctrl-C held meanwhile is discarded."""
    try:
        signal.signal(signal.SIGINT, signal.SIG_IGN)
        signal.signal(signal.SIGTERM, signal.SIG_IGN)
    except ValueError:          # not the main thread of the process: nothing to do here
        return
    signal.pthread_sigmask(signal.SIG_UNBLOCK, {signal.SIGINT})


def _explain(exc: BaseException, path: Path) -> str:
    from .recorder import explain_error
    return explain_error(exc, path)


def writer_main(inbox, outbox, protocol_dir: str, config: dict[str, Any]) -> None:
    """Entry point of the writer process (multiprocessing 'spawn')."""
    # Ctrl-C in a terminal, or a SIGTERM to the process group (a service manager, `kill
    # -TERM -PGID`), reaches the writer too.  It must not die of it: the parent decides
    # how the recording ends and tells it to close ("stop"); if the parent is gone, the
    # writer notices (_Writer.receive) and closes the file itself.
    ignore_terminal_interrupt()
    _write_recording(inbox, outbox, protocol_dir, config)


def spare_writer_main(inbox, outbox, orders, parent_pid: int) -> None:
    """Entry point of a spare writer (standby.py): spawned ahead, its imports done, it
    waits for a recording's settings on `orders` and writes it as writer_main does.  A
    recording that ended cleanly sends it back to waiting for the next one; one that
    failed ends it.  A closed pipe (the standby discarded it) or a parent gone ends it
    waiting."""
    ignore_terminal_interrupt()
    # the niceness each recording asks for is counted from the parent's, as os.nice in a
    # writer of its own counts it, not added again per recording
    inherited = os.getpriority(os.PRIO_PROCESS, 0)
    clean = True
    while clean:
        order = _next_order(orders, parent_pid)
        if order is None:
            return
        protocol_dir, config = order
        niceness = inherited + (config.get("writer_niceness") or 0)
        clean = _Writer(inbox, outbox, load_dictionary(protocol_dir), config, niceness).run()
    _exit_once_reported(outbox, 0)


def _next_order(orders, parent_pid: int):
    """The next recording's (protocol folder, settings), or None once the pipe closed or
    the parent is gone."""
    from .standby import PARENT_CHECK_S

    while True:
        try:
            if orders.poll(PARENT_CHECK_S):
                return orders.recv()
        except (EOFError, OSError):
            return None
        if os.getppid() != parent_pid:
            return None


def _lower_priority(niceness: int) -> None:
    """This process's niceness raised to `niceness` (never lowered: that needs a
    privilege; then, or where it is not permitted, it runs as it is)."""
    with contextlib.suppress(OSError):
        if niceness > os.getpriority(os.PRIO_PROCESS, 0):
            os.setpriority(os.PRIO_PROCESS, 0, niceness)


def _write_recording(inbox, outbox, protocol_dir: str, config: dict[str, Any]) -> None:
    niceness = os.getpriority(os.PRIO_PROCESS, 0) + (config.get("writer_niceness") or 0)
    _Writer(inbox, outbox, load_dictionary(protocol_dir), config, niceness).run()
    _exit_once_reported(outbox, 0)


def _exit_once_reported(outbox, code: int) -> None:
    """End the process once the last report queued has reached the pipe, without the
    interpreter's teardown of numpy and h5py, which the recorder would otherwise wait
    out at every stop (a few hundred ms on a busy machine)."""
    outbox.close()
    outbox.join_thread()
    os._exit(code)


class _Writer:
    """One recording in the writer process: the open file, what waits to be written to
    it, and whether (and why) the recording is ending."""

    def __init__(self, inbox, outbox, dictionary, config: dict[str, Any], niceness: int) -> None:
        self.inbox, self.outbox, self.config = inbox, outbox, config
        self.niceness = niceness            # taken once the file is open (run)
        self.dictionary = dictionary
        self.codec = FrameCodec(dictionary)
        self.parent = os.getppid()
        self.lf: LogFile | None = None
        self.run_number: int = config["run"]
        self.blocks: list = []
        self.journal: list = []
        self.stopping = False
        self.stop_reason = ""

    def open_file(self, path: Path, run: int) -> LogFile:
        """A new log file at `path`, its first journal record written and flushed."""
        config = self.config
        f = LogFile(path, self.dictionary, test_name=config["test_name"], run=run,
                    notes=config["notes"], testbed_text=config["testbed_text"],
                    testbed_name=config["testbed_name"], testbed_path=config["testbed_path"],
                    compression=config.get("compression"), chunk_rows=config.get("chunk_rows"))
        f.journal([(time.time(), "recorder", {"action": "started", "file": path.name,
                                              "run": run, "test_name": config["test_name"]}, b"")])
        f.flush()
        return f

    def run(self) -> bool:
        """Open the first file, then alternate receiving and writing until the recording
        ends; True when it ended cleanly (the file closed, "stopped" reported)."""
        # the recorder created this file, empty and exclusively (reserve_log_path), for this
        # writer alone: LogFile's truncating create of it overwrites nothing
        path = Path(self.config["path"])
        try:
            self.lf = self.open_file(path, self.run_number)
        except Exception as exc:
            self.outbox.put(StartFailed(f"cannot create log file: {_explain(exc, path)}"))
            return False
        # the priority is lowered only now: the recording's start waits for the file, and
        # a niced writer creating it on a core the simulator's start or the next spare's
        # imports contend for took 0.17 s instead of 0.02 s (docs/campaigns.md, "Seventh round")
        _lower_priority(self.niceness)
        self.outbox.put(Started(str(path)))
        interval = self.config["flush_interval_s"]
        next_flush = time.monotonic() + interval
        while not self.stopping:
            self.receive(next_flush)
            if time.monotonic() < next_flush and not self.stopping:
                continue
            next_flush = time.monotonic() + interval
            if self.stop_if_space_short():
                return False
            if self.write_pending():
                return True
        return False

    def receive(self, next_flush: float) -> None:
        """Take what arrives until the next flush is due, a stop is asked, or the parent
        is gone."""
        try:
            # the queue running empty ends this turn: the flush is due or nothing more came
            with contextlib.suppress(queue.Empty):
                msg = self.inbox.get(timeout=max(0.0, next_flush - time.monotonic()))
                while not self.take(msg):
                    msg = self.inbox.get_nowait()
        except (EOFError, OSError):        # the parent went away: finish cleanly
            self.stopping = True
            self.stop_reason = self.stop_reason or "the recording program's queue closed"
        if os.getppid() != self.parent:    # parent killed: keep what we have, close cleanly
            self.stopping = True
            self.stop_reason = (self.stop_reason
                                or "the recording program ended without closing the log")

    def take(self, msg) -> bool:
        """Queue one message's frames or journal record; True for a stop."""
        if isinstance(msg, Frames):
            pkt = self.codec.packet(msg.packet_id)
            data, host = msg.data, msg.host_time
            if pkt.variable_item is None:
                arr = np.frombuffer(data, np.uint8).reshape(len(host), -1)
                self.blocks.append(self.codec.decode_fixed(pkt, arr, host))
            else:
                self.blocks.append(self.codec.decode_variable(pkt, data, host))
        elif isinstance(msg, JournalEntry):
            self.journal.append((msg.at, msg.kind, msg.record, msg.blob))
        elif isinstance(msg, Stop):
            self.stopping = True
            self.stop_reason = msg.reason
            return True
        return False

    def stop_if_space_short(self) -> bool:
        """Close the file and report the failure if the next write might not fit; True
        when it did."""
        lf = self.lf
        short = _space_short(lf, self.blocks, self.journal)
        if not short:
            return False
        # stop while the file can still be closed properly: a write that fails for
        # want of space can leave HDF5's end-of-file pointer past the real end
        try:
            lf.journal([(time.time(), "recorder", {"action": "stopped", "reason": short}, b"")])
            lf.flush()
            lf.close(clean=True)
        except Exception:   # the margin was not enough after all; the flushed part stands
            pass
        self.outbox.put(Failed(short, lf.last_host_time, lf.frames_written))
        return True

    def write_pending(self) -> bool:
        """Write and flush what waits, then close the file if stopping or roll over to
        the next one if due; True when the recording has ended."""
        lf = self.lf
        try:
            lf.append(self.blocks)
            if self.stopping:
                closing = {"action": "stopped", "frames": lf.frames_written}
                if self.stop_reason:
                    closing["reason"] = self.stop_reason
                self.journal.append((time.time(), "recorder", closing, b""))
            lf.journal(self.journal)
            lf.flush()
            self.blocks, self.journal = [], []
            self.outbox.put(Flushed(lf.frames_written, lf.size_bytes, lf.last_host_time,
                                    str(lf.path)))
            if self.stopping:
                lf.close(clean=True)
                self.outbox.put(Stopped(lf.frames_written, str(lf.path)))
                return True
            if _rollover_due(lf, self.config):
                self.roll_over()
        except Exception as exc:
            # no close, no cleanup: after a failed write HDF5 may crash while closing; the
            # flushed part of the file is already safe on disk
            self.exit_failed(_explain(exc, self.lf.path), self.lf.last_host_time,
                             self.lf.frames_written)
        return False

    def roll_over(self) -> None:
        """Close the current file and continue the recording in the next one."""
        lf = self.lf
        lf.journal([(time.time(), "recorder", {"action": "rollover"}, b"")])
        lf.close(clean=True)
        self.outbox.put(Closed(lf.frames_written, str(lf.path)))
        following = None
        try:
            # reserved (created exclusively) by this writer, like the first file
            # by the recorder: never a name another recording holds
            following, self.run_number = _next_path(self.config, self.run_number + 1)
            self.lf = self.open_file(following, self.run_number)
        except Exception as exc:
            # the closed file keeps everything; the new one holds nothing of the
            # recording and is this writer's own: it goes
            if following is not None:
                _remove_own_file(following)
            why = _explain(exc, following or Path(self.config["folder"]) / "(next file)")
            # as after a failed write: HDF5's state after a failed create is not trusted
            self.exit_failed(f"could not start the next file after {lf.path.name}: {why}",
                             lf.last_host_time, 0)
        self.outbox.put(Started(str(following)))

    def exit_failed(self, why: str, last_host_time, frames: int) -> None:
        """Report the failure and end the process at once, without closing the file."""
        self.outbox.put(Failed(why, last_host_time, frames))
        _exit_once_reported(self.outbox, 3)


SPACE_MARGIN = 256 * 1024     # bytes kept free for metadata, chunk rounding and the close
EXPANSION = 5                  # file bytes per frame byte, worst case (columns, raw, frames)


def _space_short(lf: LogFile, blocks: list, journal: list) -> str:
    """Why the next write might not fit (empty string: it fits)."""
    pending = sum(b.raw.nbytes if b.raw is not None else sum(map(len, b.frames)) for b in blocks)
    need = EXPANSION * pending + sum(len(r[3]) + 512 for r in journal) + SPACE_MARGIN
    try:
        free = shutil.disk_usage(lf.path.parent).free
    except OSError:
        return ""
    if free < need:
        return f"disk nearly full ({free / 1e6:.1f} MB free) writing {lf.path}"
    soft, _ = resource.getrlimit(resource.RLIMIT_FSIZE)
    if soft != resource.RLIM_INFINITY and soft - lf.size_bytes < need:
        return f"file size limit ({soft / 1e6:.1f} MB) nearly reached writing {lf.path}"
    return ""


def _rollover_due(lf: LogFile, config: dict[str, Any]) -> bool:
    if config["rollover_bytes"] is not None and lf.size_bytes >= config["rollover_bytes"]:
        return True
    return config["rollover_seconds"] is not None and time.time() - lf.created >= config["rollover_seconds"]


def _next_path(config: dict[str, Any], run: int) -> tuple[Path, int]:
    """The next file of a rollover, created exclusively (recorder.reserve_log_path):
    run `run` or, if another recording took that name, the next free one."""
    from .recorder import reserve_log_path
    return reserve_log_path(config["folder"], config["test_name"], config["template"], run)


def _remove_own_file(path: Path) -> None:
    from .recorder import remove_own_file
    remove_own_file(path)
