"""A new user's first hour: `groundstation sim` as a tcp:// device, `record` without
--testbed, `analyze` the log.  The recorder asks the device what it is (GET_INFO) and
keeps the testbed file the device names in the log's journal, so the analysis has the
motor resistances and the autocollimator's range; a device that names no testbed file
known here gets a log whose analysis says what the device was and which option
supplies the constants."""

from __future__ import annotations

import json
import math
import shutil

import pytest

from groundstation.analysis.testbed_figures import figures_from_testbed
from groundstation.cli.main import main
from groundstation.logs import LogReader
from groundstation.logs.device_testbed import recorded_device
from groundstation.plant.testbed import TESTBEDS_DIR
from groundstation.sim.process import SimulatorProcess

#: wall seconds recorded: enough HIGH_RATE frames for the jitter and the energy
SECONDS = "2"


@pytest.fixture
def sim_of(request):
    """`groundstation sim --testbed FILE` in a child process; its tcp:// address."""
    started = []

    def start(testbed) -> str:
        sim = SimulatorProcess(testbed=str(testbed))
        started.append(sim)
        return sim.start()
    yield start
    for sim in started:
        sim.stop()


def record(capsys, address, folder):
    code = main(["record", "--device", address, "--duration", SECONDS, "--folder", str(folder),
                 "--name", "firsthour"])
    out = capsys.readouterr()
    assert code == 0, out.err
    logs = sorted(folder.glob("*.h5"))
    assert len(logs) == 1
    return logs[0], out.out


def test_a_log_from_a_tcp_device_without_testbed_is_analysed(sim_of, tmp_path, capsys):
    testbed = TESTBEDS_DIR / "inertial_2dof.toml"
    log, out = record(capsys, sim_of(testbed), tmp_path / "logs")
    assert f"testbed: {testbed}, named by the device at connect" in out
    with LogReader(log) as r:
        assert r.testbed()[2] == ""                  # no --testbed: no testbed file as such
        device = recorded_device(r)
    assert device["description"].startswith("simulated testbed: ")
    assert device["testbed_file"] == str(testbed)
    assert device["testbed_text"] == testbed.read_text()

    code = main(["analyze", str(log), "--json"])
    captured = capsys.readouterr()
    assert code == 0, captured.err
    [row] = json.loads(captured.out)
    assert row["error"] == "" and row["frames"] > 1000
    # energy needs the motor resistances; the sensor's exclusion rule its calibrated range
    assert math.isfinite(row["energy_total_j"]) and math.isfinite(row["rms_urad"])
    assert "records no testbed" not in row["notes"] + captured.err
    with LogReader(log) as r:
        figures = figures_from_testbed(r)
    assert "the device named at connect" in figures.source
    assert figures.autocollimator_range_rad is not None
    assert figures.resistance_coarse_ohm is not None


def test_a_device_that_names_no_known_testbed_says_which_option_supplies_it(sim_of, tmp_path,
                                                                           capsys):
    # a testbed file of the lab's own, not one shipped here: the device names it, but
    # nothing here says what is in it
    (tmp_path / "testbeds").mkdir()
    own = tmp_path / "testbeds" / "lab_rig_7.toml"
    shutil.copy(TESTBEDS_DIR / "inertial_2dof.toml", own)
    # with the friction slope table it names, relative to itself
    shutil.copy(TESTBEDS_DIR.parent / "friction_slope_lut.csv", tmp_path)
    log, out = record(capsys, sim_of(own), tmp_path / "logs")
    assert "the log records no testbed file" in out and "lab_rig_7.toml" in out
    assert "--testbed FILE" in out

    code = main(["analyze", str(log)])
    captured = capsys.readouterr()
    err = captured.out + captured.err               # the log's own error is in its row
    assert code != 0
    assert "motor resistances ([motor_coarse] / [motor_fine] resistance) are unknown" in err
    assert "described itself at connect as \"simulated testbed: " in err
    assert "give --testbed FILE" in err
    # the option named supplies them
    code = main(["analyze", str(log), "--testbed", str(own)])
    captured = capsys.readouterr()
    assert code == 0, captured.out + captured.err
