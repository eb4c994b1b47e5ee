"""The window's Session is an adapter over the Station verbs: while the link is up a
Station is attached to it, and the parameter table and command profiles go through that
Station (its validation gate, its history, journaled into the window's recording).
What the work reports arrives as typed Qt signals, one per event.

Offscreen, against the real simulator (a child process), through the real window."""

from __future__ import annotations

import ast
from pathlib import Path

import pytest

from groundstation.gui.session.session import Session
from groundstation.gui.session.events import PLAY_STATUSES, PlayOutcome
from groundstation.params import table as ptable
from groundstation.params.upload import ActiveTable, UploadRecord
from groundstation.profiles import PlaybackResult, load_profile
from groundstation.station.station import Station

ROOT = Path(__file__).resolve().parents[2]
CONTROLLERS = ROOT / "profiles" / "controllers"
WAVEFORMS = ROOT / "profiles" / "waveforms"
RELATIVE = "profiles/testbeds/relative_2dof.toml"
GUI = ROOT / "groundstation" / "gui"


@pytest.fixture
def window(gui_window):
    return gui_window(20.0, confirm=("parameters", "profiles"))


def connect(qtbot, window) -> Session:
    """Connect the simulated testbed and wait for the panel's read on connect."""
    session = window.session
    session.connect_sim(RELATIVE)
    qtbot.waitUntil(lambda: window.parameters.device is not None, timeout=60000)
    return session


def sent_commands(session) -> list[str]:
    sent: list[str] = []
    session.client.add_command_listener(lambda r: sent.append(r.name))
    return sent


def test_the_gui_builds_no_loader_or_player_of_its_own():
    """Parameter tables and profiles reach the device only through Station verbs."""
    offenders = []
    for path in sorted(GUI.glob("*.py")):
        for node in ast.walk(ast.parse(path.read_text())):
            if isinstance(node, ast.Name) and node.id in ("ParameterLoader", "ProfilePlayer"):
                offenders.append(f"{path.name}:{node.lineno} {node.id}")
            elif isinstance(node, ast.Attribute) and node.attr in ("ParameterLoader", "ProfilePlayer"):
                offenders.append(f"{path.name}:{node.lineno} {node.attr}")
            elif isinstance(node, ast.ImportFrom):
                offenders += [f"{path.name}:{node.lineno} imports {a.name}" for a in node.names
                              if a.name in ("ParameterLoader", "ProfilePlayer")]
    assert not offenders, offenders


def test_without_a_link_the_verbs_say_not_connected(qtbot, window):
    session = window.session
    assert session.station is None
    with qtbot.waitSignal(session.sig_params_failed, timeout=2000) as failed:
        session.params_read()
    assert failed.args == ["not connected"]
    profile = load_profile(WAVEFORMS / "pluck_fine_csv.toml", session.d)
    assert "not connected" in session.play_profile(profile, "OPEN_LOOP")
    assert not session.profiles.playing


def test_a_design_upload_from_the_panel_goes_through_the_station(qtbot, window, tmp_path):
    panel = window.parameters
    session = connect(qtbot, window)
    station = session.station
    assert isinstance(station, Station) and station.attached
    assert station.client is session.client
    assert station.history is session.param_history          # one history, the window's

    assert panel.load_design(CONTROLLERS / "relative_design2.toml")
    assert panel.report is not None and panel.report.ok, panel.result.text()
    crc = ptable.table_crc(ptable.pack(session.d, panel.values))
    session.start_recording(str(tmp_path), "adapter")
    with qtbot.waitSignal(session.sig_params_uploaded, timeout=20000) as uploaded:
        assert panel.upload()
    record = uploaded.args[0]
    assert isinstance(record, UploadRecord)
    assert record.crc == crc and record.validated and record.override_reason == ""
    assert station.last_upload is record                    # the Station's verb did it
    assert station.history.records()[-1].crc == crc
    qtbot.waitUntil(lambda: panel.device_crc == crc, timeout=10000)
    assert session.last_uploaded_crc == crc and "verified" in panel.result.text()
    # journaled into the window's recording (the Station has none of its own)
    assert not station.recording.active
    path = session.recorder.path
    session.stop_recording()
    from groundstation.logs import LogReader
    with LogReader(path) as log:
        assert [t.data["crc"] for t in log.journal("parameter_table")] == [crc]

    # closing the link detaches the Station; the next link gets a fresh one
    session.disconnect_link()
    assert session.station is None and station.client is None
    qtbot.waitUntil(lambda: session.client is None, timeout=5000)


