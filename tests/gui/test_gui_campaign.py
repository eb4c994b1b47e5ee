"""The campaign and profile panels in the real window, against the simulated testbed the
Session starts (a child process, real time): a campaign listed, run to completion on the
GUI's own link with a valid log, run again and aborted with Esc mid-dwell (device
disarmed, log valid, report "aborted"); a profile previewed, played (journaled, seen in
the telemetry) and aborted."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest
from PySide6.QtCore import Qt

from groundstation.logs import LogReader
from groundstation import Testbed

ROOT = Path(__file__).resolve().parents[2]
RELATIVE = ROOT / "profiles" / "testbeds" / "relative_2dof.toml"
DESIGN = ROOT / "profiles" / "controllers" / "relative_design2.toml"
WAVEFORMS = ROOT / "profiles" / "waveforms"
STEPS = ["connect", "upload_design", "set_mode", "arm", "start_recording", "set_reference",
         "dwell", "stop_recording", "disarm"]
DWELL = STEPS.index("dwell")


@pytest.fixture
def window(gui_window):
    # "Yes" to Run and to pause steps (campaign) and to Play (profiles)
    return gui_window(30.0, confirm=("campaign", "profiles"))


def campaign_file(tmp_path: Path, name: str, dwell_s: float) -> Path:
    text = f'''
[campaign]
name = "{name}"
description = "a 0.5 mrad step, recorded"
testbed = "{RELATIVE}"

[[setup]]
action = "connect"

[[run]]
action = "upload_design"
design = "{DESIGN}"

[[run]]
action = "set_mode"
mode = "RELATIVE"

[[run]]
action = "arm"

[[run]]
action = "start_recording"
name = "{{campaign}}_step"

[[run]]
action = "set_reference"
angle_rad = 0.0005

[[run]]
action = "dwell"
seconds = {dwell_s}

[[run]]
action = "stop_recording"

[[run]]
action = "disarm"
'''
    path = tmp_path / f"{name}.toml"
    path.write_text(text)
    return path


def connected(session) -> bool:
    c = session.client
    return c is not None and c.link_state == "up" and session.store.ring("HIGH_RATE").total_frames > 600


def test_campaign_runs_on_the_gui_link_and_esc_aborts_it(qtbot, window, tmp_path):
    panel, session = window.campaign, window.session
    ring = session.store.ring("HIGH_RATE")
    assert panel.set_file(campaign_file(tmp_path, "gui_step", 1.0))
    assert [panel.table.item(r, 2).text() for r in range(panel.table.rowCount())] == STEPS
    assert panel.table.item(1, 3).text() == "design=relative_design2.toml"
    # not connected: Run refused, the simulator with the campaign's testbed offered
    assert not panel.run_button.isEnabled() and "not connected" in panel.readiness.text()
    window.docks["Campaign"].raise_()
    assert panel.connect_button.isVisible()
    qtbot.mouseClick(panel.connect_button, Qt.MouseButton.LeftButton)
    qtbot.waitUntil(lambda: connected(session), timeout=60000)
    qtbot.waitUntil(panel.run_button.isEnabled, timeout=5000)

    panel.folder.setText(str(tmp_path / "run1"))
    assert panel.run() is None
    assert not window.commands.mode.isEnabled()               # manual controls off meanwhile
    assert window.commands.abort_button.isEnabled()
    qtbot.waitUntil(lambda: panel.outcome is not None, timeout=60000)
    report = panel.outcome.report
    assert report.status == "completed", report.summary()
    assert [r.status for r in report.steps] == ["done"] * len(STEPS)
    assert [panel.table.item(r, 4).text() for r in range(len(STEPS))] == ["done"] * len(STEPS)
    assert "COMPLETED" in panel.result.text() and str(tmp_path / "run1") in panel.result.text()
    assert json.loads((tmp_path / "run1" / "report.json").read_text())["status"] == "completed"
    qtbot.waitUntil(window.commands.mode.isEnabled, timeout=5000)
    assert session.client is not None and session.client.link_state == "up"   # the link goes on
    with LogReader(report.recordings[0]["files"][0]) as log:
        hr = log.read("HIGH_RATE", ["reference", "armed"])
        assert log.n_frames("HIGH_RATE") > 600
        assert log.journal("parameter_table")
    held = hr["reference"][hr["armed"] == 1]
    assert held[-1] == pytest.approx(0.0005, rel=1e-5) and held[0] != held[-1]   # the step, recorded

    # again, with a long dwell, aborted by Esc while it dwells
    assert panel.set_file(campaign_file(tmp_path, "gui_abort", 60.0))
    panel.folder.setText(str(tmp_path / "run2"))
    assert panel.run() is None
    # 1.5 s into the dwell: the recording has something to keep
    qtbot.waitUntil(lambda: panel.current == DWELL and panel.step_bar.value() > 25, timeout=30000)
    assert ring.latest("armed") == 1
    qtbot.keyClick(window.events.search, Qt.Key.Key_Escape)
    qtbot.waitUntil(lambda: panel.outcome is not None, timeout=20000)
    report = panel.outcome.report
    assert report.status == "aborted" and report.failed_step == DWELL, report.summary()
    assert "aborted by the operator" in report.reason
    assert panel.results[DWELL].status == "aborted"
    assert "ABORTED" in panel.result.text()
    qtbot.waitUntil(lambda: ring.latest("armed") == 0, timeout=10000)
    assert json.loads((tmp_path / "run2" / "report.json").read_text())["status"] == "aborted"
    (rec,) = report.recordings
    with LogReader(rec["files"][0]) as log:                   # closed cleanly, readable
        assert log.n_frames("HIGH_RATE") > 600
        texts = [e.data.get("text", "") for e in log.journal("event")]
    assert any(t.startswith("stopped") for t in texts)
    assert session.campaign.testbed is None and not session.campaign.running


def test_profile_preview_play_and_abort(qtbot, window, tmp_path):
    panel, session = window.profiles, window.session
    ring = session.store.ring("HIGH_RATE")
    assert panel.set_file(WAVEFORMS / "step_relative_1mrad.toml")
    (samples,) = panel.time_plot.listDataItems()
    (psd,) = panel.psd_plot.listDataItems()
    x, y = samples.xData, samples.yData                     # the data, not what the pixels show
    assert len(x) == 6000 and float(np.max(y)) == pytest.approx(1e-3, rel=1e-6)
    f, p = psd.xData, psd.yData
    assert len(f) > 10 and np.all(p > 0)
    assert panel.fields["duration"].text() == "5 s, 6000 samples"
    assert panel.fields["range"].text() == "0 rad … 1 mrad"
    assert "accept" in panel.checks.text()
    assert not panel.play_button.isEnabled()                  # nothing to play it on yet
    assert "not connected" in panel.play()

    session.connect_sim(str(RELATIVE))
    qtbot.waitUntil(lambda: connected(session), timeout=60000)
    # the relative loop the step is for, uploaded through a Testbed on the GUI's link
    tb = Testbed.attach(session.client, testbed=RELATIVE, history=tmp_path / "history",
                        log_folder=tmp_path)
    tb.upload_design(DESIGN)
    tb.close()
    assert session.client.link_state == "up"
    session.start_recording(str(tmp_path), "profile")
    qtbot.waitUntil(panel.play_button.isEnabled, timeout=5000)
    assert panel.play() is None
    qtbot.waitUntil(lambda: panel.outcome is not None, timeout=30000)
    status, text, result = panel.outcome.status, panel.outcome.text, panel.outcome.result
    assert status == "completed", text
    assert result.samples_played == 6000
    snap = ring.snapshot(["profile_index"], seconds=20.0)
    assert snap.values["profile_index"].max() == 6000         # played, as the telemetry says
    path = session.recorder.path
    session.stop_recording()
    with LogReader(path) as log:
        actions = [j.data["action"] for j in log.journal("profile")]
    assert actions == ["uploaded", "played"]

    # a longer one, aborted with Esc while it plays
    assert panel.set_file(WAVEFORMS / "sine_reference_1hz.toml")
    assert panel.play() is None
    qtbot.waitUntil(lambda: "playing" in panel.progress.format() and panel.progress.value() > 50,
                    timeout=20000)
    qtbot.keyClick(window.events.search, Qt.Key.Key_Escape)
    qtbot.waitUntil(lambda: panel.outcome is not None, timeout=10000)
    status, text, result = panel.outcome.status, panel.outcome.text, panel.outcome.result
    assert status == "aborted", text
    assert "ABORTED" in panel.status.text()
    qtbot.waitUntil(lambda: ring.latest("armed") == 0, timeout=10000)
    assert not session.profiles.playing and panel.play_button.isEnabled()


def test_a_campaign_drives_the_simulators_generator_beside_the_panel(qtbot, window, tmp_path):
    """The campaign's own VISA session to the simulator's generator, with the Generator
    panel connected to it too: both see the one instrument; Esc leaves its output off."""
    inertial = ROOT / "profiles" / "testbeds" / "inertial_2dof.toml"
    path = tmp_path / "gen.toml"
    path.write_text(f'''
[campaign]
name = "gui_generator"
testbed = "{inertial}"

[[run]]
action = "generator_set"
waveform = "SINE"
frequency_hz = 1.0
amplitude_vpp = 0.2

[[run]]
action = "dwell"
seconds = 60.0

[[teardown]]
action = "generator_off"
''')
    panel, session, fg = window.campaign, window.session, window.generator
    session.connect_sim(str(inertial))
    qtbot.waitUntil(lambda: connected(session), timeout=60000)
    qtbot.waitUntil(fg.channel.select_simulator, timeout=30000)
    qtbot.mouseClick(fg.channel.connect_button, Qt.MouseButton.LeftButton)
    qtbot.waitUntil(lambda: fg.channel.state is not None, timeout=15000)
    assert not fg.channel.state.output.on
    assert panel.set_file(path)
    panel.folder.setText(str(tmp_path / "logs"))
    assert panel.run() is None
    assert not fg.isEnabled()                                 # the panel waits meanwhile
    qtbot.waitUntil(lambda: panel.current == 1 and panel.step_bar.value() > 0, timeout=30000)
    with qtbot.waitSignal(session.generator.sig_state, timeout=10000) as seen:
        session.generator.refresh(1)                          # the panel's own session
    assert seen.args[0].output.on and seen.args[0].wave.amplitude_vpp == 0.2
    qtbot.keyClick(window.events.search, Qt.Key.Key_Escape)
    qtbot.waitUntil(lambda: panel.outcome is not None, timeout=20000)
    assert panel.outcome.report.status == "aborted"
    qtbot.waitUntil(fg.isEnabled, timeout=5000)
    with qtbot.waitSignal(session.generator.sig_state, timeout=10000) as seen:
        session.generator.refresh(1)
    assert not seen.args[0].output.on
