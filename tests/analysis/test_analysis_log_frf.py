"""analysis/log_frf.py: a frequency response from a log the fast simulator records,
checked against the testbed model; and on the same log what log_window.py gives it and
the hysteresis adapter alike: the log's testbed, the window, errors that name what is
missing, the logs of a folder.  The hysteresis loop of a triangle is in
test_analysis_log_hysteresis.py."""

from __future__ import annotations

import shutil
from pathlib import Path

import h5py
import numpy as np
import pytest

from groundstation import Testbed
from groundstation.analysis.frf import compare_frf
from groundstation.analysis.log_frf import FRF_INPUTS, FRF_OUTPUTS, frf_from_log
from groundstation.analysis.log_hysteresis import hysteresis_from_log
from groundstation.analysis.log_window import (SIGNAL_CHANNELS, LogIdentificationError,
                                               MissingChannelError, NoExcitationError,
                                               WindowTooShortError, find_logs)
from groundstation.core.errors import GroundStationError
from groundstation.logs import LogReader
from groundstation.plant.testbed import PROFILES_DIR, load_testbed

ROOT = Path(__file__).resolve().parents[2]
NOISE_PROFILE = ROOT / "profiles/waveforms/sysid_coarse_noise_1A.toml"   # 1 A RMS, 5-300 Hz
EXCITED_BAND_HZ = (10.0, 300.0)


def _copied_testbed(folder: Path) -> Path:
    """The 2-DOF relative testbed as a file of the test's own (a test moves it away), its
    slope table beside it where the file's relative path looks for it."""
    (folder / "testbeds").mkdir(parents=True)
    shutil.copy(PROFILES_DIR / "friction_slope_lut.csv", folder / "friction_slope_lut.csv")
    return Path(shutil.copy(PROFILES_DIR / "testbeds/relative_2dof.toml",
                            folder / "testbeds/relative_2dof.toml"))


@pytest.fixture(scope="module")
def sysid(tmp_path_factory):
    """(log, testbed file): open-loop random coarse current, 1 A RMS, for 6 s."""
    folder = tmp_path_factory.mktemp("sysid")
    testbed = _copied_testbed(folder)
    with Testbed("sim", testbed=testbed, fast=True, generator=None, log_folder=folder,
                 history=folder / "h") as tb:
        tb.set_mode("OPEN_LOOP")
        path = tb.start_recording("sysid")
        tb.dwell(0.5)                       # a stretch at rest before the profile
        tb.play(NOISE_PROFILE, max_seconds=6.0)
        tb.stop_recording()
    return path, testbed


def test_frf_of_open_loop_noise_matches_the_model_where_coherent(sysid):
    """The twin obeys the linear model except for the bearing's friction, which the model
    leaves out.  At 1 A RMS (32 in-oz against T_c = 2.25 in-oz) the bearing slides most of
    the time, so friction is a small disturbance: the coherence is near 1 over the excited
    band and the magnitude agrees within a fraction of a dB on average.  Where the output
    is small - the flexure's anti-resonance near 30 Hz - the friction torque is not small
    against the response, so single bins there may part by a few dB; hence a bound on the
    RMS over the coherent bins (1 dB) and a looser one on the worst bin (5 dB)."""
    path, _ = sysid
    res = frf_from_log(path, "current_coarse", "encoder_outer")
    m = res.measured
    assert res.model_path == "T1->phi1" and res.model_per_amp
    assert "K_t 32.1" in res.model_description and "ZOH" in res.model_description
    assert m.units == "rad/A"
    assert any("narrowed to the profile" in n for n in res.notes)
    assert res.frames == pytest.approx(6.0 * 1200, abs=2)      # the profile's samples only
    band = (m.freq_hz >= EXCITED_BAND_HZ[0]) & (m.freq_hz <= EXCITED_BAND_HZ[1])
    coh = m.coherence[band]
    assert np.nanmedian(coh) > 0.99
    assert np.mean(coh >= 0.9) > 0.9
    cmp_ = compare_frf(m, res.model, min_coherence=0.9, band_hz=EXCITED_BAND_HZ)
    assert cmp_.bins_used > 0.85 * np.count_nonzero(band)
    assert cmp_.rms_magnitude_ratio_db < 1.0
    assert cmp_.max_abs_magnitude_ratio_db < 5.0
    # above the anti-resonance the inertia dominates and the two agree closely, phase too
    hi = cmp_.used & (m.freq_hz >= 100.0)
    assert np.max(np.abs(cmp_.magnitude_ratio_db[hi])) < 0.5
    assert np.max(np.abs(cmp_.phase_difference_deg[hi])) < 3.0
    # no excitation above the profile's band: nothing to trust there
    assert np.nanmedian(m.coherence[m.freq_hz > 400.0]) < 0.5


