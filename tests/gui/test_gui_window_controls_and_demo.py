"""Issue 13, the smaller things a user noticed, in the real window (offscreen) and, where
the device matters, against the simulated testbed (a child process, as in `make run`):

- the limits table shows every channel's full name;
- the Mode box follows the mode the device reports, without sending anything;
- the one-click demo (a controller design uploaded, a step profile played) moves the
  simulated axis, is offered only on the simulator, and Esc stops it with the rig safe.
"""

from __future__ import annotations

import pytest
from PySide6.QtCore import Qt

from groundstation.gui.demo import DEMO_TITLE, plan_for
from groundstation.sim import SimulatedDevice


@pytest.fixture
def window(gui_window):
    # answer "Yes" to critical-command dialogs
    return gui_window(60.0, confirm=("commands",))


def ring(win):
    return win.session.store.ring("HIGH_RATE")


def connect(qtbot, win):
    win.session.connect_sim()
    qtbot.waitUntil(lambda: win.session.client is not None and ring(win).total_frames > 1200,
                    timeout=60000)


OPERATOR_COMMANDS = ("SET_MODE", "ARM", "DISARM", "ABORT", "FRICTION_COMP", "SET_REFERENCE",
                     "SET_CURRENTS")


def sent_commands(win) -> list[str]:
    """The operator-level commands the client sends from now on (the heartbeat and the
    parameter read done at connect are left out)."""
    names: list[str] = []
    win.session.client.add_command_listener(
        lambda r: names.append(r.name) if r.name in OPERATOR_COMMANDS or r.name.startswith("PROFILE")
        else None)
    return names


# ---------------------------------------------------------------------------- limits table
def test_limits_table_shows_every_channel_name_in_full(qtbot, window):
    table = window.status_panel.limits
    window.status_panel.refresh()                 # the monitor knows every limited channel
    assert table.rowCount() >= 10
    qtbot.waitUntil(lambda: table.isVisible(), timeout=5000)
    window.status_panel.refresh()
    fm = table.fontMetrics()
    longest = max((table.item(r, 0).text() for r in range(table.rowCount())), key=fm.horizontalAdvance)
    assert longest.startswith("HOUSEKEEPING.")
    # wide enough for what Qt itself needs to draw the longest name un-elided
    assert table.columnWidth(0) >= table.sizeHintForColumn(0)
    assert table.columnWidth(0) >= fm.horizontalAdvance(longest)
    for r in range(table.rowCount()):
        item = table.item(r, 0)
        name = window.session.limits.snapshot()[r].channel
        assert item.text() == name
        assert table.visualItemRect(item).width() >= fm.horizontalAdvance(name)
        assert name in item.toolTip()             # and the full name on hover
    # the name column is the one in view when the dock is narrow
    assert table.columnViewportPosition(0) == 0


# ---------------------------------------------------------------------------- mode box
def test_mode_box_follows_the_device_and_sends_nothing(qtbot, window):
    connect(qtbot, window)
    combo = window.commands.mode
    qtbot.waitUntil(lambda: window.status_panel.fields["mode"].text() == "IDLE", timeout=10000)
    assert combo.currentText() == "IDLE"
    sent = sent_commands(window)
    # the mode set elsewhere than the box (a profile, a campaign, a script, the session)
    window.session.command("SET_MODE", mode="RELATIVE")
    qtbot.waitUntil(lambda: window.status_panel.fields["mode"].text() == "RELATIVE", timeout=10000)
    qtbot.waitUntil(lambda: combo.currentText() == "RELATIVE", timeout=5000)
    # following the device sent nothing of its own
    qtbot.waitUntil(lambda: sent == ["SET_MODE"], timeout=5000)
    # the friction-compensation box too (it sends when toggled: following must not)
    assert not window.commands.friction.isChecked()
    window.session.command("FRICTION_COMP", enable=1)
    qtbot.waitUntil(lambda: ring(window).latest("friction_comp_on") == 1, timeout=10000)
    qtbot.waitUntil(lambda: window.commands.friction.isChecked(), timeout=5000)
    frames = ring(window).total_frames
    qtbot.waitUntil(lambda: ring(window).total_frames > frames + 600, timeout=10000)
    assert sent == ["SET_MODE", "FRICTION_COMP"]

    # the operator's choice, not yet sent, is not overwritten while the device stays put
    combo.setCurrentText("OPEN_LOOP")
    frames = ring(window).total_frames
    qtbot.waitUntil(lambda: ring(window).total_frames > frames + 600, timeout=10000)
    assert combo.currentText() == "OPEN_LOOP"

    # Esc: the device goes to IDLE, and so does the box
    qtbot.keyClick(window, Qt.Key.Key_Escape)
    qtbot.waitUntil(lambda: window.status_panel.fields["mode"].text() == "IDLE", timeout=10000)
    qtbot.waitUntil(lambda: combo.currentText() == "IDLE", timeout=5000)
    assert sent.count("SET_MODE") == 1 and sent.count("FRICTION_COMP") == 1 and "ABORT" in sent


