"""The upload gate: no caller gets a parameter table onto the device that failed (or
skipped) validation, except through the explicit override whose reason is recorded in
the parameter history and the recording's journal."""

from __future__ import annotations

import ast
import dataclasses
from pathlib import Path

import pytest

from groundstation.logs import LogReader
from groundstation.params import table as ptable
from groundstation.params.clearance import (Clearance, ValidationRefused, clear_design,
                                            override_table)
from groundstation.params.design_file import load_design, table_values
from groundstation.params.upload import MemoryHistory, NotClearedError, ParameterLoader
from groundstation import ScriptError, Testbed

ROOT = Path(__file__).resolve().parents[2]
CONTROLLERS = ROOT / "profiles" / "controllers"
TESTBED = ROOT / "profiles" / "testbeds" / "relative_2dof.toml"
TABLE_COMMANDS = ("PARAM_BEGIN", "PARAM_WRITE", "PARAM_COMMIT")


@pytest.fixture
def station(tmp_path):
    with Testbed("sim", testbed=TESTBED, fast=True, generator=None,
                 log_folder=tmp_path / "logs", history=tmp_path / "history") as tb:
        sent: list[str] = []
        tb.client.add_command_listener(lambda result: sent.append(result.name))
        tb.sent = sent
        yield tb


@pytest.fixture
def unstable_design(tmp_path):
    """Relative Design #2 with c0's gain 1000x: the closed loop is unstable."""
    text = (CONTROLLERS / "relative_design2.toml").read_text()
    path = tmp_path / "too_much_gain.toml"
    path.write_text(text.replace('"../testbeds/', f'"{ROOT / "profiles" / "testbeds"}/')
                    .replace("gain = 30801", "gain = 30801000"))
    return path


@pytest.fixture
def marginal_design(tmp_path):
    """Relative Design #2 with c0's gain cut to 6000: stable, phase margin about 6 deg and
    a lower gain margin about 5 dB."""
    text = (CONTROLLERS / "relative_design2.toml").read_text()
    path = tmp_path / "too_little_gain.toml"
    path.write_text(text.replace('"../testbeds/', f'"{ROOT / "profiles" / "testbeds"}/')
                    .replace("gain = 30801", "gain = 6000"))
    return path


def table_sent(sent: list[str]) -> bool:
    return any(name in TABLE_COMMANDS for name in sent)


def test_the_loader_sends_nothing_without_a_clearance(station):
    values = {**ptable.default_values(station.d), "outer_loop_gain": 20.0}
    loader = ParameterLoader(station.client, station.d, MemoryHistory())
    with pytest.raises(NotClearedError, match="has not been validated"):
        loader.upload(values, "hand-made")
    with pytest.raises(NotClearedError):
        loader.upload(values, "hand-made", clearance="validated")     # not a Clearance
    assert not table_sent(station.sent)


def test_a_clearance_cannot_be_forged_or_moved_to_another_table(station):
    values = {**ptable.default_values(station.d), "outer_loop_gain": 20.0}
    crc = ptable.table_crc(ptable.pack(station.d, values))
    with pytest.raises(TypeError, match="never constructed by hand"):
        Clearance(crc, "my design")
    good = override_table(values, station.d, "bench check")
    with pytest.raises(TypeError):
        dataclasses.replace(good, override_reason="")          # drop the recorded override
    other = {**values, "outer_loop_gain": 21.0}
    with pytest.raises(TypeError):
        dataclasses.replace(good, table_crc=ptable.table_crc(ptable.pack(station.d, other)))
    loader = ParameterLoader(station.client, station.d, MemoryHistory())
    with pytest.raises(NotClearedError, match="the clearance is for table"):
        loader.upload(other, "edited after validation", clearance=good)
    assert not table_sent(station.sent)


def test_an_override_needs_a_reason(station, unstable_design):
    values = ptable.default_values(station.d)
    for reason in ("", "   ", None):
        with pytest.raises(ValidationRefused, match="needs a reason"):
            override_table(values, station.d, reason)
        design = load_design(unstable_design)
        with pytest.raises(ValidationRefused, match="refused by validation") as info:
            clear_design(design, table_values(design, dictionary=station.d), station.d, reason)
        assert info.value.report is not None and not info.value.report.ok


