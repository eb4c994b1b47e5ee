"""The real window, offscreen, against the simulated testbed (a child process, as in
`make run`): live data on the charts, recording, replay of the recording, Esc aborts,
link loss and reconnection."""

from __future__ import annotations

import numpy as np
import pytest
from PySide6.QtCore import QSettings, Qt

from groundstation.gui.main_window import MainWindow
from groundstation.gui.session.session import Session
from groundstation.logs import LogReader


@pytest.fixture
def window(gui_window):
    # answer "Yes" to critical-command dialogs
    return gui_window(60.0, confirm=("commands",), history=False)


def hr_frames(win) -> int:
    return win.session.store.ring("HIGH_RATE").total_frames


def connect(qtbot, win):
    win.session.connect_sim()
    qtbot.waitUntil(lambda: win.session.client is not None and hr_frames(win) > 1200, timeout=60000)


def test_live_data_reaches_the_charts_and_the_status(qtbot, window):
    connect(qtbot, window)
    window.charts.refresh()
    curves = [c for plot in window.charts.stack.plots for c in plot.curves.values()]
    assert curves, "no curves on the charts"
    x, y = curves[0].getData()
    assert x is not None and len(x) > 100 and np.isfinite(y).any()
    qtbot.waitUntil(lambda: window.status_panel.fields["mode"].text() == "IDLE", timeout=5000)
    qtbot.waitUntil(lambda: "frames/s" in window.connection.health.text(), timeout=5000)
    # the bar names the testbed the simulator runs (the default one here)
    assert window.connection.testbed.currentText().endswith("relative_2dof.toml")
    assert "dropped" in window.connection.health.text()
    assert "HIGH_RATE" in window.connection.health.toolTip()       # the full line per packet
    assert window.minimumSizeHint().width() < 1400                  # the text never widens the window


def test_record_then_replay_the_same_values(qtbot, window, tmp_path):
    connect(qtbot, window)
    window.recording.folder.setText(str(tmp_path / "logs"))
    window.recording.name.setText("gui test")
    window.recording.notes.setText("from the window")
    qtbot.mouseClick(window.recording.button, Qt.MouseButton.LeftButton)
    qtbot.waitUntil(lambda: window.session.recorder is not None
                    and window.session.recorder.status().frames > 1200, timeout=30000)
    window.commands.send("SET_MODE", mode="OPEN_LOOP")      # an EVENT inside the recording
    # the recorder counts every packet's frames; HIGH_RATE is 120 of every 121 of them (a
    # HOUSEKEEPING frame each 0.1 s) plus the EVENTs: 2500 in all leaves more than the
    # 2400 HIGH_RATE frames asserted below (waiting for 2400 in all had left 2394 once)
    qtbot.waitUntil(lambda: window.session.recorder.status().frames > 2500, timeout=30000)
    qtbot.mouseClick(window.recording.button, Qt.MouseButton.LeftButton)
    qtbot.waitUntil(lambda: "stopped" in window.recording.info.text(), timeout=30000)
    logs = sorted((tmp_path / "logs").glob("*gui-test*.h5"))
    assert len(logs) == 1
    with LogReader(logs[0]) as r:
        recorded = r.read("HIGH_RATE", ["encoder_inner", "tick"])
        assert r.summary().notes == "from the window"
        # the log says which device it came from, and how to run it again
        assert [j.data for j in r.journal("testbed")] == [
            {"device": "simulated testbed", "seed": 0, "clock": "real time x1"}]
    assert len(recorded["tick"]) > 2400

    window.session.open_log(str(logs[0]))
    assert window.replay_toolbar.isVisible()
    assert any("mode OPEN_LOOP" in text for _, _, text in window.session.replay_events)
    qtbot.waitUntil(lambda: window.replay_bar.markers.events == window.session.replay_events, timeout=5000)
    window.session.replay.speed = None                      # as fast as possible
    window.session.replay.play()
    qtbot.waitUntil(lambda: window.session.replay.finished, timeout=30000)
    snap = window.session.store.ring("HIGH_RATE").snapshot(["encoder_inner", "tick"])
    assert np.array_equal(snap.values["tick"], recorded["tick"][-len(snap.values["tick"]):])
    assert np.array_equal(snap.values["encoder_inner"], recorded["encoder_inner"][-len(snap.values["tick"]):])


