"""`record` and `monitor` end the way an operator expects (issue 13: "Sessions that end
must say so", "Ctrl-C is the normal way to stop").

The CLI runs as a real child process where signals or process lifetime matter, against
a simulated device in this process on loopback; every wait is bounded and waits for a
line the program prints, never for a time."""

from __future__ import annotations

import os
import queue
import signal
import subprocess
import sys
import threading
from pathlib import Path

import pytest

from groundstation.cli.main import main
from groundstation.link import open_client
from groundstation.logs import LogReader
from groundstation.sim import SimulatedDevice

ROOT = Path(__file__).resolve().parents[2]


class Cli:
    """`groundstation ARGS` as a child in its own process group, its output read line by
    line in a thread so that the test can wait for a line with a bound."""

    def __init__(self, *args: str):
        self.proc = subprocess.Popen([sys.executable, "-m", "groundstation", *args],
                                     stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True,
                                     cwd=ROOT, start_new_session=True,
                                     env={**os.environ, "PYTHONUNBUFFERED": "1"})
        self.lines: queue.Queue[str] = queue.Queue()
        self.seen: list[str] = []
        self._pump_thread = threading.Thread(target=self._pump, daemon=True)
        self._pump_thread.start()

    def _pump(self) -> None:
        for line in self.proc.stdout:
            self.lines.put(line.rstrip("\n"))
        self.lines.put(None)                      # end of output: no line will come


    def wait_for_line(self, text: str, timeout: float = 60.0) -> str:
        while True:
            try:
                line = self.lines.get(timeout=timeout)
            except queue.Empty:
                raise AssertionError(f"no line with {text!r} within {timeout} s; seen: {self.seen[-5:]}")
            if line is None:
                raise AssertionError(f"the program ended (status {self.proc.wait()}) without a "
                                     f"line with {text!r}; seen: {self.seen[-5:]}")
            self.seen.append(line)
            if text in line:
                return line

    def finish(self, timeout: float = 60.0) -> tuple[int, str, str]:
        code = self.proc.wait(timeout)
        err = self.proc.stderr.read()
        self._pump_thread.join(timeout)            # all of stdout is in the queue
        while not self.lines.empty():
            line = self.lines.get()
            if line is not None:
                self.seen.append(line)
        return code, "\n".join(self.seen), err

    def kill(self) -> None:
        """Make sure the child is gone and its pipes are closed (every test's finally)."""
        if self.proc.poll() is None:
            os.killpg(self.proc.pid, signal.SIGKILL)
            self.proc.wait()
        self.proc.stdout.close()
        self.proc.stderr.close()


@pytest.fixture
def live_device(dictionary):
    dev = SimulatedDevice(dictionary, pacing="realtime", seed=2).start()
    yield dev
    dev.stop()


def closing_record(path: Path) -> dict:
    with LogReader(path) as r:
        assert r.attrs["clean_close"]
        stops = [j.data for j in r.journal(["recorder"]) if j.data.get("action") == "stopped"]
    assert stops, "the log has no closing record"
    return stops[-1]


def only_log(folder: Path) -> Path:
    files = sorted(folder.glob("*.h5"))
    assert len(files) == 1, files
    return files[0]


@pytest.mark.parametrize("sig, reason", [(signal.SIGINT, "interrupted by the operator (Ctrl-C)"),
                                         (signal.SIGTERM, "terminated (SIGTERM)")])
def test_ctrl_c_or_sigterm_ends_a_recording_cleanly(live_device, tmp_path, sig, reason):
    cli = Cli("record", "--device", f"tcp://127.0.0.1:{live_device.tcp_port}",
              "--folder", str(tmp_path))
    try:
        cli.wait_for_line(" frames, ")                # recording, with frames flowing
        os.killpg(cli.proc.pid, sig)                  # as the terminal does: the whole group
        code, out, err = cli.finish()
    finally:
        cli.kill()
    assert code == 0, (out, err)
    assert "Traceback" not in err and "free space" not in out + err
    assert reason in out
    stop = closing_record(only_log(tmp_path))
    assert stop["reason"] == reason
    assert stop["frames"] > 0
    assert live_device.firmware.session_token is None          # the session was ended


