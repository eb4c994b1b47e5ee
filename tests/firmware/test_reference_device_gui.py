"""The operator's window (offscreen) connected to the C reference device shows its
frames, as tests/gui connect it to a simulated device at a network address."""

from __future__ import annotations

from reference_device_helpers import running_reference_device


def test_window_connects_to_the_reference_device_and_shows_frames(qtbot, gui_window):
    win = gui_window(30.0)
    with running_reference_device() as address:
        win.session.connect_address(address)
        qtbot.waitUntil(lambda: win.session.client is not None
                        and win.session.client.link_state == "up", timeout=30000)
        ring = win.session.store.ring("HIGH_RATE")
        qtbot.waitUntil(lambda: ring.total_frames > 2400, timeout=30000)
        # what the operator reads: the status panel's fields, filled from the device's frames
        fields = win.status_panel.fields
        qtbot.waitUntil(lambda: fields["param_table_crc"].text() == "358f611e", timeout=10000)
        assert fields["mode"].text() == "IDLE" and fields["armed"].text() == "no"
        assert fields["watchdog"].text() == "OK" and fields["fault_code"].text() == "NONE"
        assert fields["temp_flexure"].text().endswith("degC")
        snap = win.session.client.stats.snapshot()
        assert snap.framing["crc_errors"] == 0 and snap.packets["HIGH_RATE"].dropped == 0
        win.session.disconnect_link()
        qtbot.waitUntil(lambda: win.session.client is None
                        or win.session.client.link_state != "up", timeout=10000)
