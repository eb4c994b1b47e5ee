"""Logs compressed in a process of their own: behind a fast campaign at the lowest
priority while the next runs record, or at once for `groundstation log compress`.

A fast session's log writer records without deflate; each log it closed cleanly is
handed here and compressed in place (compress.py: a whole log under its name at every
moment).  Behind a session the process runs at niceness 19 and in the idle scheduling
class: the simulator, the campaign and the writer come first, and the compression takes
what the cores leave (a step waiting on the device, a settle, an upload).  The session
waits for it when it closes - a log the session says it wrote is a compressed one - and
Ctrl-C during that wait stops it: the logs not reached stay as recorded, whole and
readable, and the command that compresses them later is printed.

A subprocess, not a thread: h5py holds the interpreter's lock through its HDF5 calls,
so a thread compressing would stall the campaign's own threads (the link's receiver);
and HDF5 after a failed write may crash rather than raise (a full disk did, measured),
which must not take the session or the command line with it.  A process that dies
leaves the log it was on as recorded: its temporary copy is removed here, the log is
reported failed with the reason, and a new process takes the logs after it.

The process reads one log path per line on stdin and answers one JSON line per log on
stdout; its stdin closing (the session finished, or died) tells it that no more will
come, so it finishes what it was given and ends.
"""

from __future__ import annotations

import contextlib
import json
import os
import signal
import subprocess
import sys
import threading
from pathlib import Path
from typing import Callable

from .atomic import leftovers
from .compress import COMPRESSED, FAILED, CompressOutcome, compress_log

#: the compressing process's niceness behind a session, counted from its parent's
NICENESS = 19
#: how long a stopped (SIGTERM) compression may take to remove its temporary file, s
STOP_WAIT_S = 10.0