def test_a_recording_whose_session_is_taken_over_stops_and_says_who(live_device, dictionary, tmp_path):
    cli = Cli("record", "--device", f"tcp://127.0.0.1:{live_device.tcp_port}",
              "--folder", str(tmp_path))
    try:
        cli.wait_for_line(" frames, ")
        with open_client(dictionary, f"127.0.0.1:{live_device.tcp_port}", heartbeat=False) as other:
            other.connect(take_over=True)
            code, out, err = cli.finish()
    finally:
        cli.kill()
    assert code == 3, (out, err)
    assert "taken over by 127.0.0.1:" in out
    stop = closing_record(only_log(tmp_path))
    assert "taken over by 127.0.0.1:" in stop["reason"]


def test_a_refused_connect_leaves_a_closed_log_that_says_why(live_device, dictionary, tmp_path, capsys):
    with open_client(dictionary, f"127.0.0.1:{live_device.tcp_port}", heartbeat=False) as owner:
        owner.connect()
        code = main(["record", "--device", f"tcp://127.0.0.1:{live_device.tcp_port}",
                     "--folder", str(tmp_path), "--duration", "5"])
    err = capsys.readouterr().err
    assert code == 2
    assert "SESSION_BUSY" in err            # the reason for a non-zero exit: on stderr
    stop = closing_record(only_log(tmp_path))
    assert stop["reason"].startswith("connect failed:") and "SESSION_BUSY" in stop["reason"]


def test_a_lost_link_is_reconnected_and_the_log_records_the_gap(dictionary, tmp_path):
    first = SimulatedDevice(dictionary, pacing="realtime", seed=2).start()
    port = first.tcp_port
    cli = Cli("record", "--device", f"tcp://127.0.0.1:{port}", "--folder", str(tmp_path))
    second = None
    try:
        cli.wait_for_line(" frames, ")
        first.stop()                                   # the rig goes away...
        cli.wait_for_line("reconnecting in")
        second = SimulatedDevice(dictionary, pacing="realtime", seed=3, tcp_port=port).start()
        cli.wait_for_line("reconnected to")            # ...and comes back
        cli.wait_for_line(" frames, ")
        os.killpg(cli.proc.pid, signal.SIGINT)
        code, out, err = cli.finish()
    finally:
        cli.kill()
        first.stop()
        if second is not None:
            second.stop()
    assert code == 0, (out, err)
    path = only_log(tmp_path)
    with LogReader(path) as r:
        states = [j.data.get("state") for j in r.journal(["event"])]
    assert "lost" in states and "reconnecting" in states and "reconnected" in states
    assert states.index("lost") < states.index("reconnected")
    assert closing_record(path)["reason"] == "interrupted by the operator (Ctrl-C)"


def test_no_reconnect_stops_with_status_1_when_the_link_is_lost(dictionary, tmp_path):
    dev = SimulatedDevice(dictionary, pacing="realtime", seed=2).start()
    cli = Cli("monitor", "--device", f"tcp://127.0.0.1:{dev.tcp_port}", "--no-reconnect",
              "--interval", "0.2")
    try:
        cli.wait_for_line("HIGH_RATE")
        dev.stop()
        code, out, err = cli.finish()
    finally:
        cli.kill()
        dev.stop()
    assert code == 1, (out, err)
    assert "link lost" in out and "Traceback" not in err


def test_record_warns_when_the_device_runs_another_testbed(live_device, tmp_path, capsys):
    code = main(["record", "--device", f"tcp://127.0.0.1:{live_device.tcp_port}",
                 "--folder", str(tmp_path), "--duration", "0.5",
                 "--testbed", str(ROOT / "profiles/testbeds/inertial_2dof.toml")])
    out = capsys.readouterr().out
    assert code == 0
    assert "warning: --testbed inertial_2dof.toml" in out and "relative_2dof.toml" in out
    with LogReader(only_log(tmp_path)) as r:
        notes = [j.data["text"] for j in r.journal(["note"])]
    assert any(n.startswith("warning: --testbed inertial_2dof.toml") for n in notes)
    assert any("relative_2dof.toml" in n for n in notes)
