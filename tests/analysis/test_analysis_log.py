"""The log adapter (groundstation.analysis.log_metrics) and `groundstation analyze`, on a
short log recorded from the simulated inertial testbed in open loop: constant currents
(a known energy), then currents that drive the autocollimator to both ends of its range
(samples to exclude).  The chunked reading must give what the in-memory functions give
on the same data."""

from __future__ import annotations

import csv
import io
import json
import math
import shutil
from pathlib import Path

import h5py
import numpy as np
import pytest

from groundstation.cli import analysis as cli_analysis
from groundstation import Testbed
from groundstation.analysis import (AnalysisError, analyze_log, control_energy, los_jitter, psd,
                                    sensor_valid)
from groundstation.analysis import log_metrics
from groundstation.analysis.frame_gaps import frame_steps, missing_before
from groundstation.analysis.testbed_figures import figures_from_testbed
from groundstation.cli.main import main
from groundstation.logs import LogError, LogReader
from groundstation.plant.testbed import load_testbed

ROOT = Path(__file__).resolve().parents[2]
TESTBED = ROOT / "profiles/testbeds/inertial_2dof.toml"
I_COARSE_A, I_FINE_A = 0.05, 0.01


@pytest.fixture(scope="module")
def sim_log(tmp_path_factory) -> Path:
    folder = tmp_path_factory.mktemp("analysis_logs")
    with Testbed("sim", testbed=TESTBED, fast=True, generator=None, log_folder=folder,
                 history=folder / "history") as tb:
        tb.start_recording("analysis", notes="open loop: constant currents, then the "
                                              "autocollimator driven out of its range")
        tb.set_mode("OPEN_LOOP")
        tb.arm()
        tb.set_currents(I_COARSE_A, I_FINE_A)
        tb.dwell(2.0)
        tb.set_currents(0.3, 0.0)          # to the + end of the autocollimator's range
        tb.dwell(0.5)
        tb.set_currents(-0.3, 0.0)         # through the range to the - end
        tb.dwell(0.7)
        tb.set_currents(0.0, 0.0)
        tb.dwell(0.3)
        entry = tb.stop_recording()
    return Path(entry["files"][0])


def copy_of(log: Path, tmp_path: Path) -> Path:
    out = tmp_path / log.name
    shutil.copyfile(log, out)
    return out


def in_memory(path: Path, start=None, stop=None, *, integration_period_s=1.0, psd_segment_s=1.0):
    """The figures from whole arrays read at once, with the in-memory functions."""
    tb = load_testbed(TESTBED)
    with LogReader(path) as r:
        rate = r.tick_rate_hz
        d = r.read("HIGH_RATE", ["tick", "autocollimator", "raw/autocollimator", "current_coarse",
                                 "current_fine", "coarse_saturated", "fine_saturated"],
                   start=start, stop=stop, relative=True)
    gap, missing, _ = frame_steps(d["tick"])
    ok = sensor_valid(d["autocollimator"], range_rad=math.radians(tb.sensors["autocollimator_range"]),
                      raw_counts=d["raw/autocollimator"])
    j = los_jitter(d["autocollimator"], rate, integration_period_s=integration_period_s, valid=ok,
                   gap_before=gap, missing_before=missing_before(d["tick"]), missing_frames=missing)
    e = control_energy(d["current_coarse"], d["current_fine"], rate, tb.motor_coarse["resistance"],
                       tb.motor_fine["resistance"], coarse_saturated=d["coarse_saturated"],
                       fine_saturated=d["fine_saturated"], missing_frames=missing)
    s = psd(d["autocollimator"], rate, segment_s=psd_segment_s, valid=ok, gap_before=gap)
    return j, e, s, d


JITTER_FIGURES = ("mean_rad", "rms_rad", "std_rad", "highpass_rms_rad", "smear_rms_rad")
ENERGY_FIGURES = ("energy_coarse_j", "energy_fine_j", "rms_current_coarse_a", "rms_current_fine_a",
                  "saturated_coarse_fraction", "saturated_fine_fraction")