def test_a_refused_design_is_not_sent_by_the_station(station, unstable_design):
    before = station.read_params().crc
    with pytest.raises(ScriptError, match="refused by validation, nothing sent"):
        station.upload_design(unstable_design)
    with pytest.raises(ScriptError, match="closed loop was not checked|needs a reason"):
        station.upload_table(ptable.default_values(station.d), "no design")   # no design, no reason
    with pytest.raises(ScriptError, match="upload_design/upload_table"):
        station.command("PARAM_BEGIN", table_version=1, table_length=16)
    assert not table_sent(station.sent)
    assert station.read_params().crc == before
    assert station.history.records() == []


def test_the_override_is_recorded_in_the_history_and_the_log(station, unstable_design):
    path = station.start_recording("override")
    record = station.upload_design(unstable_design, accept_risk="identification run, rig clamped")
    station.stop_recording()
    assert table_sent(station.sent)
    assert not record.validated and record.override_reason == "identification run, rig clamped"
    assert any("unstable" in p or "pole" in p for p in record.validation_problems)
    kept = station.history.records()[-1]
    assert (kept.crc, kept.validated, kept.override_reason) == (record.crc, False, record.override_reason)
    assert "not validated; accepted: identification run, rig clamped" in kept.source
    with LogReader(path) as log:
        tables = [t.data for t in log.journal("parameter_table") if t.data.get("crc") == record.crc
                  and "override_reason" in t.data]
    assert tables and tables[-1]["override_reason"] == "identification run, rig clamped"
    assert not tables[-1]["validated"] and tables[-1]["validation_problems"]


def test_a_stable_but_marginal_design_is_sent_only_with_its_margins_accepted(station, marginal_design):
    design = load_design(marginal_design)
    values = table_values(design, dictionary=station.d)
    with pytest.raises(ValidationRefused, match="stable but marginal .*phase margin 5.8 deg at 4.4 Hz "
                                                "is below 30 deg.*accept these margins with a reason"):
        clear_design(design, values, station.d)
    with pytest.raises(ScriptError, match="stable but marginal"):
        station.upload_design(marginal_design)
    assert not table_sent(station.sent)
    path = station.start_recording("marginal")
    record = station.upload_design(marginal_design, accept_risk="slow loop for a bearing run-in")
    station.stop_recording()
    assert record.accepted_risk == "marginal" and not record.validated
    assert record.validation_problems == [
        "stable but marginal: lower gain margin 5.4 dB at 3.3 Hz is below 6 dB (the loop goes "
        "unstable if its gain drops that much, e.g. in saturation)",
        "stable but marginal: phase margin 5.8 deg at 4.4 Hz is below 30 deg"]
    kept = station.history.records()[-1]
    assert kept.accepted_risk == "marginal" and kept.validation_problems == record.validation_problems
    assert "margins accepted: slow loop for a bearing run-in" in kept.source
    with LogReader(path) as log:
        table = [t.data for t in log.journal("parameter_table") if t.data.get("crc") == record.crc][-1]
    assert table["accepted_risk"] == "marginal" and table["validation_problems"] == record.validation_problems


def test_an_unstable_design_accepted_says_it_was_refused_not_marginal(station, unstable_design):
    record = station.upload_design(unstable_design, accept_risk="identification run, rig clamped")
    assert record.accepted_risk == "refused"


def test_a_validated_design_goes_through_and_says_so(station):
    record = station.upload_design(CONTROLLERS / "relative_design2.toml")
    assert record.validated and record.override_reason == "" and record.validation_problems == []
    assert station.read_params().crc == record.crc


def test_only_the_loader_sends_table_commands():
    """Outside the simulated device, the table commands' names appear only in the loader
    (which needs a Clearance) and in the Station's list of what `command` refuses - and
    in the conformance suite, whose table checks send bad tables on purpose, raw, on its
    own connection (never through a Station), disarmed, and restore the table it found."""
    allowed = {Path("params/upload.py"), Path("station/station.py")}
    package = ROOT / "groundstation"
    offenders = []
    for path in package.rglob("*.py"):
        rel = path.relative_to(package)
        if rel.parts[0] in ("sim", "conformance") or rel in allowed:
            continue
        for node in ast.walk(ast.parse(path.read_text(), str(path))):
            if isinstance(node, ast.Constant) and node.value in TABLE_COMMANDS:
                offenders.append(f"{rel}:{node.lineno} {node.value}")
    assert offenders == []