class CompressBehind:
    """Hands logs to the compressing process (started with the first one); `finish()`
    waits for it and returns every log's outcome.  `background`: at the lowest
    priority (behind a session), else at the caller's.  Thread-safe."""

    def __init__(self, echo: Callable[[str], None] = print, *, background: bool = True):
        self.echo = echo
        self.background = background
        self._proc: subprocess.Popen | None = None
        self._reader: threading.Thread | None = None
        self._lock = threading.Lock()
        self.submitted: list[Path] = []
        self.outcomes: list[CompressOutcome] = []

    def prepare(self) -> None:
        """Start the process now, ahead of the first log: its imports are done while
        that log records, not at the end of a short campaign."""
        with self._lock:
            if self._proc is None:
                self._start()

    def submit(self, paths) -> None:
        with self._lock:
            for path in map(Path, paths):
                self.submitted.append(path)
                self._send(path)

    def _send(self, path: Path) -> None:
        if self._proc is None:
            self._start()
        try:
            self._proc.stdin.write(f"{path}\n".encode())
            self._proc.stdin.flush()
        except (OSError, ValueError):
            return        # it has ended: finish() hands what it did not answer to a new one

    def _start(self) -> None:
        args = [sys.executable, "-m", "groundstation.logs.compress_behind"]
        self._proc = subprocess.Popen(
            args + (["--background"] if self.background else []),
            stdin=subprocess.PIPE, stdout=subprocess.PIPE, stderr=subprocess.DEVNULL,
            start_new_session=True)       # the terminal's Ctrl-C is its parent's to handle
        self._reader = threading.Thread(target=self._read, args=(self._proc.stdout,),
                                        name="gs-compress-behind", daemon=True)
        self._reader.start()

    def _read(self, stream) -> None:
        for line in stream:
            try:
                o = json.loads(line)
                outcome = CompressOutcome(Path(o["path"]), o["state"], o["before"], o["after"], o["note"])
            except (ValueError, KeyError, TypeError):
                continue
            with self._lock:
                self.outcomes.append(outcome)

    def pending(self) -> list[Path]:
        """Logs handed over whose outcome has not come back, in the order handed over."""
        with self._lock:
            done = {o.path for o in self.outcomes}
            return [p for p in self.submitted if p not in done]

    def finish(self) -> list[CompressOutcome]:
        """No more logs: wait until those handed over are compressed (or failed), then
        say what it came to.  Ctrl-C stops the compression (re-raised once stopped)."""
        if self._proc is None:
            return list(self.outcomes)
        left = len(self.pending())
        if left and self.background:
            self.echo(f"compressing {left} log(s) recorded uncompressed (Ctrl-C leaves them so)")
        try:
            while self._end_process():
                # it died on the first log it had not answered: that log stays as
                # recorded, and a new process takes the ones after it
                first, *rest = self.pending()
                self._died_on(first)
                if rest:
                    with self._lock:
                        self._proc = None
                        for path in rest:
                            self._send(path)
        except KeyboardInterrupt:
            self.abandon()
            raise
        self._report()
        return list(self.outcomes)

    def _end_process(self) -> bool:
        """Close its input, wait for it to end; True when it ended with logs unanswered."""
        proc = self._proc
        with contextlib.suppress(OSError):
            proc.stdin.close()
        proc.wait()
        self._collect(proc)
        return bool(self.pending())

    def _collect(self, proc: subprocess.Popen) -> None:
        """After the process ended: every answer it wrote read, its pipe closed."""
        self._reader.join(STOP_WAIT_S)
        proc.stdout.close()

    def _died_on(self, path: Path) -> None:
        _remove_leftovers(path)
        status = self._proc.returncode
        how = f"signal {-status}" if status < 0 else f"status {status}"
        with self._lock:
            self.outcomes.append(CompressOutcome(path, FAILED, note=(
                f"left as recorded: the compressing process ended ({how}) while writing the "
                f"compressed copy - is the disk full? `groundstation log check` reads the log")))

    def abandon(self) -> None:
        """Stop now; the logs not yet compressed stay as recorded (whole and readable)."""
        proc = self._proc
        if proc is None:
            return
        with contextlib.suppress(OSError):
            proc.stdin.close()
        if proc.poll() is None:
            proc.terminate()                     # it removes its temporary file and ends
            try:
                proc.wait(STOP_WAIT_S)
            except subprocess.TimeoutExpired:
                proc.kill()
                proc.wait()
        self._collect(proc)
        left = self.pending()
        for path in left:
            _remove_leftovers(path)
        if left:
            self.echo(f"{len(left)} log(s) left uncompressed (whole and readable); to compress "
                      f"them: groundstation log compress {' '.join(str(p) for p in left)}")

    def _report(self) -> None:
        done = [o for o in self.outcomes if o.state == COMPRESSED]
        if done and self.background:
            before = sum(o.bytes_before for o in done) / 1e6
            after = sum(o.bytes_after for o in done) / 1e6
            self.echo(f"compressed {len(done)} log(s): {before:.1f} MB -> {after:.1f} MB")
        for o in self.outcomes:
            if o.state == FAILED or not self.background:
                self.echo(o.text())


def _remove_leftovers(path: Path) -> None:
    """The temporary copy a compressing process that died mid-way left beside `path`."""
    for tmp in leftovers(path):
        with contextlib.suppress(OSError):
            tmp.unlink()


def _stop_on_sigterm(signum, frame) -> None:
    raise SystemExit(1)          # compress_log's temporary file is removed on the way out


def main(argv: list[str] | None = None) -> int:
    signal.signal(signal.SIGINT, signal.SIG_IGN)
    signal.signal(signal.SIGTERM, _stop_on_sigterm)
    if "--background" in (sys.argv[1:] if argv is None else argv):
        with contextlib.suppress(OSError):
            os.setpriority(os.PRIO_PROCESS, 0, min(19, os.getpriority(os.PRIO_PROCESS, 0) + NICENESS))
        with contextlib.suppress(OSError, AttributeError):
            # idle class: it runs only on a core nothing else wants
            os.sched_setscheduler(0, os.SCHED_IDLE, os.sched_param(0))
    for line in sys.stdin:
        path = line.rstrip("\n")
        if path:
            o = compress_log(path)
            print(json.dumps({"path": str(o.path), "state": o.state, "before": o.bytes_before,
                              "after": o.bytes_after, "note": o.note}), flush=True)
    return 0


if __name__ == "__main__":
    sys.exit(main())
