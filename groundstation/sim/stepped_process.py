"""The fast (manually paced) simulated testbed in a child process of its own.

Why: in fast mode the stepped clock runs the simulator as fast as the host keeps up.
In the ground station's own process the simulator (its compiled core is quick, but
encoding each chunk's frames is Python) and the telemetry receiver take turns on one
interpreter lock, so a campaign reached about 0.55 of the simulator's own rate however
many cores there were.  In a child process the simulator has an interpreter - and a
core - to itself, as a rig does; the receiver and the log writer share the other.

`SteppedSimulatorProcess` is the parent's stand-in for an in-process SimulatedDevice,
with the part of its interface the stepped clock uses (`step`, `run_ticks`,
`hold_between_steps`, `sync`, `faulted`, `dictionary`, `tcp_port`, `stop`) and
`step_ahead`, which only a device in another process needs.  Telemetry and commands still go over the wire protocol on
loopback, exactly as with the in-process device; only the clock's stepping travels over
a private control channel: a socket pair whose child end the child inherits (no
listening port), carrying pickled tuples (multiprocessing.connection framing).

Requests, answered in order (`step_ahead` sends steps without waiting for the replies,
so the child always has the next chunk queued):
    ("step", n, datagram_bytes, only_while_playing, unless_faulted)
                                                    -> ("stepped", last tick or None, fault)
    ("run", n)                                      -> ("ok", fault)
    ("hold", datagram_bytes or None)                -> ("ok", fault)
    ("sync",)                                       -> ("ok", fault)
    ("stop",)                                       -> the child stops its servers and exits
and one message the child sends by itself:
    ("ran", last tick)   a command's confirmation period was run (held between steps)
A failure in the child answers ("error", text); the parent raises LinkLostError.

Ordering: the child writes ("ran", ...) while it still holds the device lock, before the
command's answer leaves on the TCP link.  So once the host has a command's answer, a
later request's reply arrives after that "ran", and `sync()` (a round trip) makes the
clock count every period the device ran.  The child ends when the channel closes: a
ground station that dies leaves no simulator behind.
"""

from __future__ import annotations

import argparse
import contextlib
import os
import queue
import socket
import subprocess
import sys
import tempfile
import threading
from collections import deque
from multiprocessing.connection import Connection
from pathlib import Path
from typing import Callable

from ..core.errors import LinkError, LinkLostError

#: how long a request may go unanswered before the child counts as hung
REPLY_TIMEOUT_S = 30.0
#: how long the child may take to import, compile (numba's cache) and open its ports
START_TIMEOUT_S = 60.0