def test_escape_aborts_from_any_state(qtbot, window):
    connect(qtbot, window)
    window.commands.mode.setCurrentText("OPEN_LOOP")
    window.commands.send("SET_MODE", mode="OPEN_LOOP")
    qtbot.waitUntil(lambda: window.status_panel.fields["mode"].text() == "OPEN_LOOP", timeout=10000)
    window.commands.send("ARM")
    qtbot.waitUntil(lambda: window.status_panel.fields["armed"].text() == "YES", timeout=10000)
    window.session.command("SET_CURRENTS", current_coarse=0.05, current_fine=0.0)
    qtbot.waitUntil(lambda: abs(window.session.store.ring("HIGH_RATE").latest("current_coarse") - 0.05) < 1e-3,
                    timeout=10000)
    window.events.search.setFocus()                          # focus in a text field: Esc still aborts
    qtbot.keyClick(window.events.search, Qt.Key.Key_Escape)
    ring = window.session.store.ring("HIGH_RATE")
    qtbot.waitUntil(lambda: ring.latest("armed") == 0 and ring.latest("mode") == 0
                    and ring.latest("current_coarse") == 0.0, timeout=10000)
    qtbot.waitUntil(lambda: any("ABORTED" in window.events.table.item(r, 3).text()
                                for r in range(window.events.table.rowCount())), timeout=10000)


def test_link_loss_is_shown_and_the_link_comes_back(qtbot, window, tmp_path):
    connect(qtbot, window)
    window.session.start_recording(str(tmp_path), "across a link loss")
    ring = window.session.store.ring("HIGH_RATE")
    qtbot.waitUntil(lambda: ring.snapshot([], seconds=0.0).device_time[-1:].sum() > 1.5, timeout=15000)
    before = hr_frames(window)
    window.session.sim.process.kill()                        # the simulator dies
    qtbot.waitUntil(lambda: "LINK LOST" in window.connection.health.text()
                    or "LINK FAILED" in window.connection.health.text(), timeout=15000)
    assert hr_frames(window) >= before                       # nothing received is lost
    qtbot.waitUntil(lambda: window.session.client is not None
                    and window.session.client.link_state == "up", timeout=60000)
    # a fresh simulator's clock starts again at 0: the charts restart instead of
    # interleaving old and new samples, and the operator is told why
    qtbot.waitUntil(lambda: ring.restarts == 1 and hr_frames(window) > 600, timeout=30000)
    assert np.all(np.diff(ring.snapshot([]).device_time) > 0)
    qtbot.waitUntil(lambda: any("device time restarted" in window.events.table.item(r, 3).text()
                                for r in range(window.events.table.rowCount())), timeout=10000)
    recorded = window.session.recorder.status().frames
    # the recording goes on with the new link
    qtbot.waitUntil(lambda: window.session.recorder.status().frames > recorded + 600, timeout=30000)


def test_layout_and_chart_channels_survive_a_restart(qtbot, dictionary, tmp_path):
    settings = QSettings(str(tmp_path / "s.ini"), QSettings.Format.IniFormat)
    first = MainWindow(Session(dictionary, store_seconds=10.0), settings)
    qtbot.addWidget(first)
    first.charts.set_layout([["HIGH_RATE.gyro_rate"], ["HOUSEKEEPING.temp_flexure"]])
    first.charts.set_window_seconds(60)
    first.docks["Spectrum"].setVisible(False)
    first.close()
    again = MainWindow(Session(dictionary, store_seconds=10.0), settings)
    qtbot.addWidget(again)
    assert again.charts.stack.layout_ids() == [["HIGH_RATE.gyro_rate"], ["HOUSEKEEPING.temp_flexure"]]
    assert again.charts.settings.window_seconds == 60
    again.close()
