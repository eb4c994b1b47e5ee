"""`from groundstation import Testbed`: the verbs work, and leaving the block by an
exception leaves the rig safe (disarmed, generator off, recording closed and valid)."""

from __future__ import annotations

from pathlib import Path

import pytest

from groundstation import Testbed
from groundstation.logs import LogReader
from groundstation import ScriptError

ROOT = Path(__file__).resolve().parents[2]


def test_an_exception_inside_the_block_leaves_the_rig_safe(tmp_path):
    with pytest.raises(RuntimeError, match="the script's own bug"):
        with Testbed("sim", testbed=ROOT / "profiles/testbeds/inertial_2dof.toml", fast=True,
                     log_folder=tmp_path, history=tmp_path / "h") as tb:
            tb.set_mode("OPEN_LOOP")
            tb.arm()
            tb.set_currents(coarse_a=0.05)
            tb.generator_set(1, waveform="SINE", frequency_hz=2.0, amplitude_vpp=0.3)
            path = tb.start_recording("crash", notes="an exception mid-run")
            tb.dwell(0.5)
            assert tb.simulator.firmware.armed and tb.generator.get_output(1)
            fw, gen = tb.simulator.firmware, tb.generator
            raise RuntimeError("the script's own bug")
    assert not fw.armed and fw.mode == 0                      # ABORT: drives off, IDLE
    assert gen.closed                                         # and its output was switched off first
    with LogReader(path) as log:
        assert log.n_frames("HIGH_RATE") >= 600
        texts = [e.data.get("text", "") for e in log.journal("event")]
    assert any("RuntimeError: the script's own bug" in t for t in texts)


def test_verbs_refuse_what_they_cannot_do(tmp_path):
    with Testbed("sim", testbed=ROOT / "profiles/testbeds/relative_2dof.toml", fast=True,
                 log_folder=tmp_path, history=tmp_path / "h") as tb:
        assert tb.generator is None                           # a relative rig has no stage
        with pytest.raises(ScriptError, match="no function generator"):
            tb.generator_set(1, waveform="SINE", frequency_hz=1.0, amplitude_vpp=0.1)
        # a design for another kind of rig is refused before its table is even built
        with pytest.raises(ScriptError, match="inertial_design2.toml is a design for a 2dof "
                                              "inertial testbed; this session runs "
                                              "relative_2dof.toml"):
            tb.upload_design(ROOT / "profiles/controllers/inertial_design2.toml")
        with pytest.raises(ScriptError, match="no operator"):
            tb.pause("look at the rig")
        with pytest.raises(ScriptError, match="nothing is recording"):
            tb.stop_recording()
        record = tb.upload_design(ROOT / "profiles/controllers/relative_design2.toml")
        assert tb.simulator.firmware.param_crc == record.crc
        result = tb.play(ROOT / "profiles/waveforms/step_relative_1mrad.toml")
        assert result.completed and not tb.simulator.firmware.armed
