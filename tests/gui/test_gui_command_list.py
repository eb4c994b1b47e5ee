"""The Commands dock's list: routine read-backs (a table read is one PARAM_READ per
block) fold into one counting line; failures and the operator's commands keep a line
each."""

from __future__ import annotations

import pytest

from groundstation.gui.panels.session_panels import CommandPanel
from groundstation.gui.session.session import Session


@pytest.fixture
def panel(qtbot, dictionary, tmp_path):
    session = Session(dictionary, store_seconds=1.0, param_history=tmp_path / "history")
    widget = CommandPanel(session)
    qtbot.addWidget(widget)
    yield widget
    session.shutdown()


def lines(panel) -> list[str]:
    # without the leading time (HH:MM:SS and two spaces)
    return [panel.stages.item(r).text()[10:] for r in range(panel.stages.count())]


def test_routine_read_backs_fold_into_one_counting_line(panel):
    emit = panel.session.sig_command.emit
    emit("SET_MODE", "1", "COMPLETED", "OK")
    for seq in range(37):
        emit("PARAM_READ", str(10 + seq), "COMPLETED", "OK")
    assert lines(panel) == ["PARAM_READ ×37 read-backs, last COMPLETED", "SET_MODE: COMPLETED"]
    # a failed read-back has its own line; an operator's command too; the counting line
    # moves to the top with the next read-back
    emit("PARAM_READ", "60", "TIMEOUT", "no answer")
    emit("ARM", "61", "REJECTED", "NOT_IDLE")
    emit("PARAM_READ", "62", "COMPLETED", "OK")
    assert lines(panel) == ["PARAM_READ ×38 read-backs, last COMPLETED", "ARM: REJECTED (NOT_IDLE)",
                            "PARAM_READ: TIMEOUT (no answer)", "SET_MODE: COMPLETED"]
    assert panel.stages.count() == 4
    # an upload's block writes fold too, each command on its own counting line
    for seq in range(3):
        emit("PROFILE_WRITE", str(70 + seq), "COMPLETED", "OK")
    emit("PROFILE_COMMIT", "80", "COMPLETED", "OK")
    assert lines(panel)[:3] == ["PROFILE_COMMIT: COMPLETED", "PROFILE_WRITE ×3 blocks written, last COMPLETED",
                                "PARAM_READ ×38 read-backs, last COMPLETED"]


def test_the_counting_line_comes_back_after_it_scrolled_off(panel):
    emit = panel.session.sig_command.emit
    emit("PARAM_READ", "1", "COMPLETED", "OK")
    for seq in range(210):                          # the list keeps the newest 200 lines
        emit("SET_REFERENCE", str(seq), "COMPLETED", "OK")
    assert not any("PARAM_READ" in text for text in lines(panel))
    emit("PARAM_READ", "999", "COMPLETED", "OK")
    assert lines(panel)[0] == "PARAM_READ ×2 read-backs, last COMPLETED"
    assert panel.stages.count() == 200
