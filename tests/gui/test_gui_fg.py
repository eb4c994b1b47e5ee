"""The generator panel in the real window against the simulated inertial testbed (a child
process with its function generator, as the GUI starts it): the simulator's generator in
the picker, a sine that moves the base at its frequency, refusals before sending, the
output off on Esc, on disconnect and before the simulator stops at window close, and a
base-motion profile previewed, uploaded, played and checked against its target - in the
panel and, from the recording, with `groundstation fg check`.

The simulator runs at 3x the wall clock (Session.sim_speed): every time here is device
time (ticks), so only the waiting gets shorter."""

from __future__ import annotations

import re
from pathlib import Path

import numpy as np
import pytest
import pyvisa
from PySide6.QtCore import Qt
from PySide6.QtWidgets import QMenu

from groundstation.basemotion import BaseStageModel
from groundstation.cli.main import main
from groundstation.gui.generator.motion_check import newest_device_time
from groundstation.gui.generator.channel_editor import FIELD_BAD
from groundstation.logs import LogReader
from groundstation.plant.testbed import load_testbed

ROOT = Path(__file__).resolve().parents[2]
INERTIAL = "profiles/testbeds/inertial_2dof.toml"
BM3 = ROOT / "profiles" / "base_motion" / "BM3.csv"
STAGE = BaseStageModel.from_testbed(load_testbed(ROOT / INERTIAL))


@pytest.fixture
def window(gui_window):
    win = gui_window(60.0, history=False, sim_speed=3.0)
    win.docks["Generator"].raise_()
    return win


def newest(session) -> float:
    """The product's newest HIGH_RATE device time, 0.0 before any (the waits compare it)."""
    return newest_device_time(session) or 0.0


def open_simulated_generator(qtbot, win):
    panel = win.generator
    win.session.connect_sim(INERTIAL)
    # the simulator's generator joins the picker once the simulated testbed is up
    qtbot.waitUntil(panel.channel.select_simulator, timeout=60000)
    assert panel.channel.resource.currentText().startswith("simulator - TCPIP0::127.0.0.1::")
    qtbot.mouseClick(panel.channel.connect_button, Qt.MouseButton.LeftButton)
    qtbot.waitUntil(lambda: panel.channel.state is not None, timeout=15000)
    assert "4053B" in panel.channel.identity.text()
    assert panel.channel.connect_button.text() == "Disconnect"
    return panel


def read_back(qtbot, gen):
    """A fresh read-back of channel 1 (what the instrument holds now)."""
    with qtbot.waitSignal(gen.sig_state, timeout=10000) as blocker:
        gen.refresh(1)
    return blocker.args[0]


def test_sine_moves_the_base_refusals_and_every_way_off(qtbot, window):
    panel = open_simulated_generator(qtbot, window)
    session, gen = window.session, window.session.generator
    view = next(m for m in window.menuBar().findChildren(QMenu) if m.title() == "&View")
    assert window.docks["Generator"].toggleViewAction() in view.actions()
    assert "testbed: ≤ 2 Vpp" in panel.channel.ranges["amplitude"].text()    # the testbed's limit
    # listing the resources again while the generator is open must not close its session
    panel.channel.refresh_resources()
    qtbot.waitUntil(panel.channel.refresh_button.isEnabled, timeout=15000)

    panel.channel.waveform.setCurrentText("SINE")
    panel.channel.load.setCurrentIndex(panel.channel.load.findData("HZ"))
    channel = panel.channel
    for spin, value in ((channel.frequency, 1.0), (channel.amplitude, 0.2), (channel.offset, 0.0),
                        (channel.phase, 0.0)):
        spin.setValue(value)
    assert panel.channel.apply() is None
    qtbot.waitUntil(lambda: panel.channel.state.wave.amplitude_vpp == 0.2
                    and panel.channel.state.wave.waveform == "SINE", timeout=10000)
    assert not panel.channel.state.output.on and "Output off" in panel.channel.output_button.text()

    qtbot.mouseClick(panel.channel.output_button, Qt.MouseButton.LeftButton)
    qtbot.waitUntil(lambda: panel.channel.state.output.on, timeout=10000)
    assert "OUTPUT ON" in panel.channel.output_button.text()    # as the instrument reports it
    t_on = newest(session)
    qtbot.waitUntil(lambda: newest(session) > t_on + 5.0, timeout=20000)
    snap = session.store.ring("HIGH_RATE").snapshot(["encoder_base"], seconds=2.0)
    x = snap.values["encoder_base"] - snap.values["encoder_base"].mean()
    assert len(x) >= 2000 and not len(snap.gap_sizes)
    spectrum = np.abs(np.fft.rfft(x * np.hanning(len(x))))
    f = np.fft.rfftfreq(len(x), 1 / 1200.0)
    assert f[np.argmax(spectrum)] == pytest.approx(1.0, abs=0.3)      # 2 s: 0.5 Hz bins
    # the stage's steady response: 0.1 V amplitude x |H(1 Hz)| (the transient has decayed)
    expected = 0.1 * abs(STAGE.response(1.0))
    assert np.ptp(x) / 2 == pytest.approx(expected, rel=0.1)

    # beyond the testbed's 2 Vpp and beyond the instrument: refused, nothing sent
    panel.channel.amplitude.setValue(3.0)
    reason = panel.channel.apply()
    assert "safety limit of 2 Vpp" in reason and "fg_max_amplitude" in reason
    assert "refused" in panel.status.text() and panel.channel.amplitude.styleSheet() == FIELD_BAD
    panel.channel.amplitude.setValue(0.2)
    panel.channel.frequency.setValue(2e7)
    assert "outside" in panel.channel.apply() and "4053B" in panel.channel.apply()
    state = read_back(qtbot, gen)
    assert (state.wave.amplitude_vpp, state.wave.frequency_hz, state.output.on) == (0.2, 1.0, True)

    # Esc from anywhere: the output reads back OFF
    qtbot.keyClick(window.events.search, Qt.Key.Key_Escape)
    qtbot.waitUntil(lambda: not panel.channel.state.output.on, timeout=10000)
    assert "Output off" in panel.channel.output_button.text()

    # an "output on" asked for just before an abort never outlives it (dropped from the
    # queue, or switched off right after if it was under way)
    panel.channel.set_output(True)
    window.abort()
    qtbot.waitUntil(gen.idle, timeout=10000)
    assert not read_back(qtbot, gen).output.on

    # disconnecting the simulated testbed switches it off too
    panel.channel.set_output(True)
    qtbot.waitUntil(lambda: panel.channel.state.output.on, timeout=10000)
    session.disconnect_link()
    qtbot.waitUntil(lambda: not panel.channel.state.output.on, timeout=10000)

    # closing the window: the generator is off before the simulator is stopped
    panel.channel.set_output(True)
    qtbot.waitUntil(lambda: panel.channel.state.output.on, timeout=10000)
    rm = pyvisa.ResourceManager("@py")
    probe = rm.open_resource(gen.resource, read_termination="\n", write_termination="\n",
                             timeout=2000)
    seen = []
    sim = session.sim
    real_stop = sim.stop

    def stop_after_looking():
        seen.append(probe.query("C1:OUTP?").strip())
        probe.close()
        real_stop()
    sim.stop = stop_after_looking
    assert probe.query("C1:OUTP?").startswith("C1:OUTP ON")
    window.close()
    assert seen and seen[0].startswith("C1:OUTP OFF"), seen


