"""Labels and tables whose contents change several times a second must not lay the main
window out again (each layout request walks the whole window): SteadyLabel (the charts'
figures, the link health, the spectrum's RMS, the status values, the recording figures)
and the status panel's limit table.  Counted with an event filter, no timing."""

from __future__ import annotations

import pytest
from PySide6.QtCore import QEvent, QObject
from PySide6.QtGui import QColor
from PySide6.QtWidgets import (QAbstractScrollArea, QApplication, QTableWidgetItem,
                               QVBoxLayout, QWidget)

from groundstation.gui.common.steady_label import SteadyLabel
from groundstation.gui.panels.session_panels import _LimitTable


class _LayoutRequests(QObject):
    def __init__(self, watched: QWidget):
        super().__init__()
        self.count = 0
        watched.installEventFilter(self)

    def eventFilter(self, obj, event):
        if event.type() == QEvent.Type.LayoutRequest:
            self.count += 1
        return False


@pytest.fixture
def host(qtbot):
    w = QWidget()
    QVBoxLayout(w)
    qtbot.addWidget(w)
    w.show()
    return w


def _settle():
    QApplication.sendPostedEvents()
    QApplication.processEvents()


def test_steady_label_text_changes_do_not_lay_out(host):
    label = SteadyLabel("30 fps · 3.1 ms · newest 12.5 s")
    host.layout().addWidget(label)
    _settle()
    size = label.size()
    requests = _LayoutRequests(host)
    for k in range(20):
        label.setText(f"{29 + k % 3} fps · {k % 10}.{k % 7} ms · newest {12.5 + k:.1f} s")
        _settle()
    assert requests.count == 0
    assert label.is_fixed() and label.size() == size
    label.setText("30 fps · 3.1 ms · " + "newest 12.5 s " * 4)     # needs more room: grows once
    _settle()
    assert requests.count >= 1 and label.width() > size.width()
    grown, requests.count = label.width(), 0
    label.setText("short")                                        # keeps its size
    _settle()
    assert requests.count == 0 and label.width() == grown
    assert label.text() == "short"


def test_steady_label_with_a_width_keeps_it(host):
    label = SteadyLabel("not connected", width=300)
    host.layout().addWidget(label)
    _settle()
    requests = _LayoutRequests(host)
    label.setText("1200 frames/s · dropped 0 · CRC errors 0 · latency 1.2 ms " * 3)
    label.setStyleSheet("color:#c62828; font-weight:bold;")
    _settle()
    assert label.width() == 300 and label.is_fixed()
    label.setText("1201 frames/s · dropped 0 · CRC errors 0")
    _settle()
    assert label.width() == 300
    assert requests.count <= 1              # the style change may re-polish once; the texts not


def test_limit_table_values_only_repaint(host):
    table = _LimitTable(2, 4)
    for r in range(2):
        for c in range(4):
            table.setItem(r, c, QTableWidgetItem(f"HOUSEKEEPING.temp_{r}" if c == 0 else "-"))
    table.setSizeAdjustPolicy(QAbstractScrollArea.SizeAdjustPolicy.AdjustToContents)
    host.layout().addWidget(table)
    _settle()
    requests = _LayoutRequests(host)
    for k in range(10):
        table.item(0, 1).setText(f"{k}.5 degC")
        table.item(1, 3).setText(f"{k}")
        table.item(0, 2).setBackground(QColor("#2e7d32" if k % 2 else "#c62828"))
        _settle()
    assert requests.count == 0
    assert table.item(0, 1).text() == "9.5 degC"
    table.item(1, 0).setText("HOUSEKEEPING.a_much_longer_channel_name")   # the names still count
    _settle()
    assert requests.count >= 1
