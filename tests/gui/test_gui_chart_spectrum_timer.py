"""The spectrum dock computes its PSD on its timer only while it can be seen: a dock
tabbed behind another one stays "visible" to Qt, placed outside the window, and must
not cost the GUI thread a Welch PSD four times a second.  The timer's slot is called
directly: no waiting, no timing."""

from __future__ import annotations

import pytest
from PySide6.QtWidgets import QApplication, QWidget

from groundstation.live.display_buffers import TelemetryStore
from groundstation.gui.charts.spectrum import SpectrumView


@pytest.fixture
def view_in_host(qtbot, dictionary):
    host = QWidget()
    host.resize(800, 600)
    view = SpectrumView(TelemetryStore(dictionary), dictionary, parent=host)
    # the tests call the timer's slot themselves: the view's own timer, left running,
    # fires too whenever processEvents() runs late enough (a busy machine) and would
    # add a refresh the test did not ask for
    view._timer.stop()
    view.setGeometry(0, 0, 700, 480)
    qtbot.addWidget(host)
    host.show()
    QApplication.processEvents()
    calls = []
    view.refresh = lambda: calls.append(1)
    return host, view, calls


def test_refreshes_on_its_timer_while_on_screen(view_in_host):
    _host, view, calls = view_in_host
    assert view.isVisible() and not view.visibleRegion().isEmpty()
    view._on_timer()
    assert calls == [1]


def test_no_psd_while_placed_outside_the_window(view_in_host):
    _host, view, calls = view_in_host
    view.setGeometry(-1197, -980, 697, 480)       # where a tabbed-behind dock sits
    QApplication.processEvents()
    assert view.isVisible()                       # Qt still calls it visible
    view._on_timer()
    assert calls == []
    view.setGeometry(0, 0, 700, 480)              # its tab chosen: back on screen
    QApplication.processEvents()
    view._on_timer()
    assert calls == [1]


def test_no_psd_while_hidden(view_in_host):
    _host, view, calls = view_in_host
    view.hide()
    view._on_timer()
    assert calls == []
