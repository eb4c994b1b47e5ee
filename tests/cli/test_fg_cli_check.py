"""`groundstation fg check LOG` and `fg upload --check`: achieved vs target base motion
from the command line.  The log is recorded from the simulated inertial testbed (clocked
by the test, so a settled period takes well under a second) with its generator playing
a base-motion profile through the real driver; `upload --check` runs the whole chain on
a simulated testbed child in real time with a short period."""

from __future__ import annotations

import re
from pathlib import Path

import numpy as np
import pytest

from conftest import wait_for
from groundstation.basemotion import (BaseMotionError, band_rms, check_record, load_profile,
                                      preview_spectrum)
from groundstation.cli.main import main
from groundstation.instruments import open_generator
from groundstation.link import open_client
from groundstation.logs import Recorder
from groundstation.logs.live import attach_recorder
from groundstation.sim import SimulatedDevice
from groundstation.sim.scpi_server import attach_generator
from groundstation.plant.testbed import TESTBEDS_DIR, load_testbed

ROOT = Path(__file__).resolve().parents[2]
BM_DIR = ROOT / "profiles" / "base_motion"
INERTIAL = load_testbed(TESTBEDS_DIR / "inertial_2dof.toml")
PERIOD_S, SEED = 10.0, 3
SETTLE_S = 5.0                      # > the stage's 3.7 s settling time


def _rms(out: str, which: str) -> float:
    m = re.search(rf"{which} ([0-9.]+) mrad", out)
    assert m, out
    return float(m.group(1))


@pytest.fixture(scope="module")
def bm_log(dictionary, tmp_path_factory):
    """A log of BM2_stage4hz (0.5-8 Hz, the first assumed BM2: 10 s period, seed 3) played for 5 s of settling + one period; the
    output is still on at the log's end (no journal: the window is the log's last period)."""
    folder = tmp_path_factory.mktemp("fg_logs")
    dev = SimulatedDevice(dictionary, pacing="manual", seed=1, testbed=INERTIAL).start()
    server = attach_generator(dev)
    client = open_client(dictionary, f"tcp://127.0.0.1:{dev.tcp_port}?telemetry=stream",
                         heartbeat=False)
    frames = [0]
    client.subscribe(lambda b: frames.__setitem__(0, frames[0] + len(b)) if b.name == "HIGH_RATE" else None)
    rec = Recorder(dictionary, folder, test_name="bm2", testbed_path=str(INERTIAL.path))
    path = rec.start()
    try:
        attach_recorder(client, rec)
        client.connect()
        profile = load_profile(BM_DIR / "BM2_stage4hz.csv", INERTIAL, duration_s=PERIOD_S, seed=SEED)
        with open_generator(server.resource, testbed=INERTIAL) as fg:
            fg.upload_arbitrary(1, profile.volts, name="BM2", frequency_hz=profile.frequency_hz)
            fg.set_output(1, True)
            ticks = int((SETTLE_S + PERIOD_S) * 1200)           # 18000: three steps of 6000
            for done in range(6000, ticks + 1, 6000):
                dev.run_ticks(6000)
                wait_for(lambda: frames[0] >= done, timeout=20)
    finally:
        rec.stop()
        client.close()
        server.stop()
        dev.stop()
    return path


def test_the_check_helpers_agree_with_the_profile():
    """The preview spectrum integrates to the target variance, the octave bands add up to
    the whole, and a window that reaches before the stage settled is refused."""
    profile = load_profile(BM_DIR / "BM1.csv", INERTIAL, duration_s=20.0, seed=1)
    spectrum = preview_spectrum(profile)
    assert np.sum(spectrum.synthesised_psd_rad2_per_hz) / profile.duration_s == pytest.approx(
        profile.target_rms_rad ** 2, rel=1e-6)
    t = np.arange(int(30 * 1200)) / 1200.0             # the expected angle, 1.5 periods
    x = np.interp(t % profile.duration_s, profile.time_s, profile.expected_angle_rad)
    check, window = check_record(t, x, 1200.0, profile, not_before_s=5.0)
    assert window.seconds == pytest.approx(20.0) and window.missing_frames == 0
    assert check.achieved_rms_rad == pytest.approx(profile.target_rms_rad, rel=0.01)
    bands = band_rms(check)
    assert bands[0].low_hz == pytest.approx(0.1) and bands[-1].high_hz == pytest.approx(3.0)
    total = np.sqrt(sum(b.achieved_rms_rad ** 2 for b in bands))
    assert total == pytest.approx(check.achieved_rms_rad, rel=0.02)     # ~all in the band
    with pytest.raises(BaseMotionError, match="more are needed"):
        check_record(t, x, 1200.0, profile, not_before_s=15.0)
    holes = np.ones(len(t), bool)
    holes[20000:21000] = False                           # 1000 frames lost in the window
    with pytest.raises(BaseMotionError, match="missing"):
        check_record(t[holes], x[holes], 1200.0, profile)


