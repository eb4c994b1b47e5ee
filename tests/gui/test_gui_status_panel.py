"""The status panel sets a label only when what it shows changes: it refreshes ten times
a second, and every style sheet set re-polishes the label and lays the window out."""

from __future__ import annotations

import numpy as np

from groundstation.gui.panels.session_panels import StatusPanel
from groundstation.gui.session.session import Session

from conftest import HighRateFeeder


def test_unchanged_status_sets_no_label_and_a_change_shows(qtbot, dictionary, tmp_path):
    session = Session(dictionary, store_seconds=5.0, param_history=tmp_path / "history")
    panel = StatusPanel(session)
    qtbot.addWidget(panel)
    panel._timer.stop()                               # the test refreshes by hand
    feed = HighRateFeeder(dictionary, session.store)
    mode = dictionary.packet("HIGH_RATE").item_by_name["mode"].states      # name -> value
    seq = np.arange(0, 10)
    feed(seq, mode=np.full(10, mode["IDLE"]), armed=np.zeros(10), fault=np.zeros(10))
    sets = []
    for name, label in panel.fields.items():
        original = label.setStyleSheet
        label.setStyleSheet = lambda css, name=name, original=original: (sets.append(name), original(css))
    panel.refresh()
    assert panel.fields["mode"].text() == "IDLE" and "mode" in sets
    sets.clear()
    for _ in range(3):
        panel.refresh()
    assert sets == []                                 # nothing changed: no label touched
    feed(seq + 10, mode=np.full(10, mode["IDLE"]), armed=np.ones(10), fault=np.zeros(10))
    panel.refresh()
    assert sets == ["armed"] and panel.fields["armed"].text() == "YES"
    assert "2e7d32" in panel.fields["armed"].styleSheet()
    session.shutdown()
