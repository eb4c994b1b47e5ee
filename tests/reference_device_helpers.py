"""The C reference device (firmware/reference_device) as a child process, for tests.

    with running_reference_device("watchdog-x2") as address:   # "tcp://127.0.0.1:PORT"
        client = open_client(dictionary, address)

Building: `make -C <repo> firmware`, always, under a file lock.  make already knows when
the binary is stale (it depends on every source and on the committed kit), and the
flags live in one place (the Makefile), so the tests build exactly what `make firmware`
builds; when nothing changed, make returns at once.  The lock keeps two test processes
from writing the binary at the same time.
"""

from __future__ import annotations

import contextlib
import fcntl
import os
import selectors
import subprocess
import time
from pathlib import Path

REPO = Path(__file__).resolve().parent.parent
FIRMWARE_DIR = REPO / "firmware" / "reference_device"
BINARY = FIRMWARE_DIR / "build" / "hfb_reference_device"

BUILD_TIMEOUT_S = 120.0
START_TIMEOUT_S = 10.0
STOP_TIMEOUT_S = 5.0


def build_reference_device() -> Path:
    """Build (or bring up to date) the binary with `make firmware`; return its path.
    Raises RuntimeError with the compiler's output when the build fails."""
    (FIRMWARE_DIR / "build").mkdir(parents=True, exist_ok=True)
    with open(FIRMWARE_DIR / "build" / ".lock", "w") as lock:
        fcntl.flock(lock, fcntl.LOCK_EX)
        try:
            proc = subprocess.run(["make", "-C", str(REPO), "firmware"], capture_output=True,
                                  text=True, timeout=BUILD_TIMEOUT_S)
        finally:
            fcntl.flock(lock, fcntl.LOCK_UN)
    if proc.returncode != 0:
        raise RuntimeError(f"make firmware failed ({proc.returncode}):\n{proc.stdout}\n{proc.stderr}")
    return BINARY


def _read_line(proc: subprocess.Popen, timeout: float) -> str:
    """One line of the child's stdout, waiting at most `timeout` s for it (select on the
    pipe, no sleeping)."""
    deadline = time.monotonic() + timeout
    fd = proc.stdout.fileno()
    buf = b""
    with selectors.DefaultSelector() as sel:
        sel.register(fd, selectors.EVENT_READ)
        while b"\n" not in buf:
            left = deadline - time.monotonic()
            if left <= 0:
                raise TimeoutError(f"no 'listening' line from the reference device within {timeout} s")
            if not sel.select(left):
                continue
            chunk = os.read(fd, 4096)
            if not chunk:
                raise RuntimeError(f"the reference device exited (status {proc.wait()}) before "
                                   f"listening: {proc.stderr.read().decode(errors='replace')}")
            buf += chunk
    return buf.split(b"\n", 1)[0].decode()


def _stop(proc: subprocess.Popen) -> int:
    if proc.poll() is None:
        proc.terminate()
        try:
            proc.wait(STOP_TIMEOUT_S)
        except subprocess.TimeoutExpired:
            proc.kill()
            proc.wait(STOP_TIMEOUT_S)
    for stream in (proc.stdout, proc.stderr):
        if stream is not None:
            stream.close()
    return proc.returncode


@contextlib.contextmanager
def running_reference_device(*deviations: str, extra_args: tuple[str, ...] = ()):
    """Build if needed, start the device on a free loopback port, yield its address
    ("tcp://127.0.0.1:PORT", usable as --device), and stop it at exit (SIGTERM, then
    SIGKILL after STOP_TIMEOUT_S)."""
    binary = build_reference_device()
    args = [str(binary), "--host", "127.0.0.1", "--port", "0", *extra_args]
    for name in deviations:
        args += ["--deviate", name]
    proc = subprocess.Popen(args, stdout=subprocess.PIPE, stderr=subprocess.PIPE)
    try:
        line = _read_line(proc, START_TIMEOUT_S)
        prefix = "listening "
        if not line.startswith(prefix + "tcp://"):
            raise RuntimeError(f"unexpected first line from the reference device: {line!r}")
        yield line[len(prefix):]
    finally:
        _stop(proc)