def test_a_recorded_profile_passes_and_its_csp_is_written(bm_log, tmp_path, capsys):
    csv = tmp_path / "csp.csv"
    rc = main(["fg", "check", str(bm_log), "--profile", str(BM_DIR / "BM2_stage4hz.csv"),
               "--duration", str(PERIOD_S), "--seed", str(SEED), "--csv", str(csv)])
    out = capsys.readouterr().out
    assert rc == 0, out
    assert "window ends at the end of the log" in out and "result: PASS" in out
    assert _rms(out, "target") == pytest.approx(2.5, abs=1e-3)
    achieved = _rms(out, "achieved")
    assert achieved == pytest.approx(2.5, rel=0.10)
    assert "12000 samples, none missing" in out            # one whole period at 1200 Hz
    assert "per band" in out and "0.5-1" in out              # octaves across 0.5-8 Hz
    table = np.loadtxt(csv, delimiter=",", skiprows=2)
    assert table.shape[1] == 3 and np.all(np.diff(table[:, 0]) > 0)
    # the square root of the CSP at the top is the RMS: target and achieved
    assert np.sqrt(table[-1, 1]) * 1e3 == pytest.approx(2.5, rel=1e-3)
    assert np.sqrt(table[-1, 2]) * 1e3 == pytest.approx(achieved, abs=2e-3)


def test_a_different_target_fails_and_the_tolerance_decides(bm_log, capsys):
    common = ["fg", "check", str(bm_log), "--profile", str(BM_DIR / "BM2_stage4hz.csv"),
              "--duration", str(PERIOD_S), "--rms-mrad", "3.0"]
    assert main(common) == 1                                 # 2.5 achieved vs 3.0: -17 %
    out = capsys.readouterr().out
    assert "result: FAIL" in out and "NOT within 10 %" in out
    assert main(common + ["--tolerance", "0.2"]) == 0
    assert "result: PASS" in capsys.readouterr().out


def test_the_window_can_end_earlier_but_not_before_a_whole_period(bm_log, capsys):
    base = ["fg", "check", str(bm_log), "--profile", str(BM_DIR / "BM2_stage4hz.csv"),
            "--duration", str(PERIOD_S)]
    assert main(base + ["--end", "14"]) in (0, 1)            # 4-14 s: a whole period
    assert "window: device time" in capsys.readouterr().out
    assert main(base + ["--end", "6"]) == 2
    assert "more are needed" in capsys.readouterr().err


def test_unusable_logs_and_profiles_exit_2(bm_log, tmp_path, capsys):
    text = tmp_path / "not_a_log.h5"
    text.write_text("hello")
    assert main(["fg", "check", str(text), "--profile", str(BM_DIR / "BM2_stage4hz.csv")]) == 2
    assert "not an HDF5 file" in capsys.readouterr().err
    assert main(["fg", "check", str(tmp_path / "missing.h5"), "--profile",
                 str(BM_DIR / "BM2_stage4hz.csv")]) == 2
    assert "no such file" in capsys.readouterr().err
    assert main(["fg", "check", str(bm_log), "--profile", str(tmp_path / "nope.csv")]) == 2
    assert "PSD file not found" in capsys.readouterr().err


def test_upload_check_refuses_what_cannot_be_checked_before_anything_moves(capsys):
    bm3 = str(BM_DIR / "BM3.csv")
    assert main(["fg", "upload", "--resource", "sim", "--profile", bm3, "--duration", "2",
                 "--output", "on", "--hold", "3", "--check"]) == 2
    assert "too short for --check" in capsys.readouterr().err
    assert main(["fg", "upload", "--resource", "TCPIP0::127.0.0.1::1::SOCKET", "--profile", bm3,
                 "--duration", "2", "--output", "on", "--hold", "10", "--check"]) == 2
    assert "--device ADDRESS" in capsys.readouterr().err
    assert main(["fg", "upload", "--resource", "sim", "--profile", bm3, "--check"]) == 2
    assert "--check needs --output on" in capsys.readouterr().err


def test_upload_check_on_the_simulated_testbed(tmp_path, capsys):
    """The chain in real time: a 2 s BM3 period, 3.7 s of settling, held 6.5 s."""
    csv = tmp_path / "csp.csv"
    rc = main(["fg", "upload", "--resource", "sim", "--profile", str(BM_DIR / "BM3.csv"),
               "--duration", "2", "--output", "on", "--hold", "6.5", "--check", "--csv", str(csv)])
    out = capsys.readouterr().out
    assert rc == 0, out
    assert "watching the base encoder" in out and "switched off" in out
    assert "achieved vs target (BM3" in out and "result: PASS" in out
    assert _rms(out, "achieved") == pytest.approx(2.1, rel=0.10)
    assert csv.exists()
