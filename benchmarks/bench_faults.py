"""What each injected fault loses, measured end to end (README "Reliability").

Each case runs the real `groundstation record` as a child process against a simulated
device in this process (real time, loopback), injects one fault, and compares the log
with what the device sent.  Device frames lost = HIGH_RATE sequence numbers the device
sent while the session was open that the log does not hold.

    fault                         what is compared
    Ctrl-C (SIGINT to the group)  log vs everything the device sent until the session ended
    SIGTERM                       same
    SIGKILL of the recorder       log vs everything sent until the kill (the writer child
                                  closes the file when its parent is gone)
    forged telemetry              2,400 valid-CRC HIGH_RATE frames from another socket during
                                  the recording: how many reached the log
    link lost, device back        the gap in the log between the last frame before the loss
                                  and the first one after the reconnect (seconds)
    session taken over            how long after the take-over the recording stopped
"""

from __future__ import annotations

import os
import signal
import socket
import subprocess
import sys
import tempfile
import threading
import time
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).parent))
from common import machine, save  # noqa: E402

from groundstation.codec import FrameCodec  # noqa: E402
from groundstation.core.dictionary import load_dictionary  # noqa: E402
from groundstation.link import open_client  # noqa: E402
from groundstation.logs import LogReader  # noqa: E402
from groundstation.sim import SimulatedDevice  # noqa: E402

ROOT = Path(__file__).resolve().parent.parent
RUN_S = 5.0


def start_record(port: int, folder: Path) -> tuple[subprocess.Popen, list[str]]:
    proc = subprocess.Popen([sys.executable, "-m", "groundstation", "record", "--device",
                             f"tcp://127.0.0.1:{port}", "--folder", str(folder)],
                            stdout=subprocess.PIPE, stderr=subprocess.DEVNULL, text=True,
                            cwd=ROOT, start_new_session=True,
                            env={**os.environ, "PYTHONUNBUFFERED": "1"})
    lines: list[str] = []
    threading.Thread(target=lambda: lines.extend(iter(proc.stdout.readline, "")), daemon=True).start()
    return proc, lines


def wait_line(lines: list[str], text: str, timeout: float = 60.0) -> None:
    deadline = time.monotonic() + timeout
    while not any(text in line for line in lines):
        if time.monotonic() > deadline:
            raise RuntimeError(f"no {text!r} within {timeout} s: {lines[-3:]}")
        time.sleep(0.05)


def logged_sequences(folder: Path) -> tuple[np.ndarray, np.ndarray, bool]:
    (path,) = sorted(folder.glob("*.h5"))
    with LogReader(path) as r:
        seq = r.read("HIGH_RATE", ["sequence"])["sequence"].astype(np.int64)
        host = r.read("HIGH_RATE", ["host_time"])["host_time"]
        clean = bool(r.attrs.get("clean_close", False))
    return seq, host, clean


def device_sent(dev: SimulatedDevice) -> int:
    return int(dev._seq["HIGH_RATE"])          # the next sequence number it would send


class SessionEndWatch:
    """The device's next HIGH_RATE sequence number at the moment its session ends (the
    simulator goes on counting frames it no longer sends, so it must be caught then)."""

    def __init__(self, dev: SimulatedDevice):
        self.sent_until: int | None = None
        self._dev = dev
        self._thread = threading.Thread(target=self._watch, daemon=True)
        self._thread.start()

    def _watch(self) -> None:
        fw = self._dev.firmware
        while fw.session_token is None:           # wait for the session to open
            time.sleep(0.001)
        while fw.session_token is not None:
            last = device_sent(self._dev)
            time.sleep(0.0005)
        self.sent_until = last

    def result(self, timeout: float = 30.0) -> int:
        self._thread.join(timeout)
        assert self.sent_until is not None, "the session did not end"
        return self.sent_until


def lost_frames(seq: np.ndarray, first_sent: int, sent_until: int) -> int:
    """Frames the device sent in [first logged, sent_until) that the log lacks."""
    if not len(seq):
        return sent_until - first_sent
    # the session-end watch polls every 0.5 ms: it can read one frame early (never below 0)
    return max(0, int(sent_until - seq[0] - len(np.unique(seq))))


