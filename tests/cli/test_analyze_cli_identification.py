"""`groundstation analyze --metrics step,frf,hysteresis`: the identification figures of
analysis/log_step.py, log_frf.py and log_hysteresis.py per log, from short logs the fast
simulator records; a log whose figure cannot be computed gets the error in its row and
exit status 1."""

from __future__ import annotations

import csv
import io
import json
from pathlib import Path

import numpy as np
import pytest

from groundstation import Testbed
from groundstation.analysis.log_step import NoStepError, step_from_log
from groundstation.analysis.step import step_metrics
from groundstation.cli.main import main
from groundstation.logs import LogReader
from groundstation.plant.slope_table import load_slope_table
from groundstation.profiles.profile import profile_from_dict

ROOT = Path(__file__).resolve().parents[2]
TESTBED = ROOT / "profiles/testbeds/relative_2dof.toml"
DESIGN = ROOT / "profiles/controllers/relative_design2.toml"
NOISE_PROFILE = ROOT / "profiles/waveforms/sysid_coarse_noise_1A.toml"   # 1 A RMS, 5-300 Hz
STEP_RAD = 1e-4


@pytest.fixture(scope="module")
def logs(tmp_path_factory):
    """{"step": a 100 urad relative step, "noise": open-loop random coarse current}."""
    tmp = tmp_path_factory.mktemp("identification_cli")
    with Testbed("sim", testbed=TESTBED, fast=True, generator=None, log_folder=tmp,
                 history=tmp / "h") as tb:
        tb.upload_design(DESIGN)
        tb.set_mode("RELATIVE")
        tb.arm()
        tb.start_recording("step")
        tb.dwell(0.5)
        tb.set_reference(STEP_RAD)
        tb.dwell(2.0)
        step = tb.stop_recording()["files"][0]
    with Testbed("sim", testbed=TESTBED, fast=True, generator=None, log_folder=tmp,
                 history=tmp / "h2") as tb:
        tb.set_mode("OPEN_LOOP")
        noise = tb.start_recording("sysid")
        tb.dwell(0.5)
        tb.play(NOISE_PROFILE, max_seconds=3.0)
        tb.stop_recording()
    return {"step": Path(step), "noise": Path(noise)}


def _expected_step(path: Path):
    """step_metrics of the log's own arrays, the step found here independently."""
    with LogReader(path) as r:
        d = r.read("HIGH_RATE", ["reference", "error_angle", "current_coarse"])
        origin = r.origin("device")
    t = d["device_time"] - origin
    ref = np.asarray(d["reference"], dtype=np.float64)
    k = int(np.argmax(np.abs(np.diff(ref))))
    size = ref[k + 1] - ref[k]
    return t[k + 1], size, step_metrics(t, ref - d["error_angle"], size, t[k + 1],
                                        d["current_coarse"])


def test_step_figures_are_step_metrics_of_the_logs_arrays(logs, capsys):
    t_step, size, exp = _expected_step(logs["step"])
    assert size == pytest.approx(STEP_RAD, rel=1e-3) and t_step == pytest.approx(0.5, abs=0.05)
    assert exp.rise_time_s > 0 and exp.peak_effort > 0
    res = step_from_log(logs["step"])
    assert res.step_time_s == t_step and res.step_size == size and res.metrics == exp

    assert main(["analyze", str(logs["step"]), "--metrics", "step", "--json"]) == 0
    (row,) = json.loads(capsys.readouterr().out)
    assert row["error"] == "" and row["step_effort_channel"] == "current_coarse"
    assert row["step_time_s"] == pytest.approx(t_step)
    assert row["step_size_urad"] == pytest.approx(size * 1e6)
    assert row["step_rise_s"] == pytest.approx(exp.rise_time_s)
    assert row["step_overshoot_pct"] == pytest.approx(exp.overshoot_percent)
    assert row["step_steady_state_error_urad"] == pytest.approx(exp.steady_state_error * 1e6)
    assert row["step_peak_effort"] == pytest.approx(exp.peak_effort)
    if exp.settled:
        assert row["step_settling_s"] == pytest.approx(exp.settling_time_s)
    else:
        assert row["step_settling_s"] is None

    assert main(["analyze", str(logs["step"]), "--metrics", "energy,step"]) == 0
    out = capsys.readouterr().out
    assert "E total J" in out.splitlines()[0]
    line = next(ln for ln in out.splitlines() if ": step: " in ln)
    assert f"rise {exp.rise_time_s * 1e3:.1f} ms" in line
    assert f"overshoot {exp.overshoot_percent:.2f} %" in line
    assert f"steady-state error {exp.steady_state_error * 1e6:.3g} urad" in line
    assert f"peak effort {exp.peak_effort:.4g} A (current_coarse)" in line


def test_frf_of_open_loop_noise_has_coherent_figures(logs, capsys):
    args = ["analyze", str(logs["noise"]), "--metrics", "frf"]
    assert main(args + ["--json"]) == 0
    (row,) = json.loads(capsys.readouterr().out)
    assert row["error"] == ""
    assert (row["frf_input"], row["frf_output"]) == ("current_coarse", "encoder_outer")
    assert row["frf_coherent_bins"] > 10
    assert row["frf_coherent_from_hz"] < 100.0 and row["frf_coherent_to_hz"] > 250.0
    assert 0.0 <= row["frf_rms_db"] < 2.0            # the twin is the model but for friction
    assert "narrowed to the profile" in row["notes"]

    assert main(args + ["--csv", "--frf-input", "torque_coarse_cmd"]) == 0
    (crow,) = list(csv.DictReader(io.StringIO(capsys.readouterr().out)))
    assert crow["frf_input"] == "torque_coarse_cmd" and float(crow["frf_coherent_bins"]) > 10
    assert crow["rms_urad"] == "" and crow["step_rise_s"] == ""

    assert main(args) == 0
    out = capsys.readouterr().out
    assert "frf: current_coarse -> encoder_outer: coherence >= 0.9 from" in out
    assert "dB from the model (T1->phi1) over the coherent bins" in out


