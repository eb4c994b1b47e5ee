"""`groundstation record`, `log info|export|redecode` from the command line, end to end
against the simulated testbed; re-decoding with a changed dictionary."""

from __future__ import annotations

import shutil
import subprocess
import sys
from pathlib import Path

import numpy as np
import scipy.io

from groundstation.core.dictionary import load_dictionary
from groundstation.logs import LogReader
from groundstation.logs.redecode import redecode

ROOT = Path(__file__).resolve().parents[2]


def gs(*args, timeout=120):
    return subprocess.run([sys.executable, "-m", "groundstation", *args], capture_output=True,
                          text=True, timeout=timeout, cwd=ROOT)


def test_record_info_export_and_redecode(tmp_path):
    out = gs("record", "--folder", str(tmp_path), "--name", "cli test", "--duration", "2",
             "--notes", "bench A, design 2", "--testbed", "profiles/testbeds/inertial_2dof.toml")
    assert out.returncode == 0, out.stderr
    logs = sorted(tmp_path.glob("*.h5"))
    assert len(logs) == 1 and "cli-test_run001" in logs[0].name
    log = logs[0]

    info = gs("log", "info", str(log))
    assert info.returncode == 0, info.stderr
    assert "closed cleanly" in info.stdout and "notes: bench A, design 2" in info.stdout
    assert "encoder_outer [rad]" in info.stdout and "drops 0" in info.stdout
    assert "session opened" in info.stdout                     # the device's EVENT
    with LogReader(log) as r:
        assert r.testbed()[0] == "2-DOF inertial"
        commands = [rec.data["name"] for rec in r.journal("command")]
        assert "CONNECT" in commands and "HEARTBEAT" not in commands
        assert any(rec.data["final_stage"] == "COMPLETED" for rec in r.journal("command"))
        assert r.journal("link")                                # link health, once a second
        n = r.n_frames("HIGH_RATE")
        assert n > 1800

    csv = tmp_path / "x.csv"
    ex = gs("log", "export", str(log), "--channels", "encoder_outer,gyro_rate",
            "--from", "0.5", "--to", "1.0", "--relative", "-o", str(csv))
    assert ex.returncode == 0, ex.stderr
    assert csv.read_text().splitlines()[0].startswith("time_from_start [s],device_time [s],")
    table = np.loadtxt(csv, delimiter=",", skiprows=1)
    assert table.shape == (601, 5)
    assert np.allclose(np.diff(table[:, 0]), 1 / 1200)
    # relative bounds, relative times: the first column lies within the window asked for
    # to a float's rounding (the reader compares t with origin + bound, within 1 ns)
    assert 0.5 - 2e-9 <= table[0, 0] < 0.5 + 1 / 1200 and table[-1, 0] <= 1.0 + 2e-9
    assert np.allclose(table[:, 1] - table[:, 0], table[0, 1] - table[0, 0])   # absolute kept
    mat = tmp_path / "x.mat"
    assert gs("log", "export", str(log), "--format", "mat", "-o", str(mat)).returncode == 0
    m = scipy.io.loadmat(mat, squeeze_me=True, struct_as_record=False)
    assert len(m["HIGH_RATE"].encoder_outer) == n
    assert not hasattr(m["HIGH_RATE"], "time_from_start")          # absolute range: none
    assert gs("log", "export", str(log), "--format", "mat", "-o", str(mat), "--from", "0.5",
              "--to", "1.0", "--relative").returncode == 0
    rel = scipy.io.loadmat(mat, squeeze_me=True, struct_as_record=False)["HIGH_RATE"]
    assert 0.5 - 2e-9 <= rel.time_from_start[0] < 0.5 + 1 / 1200
    assert rel.time_from_start[-1] <= 1.0 + 2e-9
    assert rel.units.time_from_start == "s"

    rp = gs("replay", "--headless", str(log))       # the link statistics, no window
    assert rp.returncode == 0, rp.stderr
    assert f"HIGH_RATE {n} frames, 0 dropped in 0 gap(s)" in " ".join(rp.stdout.split())

    # a newer dictionary that scales the coarse current 2x: same frames, new values
    proto = tmp_path / "protocol"
    shutil.copytree(ROOT / "protocol", proto)
    text = (proto / "telemetry.toml").read_text()
    old = 'name = "current_coarse", type = "i16", units = "A", scale = 1.0e-4'
    assert text.count(old) == 1
    (proto / "telemetry.toml").write_text(text.replace(old, old.replace("1.0e-4", "2.0e-4")))
    target = tmp_path / "redecoded.h5"
    counts = redecode(log, target, load_dictionary(proto))
    assert counts["rejected"] == 0 and counts["HIGH_RATE_frames"] == n
    with LogReader(log) as a, LogReader(target) as b:
        assert np.array_equal(a.frames("HIGH_RATE"), b.frames("HIGH_RATE"))
        ca = a.read("HIGH_RATE", ["current_coarse", "encoder_outer"])
        cb = b.read("HIGH_RATE", ["current_coarse", "encoder_outer"])
        assert np.allclose(cb["current_coarse"], 2 * ca["current_coarse"])
        assert np.array_equal(cb["encoder_outer"], ca["encoder_outer"])
        assert np.array_equal(cb["host_time"], ca["host_time"])
        assert b.summary().dictionary_hash != a.summary().dictionary_hash
        assert [r.kind for r in b.journal("recorder")][-1] == "recorder"


def test_log_commands_explain_bad_files(tmp_path):
    bogus = tmp_path / "not-a-log.h5"
    bogus.write_text("hello")
    out = gs("log", "info", str(bogus))
    assert out.returncode == 2 and "not-a-log.h5" in out.stderr and "Traceback" not in out.stderr
    out = gs("record", "--folder", str(bogus / "sub"), "--duration", "1")
    assert out.returncode == 2 and "not a folder" in out.stderr
