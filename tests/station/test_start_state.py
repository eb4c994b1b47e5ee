"""A run's clock starts from a verified start state (Station.settle, the campaign's settle
action): at rest, in range, unfaulted - checked on the simulated rig's own telemetry,
with the measured values in the refusal."""

from __future__ import annotations

from pathlib import Path

import pytest

from groundstation import Testbed
from groundstation.logs import LogReader
from groundstation import ScriptError
from groundstation.station.start_state import StartCriteria

ROOT = Path(__file__).resolve().parents[2]
DEG = 3.141592653589793 / 180
INERTIAL = ROOT / "profiles/testbeds/inertial_2dof.toml"
RELATIVE = ROOT / "profiles/testbeds/relative_2dof.toml"


def _push_los_off_the_autocollimator(tb) -> None:
    """Open loop: a coarse-motor current turns the gimbal past the autocollimator's
    +-5.76 mrad; then the motors are off and the rig is left to come to rest."""
    tb.set_mode("OPEN_LOOP")
    tb.arm()
    tb.set_currents(coarse_a=0.4)
    tb.dwell(0.15)
    tb.set_currents(coarse_a=-0.4)
    tb.dwell(0.05)
    tb.set_currents(0.0, 0.0)
    tb.disarm()


def test_a_fresh_rig_is_ready_and_the_start_state_is_marked_in_the_log(tmp_path):
    with Testbed("sim", testbed=INERTIAL, fast=True, log_folder=tmp_path, history=tmp_path / "h") as tb:
        path = tb.start_recording("start")
        state = tb.settle(max_seconds=5.0)
        tb.stop_recording()
    assert abs(state["autocollimator_rad"]) < 1e-6 and abs(state["outer_rad"]) < 1e-6
    with LogReader(path) as log:
        texts = [e.data.get("text", "") for e in log.journal("event")]
    assert any(t.startswith("start state verified: outer_rad") for t in texts)


def test_a_moving_rig_is_not_at_rest_and_the_refusal_says_how_much_it_moves(tmp_path):
    with Testbed("sim", testbed=RELATIVE, fast=True, log_folder=tmp_path, history=tmp_path / "h") as tb:
        tb.set_mode("OPEN_LOOP")
        tb.arm()
        tb.set_currents(coarse_a=0.3)            # the gimbal keeps turning while settle watches
        with pytest.raises(ScriptError, match=r"not at rest: encoder_outer moved [0-9.]+ urad in 0.5 s"):
            tb.settle(max_seconds=1.0, criteria=StartCriteria(hold_s=0.5))


def test_the_los_off_the_autocollimator_is_refused_with_its_reading(tmp_path):
    with Testbed("sim", testbed=INERTIAL, fast=True, log_folder=tmp_path, history=tmp_path / "h") as tb:
        _push_los_off_the_autocollimator(tb)
        with pytest.raises(ScriptError, match=r"out of range: the autocollimator reads 5\.760 mrad, "
                                              r"beyond 5\.18 mrad"):
            tb.settle(max_seconds=3.0)


def test_recentring_brings_the_los_back_onto_the_autocollimator_and_says_so_in_the_log(tmp_path):
    recentre = ROOT / "profiles/controllers/recentre_inertial.toml"
    with Testbed("sim", testbed=INERTIAL, fast=True, log_folder=tmp_path, history=tmp_path / "h") as tb:
        _push_los_off_the_autocollimator(tb)
        path = tb.start_recording("recentre")
        state = tb.settle(max_seconds=5.0, recentre=recentre)
        tb.stop_recording()
        assert not tb.simulator.firmware.armed                  # recentred, then disarmed
        assert "recentre_inertial.toml" in tb.history.records()[-1].source   # validated upload
    assert abs(state["autocollimator_rad"]) < 0.9 * 0.33 * DEG and abs(state["outer_rad"]) < 0.9 * 0.33 * DEG
    with LogReader(path) as log:
        texts = [e.data.get("text", "") for e in log.journal("event")]
    recentring = [t for t in texts if t.startswith("recentring with recentre_inertial.toml")]
    assert recentring and "the autocollimator reads 5.760 mrad" in recentring[0]
    assert any(t.startswith("start state verified:") for t in texts)


def test_a_latched_fault_is_acknowledged_before_the_check(tmp_path):
    from groundstation.params import table as ptable
    with Testbed("sim", testbed=RELATIVE, fast=True, log_folder=tmp_path, history=tmp_path / "h") as tb:
        values = dict(ptable.default_values(tb.d))
        values["travel_limit"] = 0.0005          # 0.5 mrad: a short open-loop push trips it
        tb.upload_table(values, "start-state test", accept_risk="test: a tiny travel limit to trip over-travel")
        tb.set_mode("OPEN_LOOP")
        tb.arm()
        tb.set_currents(coarse_a=0.3)
        with pytest.raises(ScriptError, match="send DISARM"):
            tb.dwell(1.0)                                      # the wait ends at the fault
        assert tb.state.fault and not tb.state.armed          # over-travel: disarmed, latched
        state = tb.settle(max_seconds=5.0)
        assert not tb.state.fault and state["outer_rad"] > 0.0005