def test_a_log_without_a_step_is_a_row_with_the_error(logs, capsys):
    with pytest.raises(NoStepError, match="makes no step"):
        step_from_log(logs["noise"])
    assert main(["analyze", str(logs["noise"]), str(logs["step"]), "--metrics", "step",
                 "--json"]) == 1
    out, err = capsys.readouterr()
    rows = json.loads(out)
    assert rows[0]["error"].startswith("step: ") and "makes no step" in rows[0]["error"]
    # stdout is data: the reason for exit status 1 is on stderr too
    assert "error: 1 of 2 log(s) could not be analysed:" in err
    assert f"{logs['noise'].name}: step: " in err and "makes no step" in err
    assert rows[0]["step_rise_s"] is None
    assert rows[1]["error"] == "" and rows[1]["step_rise_s"] > 0          # the other goes on
    assert main(["analyze", str(logs["noise"]), "--metrics", "step"]) == 1
    out, err = capsys.readouterr()
    assert f"{logs['noise'].name}: step: error: " in out
    assert f"error: 1 of 1 log(s) could not be analysed: {logs['noise'].name}" in err


def test_hysteresis_of_a_triangle_writes_the_slope_table(tmp_path, capsys):
    """A closed-loop position triangle as in test_analysis_log_hysteresis.py; the
    slope table's file is written (--slope-table implies --metrics hysteresis)."""
    profile = profile_from_dict({
        "profile": {"name": "friction_triangle_test", "target": "REFERENCE", "units": "rad",
                    "origin": "relative"},
        "generator": {"type": "triangle", "amplitude_deg": 0.05, "velocity_deg_per_s": 0.01,
                      "cycles": 2, "turnaround_s": 0.5}})
    with Testbed("sim", testbed=TESTBED, fast=True, generator=None, log_folder=tmp_path,
                 history=tmp_path / "h") as tb:
        tb.upload_design(DESIGN)
        path = tb.start_recording("triangle")
        tb.play(profile)
        tb.stop_recording()
    table = tmp_path / "lut.csv"
    assert main(["analyze", str(path), "--metrics", "energy", "--slope-table", str(table),
                 "--json"]) == 0
    (row,) = json.loads(capsys.readouterr().out)
    assert row["error"] == "" and row["hyst_slope_table"] is True
    assert row["hyst_complete_branches"] >= 2 and 1.5 < row["hyst_coulomb_in_oz"] < 3.0
    assert row["hyst_slope_table_file"] == str(table)
    assert row["energy_total_j"] > 0
    x, f = load_slope_table(table)
    assert x[0] == 0.0 and x[-1] == 2.0 and np.all(np.diff(f) <= 0)


def test_the_cli_channel_choices_are_the_analysis_ones():
    from groundstation.cli import analysis as cli_analysis
    from groundstation.analysis import log_frf

    assert cli_analysis.FRF_INPUTS == tuple(log_frf.FRF_INPUTS)
    assert cli_analysis.FRF_OUTPUTS == tuple(log_frf.FRF_OUTPUTS)
    assert cli_analysis.MIN_COHERENCE == log_frf.DEFAULT_MIN_COHERENCE


def test_reference_transitions_group_a_shaped_step_and_split_separate_ones():
    from groundstation.analysis.log_step import STEP_MERGE_S, _reference_transitions

    rate = 1200.0
    ref = np.zeros(3 * int(rate))
    ref[600:] = 1e-3                                          # a raw step: one frame
    shaped = 0.5 - 0.5 * np.cos(np.pi * np.arange(1, 13) / 12)    # 12 frames, 0 -> 1
    ref[1800:1812] = 1e-3 - 1e-3 * shaped                     # a shaped step back down
    ref[1812:] = 0.0
    assert _reference_transitions(ref, rate) == [(599, 599), (1799, 1810)]
    # a pause shorter than STEP_MERGE_S inside a move joins the two halves
    ref2 = np.zeros(2000)
    ref2[500:] = 1e-4
    ref2[500 + int(STEP_MERGE_S * rate) // 2:] = 2e-4
    assert len(_reference_transitions(ref2, rate)) == 1
    assert _reference_transitions(np.zeros(100), rate) == []


def test_a_step_up_then_back_is_scored_until_the_reference_moves_again(tmp_path):
    """The steady state of the step up is its own, not the level after the step back."""
    with Testbed("sim", testbed=TESTBED, fast=True, generator=None, log_folder=tmp_path,
                 history=tmp_path / "h") as tb:
        tb.upload_design(DESIGN)
        tb.set_mode("RELATIVE")
        tb.arm()
        tb.start_recording("up and back")
        tb.dwell(0.3)
        tb.set_reference(STEP_RAD)
        tb.dwell(1.5)
        tb.set_reference(0.0)
        tb.dwell(1.0)
        log = Path(tb.stop_recording()["files"][0])
    s = step_from_log(log)
    assert s.step_size == pytest.approx(STEP_RAD, rel=1e-3)
    assert any("scored until the reference changes again" in n for n in s.notes)
    assert abs(s.metrics.steady_state_error) < 0.1 * STEP_RAD