def case_signal(d, sig: int, name: str) -> dict:
    dev = SimulatedDevice(d, pacing="realtime", seed=5).start()
    folder = Path(tempfile.mkdtemp(prefix=f"gs-fault-{name}-"))
    try:
        watch = SessionEndWatch(dev)
        proc, lines = start_record(dev.tcp_port, folder)
        wait_line(lines, " frames, ")
        time.sleep(RUN_S)
        if sig == signal.SIGKILL:
            sent_until = device_sent(dev)          # the kill comes now: count what was sent
        os.killpg(proc.pid, sig)
        code = proc.wait(60)
        if sig != signal.SIGKILL:
            sent_until = watch.result()            # session ended: telemetry stopped
        time.sleep(1.0 if sig == signal.SIGKILL else 0.0)   # the orphaned writer closes
        seq, _host, clean = logged_sequences(folder)
    finally:
        dev.stop()
    lost = lost_frames(seq, int(seq[0]) if len(seq) else 0, sent_until)
    return {"fault": name, "exit_status": code, "frames_logged": int(len(seq)),
            "frames_lost": lost, "seconds_lost": lost / d.control_rate_hz, "clean_close": clean}


def case_forged(d) -> dict:
    dev = SimulatedDevice(d, pacing="realtime", seed=5).start()
    folder = Path(tempfile.mkdtemp(prefix="gs-fault-forged-"))
    codec = FrameCodec(d)
    pkt = d.packet("HIGH_RATE")
    try:
        watch = SessionEndWatch(dev)
        proc, lines = start_record(dev.tcp_port, folder)
        wait_line(lines, " frames, ")
        # the recorder's telemetry port: the device sends to it
        port = dev.firmware.telemetry_port
        stranger = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
        for i in range(2400):
            stranger.sendto(codec.frame(pkt.id, bytes(pkt.fixed_payload_size), 10**9 + i, i),
                            ("127.0.0.1", port))
            if i % 12 == 0:
                time.sleep(0.01)
        stranger.close()
        time.sleep(1.0)
        os.killpg(proc.pid, signal.SIGINT)
        code = proc.wait(60)
        sent_until = watch.result()
        seq, _host, clean = logged_sequences(folder)
    finally:
        dev.stop()
    forged_in_log = int(np.count_nonzero(seq >= 10**9))
    device_seq = seq[seq < 10**9]
    return {"fault": "forged telemetry (2,400 frames)", "exit_status": code,
            "forged_frames_in_log": forged_in_log,
            "frames_lost": lost_frames(device_seq, int(device_seq[0]), sent_until),
            "clean_close": clean}


def case_reconnect(d) -> dict:
    first = SimulatedDevice(d, pacing="realtime", seed=5).start()
    port = first.tcp_port
    folder = Path(tempfile.mkdtemp(prefix="gs-fault-link-"))
    second = None
    try:
        proc, lines = start_record(port, folder)
        wait_line(lines, " frames, ")
        time.sleep(2.0)
        first.stop()
        wait_line(lines, "reconnecting in")
        second = SimulatedDevice(d, pacing="realtime", seed=6, tcp_port=port).start()
        wait_line(lines, "reconnected to")
        time.sleep(2.0)
        os.killpg(proc.pid, signal.SIGINT)
        code = proc.wait(60)
        seq, host, clean = logged_sequences(folder)
    finally:
        first.stop()
        if second is not None:
            second.stop()
    gap = float(np.max(np.diff(host)))
    return {"fault": "link lost, device back at once", "exit_status": code,
            "gap_in_log_s": gap, "clean_close": clean}


def case_take_over(d) -> dict:
    dev = SimulatedDevice(d, pacing="realtime", seed=5).start()
    folder = Path(tempfile.mkdtemp(prefix="gs-fault-takeover-"))
    try:
        proc, lines = start_record(dev.tcp_port, folder)
        wait_line(lines, " frames, ")
        with open_client(d, f"127.0.0.1:{dev.tcp_port}", heartbeat=False) as other:
            t0 = time.monotonic()
            other.connect(take_over=True)
            code = proc.wait(60)
            stopped_after = time.monotonic() - t0
        _seq, _host, clean = logged_sequences(folder)
    finally:
        dev.stop()
    return {"fault": "session taken over by another station", "exit_status": code,
            "stopped_after_s": stopped_after, "clean_close": clean}


def main() -> None:
    d = load_dictionary()
    results = [case_signal(d, signal.SIGINT, "Ctrl-C"), case_signal(d, signal.SIGTERM, "SIGTERM"),
               case_signal(d, signal.SIGKILL, "SIGKILL of the recording program"),
               case_forged(d), case_reconnect(d), case_take_over(d)]
    for r in results:
        print("  " + ", ".join(f"{k} {v:.3f}" if isinstance(v, float) else f"{k} {v}"
                               for k, v in r.items()), flush=True)
    save("faults", {"machine": machine(), "cases": results})


if __name__ == "__main__":
    main()
