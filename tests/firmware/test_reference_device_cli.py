"""The ground station's own commands against the C reference device: a controller
design uploaded and verified, a profile played, a recording read back, monitor."""

from __future__ import annotations

import subprocess
import sys
from pathlib import Path

from reference_device_helpers import running_reference_device

ROOT = Path(__file__).resolve().parents[2]


def run(*args, timeout=120, **kw):
    return subprocess.run([sys.executable, "-m", "groundstation", *args], capture_output=True,
                          text=True, timeout=timeout, cwd=ROOT, **kw)


SHORT_STEP = """
[profile]
name = "reference_device_step"
target = "REFERENCE"
units = "rad"
origin = "relative"
description = "0.1 mrad step, 0.5 s, for the reference device's tests"
duration_s = 0.5

[generator]
type = "step"
level_mrad = 0.1
t_step_s = 0.1
rise_s = 0.02
shape = "minimum_jerk"
"""


def test_params_upload_is_verified_and_a_profile_plays(tmp_path):
    profile = tmp_path / "step.toml"
    profile.write_text(SHORT_STEP)
    with running_reference_device() as address:
        out = run("params", "upload", "profiles/controllers/relative_design2.toml",
                  "--device", address, "--history", str(tmp_path / "history"))
        assert out.returncode == 0, out.stdout + out.stderr
        assert "verified" in out.stdout and "read back bit for bit" in out.stdout
        out = run("params", "show", "--device", address)
        assert out.returncode == 0, out.stdout + out.stderr
        out = run("profile", "play", str(profile), "--device", address)
        assert out.returncode == 0, out.stdout + out.stderr
        assert "played all 600 samples" in out.stdout


def test_record_then_log_info(tmp_path):
    with running_reference_device() as address:
        out = run("record", "--device", address, "--duration", "1", "--folder", str(tmp_path),
                  "--name", "refdev", "--no-reconnect")
        assert out.returncode == 0, out.stdout + out.stderr
    logs = sorted(tmp_path.glob("*.h5"))
    assert len(logs) == 1
    out = run("log", "info", str(logs[0]))
    assert out.returncode == 0, out.stdout + out.stderr
    assert "HIGH_RATE" in out.stdout and "drops 0 in 0 gap(s)" in out.stdout
    out = run("log", "check", str(logs[0]))
    assert out.returncode == 0, out.stdout + out.stderr


def test_monitor_runs_and_stops_by_itself():
    with running_reference_device() as address:
        out = run("monitor", "--device", address, "--duration", "1.5", "--interval", "0.5",
                  "--no-reconnect")
    assert out.returncode == 0, out.stdout + out.stderr
    assert "C reference device" in out.stdout and "protocol 1.0" in out.stdout
    assert "HIGH_RATE" in out.stdout and "crc=0" in out.stdout