def test_base_motion_preview_upload_play_and_check(qtbot, window, tmp_path, capsys):
    panel = open_simulated_generator(qtbot, window)
    session, gen = window.session, window.session.generator
    panel.base_motion.set_profile_file(BM3)
    panel.base_motion.duration.setValue(10.0)
    profile = panel.base_motion.preview()
    assert profile is not None and profile.name == "BM3" and profile.duration_s == 10.0
    assert panel.base_motion.rms.value() == pytest.approx(2.1)       # the table's own RMS
    motion = panel.base_motion
    for plot in (motion.volts_plot, motion.angle_plot, motion.psd_plot, motion.csp_plot):
        assert plot.listDataItems(), plot
    x, y = panel.base_motion.volts_plot.listDataItems()[0].getData()
    assert len(x) == 16384 and np.max(np.abs(y)) == pytest.approx(profile.amplitude_vpp / 2)
    assert "Vpp of the 2 Vpp allowed" in panel.base_motion.profile_info.text()

    session.start_recording(str(tmp_path), "bm3")
    assert panel.base_motion.upload() is None
    qtbot.waitUntil(lambda: gen.uploaded is not None and panel.channel.state.wave.waveform == "ARB",
                    timeout=15000)
    assert panel.channel.state.wave.frequency_hz == pytest.approx(0.1) and not panel.channel.state.output.on
    assert "BM3 uploaded" in panel.base_motion.check_text.text()
    assert panel.base_motion.check() is None and "output has not been on" in panel.base_motion.check_text.text()

    panel.channel.set_output(True)
    qtbot.waitUntil(lambda: panel.channel.state.output.on and gen.motion_start_s is not None,
                    timeout=10000)
    assert panel.base_motion.check() is None and "more are needed" in panel.base_motion.check_text.text()
    ready = gen.motion_start_s + STAGE.settling_time_s() + profile.duration_s + 0.1
    qtbot.waitUntil(lambda: newest(session) > ready, timeout=30000)
    result = panel.base_motion.check()
    assert result is not None and result.ok, panel.base_motion.check_text.text()
    gui_rms = result.check.achieved_rms_rad
    assert gui_rms == pytest.approx(2.1e-3, rel=0.10)
    assert result.window.seconds == pytest.approx(10.0) and result.window.missing_frames == 0
    assert "within 10 %" in panel.base_motion.check_text.text()
    names = [item.name() for item in panel.base_motion.csp_plot.listDataItems()]
    assert any(n.startswith("target") for n in names) and any(n.startswith("achieved") for n in names)
    panel.channel.set_output(False)
    qtbot.waitUntil(lambda: not panel.channel.state.output.on, timeout=10000)
    path = session.recorder.path
    session.stop_recording()

    # the recording says what the generator did; the command line checks it the same way
    with LogReader(path) as log:
        actions = [r.data["action"] for r in log.journal("function_generator")]
    assert actions[:1] == ["upload"] and "output" in actions and "check" in actions
    rc = main(["fg", "check", str(path), "--profile", str(BM3)])
    out = capsys.readouterr().out
    assert rc == 0, out
    assert "where the output went off (journal)" in out and "16384 points over 10 s" in out
    cli_rms = float(re.search(r"achieved ([0-9.]+) mrad", out).group(1)) / 1e3
    assert cli_rms == pytest.approx(gui_rms, rel=0.02)