class SteppedSimulatorProcess:
    """The parent's handle on a manually paced SimulatedDevice in a child process."""

    def __init__(self, dictionary, *, testbed: str | Path, seed: int = 0,
                 generator: bool = False, host: str = "127.0.0.1",
                 start_timeout: float = START_TIMEOUT_S):
        self.dictionary = dictionary
        self.args = [sys.executable, "-m", "groundstation.sim.stepped_process",
                     "--testbed", str(Path(testbed).resolve()), "--seed", str(int(seed)), "--host", host]
        if generator:
            self.args.append("--generator")
        self.start_timeout = start_timeout
        self.tcp_port: int | None = None
        #: the simulated generator's VISA resource, when one was asked for
        self.fg_resource: str | None = None
        self.proc: subprocess.Popen | None = None
        self._conn: Connection | None = None
        #: what to do with each reply still to come, in the order of the requests
        self._pending: deque[Callable[[tuple], None]] = deque()
        self._send_lock = threading.Lock()
        self._dead: str = ""                 # why the channel closed, once it has
        self._on_ran: Callable[[int], None] | None = None
        self._fault = 0
        self._stderr = None
        self._reader: threading.Thread | None = None

    # ------------------------------------------------------------------ lifecycle
    def launch(self) -> "SteppedSimulatorProcess":
        """Start the child's interpreter; `start()` waits until it is ready.  Its imports
        and numba's cache take about half a second, which a caller with other work to
        do meanwhile (checking a campaign) need not wait for: launch_ahead.py."""
        if self.proc is not None:
            return self
        parent_end, child_end = socket.socketpair()
        # the child's complaints go to a file: a pipe nobody reads could fill and block it
        self._stderr = tempfile.TemporaryFile()
        try:
            self.proc = subprocess.Popen(
                self.args + ["--fd", str(child_end.fileno())], pass_fds=(child_end.fileno(),),
                stdin=subprocess.DEVNULL, stdout=subprocess.DEVNULL, stderr=self._stderr,
                env=_child_environment(),
                # its own session: the terminal's Ctrl-C is for the ground station, which
                # makes the rig safe over the link and then stops this child itself
                start_new_session=True)
        finally:
            child_end.close()
        self._conn = Connection(parent_end.detach())
        return self

    def start(self) -> "SteppedSimulatorProcess":
        self.launch()
        if not self._conn.poll(self.start_timeout):
            why = self._last_complaint()
            self.stop()
            raise LinkError(f"the fast simulated testbed did not start within "
                            f"{self.start_timeout:g} s{why}")
        try:
            first = self._conn.recv()
        except (EOFError, OSError):
            first = ("error", "it exited while starting")
        if first[0] != "ready":
            with contextlib.suppress(subprocess.TimeoutExpired):
                self.proc.wait(timeout=10)       # its last words are in stderr once it ends
            why = self._last_complaint()
            self.stop()
            raise LinkError(f"the fast simulated testbed did not start: {first[1]}{why}")
        _, self.tcp_port, self.fg_resource = first
        self._reader = threading.Thread(target=self._read, name="gs-sim-control", daemon=True)
        self._reader.start()
        return self

    def gone(self) -> str:
        """Why the child can no longer answer ("" while it runs): what the link's command
        wait asks before giving up on an answer (DeviceClient.device_gone)."""
        if self._dead:
            return self._dead
        proc = self.proc
        if proc is None:
            return "stopped"
        code = proc.poll()
        return "" if code is None else f"its process ended (status {code})"

    def stop(self) -> None:
        proc, self.proc = self.proc, None
        conn = self._conn
        if conn is not None and proc is not None and proc.poll() is None:
            with self._send_lock, contextlib.suppress(OSError):   # gone: terminated below
                conn.send(("stop",))
        if proc is not None:
            try:
                proc.wait(timeout=5)
            except subprocess.TimeoutExpired:
                proc.terminate()
                try:
                    proc.wait(timeout=5)
                except subprocess.TimeoutExpired:
                    proc.kill()
                    proc.wait()
        if conn is not None:
            # a shutdown wakes the reader thread blocked in recv (a close alone would not)
            with contextlib.suppress(OSError), \
                    socket.fromfd(conn.fileno(), socket.AF_UNIX, socket.SOCK_STREAM) as sock:
                sock.shutdown(socket.SHUT_RDWR)          # (OSError: the child's end shut it)
            conn.close()
        if self._stderr is not None:
            self._stderr.close()
            self._stderr = None
        if self._reader is not None and self._reader is not threading.current_thread():
            self._reader.join(timeout=5)

    def _last_complaint(self) -> str:
        """The last line the child wrote to stderr, for an error message."""
        stderr = self._stderr              # (stop() may close it meanwhile: ValueError)
        if stderr is None:
            return ""
        try:
            stderr.seek(0)
            lines = stderr.read().decode(errors="replace").strip().splitlines()
        except (OSError, ValueError):
            return ""
        return f": {lines[-1]}" if lines else ""

    # ------------------------------------------------------------------ the channel
    def _read(self) -> None:
        conn = self._conn
        while True:
            try:
                msg = conn.recv()
            except (EOFError, OSError):
                self._gone("the fast simulated testbed's process ended" + self._last_complaint())
                return
            if msg[0] == "ran":
                on_ran = self._on_ran
                if on_ran is not None:
                    on_ran(msg[1])
                continue
            if msg[0] != "error":
                self._fault = msg[-1]
            with self._send_lock:
                done = self._pending.popleft() if self._pending else None
            if done is not None:
                done(msg)

    def _gone(self, why: str) -> None:
        """The channel closed: every request still waiting is answered with why."""
        with self._send_lock:
            self._dead = why
            pending, self._pending = list(self._pending), deque()
        for done in pending:
            done(("gone", why))

    def _send(self, msg: tuple, done: Callable[[tuple], None]) -> None:
        """Send a request; `done(reply)` is called on the reader thread when its reply
        comes (replies come in the order of the requests)."""
        with self._send_lock:
            if self._dead or self._conn is None:
                raise LinkLostError(f"the fast simulated testbed: {self._dead or 'not running'}")
            self._pending.append(done)
            try:
                self._conn.send(msg)
            except OSError as exc:
                self._pending.pop()
                raise LinkLostError(f"the fast simulated testbed's process is gone: {exc}") from exc

    def _request(self, *msg):
        waiter: queue.Queue = queue.Queue(maxsize=1)
        self._send(msg, waiter.put)
        try:
            reply = waiter.get(timeout=REPLY_TIMEOUT_S)
        except queue.Empty:
            raise LinkLostError(f"the fast simulated testbed did not answer {msg[0]} "
                                f"within {REPLY_TIMEOUT_S:g} s") from None
        if reply[0] in ("error", "gone"):
            raise LinkLostError(f"the fast simulated testbed: {reply[1]}")
        return reply

    # ------------------------------------------------------------------ what the clock uses
    def step(self, n: int, *, datagram_bytes: int = 0, only_while_playing: bool = False,
             unless_faulted: bool = False) -> int | None:
        """SimulatedDevice.step in the child; the last tick run (None: nothing ran)."""
        return self._request("step", int(n), int(datagram_bytes), bool(only_while_playing),
                             bool(unless_faulted))[1]

    def step_ahead(self, n: int, done: Callable[[int | None, str | None], None], *,
                   datagram_bytes: int = 0, unless_faulted: bool = False) -> None:
        """step() without waiting for it: the request is queued in the child behind the
        ones before it, and `done(last_tick, None)` - or `done(None, why)` on a failure -
        is called on the reader thread once it has run.  The child then never waits for
        the host's next request between two chunks."""
        def answered(reply: tuple) -> None:
            if reply[0] == "stepped":
                done(reply[1], None)
            else:
                done(None, f"the fast simulated testbed: {reply[1]}")
        self._send(("step", int(n), int(datagram_bytes), False, bool(unless_faulted)), answered)

    def run_ticks(self, n: int) -> None:
        self._request("run", int(n))

    def hold_between_steps(self, on_ran: Callable[[int], None] | None, *,
                           datagram_bytes: int = 0) -> None:
        """SimulatedDevice.hold_between_steps: `on_ran(last_tick)` is called (on this
        handle's reader thread) after each confirmation period the child ran."""
        self._on_ran = on_ran
        self._request("hold", None if on_ran is None else int(datagram_bytes))

    def sync(self) -> None:
        """A round trip: every confirmation period run before it has been reported."""
        self._request("sync")

    @property
    def faulted(self) -> bool:
        """Whether the firmware's fault was latched when the child last answered."""
        return bool(self._fault)