# ---------------------------------------------------------------------------- command order
FINAL_STAGES = ("COMPLETED", "REJECTED", "FAILED", "TIMEOUT", "CANCELLED")


def final_stages(win) -> list[tuple[str, str]]:
    """How each command sent from now on ended: the client's report of a command it sent
    (with its sequence number), or the Session's CANCELLED for one it never sent (the
    per-stage reports, without a sequence number, are left out)."""
    out: list[tuple[str, str]] = []

    def seen(name, seq, stage, _reason):
        if (seq and stage in FINAL_STAGES and name != "HEARTBEAT") or (not seq and stage == "CANCELLED"):
            out.append((name, stage))
    win.session.sig_command.connect(seen)
    return out


def test_commands_go_out_in_the_order_given_and_abort_drops_what_waits(qtbot, window):
    connect(qtbot, window)
    ended = final_stages(window)
    sent = sent_commands(window)
    # given at once: the ARM must not overtake the SET_MODE (it would be refused in IDLE)
    window.session.command("SET_MODE", mode="OPEN_LOOP")
    window.session.command("ARM")
    qtbot.waitUntil(lambda: len(ended) >= 2, timeout=20000)
    assert ended == [("SET_MODE", "COMPLETED"), ("ARM", "COMPLETED")]
    assert sent == ["SET_MODE", "ARM"]
    qtbot.waitUntil(lambda: ring(window).latest("armed") == 1, timeout=10000)

    # a queue of commands, then ABORT: whatever had not gone out yet is dropped
    ended.clear()
    queued = 30
    for i in range(queued):
        window.session.command("SET_CURRENTS", current_coarse=0.001 * (i % 3), current_fine=0.0)
    window.session.abort()
    qtbot.waitUntil(lambda: len(ended) >= queued + 1, timeout=30000)
    assert len(ended) == queued + 1, ended
    stages = dict.fromkeys(ended)
    assert ("ABORT", "COMPLETED") in stages
    assert all(stage in ("COMPLETED", "CANCELLED", "REJECTED") for _, stage in ended)
    assert sent.count("SET_CURRENTS") + sum(s == "CANCELLED" for _, s in ended) == queued
    qtbot.waitUntil(lambda: ring(window).latest("armed") == 0 and ring(window).latest("mode") == 0
                    and ring(window).latest("current_coarse") == 0.0, timeout=10000)


# ---------------------------------------------------------------------------- replaced links
def test_a_replaced_link_saying_lost_starts_no_reconnect(qtbot, window, dictionary):
    """Switching devices closes the old client on a worker thread; if its device goes
    away first, the old client still reports "lost".  That must not start a reconnect
    that takes the new link over."""
    session = window.session
    events: list[str] = []
    session.sig_event.connect(lambda _level, _source, text: events.append(text))
    old_dev = SimulatedDevice(dictionary, pacing="realtime", seed=1).start()
    new_dev = SimulatedDevice(dictionary, pacing="realtime", seed=2).start()
    try:
        session.connect_address(f"tcp://127.0.0.1:{old_dev.tcp_port}")
        qtbot.waitUntil(lambda: session.client is not None and session.client.link_state == "up",
                        timeout=30000)
        old_client = session.client
        session.connect_address(f"tcp://127.0.0.1:{new_dev.tcp_port}")
        qtbot.waitUntil(lambda: session.client is not None and session.client is not old_client
                        and session.client.link_state == "up", timeout=30000)
        new_client = session.client
        old_client._lost("the old device went away")       # the client's own loss path
        frames = ring(window).total_frames
        qtbot.waitUntil(lambda: ring(window).total_frames > frames + 600, timeout=10000)
        assert session.client is new_client and new_client.link_state == "up"
        assert not session._reconnect.isActive()
        assert not any("reconnecting" in e or "link lost" in e for e in events), events
        # the session's own link going away still reconnects
        new_client._lost("cable pulled")
        qtbot.waitUntil(lambda: any("reconnecting" in e for e in events), timeout=5000)
        session.disconnect_link()
    finally:
        old_dev.stop()
        new_dev.stop()