def test_a_table_without_a_design_goes_only_with_a_reason(qtbot, window):
    panel = window.parameters
    session = connect(qtbot, window)
    sent = sent_commands(session)
    assert panel.design is None and panel.values is not None  # editing the device's table
    assert panel.set_value("saturation_fine", "12.5") is None
    crc = ptable.table_crc(ptable.pack(session.d, panel.values))

    # the panel asks for a reason; none given: nothing is sent
    panel.override_reason = ""
    assert not panel.upload()
    assert "reason" in panel.result.text()
    # the Session's verb refuses it too: the gate is the Station's, not the panel's
    with qtbot.waitSignal(session.sig_params_failed, timeout=10000) as failed:
        session.params_upload(dict(panel.values), "hand-edited", design=None, accept_risk=None)
    assert "needs a reason" in failed.args[0]
    assert not [n for n in sent if n.startswith("PARAM_BEGIN")]
    assert session.station.last_upload is None

    # with the operator's reason it goes, recorded as not validated, with the reason
    reason = "bench check: saturation only, loop gains unchanged"
    panel.override_reason = reason
    events: list[tuple[str, str, str]] = []
    session.sig_event.connect(lambda *e: events.append(e))
    with qtbot.waitSignal(session.sig_params_uploaded, timeout=20000) as uploaded:
        assert panel.upload()
    record = uploaded.args[0]
    assert isinstance(record, UploadRecord) and record.crc == crc
    assert record.validated is False and record.override_reason == reason
    assert record.validation_problems and "not validated" in record.source
    assert session.param_history.records()[-1].override_reason == reason
    qtbot.waitUntil(lambda: panel.device_crc == crc, timeout=10000)
    assert "NOT validated" in panel.result.text()
    assert any(level == "WARNING" and source == "parameters" and "NOT validated" in text
               for level, source, text in events)


def test_the_typed_signals_carry_typed_payloads(qtbot, window):
    session = connect(qtbot, window)
    progress: list[tuple[str, float]] = []
    session.sig_params_progress.connect(lambda step, f: progress.append((step, f)))
    with qtbot.waitSignal(session.sig_params_active, timeout=10000) as active:
        session.params_read()
    table = active.args[0]
    assert isinstance(table, ActiveTable)
    assert table.crc == ptable.table_crc(table.blob) and "saturation_fine" in table.values
    assert progress and all(isinstance(s, str) and isinstance(f, float) for s, f in progress)
    assert progress[-1][1] == pytest.approx(1.0)

    # the shortest shipped profile that needs no controller design: fine-stage currents
    profile = load_profile(WAVEFORMS / "pluck_fine_csv.toml", session.d)
    steps: list[str] = []
    uploads: list[float] = []
    played: list[tuple[int, int]] = []
    session.profiles.sig_step.connect(steps.append)
    session.profiles.sig_upload.connect(uploads.append)
    session.profiles.sig_progress.connect(lambda n, count: played.append((n, count)))
    assert window.profiles.set_file(WAVEFORMS / "pluck_fine_csv.toml")
    window.profiles.mode.setCurrentText("OPEN_LOOP")
    with qtbot.waitSignal(session.profiles.sig_done, timeout=30000) as done:
        assert window.profiles.play(confirm=False) is None
        assert session.profiles.playing
    outcome = done.args[0]
    assert isinstance(outcome, PlayOutcome) and outcome.status in PLAY_STATUSES
    assert outcome.status == "completed" and outcome.completed, outcome.text
    assert isinstance(outcome.result, PlaybackResult)
    assert outcome.result.samples_played == profile.sample_count
    assert window.profiles.outcome is outcome
    assert "uploading" in steps and "playing" in steps
    assert uploads and uploads[-1] == pytest.approx(1.0)
    assert played and all(isinstance(n, int) and count == profile.sample_count for n, count in played)
    qtbot.waitUntil(lambda: not session.profiles.playing, timeout=5000)
    with pytest.raises(ValueError):
        PlayOutcome("finished", "not a status")
