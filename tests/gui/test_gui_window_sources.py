"""The window per source (issue: the source bar named the simulator's testbed whatever
was connected, and a replay offered Connect and Arm): the bar says what is connected -
the simulator's testbed file, a rig's address and what it says it is, the replayed
file, the watched publisher - and what cannot act on that source is off or hidden."""

from __future__ import annotations

import socket

import pytest
from PySide6.QtWidgets import QCheckBox, QComboBox, QPushButton

from groundstation import Testbed
from groundstation.fanout.endpoints import read_only_message
from groundstation.gui.main_window import REPLAY_REASON
from groundstation.gui.session.source import source_text
from groundstation.sim import SimulatedDevice


@pytest.fixture
def window(gui_window):
    return gui_window(30.0)


@pytest.fixture(scope="module")
def short_log(tmp_path_factory):
    folder = tmp_path_factory.mktemp("source_log")
    with Testbed("sim", fast=True, generator=None, log_folder=folder, history=folder / "h") as tb:
        path = tb.start_recording("short")
        tb.dwell(0.5)
        tb.stop_recording()
    return path


def source_delivered(window) -> bool:
    """The source, sent from the connect worker as a queued signal, has reached every
    receiver: the bar's first, the main window's (its title) last - it is connected
    last.  Checking the bar alone, a stressed run saw the title one event behind."""
    return (window.connection.source.text() != "Not connected"
            and window.windowTitle() != "Ground station - hybrid flexure bearing testbed")


def up(session) -> bool:
    return session.client is not None and session.client.link_state == "up"


def command_controls(win) -> list:
    return [w for kind in (QPushButton, QComboBox, QCheckBox) for w in win.commands.findChildren(kind)
            if w is not win.commands.abort_button]


def choosers_shown(win) -> bool:
    # in the bar or in its extension menu (the offscreen screen is narrow)
    bar = win.connection
    return bar.offers(bar.kind) and bar.offers(bar.connect_button)


def enabled_actions(win) -> set[str]:
    return {name for name, a in win.device_actions.items() if a.isEnabled()}


def test_the_words_for_each_source():
    assert source_text("live", "tcp://127.0.0.1:40000", simulated=True) == \
        "Simulated testbed: relative_2dof.toml"
    assert source_text("live", "tcp://127.0.0.1:40000", simulated=True,
                       testbed="profiles/testbeds/rigid_1dof.toml") == "Simulated testbed: rigid_1dof.toml"
    # a rig: its address, never the simulator's file; what it says it is, when it says
    assert source_text("live", "tcp://10.0.0.7:5020", testbed="relative_2dof.toml") == \
        "Rig tcp://10.0.0.7:5020"
    assert source_text("live", "serial:///dev/ttyUSB0?baud=2000000", description="lab rig 2") == \
        "Rig serial:///dev/ttyUSB0?baud=2000000 - lab rig 2"
    assert source_text("replay", "/data/logs/2026-11-28_run.h5") == "Replay of 2026-11-28_run.h5"
    assert source_text("watch", "tcp://10.0.0.2:5600") == "Read-only console watching tcp://10.0.0.2:5600"
    assert source_text("watch", "tcp://10.0.0.2:5600", watched_device="tcp://10.0.0.7:5020") == \
        "Read-only console watching tcp://10.0.0.2:5600 (device tcp://10.0.0.7:5020)"
    assert source_text("none", "") == "Not connected"


def test_the_simulator_names_its_testbed_and_offers_the_demo(qtbot, window):
    window.session.connect_sim()
    bar = window.connection
    qtbot.waitUntil(lambda: up(window.session) and source_delivered(window), timeout=60000)
    assert bar.source.text() == "Simulated testbed: relative_2dof.toml"
    assert bar.kind.currentIndex() == 0 and bar.offers(bar.testbed) and choosers_shown(window)
    assert "Simulated testbed: relative_2dof.toml" in window.windowTitle()
    qtbot.waitUntil(lambda: window.demo_action.isEnabled(), timeout=10000)
    assert window.demo_action.isVisible()
    assert all(w.isEnabled() for w in command_controls(window))
    assert enabled_actions(window) == set(window.device_actions)


