"""`gui --watch`: a second window shows the rig live while a script commands it from a
publishing Station; every command control is off with the reason, Abort stops the rig."""

from __future__ import annotations

import threading

import pytest

from groundstation.fanout.endpoints import read_only_message
from groundstation.logs.check import check_log
from groundstation import Testbed
from groundstation.station.options import ConsolePublishing

pytest.importorskip("pytestqt")


@pytest.fixture
def commander(tmp_path):
    """A script holding the session on a fast simulated testbed, publishing; it dwells
    (the device runs) until the test lets it go."""
    tb = Testbed("sim", fast=True, log_folder=tmp_path / "commander", generator=None,
                 publishing=ConsolePublishing("tcp://127.0.0.1:*"))
    tb.open()
    release, failures = threading.Event(), []

    def script():
        try:
            tb.set_mode("OPEN_LOOP")
            tb.arm()
            tb.set_currents(coarse_a=0.02)
            for _ in range(2000):                  # bounded: at most ~200 s of device time
                if release.is_set() or not tb.simulator.firmware.armed:
                    break
                tb.dwell(0.1)
        except Exception as exc:                   # the viewer's ABORT may end a command
            failures.append(exc)
    worker = threading.Thread(target=script, daemon=True)
    worker.start()
    yield tb
    release.set()
    worker.join(10.0)
    tb.close()


def test_a_watching_window_is_live_read_only_and_can_abort(gui_window, qtbot, commander, tmp_path):
    win = gui_window(60.0)
    session = win.session
    endpoint = commander.publisher.endpoint
    session.watch(endpoint)
    reason = read_only_message(endpoint)
    assert "read-only console watching" in win.windowTitle()
    hr = session.store.ring("HIGH_RATE")
    qtbot.waitUntil(lambda: hr.latest("armed") is not None and bool(hr.latest("armed")),
                    timeout=20000)
    # every command control off, saying why; Abort on
    from PySide6.QtWidgets import QCheckBox, QComboBox, QPushButton
    controls = [w for kind in (QPushButton, QComboBox, QCheckBox)
                for w in win.commands.findChildren(kind) if w is not win.commands.abort_button]
    assert controls and all(not w.isEnabled() and w.toolTip() == reason for w in controls)
    for panel in (win.parameters, win.generator, win.profiles, win.campaign):
        assert not panel.isEnabled() and panel.toolTip() == reason
    assert win.commands.abort_button.isEnabled()
    # a command asked of the session anyway is refused with the reason, nothing sent
    errors = []
    session.sig_event.connect(lambda level, source, text: errors.append(text))
    session.command("DISARM")
    qtbot.waitUntil(lambda: any(reason in e for e in errors), timeout=5000)
    assert commander.simulator.firmware.armed

    # the viewer records a normal log of what it watches
    path = session.start_recording(str(tmp_path / "viewer"), "watched")
    before = hr.latest("tick")
    qtbot.waitUntil(lambda: hr.latest("tick") > before + 600, timeout=20000)

    win.commands.abort_button.click()            # ABORT straight to the device
    qtbot.waitUntil(lambda: not commander.simulator.firmware.armed, timeout=10000)
    qtbot.waitUntil(lambda: hr.latest("armed") is not None and not bool(hr.latest("armed")),
                    timeout=10000)
    session.stop_recording()
    assert check_log(path).exit_code == 0