def _child_environment() -> dict[str, str]:
    """This process's environment with one BLAS thread set (core/blas_threads.py): the
    command line has set it already, a notebook or a script holding a Testbed may not."""
    from ..core.blas_threads import one_blas_thread

    env = dict(os.environ)
    one_blas_thread(env)
    return env


# ---------------------------------------------------------------------- the child
def _serve(conn: Connection, testbed: str, seed: int, generator: bool, host: str) -> None:
    from ..core.dictionary import load_dictionary
    from ..plant.testbed import load_testbed
    from .device import SimulatedDevice
    from .firmware import Firmware

    d = load_dictionary()
    fw = Firmware(d, seed=seed, testbed=load_testbed(Path(testbed)))
    device = SimulatedDevice(d, host=host, pacing="manual", firmware=fw).start()
    fg_server = None
    send_lock = threading.Lock()

    def send(msg) -> None:
        with send_lock:
            conn.send(msg)

    try:
        if generator:
            from .scpi_server import attach_generator
            fg_server = attach_generator(device, host=host)
        send(("ready", device.tcp_port, fg_server.resource if fg_server else None))
        while True:
            try:
                msg = conn.recv()
            except (EOFError, OSError):      # the ground station is gone
                return
            verb = msg[0]
            if verb == "stop":
                _end_now(conn)
            try:
                if verb == "step":
                    last = device.step(msg[1], datagram_bytes=msg[2], only_while_playing=msg[3],
                                       unless_faulted=msg[4])
                    send(("stepped", last, fw.fault))
                    continue
                if verb == "run":
                    device.run_ticks(msg[1])
                elif verb == "hold":
                    device.hold_between_steps(None if msg[1] is None else
                                              (lambda last: send(("ran", last))),
                                              datagram_bytes=msg[1] or 0)
                elif verb != "sync":
                    raise ValueError(f"unknown request {verb!r}")
                send(("ok", fw.fault))
            except Exception as exc:         # said to the parent, which stops the session
                send(("error", f"{verb}: {type(exc).__name__}: {exc}"))
    finally:
        if fg_server is not None:
            fg_server.stop()
        device.stop()


def _end_now(conn: Connection) -> None:
    """The parent asked the child to end: it ends at once.  Nothing in it outlives the
    process (no file; its sockets close with it), so the servers' threads need no
    joining - their accept loops would each wait out a timeout - and the interpreter no
    teardown: together about 0.3 s of every session's close, measured."""
    conn.close()
    sys.stdout.flush()
    sys.stderr.flush()
    os._exit(0)


def main(argv: list[str] | None = None) -> None:
    ap = argparse.ArgumentParser(description="the fast simulated testbed's child process "
                                 "(started by the ground station, not by hand)")
    ap.add_argument("--fd", type=int, required=True, help="the control channel's socket")
    ap.add_argument("--testbed", required=True)
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--host", default="127.0.0.1")
    ap.add_argument("--generator", action="store_true")
    args = ap.parse_args(argv)
    conn = Connection(args.fd)
    try:
        _serve(conn, args.testbed, args.seed, args.generator, args.host)
    except Exception as exc:                 # before or after "ready": the parent hears why
        try:
            conn.send(("error", f"{type(exc).__name__}: {exc}"))
        except OSError:
            print(f"fast simulated testbed: {exc}", file=sys.stderr)
        raise
    finally:
        conn.close()


if __name__ == "__main__":
    main()