def test_a_rig_shows_its_address_and_description_and_no_demo(qtbot, window, dictionary):
    dev = SimulatedDevice(dictionary, pacing="realtime", seed=3).start()
    dev.firmware.description = "lab rig B: relative_2dof"      # what GET_INFO says
    try:
        address = f"tcp://127.0.0.1:{dev.tcp_port}"
        window.session.connect_address(address)
        bar = window.connection
        qtbot.waitUntil(lambda: source_delivered(window), timeout=30000)
        assert bar.source.text() == f"Rig {address} - lab rig B: relative_2dof"
        assert "Simulated" not in bar.source.text() and address in window.windowTitle()
        # the choosers say what the link was opened on: Ethernet and its address
        assert bar.kind.currentIndex() == 1 and bar.address.text() == address
        assert bar.offers(bar.address) and not bar.offers(bar.testbed)
        # the simulator's demo is not offered on a rig; the rig's own controls are on
        assert not window.demo_action.isVisible() and not window.demo_action.isEnabled()
        assert all(w.isEnabled() for w in command_controls(window))
        assert enabled_actions(window) == set(window.device_actions)
        window.session.disconnect_link()
        assert bar.source.text() == "Not connected"        # not the rig any more
    finally:
        dev.stop()


def test_a_replay_has_no_link_or_device_controls(qtbot, window, short_log):
    window.session.open_log(str(short_log))
    bar = window.connection
    assert bar.source.text() == f"Replay of {short_log.name}"
    assert short_log.name in window.windowTitle()
    # no choosers, no Connect: File > Close replay leaves the replay
    assert not choosers_shown(window) and not bar.offers(bar.testbed)
    controls = command_controls(window)
    assert controls and all(not w.isEnabled() and w.toolTip() == REPLAY_REASON for w in controls)
    p = window.parameters
    assert not any(b.isEnabled() for b in (p.upload_button, p.read_button, p.rollback_button))
    assert p.read_button.toolTip() == REPLAY_REASON
    assert p.load_button.isEnabled()                 # designs can still be looked at
    assert not window.profiles.play_button.isEnabled()
    assert not window.campaign.run_button.isEnabled()
    assert not window.demo_action.isVisible()
    assert enabled_actions(window) == set()
    # the replay closed: the choosers and the controls are back
    window.session.close_replay()
    assert bar.source.text() == "Not connected"
    assert choosers_shown(window) and bar.offers(bar.testbed)
    assert all(w.isEnabled() for w in command_controls(window)) and p.read_button.isEnabled()
    assert enabled_actions(window) == set(window.device_actions)


def test_a_read_only_console_has_nothing_that_commands(qtbot, window):
    with socket.socket() as s:                         # a port nobody publishes on
        s.bind(("127.0.0.1", 0))
        endpoint = f"tcp://127.0.0.1:{s.getsockname()[1]}"
    window.session.watch(endpoint)
    bar = window.connection
    assert bar.source.text() == f"Read-only console watching {endpoint}"
    assert "read-only console watching" in window.windowTitle().lower()
    assert not choosers_shown(window) and not bar.offers(bar.testbed)
    reason = read_only_message(endpoint)
    assert all(not w.isEnabled() and w.toolTip() == reason for w in command_controls(window))
    assert window.commands.abort_button.isEnabled()
    for panel in (window.parameters, window.generator, window.profiles, window.campaign):
        assert not panel.isEnabled()
    assert not window.demo_action.isVisible()
    # only leaving the console (Disconnect) stays in the Device menu; ABORT is not in it
    assert enabled_actions(window) == {"disconnect"}
    # leaving the console (Device > Disconnect): the choosers and the controls are back
    window.session.disconnect_link()
    assert bar.source.text() == "Not connected"
    assert choosers_shown(window) and "read-only" not in window.windowTitle()
    assert all(w.isEnabled() for w in command_controls(window))
    assert all(panel.isEnabled() for panel in (window.parameters, window.generator, window.profiles,
                                               window.campaign))
    assert enabled_actions(window) == set(window.device_actions)
