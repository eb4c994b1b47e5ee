"""Smoke tests of every entry point, run as a user runs them (subprocesses)."""

from __future__ import annotations

import os
import re
import shutil
import subprocess
import time
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parents[2]


def run(*args, timeout=60, **kw):
    return subprocess.run([sys.executable, "-m", "groundstation", *args], capture_output=True,
                          text=True, timeout=timeout, cwd=ROOT, **kw)


def test_protocol_info_and_check():
    out = run("protocol", "info")
    assert out.returncode == 0, out.stderr
    assert "HIGH_RATE" in out.stdout and re.search(r"dictionary hash [0-9a-f]{8}", out.stdout)
    out = run("protocol", "check")
    assert out.returncode == 0 and "OK" in out.stdout


def test_malformed_protocol_file_gives_a_message_not_a_traceback(tmp_path):
    shutil.copytree(ROOT / "protocol", tmp_path / "p")
    (tmp_path / "p" / "commands.toml").write_text("[[command]\nname = 'X'\n")
    out = run("--protocol-dir", str(tmp_path / "p"), "protocol", "check")
    assert out.returncode == 2
    assert "commands.toml" in out.stderr and "malformed TOML" in out.stderr
    assert "Traceback" not in out.stderr


def test_monitor_shows_live_statistics_of_the_simulated_device():
    out = run("monitor", "--device", "sim", "--duration", "2.5", "--interval", "1", timeout=90)
    assert out.returncode == 0, out.stderr
    lines = [ln for ln in out.stdout.splitlines() if "HIGH_RATE" in ln]
    assert len(lines) >= 2, out.stdout
    rate = float(re.search(r"HIGH_RATE\s+([0-9.]+)/s", lines[-1]).group(1))
    assert rate > 600          # the simulator streams at 1200 Hz; loaded CI machines lag
    assert "drop=0" in lines[-1] and "crc=0" in lines[-1]


def test_monitor_reports_an_unreachable_device():
    out = run("monitor", "--device", "tcp://127.0.0.1:1", "--duration", "1")
    assert out.returncode == 2
    assert "connection refused" in out.stderr and "Traceback" not in out.stderr


def test_sim_serves_a_serial_pty_and_stops_on_sigterm():
    proc = subprocess.Popen([sys.executable, "-m", "groundstation", "sim", "--tcp-port", "0",
                             "--pty"], stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True,
                            cwd=ROOT, env={**os.environ, "PYTHONUNBUFFERED": "1"})
    try:
        lines = [proc.stdout.readline() for _ in range(3)]
        assert any("simulated testbed on tcp://127.0.0.1:" in ln for ln in lines), lines
        assert any("friction model DB-DHM" in ln for ln in lines), lines
        serial_line = [ln for ln in lines if ln.startswith("serial link on serial:///dev/pts/")]
        assert serial_line, lines
        out = run("monitor", "--device", serial_line[0].split()[-1], "--duration", "1.5", timeout=60)
        assert out.returncode == 0, out.stderr
        assert "HIGH_RATE" in out.stdout
    finally:
        proc.terminate()
        assert proc.wait(timeout=10) == 0
        proc.stdout.close()
        proc.stderr.close()


def test_a_simulator_started_by_a_ground_station_ends_with_it(tmp_path):
    """If the ground station is killed, its simulator child must not run on forever."""
    script = ("from groundstation.sim.process import SimulatorProcess\n"
              "import os, sys\n"
              "sim = SimulatorProcess(); sim.start()\n"
              "print(sim.proc.pid, flush=True)\n"
              "os._exit(9)\n")                      # the parent dies without cleaning up
    out = subprocess.run([sys.executable, "-c", script], capture_output=True, text=True,
                         timeout=120, cwd=ROOT)
    assert out.stdout.split(), out.stderr
    child = int(out.stdout.split()[0])
    # it notices within 0.5 s and stops in about a second; the bound only turns a child
    # that never notices (it once took init for its parent: a race at start) into a
    # failure instead of a hang
    deadline = time.monotonic() + 120
    while time.monotonic() < deadline:
        try:
            state = Path(f"/proc/{child}/stat").read_text().rsplit(")", 1)[1].split()[0]
        except (FileNotFoundError, ProcessLookupError):
            return                                    # gone
        if state == "Z":
            return                                    # exited; its new parent has not reaped it
        time.sleep(0.1)
    os.kill(child, 9)
    raise AssertionError("the simulator outlived the process that started it")