# ---------------------------------------------------------------------- chunked = in memory
@pytest.mark.parametrize("window", [(None, None), (0.3, 3.2)])
def test_chunked_reading_equals_the_in_memory_functions(sim_log, window):
    j, e, s, d = in_memory(sim_log, *window)
    # the log drove the autocollimator out of range and back: exclusions and two stretches
    assert j.samples_excluded > 500 and j.segments >= 2
    m = analyze_log(sim_log, start_s=window[0], stop_s=window[1], psd_segment_s=1.0, chunk_rows=97)
    assert m.frames == len(d["tick"]) == m.jitter.samples_used + m.jitter.samples_excluded
    for name in JITTER_FIGURES:
        assert getattr(m.jitter, name) == pytest.approx(getattr(j, name), rel=1e-9, nan_ok=True), name
    assert (m.jitter.samples_used, m.jitter.samples_excluded, m.jitter.segments) == \
        (j.samples_used, j.samples_excluded, j.segments)
    for name in ENERGY_FIGURES:
        assert getattr(m.energy, name) == pytest.approx(getattr(e, name), rel=1e-9), name
    assert m.spectrum.segments == s.segments
    np.testing.assert_allclose(m.spectrum.density, s.density, rtol=1e-9)
    assert "0.33 deg" in m.jitter.exclusion_rule and "16-bit A/D rail" in m.jitter.exclusion_rule


def test_the_default_chunk_gives_the_same_figures(sim_log):
    small = analyze_log(sim_log, chunk_rows=1000)
    big = analyze_log(sim_log)
    for name in JITTER_FIGURES:
        assert getattr(small.jitter, name) == pytest.approx(getattr(big.jitter, name), rel=1e-9, nan_ok=True)
    assert small.energy.energy_total_j == pytest.approx(big.energy.energy_total_j, rel=1e-12)


# ---------------------------------------------------------------------- known answers
def test_constant_currents_give_i2_r_t(sim_log):
    with LogReader(sim_log) as r:
        d = r.read("HIGH_RATE", ["current_coarse", "current_fine"], relative=True)
        on = np.flatnonzero(np.isclose(d["current_coarse"], I_COARSE_A))
        t_on = d["device_time"][on[0]] - r.origin()
        t_off = d["device_time"][on[-1]] - r.origin()
        rate = r.tick_rate_hz
    start, stop = t_on + 0.1, t_off - 0.1
    m = analyze_log(sim_log, metrics=["energy"], start_s=start, stop_s=stop)
    seconds = m.frames / rate
    assert seconds == pytest.approx(stop - start, abs=1.5 / rate)
    tb = load_testbed(TESTBED)
    r1, r2 = tb.motor_coarse["resistance"], tb.motor_fine["resistance"]
    assert m.energy.energy_coarse_j == pytest.approx(I_COARSE_A ** 2 * r1 * seconds, rel=1e-9)
    assert m.energy.energy_fine_j == pytest.approx(I_FINE_A ** 2 * r2 * seconds, rel=1e-9)
    assert m.energy.rms_current_coarse_a == pytest.approx(I_COARSE_A, rel=1e-9)
    assert m.energy.saturated_coarse_fraction == 0.0 and m.energy.saturated_fine_fraction == 0.0
    assert m.window_from_s == pytest.approx(start, abs=1 / rate)
    assert m.jitter is None and m.spectrum is None and m.missing_metrics == ()


def test_other_sensors_can_be_scored(sim_log):
    for sensor in ("los_estimate", "encoder_inner"):
        m = analyze_log(sim_log, metrics=["jitter"], sensor=sensor)
        assert m.sensor == sensor and m.jitter.samples_excluded == 0 and m.jitter.segments == 1
        assert m.jitter.std_rad > 0
    with pytest.raises(AnalysisError, match="unknown sensor 'gyro_rate'"):
        analyze_log(sim_log, sensor="gyro_rate")