# ---------------------------------------------------------------------------- demo
def test_demo_moves_the_simulated_axis_and_esc_stops_it(qtbot, window):
    demo = window.demo
    assert DEMO_TITLE.startswith("Demo:")
    assert window.demo_action.text() == DEMO_TITLE
    assert not window.demo_action.isEnabled()            # nothing connected yet
    connect(qtbot, window)
    qtbot.waitUntil(lambda: window.demo_action.isEnabled(), timeout=10000)
    assert window.demo_button.isVisible()
    plan = plan_for(window.session.testbed)
    assert plan is not None and plan.design.name == "relative_design2.toml"

    # one click: the design is validated and uploaded, then the step is played
    encoder = ring(window).latest("encoder_inner")
    window.demo_action.trigger()
    assert demo.running and not window.demo_action.isEnabled()
    qtbot.waitUntil(lambda: demo.state == "completed", timeout=60000)
    assert window.parameters.report is not None and window.parameters.report.ok
    assert window.session.last_uploaded_crc is not None
    snap = ring(window).snapshot(["encoder_inner", "reference"], seconds=30.0)
    moved = snap.values["encoder_inner"].max() - encoder
    assert moved > 0.8e-3, f"the axis moved {moved:.3g} rad for a 1 mrad step"
    assert snap.values["reference"].max() - snap.values["reference"].min() > 0.9e-3
    # the charts show the channels that move
    shown = {c for plot in window.charts.stack.layout_ids() for c in plot}
    assert {"HIGH_RATE.encoder_inner", "HIGH_RATE.reference", "HIGH_RATE.current_fine"} <= shown
    assert "HIGH_RATE.gyro_rate" not in shown         # flat on a testbed without a gyro
    # the mode the profile played in is what the Mode box shows
    qtbot.waitUntil(lambda: window.commands.mode.currentText() == "RELATIVE", timeout=5000)
    qtbot.waitUntil(lambda: window.demo_action.isEnabled(), timeout=5000)

    # again, and Esc in the middle of the step: ABORT, the rig safe, the demo stopped
    window.demo_action.trigger()
    assert demo.state == "uploading", demo.text
    qtbot.waitUntil(lambda: demo.state != "uploading", timeout=30000)
    assert demo.state == "playing", demo.text
    start = ring(window).latest("encoder_inner")
    qtbot.waitUntil(lambda: ring(window).latest("armed") == 1
                    and ring(window).latest("encoder_inner") - start > 0.5e-3, timeout=20000)
    window.events.search.setFocus()
    qtbot.keyClick(window.events.search, Qt.Key.Key_Escape)
    qtbot.waitUntil(lambda: demo.state == "aborted", timeout=10000)
    qtbot.waitUntil(lambda: ring(window).latest("armed") == 0 and ring(window).latest("mode") == 0
                    and ring(window).latest("current_coarse") == 0.0
                    and ring(window).latest("current_fine") == 0.0, timeout=10000)
    qtbot.waitUntil(lambda: not window.session.profiles.playing, timeout=10000)
    assert "aborted" in window.demo_status.text().lower()
    assert "ABORT" in window.demo_status.toolTip()


