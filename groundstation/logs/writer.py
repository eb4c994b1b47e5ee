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
    """SIGINT and SIGTERM ignored in this process (the writer: see writer_main)."""
    try:
        signal.signal(signal.SIGINT, signal.SIG_IGN)
        signal.signal(signal.SIGTERM, signal.SIG_IGN)
    except ValueError:          # not the main thread of the process: nothing to do here
        pass


def _explain(exc: BaseException, path: Path) -> str:
    from .recorder import explain_error
    return explain_error(exc, path)


def writer_main(inbox, outbox, protocol_dir: str, config: dict[str, Any]) -> None:
    """Entry point of the writer process (multiprocessing 'spawn')."""
    # Ctrl-C in a terminal, or a SIGTERM to the process group (a service manager, `kill
    # -TERM -PGID`), reaches the writer too.  It must not die of it: the parent decides
    # how the recording ends and tells it to close ("stop"); if the parent is gone, the
    # writer notices (below) and closes the file itself.
    ignore_terminal_interrupt()
    if config.get("writer_niceness"):
        # not permitted here (OSError): the writer runs at the usual priority
        with contextlib.suppress(OSError):
            os.nice(config["writer_niceness"])
    d = load_dictionary(protocol_dir)
    codec = FrameCodec(d)
    parent = os.getppid()
    lf: LogFile | None = None

    def open_file(path: Path, run: int) -> LogFile:
        f = LogFile(path, d, test_name=config["test_name"], run=run, notes=config["notes"],
                    testbed_text=config["testbed_text"], testbed_name=config["testbed_name"],
                    testbed_path=config["testbed_path"], compression=config.get("compression"),
                    chunk_rows=config.get("chunk_rows"))
        f.journal([(time.time(), "recorder", {"action": "started", "file": path.name,
                                              "run": run, "test_name": config["test_name"]}, b"")])
        f.flush()
        return f

    # the recorder created this file, empty and exclusively (reserve_log_path), for this
    # writer alone: LogFile's truncating create of it overwrites nothing
    path, run = Path(config["path"]), config["run"]
    try:
        lf = open_file(path, run)
    except Exception as exc:
        outbox.put(StartFailed(f"cannot create log file: {_explain(exc, path)}"))
        return
    outbox.put(Started(str(path)))
    blocks: list = []
    journal: list = []
    interval = config["flush_interval_s"]
    next_flush = time.monotonic() + interval
    stopping = False
    stop_reason = ""
    while not stopping:
        try:
            msg = inbox.get(timeout=max(0.0, next_flush - time.monotonic()))
            while True:
                if isinstance(msg, Frames):
                    pkt = codec.packet(msg.packet_id)
                    data, host = msg.data, msg.host_time
                    if pkt.variable_item is None:
                        arr = np.frombuffer(data, np.uint8).reshape(len(host), -1)
                        blocks.append(codec.decode_fixed(pkt, arr, host))
                    else:
                        blocks.append(codec.decode_variable(pkt, data, host))
                elif isinstance(msg, JournalEntry):
                    journal.append((msg.at, msg.kind, msg.record, msg.blob))
                elif isinstance(msg, Stop):
                    stopping = True
                    stop_reason = msg.reason
                    break
                msg = inbox.get_nowait()
        except queue.Empty:
            pass
        except (EOFError, OSError):        # the parent went away: finish cleanly
            stopping = True
            stop_reason = stop_reason or "the recording program's queue closed"
        if os.getppid() != parent:         # parent killed: keep what we have, close cleanly
            stopping = True
            stop_reason = stop_reason or "the recording program ended without closing the log"
        if time.monotonic() < next_flush and not stopping:
            continue
        next_flush = time.monotonic() + interval
        short = _space_short(lf, blocks, journal)
        if short:
            # stop while the file can still be closed properly: a write that fails for
            # want of space can leave HDF5's end-of-file pointer past the real end
            try:
                lf.journal([(time.time(), "recorder", {"action": "stopped", "reason": short}, b"")])
                lf.flush()
                lf.close(clean=True)
            except Exception:   # the margin was not enough after all; the flushed part stands
                pass
            outbox.put(Failed(short, lf.last_host_time, lf.frames_written))
            return
        try:
            lf.append(blocks)
            if stopping:
                closing = {"action": "stopped", "frames": lf.frames_written}
                if stop_reason:
                    closing["reason"] = stop_reason
                journal.append((time.time(), "recorder", closing, b""))
            lf.journal(journal)
            lf.flush()
            blocks, journal = [], []
            outbox.put(Flushed(lf.frames_written, lf.size_bytes, lf.last_host_time, str(lf.path)))
            if stopping:
                lf.close(clean=True)
                outbox.put(Stopped(lf.frames_written, str(lf.path)))
                return
            if _rollover_due(lf, config):
                lf.journal([(time.time(), "recorder", {"action": "rollover"}, b"")])
                lf.close(clean=True)
                outbox.put(Closed(lf.frames_written, str(lf.path)))
                following = None
                try:
                    # reserved (created exclusively) by this writer, like the first file
                    # by the recorder: never a name another recording holds
                    following, run = _next_path(config, run + 1)
                    lf = open_file(following, run)
                except Exception as exc:
                    # the closed file keeps everything; the new one holds nothing of the
                    # recording and is this writer's own: it goes
                    if following is not None:
                        _remove_own_file(following)
                    why = _explain(exc, following or Path(config["folder"]) / "(next file)")
                    outbox.put(Failed(f"could not start the next file after {lf.path.name}: "
                                      f"{why}", lf.last_host_time, 0))
                    outbox.close()
                    outbox.join_thread()
                    os._exit(3)         # as below: HDF5's state after a failed create
                outbox.put(Started(str(following)))
        except Exception as exc:
            last = lf.last_host_time
            outbox.put(Failed(_explain(exc, lf.path), last, lf.frames_written))
            outbox.close()
            outbox.join_thread()
            # no close, no cleanup: after a failed write HDF5 may crash while closing; the
            # flushed part of the file is already safe on disk
            os._exit(3)


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