# ---------------------------------------------------------------------- missing frames
def test_missing_frames_are_counted_and_never_bridged(sim_log, tmp_path):
    """Five frames lost after row 1500: the ticks jump by 6 there."""
    log = copy_of(sim_log, tmp_path)
    with h5py.File(log, "r+") as f:
        tick = f["telemetry/HIGH_RATE/tick"]
        t = tick[...]
        t[1500:] += 5
        tick[...] = t
    intact = analyze_log(sim_log, metrics=["jitter", "energy"], chunk_rows=256)
    holed = analyze_log(log, metrics=["jitter", "energy"], chunk_rows=256)
    assert holed.missing_frames == 5 and intact.missing_frames == 0
    assert holed.jitter.missing_frames == 5 and holed.energy.missing_frames == 5
    assert holed.jitter.segments == intact.jitter.segments + 1
    # the energy covers the frames received, not the hole
    assert holed.energy.samples == intact.energy.samples == holed.frames
    assert holed.energy.energy_total_j == pytest.approx(intact.energy.energy_total_j, rel=1e-12)
    gap, missing, stalled = frame_steps(np.array([10, 11, 15, 15, 16, 2 ** 32 - 1, 0], np.uint32), 9)
    assert gap.tolist() == [False, False, True, True, False, True, False]
    # 11 -> 15: three missing; 15 -> 15 and 16 -> 2^32 - 1 (17 back, modulo the wrap) stall
    assert (missing, stalled) == (3, 2)
    # per frame, for the high-pass's bridge: 3 before 15, -1 (no known length) at a stall
    assert missing_before(np.array([10, 11, 15, 15, 16, 2 ** 32 - 1, 0], np.uint32), 9).tolist() == \
        [0, 0, 3, -1, 0, -1, 0]


def test_a_wrapping_tick_is_not_a_gap():
    gap, missing, stalled = frame_steps(np.array([2 ** 32 - 2, 2 ** 32 - 1, 0, 1], np.uint32))
    assert not gap.any() and missing == stalled == 0
    gap, missing, _ = frame_steps(np.array([0, 1], np.uint32), 2 ** 32 - 1)
    assert not gap.any() and missing == 0


# ---------------------------------------------------------------------- the testbed constants
def test_the_testbed_comes_from_the_log(sim_log, tmp_path):
    with LogReader(sim_log) as r:
        fig = figures_from_testbed(r)
    assert fig.autocollimator_range_rad == pytest.approx(math.radians(0.33))
    assert (fig.resistance_coarse_ohm, fig.resistance_fine_ohm) == (4.8, 6.8)
    assert "2-DOF inertial" in fig.source
    # the recorded path gone (another machine): the text recorded with the log
    log = copy_of(sim_log, tmp_path)
    with h5py.File(log, "r+") as f:
        f["testbed"].attrs["path"] = "/nowhere/inertial_2dof.toml"
    with LogReader(log) as r:
        fig = figures_from_testbed(r)
    assert "as recorded in the log" in fig.source and fig.resistance_fine_ohm == 6.8


def test_a_log_without_its_testbed(sim_log, tmp_path):
    log = copy_of(sim_log, tmp_path)
    with h5py.File(log, "r+") as f:
        del f["testbed"]
    with pytest.raises(AnalysisError, match=r"motor resistances .* unknown .* give --testbed FILE"):
        analyze_log(log)
    m = analyze_log(log, metrics=["jitter"])
    assert any("calibrated range is unknown" in n for n in m.notes)
    # the rail still excludes what the range would have (the range is the rail here)
    assert m.jitter.samples_excluded == analyze_log(sim_log, metrics=["jitter"]).jitter.samples_excluded
    full = analyze_log(log, testbed=TESTBED)
    assert full.energy.resistance_coarse_ohm == 4.8 and f"testbed file {TESTBED}" == full.testbed_source


# ---------------------------------------------------------------------- bad input
def test_bad_input_gets_a_specific_message(sim_log, tmp_path):
    with pytest.raises(AnalysisError, match=r"no HIGH_RATE frames in the window .*the log holds 0.0 \.\."):
        analyze_log(sim_log, start_s=100.0, stop_s=200.0)
    not_a_log = tmp_path / "notes.h5"
    not_a_log.write_text("not a log")
    with pytest.raises(LogError, match="not an HDF5 file"):
        analyze_log(not_a_log)
    with pytest.raises(LogError, match="no such file"):
        analyze_log(tmp_path / "missing.h5")
    log = copy_of(sim_log, tmp_path)
    with h5py.File(log, "r+") as f:
        del f["telemetry/HIGH_RATE/autocollimator"]
        del f["telemetry/HIGH_RATE/raw/autocollimator"]
    with pytest.raises(AnalysisError, match=r"no HIGH_RATE channel 'autocollimator'; score another "
                                            r"sensor \(--sensor los_estimate \| encoder_inner\)"):
        analyze_log(log)
    with pytest.raises(AnalysisError, match="unknown metric"):
        analyze_log(sim_log, metrics=["jitter", "bode"])


