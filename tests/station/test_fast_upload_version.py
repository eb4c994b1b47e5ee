"""On the fast simulated testbed, held between steps, an upload numbers its table after
the active one from the HOUSEKEEPING already seen: device time stands still between
steps, so no new report comes to wait for (the upload used to wait out its 3 s timeout
for one and then numbered every table 1)."""

from __future__ import annotations

from pathlib import Path

from groundstation import Testbed

ROOT = Path(__file__).resolve().parents[2]
CONTROLLERS = ROOT / "profiles" / "controllers"


def test_consecutive_fast_uploads_number_their_tables_in_sequence(tmp_path):
    with Testbed("sim", testbed=ROOT / "profiles/testbeds/relative_2dof.toml", fast=True,
                 generator=None, log_folder=tmp_path / "logs", history=tmp_path / "history") as tb:
        first = tb.upload_design(CONTROLLERS / "relative_design1.toml")
        second = tb.upload_design(CONTROLLERS / "relative_design2.toml")
        third = tb.upload_design(CONTROLLERS / "relative_design1.toml")
        assert first.version >= 1
        assert (second.version, third.version) == (first.version + 1, first.version + 2)
        # the device's own report of the active table agrees with the last upload
        assert tb.state.active_table == (third.version, third.crc)


def test_a_held_device_is_not_waited_for_a_report_it_does_not_send(tmp_path):
    """Before any HOUSEKEEPING has come, a held device's first upload numbers its table
    after the fresh device's version 0 - what the device itself then reports - instead of
    waiting for a report that device time standing still never brings."""
    with Testbed("sim", testbed=ROOT / "profiles/testbeds/relative_2dof.toml", fast=True,
                 generator=None, log_folder=tmp_path / "logs", history=tmp_path / "history") as tb:
        assert tb.state.active_table is None                 # nothing reported yet
        assert tb.parameter_loader().reports_between_steps is False
        first = tb.upload_design(CONTROLLERS / "relative_design2.toml")
        assert first.version == 1
        assert tb.state.active_table == (1, first.crc)       # the device agrees
    with Testbed("sim", testbed=ROOT / "profiles/testbeds/relative_2dof.toml", generator=None,
                 log_folder=tmp_path / "logs2", history=tmp_path / "history2") as live:
        # a device in real time keeps reporting: there the loader waits for the report
        assert live.parameter_loader().reports_between_steps is True