def test_frf_against_the_torque_command_is_per_in_oz(sysid):
    path, _ = sysid
    amps = frf_from_log(path, "current_coarse", "encoder_outer", nperseg=512)
    torque = frf_from_log(path, "torque_coarse_cmd", "encoder_outer", nperseg=512)
    assert not torque.model_per_amp and torque.measured.units == "rad/in-oz"
    kt = load_testbed(sysid[1]).motor_coarse["torque_constant"]
    # the same response, per ampere = per in-oz x K_t (the current is 0.1 mA quantised)
    band = (amps.measured.freq_hz >= 100.0) & (amps.measured.freq_hz <= 300.0)
    ratio = np.abs(amps.measured.response[band] / torque.measured.response[band])
    np.testing.assert_allclose(ratio, kt, rtol=0.01)
    np.testing.assert_allclose(amps.model, torque.model * kt, rtol=1e-12)


def test_window_and_segments_choose_the_data(sysid):
    path, _ = sysid
    whole = frf_from_log(path)
    part = frf_from_log(path, start_s=whole.window_from_s + 1.0, stop_s=whole.window_from_s + 4.0,
                        nperseg=256)
    assert part.frames == pytest.approx(3.0 * 1200, abs=2)
    assert part.measured.nperseg == 256 and part.measured.segments >= 2
    kept = frf_from_log(path, trim_to_profile=False)
    assert kept.frames > whole.frames and not any("narrowed" in n for n in kept.notes)


def test_a_moved_testbed_file_leaves_the_measurement_without_a_model(sysid):
    path, testbed = sysid
    away = testbed.with_suffix(".moved")
    testbed.rename(away)
    try:
        res = frf_from_log(path)
        assert res.model is None and res.comparison is None and res.model_path == ""
        assert any("not there any more" in n for n in res.notes)
        given = frf_from_log(path, testbed=ROOT / "profiles/testbeds/relative_2dof.toml")
        assert given.model is not None and "testbed file" in given.testbed_source
        # the hysteresis takes K_t from the text the log recorded
        loop = hysteresis_from_log(path)
        assert loop.torque_constant_in_oz_per_a == 32.1
    finally:
        away.rename(testbed)


def test_missing_channel_is_named(sysid, tmp_path):
    path, _ = sysid
    broken = Path(shutil.copy(path, tmp_path / "no_current.h5"))
    with h5py.File(broken, "a") as f:
        del f["telemetry/HIGH_RATE/current_coarse"]
        del f["telemetry/HIGH_RATE/raw/current_coarse"]
    with pytest.raises(MissingChannelError, match="no HIGH_RATE channel 'current_coarse'"):
        frf_from_log(broken)
    with pytest.raises(MissingChannelError, match="'current_coarse' for a hysteresis loop"):
        hysteresis_from_log(broken)
    # the other input still works on the same file
    assert frf_from_log(broken, "torque_coarse_cmd").frames > 0


def test_short_window_and_no_excitation_are_specific_errors(sysid):
    path, _ = sysid
    with LogReader(path) as r:
        d = r.read("HIGH_RATE", ["profile_index"], relative=True)
        t = d["device_time"] - r.origin("device")
    first_played = float(t[np.argmax(d["profile_index"] > 0)])
    with pytest.raises(WindowTooShortError, match="too few for a frequency response"):
        frf_from_log(path, start_s=first_played + 1.0, stop_s=first_played + 1.005)
    with pytest.raises(WindowTooShortError, match="with segments of 4096"):
        frf_from_log(path, start_s=first_played + 1.0, stop_s=first_played + 3.0, nperseg=4096)
    with pytest.raises(WindowTooShortError, match="no HIGH_RATE frames in the window"):
        frf_from_log(path, start_s=1e4)
    with pytest.raises(WindowTooShortError, match="'from' must be before 'to'"):
        hysteresis_from_log(path, start_s=3.0, stop_s=2.0)
    # the rest before the profile: no current, nothing moves
    with pytest.raises(NoExcitationError, match="current_coarse is constant"):
        frf_from_log(path, stop_s=first_played - 0.1)
    with pytest.raises(NoExcitationError, match="no torque, no loop"):
        hysteresis_from_log(path, stop_s=first_played - 0.1)
    with pytest.raises(LogIdentificationError, match="choose one of"):
        frf_from_log(path, input_channel="reference")
    for cls in (MissingChannelError, WindowTooShortError, NoExcitationError):
        assert issubclass(cls, GroundStationError)


def test_find_logs_lists_a_folder(sysid, tmp_path):
    path, _ = sysid
    (tmp_path / "run" / "sub").mkdir(parents=True)
    shutil.copy(path, tmp_path / "run" / "b.h5")
    shutil.copy(path, tmp_path / "run" / "sub" / "a.h5")
    (tmp_path / "run" / "notes.txt").write_text("not a log")
    assert find_logs(tmp_path / "run") == [tmp_path / "run" / "b.h5", tmp_path / "run" / "sub" / "a.h5"]
    with pytest.raises(GroundStationError, match="not a folder"):
        find_logs(tmp_path / "nowhere")


def test_a_missing_channel_message_lists_the_frf_channels_the_log_has():
    """log_window names them for every adapter; they are the frequency response's."""
    assert SIGNAL_CHANNELS == (*FRF_INPUTS, *FRF_OUTPUTS)
