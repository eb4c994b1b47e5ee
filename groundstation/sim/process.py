"""The simulated testbed as a child process (what `make run` and the GUI start).

The child prints one line `LISTENING tcp://HOST:PORT` once its command port is open
(preceded, with --fg-port, by `FG_LISTENING TCPIP0::HOST::PORT::SOCKET` for the simulated
function generator); the parent reads them (with a timeout) to learn the ports, and
terminates the child when done.  A separate process keeps the simulator's 1200 Hz loop
off the ground station's interpreter lock, as a real rig would be.
"""

from __future__ import annotations

import os
import select
import subprocess
import sys
import time

from ..core.errors import LinkError, PortInUseError

ANNOUNCE = "LISTENING "
FG_ANNOUNCE = "FG_LISTENING "       # the function generator's line (sim --fg-port)


class SimulatorProcess:
    def __init__(self, *, host: str = "127.0.0.1", tcp_port: int = 0, pacing: str = "realtime",
                 seed: int = 0, testbed: str | None = None, start_timeout: float = 60.0,
                 speed: float = 1.0, fg_port: int | None = None, deviations: tuple = ()):
        self.host, self.tcp_port = host, tcp_port
        self.args = [sys.executable, "-m", "groundstation", "sim", "--host", host,
                     "--tcp-port", str(tcp_port), "--pacing", pacing, "--seed", str(seed),
                     "--announce"] + (["--testbed", str(testbed)] if testbed else [])
        if speed != 1.0:                    # realtime pacing at `speed` x 1200 periods/s
            self.args += ["--speed", repr(float(speed))]
        if fg_port is not None:             # serve the function generator too (0: any port)
            self.args += ["--fg-port", str(fg_port)]
        for name in deviations:             # test only: sim/deviations.py
            self.args += ["--deviate", name]
        self.start_timeout = start_timeout
        self.seed = seed
        self.proc: subprocess.Popen | None = None
        self.address: str = ""
        #: the simulated generator's VISA resource (TCPIP0::HOST::PORT::SOCKET), if served
        self.fg_resource: str | None = None

    def start(self) -> str:
        # its own session: the terminal's Ctrl-C is for the ground station, which then
        # ends the session (the rig goes safe) and stops this child itself
        self.proc = subprocess.Popen(self.args, stdout=subprocess.PIPE, stderr=subprocess.PIPE,
                                     text=True, env={**os.environ, "PYTHONUNBUFFERED": "1"},
                                     start_new_session=True)
        deadline = time.monotonic() + self.start_timeout
        assert self.proc.stdout is not None
        while time.monotonic() < deadline:
            ready, _, _ = select.select([self.proc.stdout], [], [], 0.1)
            if ready:
                line = self.proc.stdout.readline()
                # announced just before LISTENING: read on (LISTENING may be buffered already)
                while line.startswith(FG_ANNOUNCE):
                    self.fg_resource = line[len(FG_ANNOUNCE):].strip()
                    line = self.proc.stdout.readline()
                if line.startswith(ANNOUNCE):
                    self.address = line[len(ANNOUNCE):].strip()
                    return self.address
                if not line and self.proc.poll() is not None:
                    break
        code = self.proc.poll()
        err = self.proc.stderr.read() if code is not None and self.proc.stderr else ""
        self.stop()
        why = err.strip().splitlines()[-1] if err.strip() else ""
        if code is not None and "in use" in why:
            # the child's words name its own option (--tcp-port); whoever asked for this
            # port knows it by another name (--sim-port, a script's argument)
            raise PortInUseError(
                f"the simulated testbed cannot listen on {self.host}:{self.tcp_port}: the port "
                f"(TCP, or the UDP port of the same number its telemetry leaves from) is in use "
                f"by another program - choose another port, or 0 for any free one "
                f"({why.removeprefix('error: ').split(' - ')[0]})")
        if code is not None:
            raise LinkError(f"the simulated testbed's process ended (status {code}) before it "
                            f"listened" + (f": {why}" if why else ""))
        raise LinkError(f"the simulated testbed did not start within {self.start_timeout} s")

    def gone(self) -> str:
        """Why the simulator can no longer answer ("" while its process runs)."""
        proc = self.proc
        if proc is None:
            return "stopped"
        code = proc.poll()
        return "" if code is None else f"the simulator's process ended (status {code})"

    def stop(self) -> None:
        if self.proc is None:
            return
        if self.proc.poll() is None:
            self.proc.terminate()
            try:
                self.proc.wait(timeout=5)
            except subprocess.TimeoutExpired:
                self.proc.kill()
                self.proc.wait()
        for f in (self.proc.stdout, self.proc.stderr):
            if f is not None:
                f.close()
        self.proc = None

    def __enter__(self) -> str:
        return self.start()

    def __exit__(self, *exc) -> None:
        self.stop()