def test_every_sample_excluded_leaves_that_figure_out_with_the_reason(sim_log):
    with LogReader(sim_log) as r:
        d = r.read("HIGH_RATE", ["raw/autocollimator"], relative=True)
        rail = np.flatnonzero(d["raw/autocollimator"] == 32767)
        t0, t1 = d["device_time"][rail[100]] - r.origin(), d["device_time"][rail[400]] - r.origin()
    m = analyze_log(sim_log, start_s=t0, stop_s=t1)
    assert m.jitter is None and m.spectrum is None and m.energy is not None
    assert m.missing_metrics == ("jitter", "psd")
    assert any("no jitter: all 301 autocollimator samples" in n for n in m.notes)


# ---------------------------------------------------------------------- the command line
def test_the_cli_prints_one_row_per_log(sim_log, tmp_path, capsys):
    assert main(["analyze", str(sim_log), "--psd-segment", "1"]) == 0
    out = capsys.readouterr().out
    lines = out.splitlines()
    assert lines[0].split()[:3] == ["log", "window", "s"]
    assert sim_log.name in lines[1] and "E total J" in lines[0] and "RMS urad" in lines[0]
    assert "samples excluded (|angle| >= 5.76 mrad" in out and "resistances 4.8 / 6.8 ohm" in out


def test_the_cli_json_and_csv_agree_with_the_adapter(sim_log, tmp_path, capsys):
    m = analyze_log(sim_log, psd_segment_s=1.0, start_s=0.2, stop_s=1.9)
    args = ["analyze", str(sim_log), "--from", "0.2", "--to", "1.9", "--psd-segment", "1"]
    assert main(args + ["--json"]) == 0
    rows = json.loads(capsys.readouterr().out)
    assert len(rows) == 1 and rows[0]["error"] == ""
    assert rows[0]["rms_urad"] == pytest.approx(m.jitter.rms_rad * 1e6)
    assert rows[0]["energy_total_j"] == pytest.approx(m.energy.energy_total_j)
    assert rows[0]["psd_rms_urad"] == pytest.approx(m.spectrum.rms * 1e6)
    assert main(args + ["--csv", "--metrics", "energy"]) == 0
    table = list(csv.DictReader(io.StringIO(capsys.readouterr().out)))
    assert list(table[0]) == cli_analysis.ROW_KEYS
    assert float(table[0]["energy_fine_j"]) == pytest.approx(m.energy.energy_fine_j)
    assert table[0]["rms_urad"] == ""                       # jitter not asked for


def test_an_unreadable_log_is_a_row_with_its_error(sim_log, tmp_path, capsys):
    bad = tmp_path / "broken.h5"
    bad.write_bytes(b"")
    assert main(["analyze", str(sim_log), str(bad), "--json", "--psd-segment", "1"]) == 1
    out, err = capsys.readouterr()
    rows = json.loads(out)
    assert [r["log"] for r in rows] == [sim_log.name, "broken.h5"]
    assert "broken.h5: " in err and "damaged log" in err      # the reason, not only a status
    assert rows[0]["error"] == "" and "damaged log" in rows[1]["error"] and rows[1]["rms_urad"] is None
    assert main(["analyze", str(bad)]) == 1
    out = capsys.readouterr().out
    assert "broken.h5: error:" in out and "empty (0 bytes)" in out