def test_demo_is_offered_only_once_the_telemetry_shows_the_drives_disarmed(qtbot, window):
    connect(qtbot, window)
    qtbot.waitUntil(lambda: window.demo_action.isEnabled(), timeout=10000)
    # each command goes on its own worker thread: the ARM only once the mode shows
    window.session.command("SET_MODE", mode="OPEN_LOOP")
    qtbot.waitUntil(lambda: window.status_panel.fields["mode"].text() == "OPEN_LOOP", timeout=10000)
    window.session.command("ARM")
    qtbot.waitUntil(lambda: ring(window).latest("armed") == 1, timeout=10000)
    qtbot.waitUntil(lambda: not window.demo_action.isEnabled(), timeout=5000)
    assert "disarm first" in window.demo_action.toolTip()
    # a click anyway (e.g. from the menu's shortcut) is refused: nothing is sent
    sent = sent_commands(window)
    assert "disarm first" in (window.demo.start() or "")
    assert window.demo.state == "idle" and not sent
    window.session.command("DISARM")
    qtbot.waitUntil(lambda: ring(window).latest("armed") == 0, timeout=10000)
    qtbot.waitUntil(lambda: window.demo_action.isEnabled(), timeout=5000)


def test_demo_escape_while_the_design_is_validated_sends_no_table(qtbot, window):
    """The design is validated off the GUI thread while the window serves events, so Esc
    can arrive before the upload is sent: then nothing is sent at all."""
    connect(qtbot, window)
    qtbot.waitUntil(lambda: window.demo_action.isEnabled(), timeout=10000)
    tables: list[str] = []
    window.session.client.add_command_listener(
        lambda r: tables.append(r.name) if r.name.startswith("PARAM_") and r.name != "PARAM_READ"
        else None)
    sent = sent_commands(window)

    def esc_at_once(state: str, _text: str) -> None:
        if state == "uploading":                     # the demo has begun: the operator hits Esc
            window.abort()
    window.demo.sig_state.connect(esc_at_once)
    window.demo_action.trigger()
    window.demo.sig_state.disconnect(esc_at_once)
    assert window.demo.state == "aborted"
    qtbot.waitUntil(lambda: "ABORT" in sent, timeout=10000)
    qtbot.waitUntil(lambda: window.demo_action.isEnabled(), timeout=30000)
    frames = ring(window).total_frames
    qtbot.waitUntil(lambda: ring(window).total_frames > frames + 1200, timeout=10000)
    assert tables == [] and "ARM" not in sent


def test_demo_escape_during_the_upload_plays_nothing(qtbot, window):
    connect(qtbot, window)
    qtbot.waitUntil(lambda: window.demo_action.isEnabled(), timeout=10000)
    sent = sent_commands(window)
    window.demo_action.trigger()
    assert window.demo.state == "uploading"
    window.abort()                                       # before the upload has finished
    assert window.demo.state == "aborted"
    # whatever the upload does now, no profile is armed or played afterwards
    qtbot.waitUntil(lambda: "ABORT" in sent, timeout=10000)
    qtbot.waitUntil(lambda: window.demo_action.isEnabled(), timeout=30000)
    frames = ring(window).total_frames
    qtbot.waitUntil(lambda: ring(window).total_frames > frames + 1200, timeout=10000)
    assert "ARM" not in sent and not any(n.startswith("PROFILE") for n in sent)
    assert ring(window).latest("armed") == 0


def test_demo_is_not_offered_on_a_rig_or_a_testbed_without_a_valid_design(qtbot, window, dictionary):
    # a device at a network address is a rig as far as the window can know
    dev = SimulatedDevice(dictionary, pacing="realtime", seed=1).start()
    try:
        window.session.connect_address(f"tcp://127.0.0.1:{dev.tcp_port}")
        qtbot.waitUntil(lambda: window.session.client is not None
                        and window.session.client.link_state == "up", timeout=30000)
        qtbot.waitUntil(lambda: not window.demo_button.isVisible(), timeout=5000)
        assert not window.demo_action.isEnabled() and not window.demo_action.isVisible()
        assert "simulated testbed" in window.demo.unavailable_reason()
        assert window.demo.start() is not None and window.demo.state == "idle"
        window.session.disconnect_link()
    finally:
        dev.stop()
    # the inertial designs are refused by validation (docs/controllers.md): no demo there
    assert plan_for("profiles/testbeds/inertial_2dof.toml") is None
    assert plan_for("profiles/testbeds/rigid_1dof.toml").design.name == "rigid_pid.toml"
    assert plan_for(None).design.name == "relative_design2.toml"        # the default testbed