def test_bad_arguments_exit_2(sim_log, capsys):
    for args in (["--metrics", "jitter,bode"], ["--sensor", "gyro_rate"],
                 ["--integration-period", "0"], ["--json", "--csv"]):
        with pytest.raises(SystemExit) as exc:
            main(["analyze", str(sim_log), *args])
        assert exc.value.code == 2, args
    capsys.readouterr()
    assert main(["analyze", str(sim_log), "--from", "3", "--to", "1"]) == 2
    assert "--from 3 s is after --to 1 s" in capsys.readouterr().err
    assert main(["analyze", str(sim_log), "--testbed", "no/such/testbed.toml"]) == 2
    assert "testbed file not found" in capsys.readouterr().err


def test_the_cli_plots_the_spectrum(sim_log, tmp_path, capsys):
    png = tmp_path / "psd.png"
    assert main(["analyze", str(sim_log), "--metrics", "energy", "--plot", str(png),
                 "--psd-segment", "1"]) == 0
    assert png.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"
    assert f"plot: {png}" in capsys.readouterr().err


def test_the_cli_choices_are_the_analysis_ones():
    assert cli_analysis.METRICS == log_metrics.METRICS
    assert cli_analysis.SENSORS == log_metrics.SENSORS
    assert cli_analysis.SENSORS[0] == log_metrics.DEFAULT_SENSOR
    assert cli_analysis.AUTO_SENSOR == log_metrics.AUTO_SENSOR


def test_a_sensor_that_never_moves_is_not_scored_as_perfect(tmp_path):
    """The relative rig has no autocollimator: its channel reads one constant.  That is
    no jitter figure (not 0 urad), with the reason and the sensor to choose instead."""
    with Testbed("sim", testbed=ROOT / "profiles/testbeds/relative_2dof.toml", fast=True,
                 generator=None, log_folder=tmp_path, history=tmp_path / "history") as tb:
        tb.start_recording("no autocollimator")
        tb.dwell(1.0)
        log = Path(tb.stop_recording()["files"][0])
    m = analyze_log(log)
    assert m.jitter is None and m.spectrum is None and m.energy is not None
    assert any("autocollimator reads one constant value" in n and "relative set-up" in n
               and "--sensor encoder_inner" in n for n in m.notes)
    inner = analyze_log(log, sensor="encoder_inner")
    assert inner.jitter is not None and inner.jitter.std_rad > 0
    # "auto" (the command line's default) picks the relative set-up's sensor by itself
    auto = analyze_log(log, sensor=log_metrics.AUTO_SENSOR)
    assert auto.sensor == "encoder_inner" and auto.jitter == inner.jitter
    assert main(["analyze", str(log), "--json"]) == 0


# ---------------------------------------------------------------------- validity
def test_a_window_off_the_range_is_not_valid(sim_log):
    """The log drove the autocollimator off its range: its row says which fraction of
    the window was excluded and that the window is not valid (above 1 %), in words."""
    m = analyze_log(sim_log)
    row = m.row()
    excluded = m.jitter.samples_excluded / (m.frames + m.missing_frames)
    assert row["excluded_fraction"] == pytest.approx(excluded) and excluded > 0.01
    assert row["valid"] is False and row["max_excluded_fraction"] == 0.01
    assert "of the window off the autocollimator's range or at its A/D rail" in row["invalid_reason"]
    assert "NOT VALID" in m.text()
    assert row["highpass_samples_used"] + row["highpass_samples_settling"] == row["samples_used"]
    # the limit is the caller's to move; the part before the excursion is a clean window
    assert m.row(max_excluded_fraction=1.0)["valid"] is True
    clean = analyze_log(sim_log, stop_s=1.5).row()
    assert clean["valid"] is True and clean["excluded_fraction"] == 0.0 and clean["invalid_reason"] == ""


def test_a_figure_that_cannot_be_computed_says_why_on_stderr_with_csv(sim_log, capsys):
    """--csv puts the rows on stdout; the reason for exit status 1 (a PSD segment longer
    than the log) must not hide in the notes column only."""
    assert main(["analyze", str(sim_log), "--csv", "--psd-segment", "1000"]) == 1
    out, err = capsys.readouterr()
    assert sim_log.name in out
    assert "error: 1 of 1 log(s) could not be analysed:" in err
    assert f"{sim_log.name}: not computed: psd" in err
