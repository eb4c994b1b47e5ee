"""The parameter panel in the real window against the simulated testbed: load a thesis
design, validate it, upload it (journaled in the recording), see all three columns
agree, edit with range checks, roll back."""

from __future__ import annotations

from pathlib import Path

import pytest

from groundstation.logs import LogReader
from groundstation.params import table as ptable

CONTROLLERS = Path(__file__).resolve().parents[2] / "profiles" / "controllers"


@pytest.fixture
def window(gui_window):
    return gui_window(20.0, confirm=("parameters",))


def design2_with_c0_gain(tmp_path, gain: str) -> Path:
    """Relative Design #2 with c0's gain replaced (and its testbed path made absolute)."""
    text = (CONTROLLERS / "relative_design2.toml").read_text()
    path = tmp_path / f"design2_c0_gain_{gain}.toml"
    path.write_text(text.replace('"../testbeds/', f'"{CONTROLLERS.parent / "testbeds"}/')
                    .replace("gain = 30801", f"gain = {gain}"))
    return path


def tree_row(panel, name):
    for i in range(panel.tree.topLevelItemCount()):
        item = panel.tree.topLevelItem(i)
        if item.text(0) == name:
            return item
    raise AssertionError(f"{name} not in the parameter tree")


def test_design_to_verified_table_and_back(qtbot, window, tmp_path):
    panel, session = window.parameters, window.session
    session.connect_sim("profiles/testbeds/relative_2dof.toml")
    qtbot.waitUntil(lambda: panel.device is not None, timeout=60000)   # read on connect
    assert window.connection.testbed.currentText().endswith("relative_2dof.toml")
    original_crc = panel.device_crc
    assert tree_row(panel, "outer_loop_gain").text(3) == tree_row(panel, "outer_loop_gain").text(1)

    assert panel.load_design(CONTROLLERS / "relative_design2.toml")
    assert panel.report is not None and panel.report.ok, panel.result.text()
    assert "OK" in panel.result.text() and "phase margin" in panel.result.text()
    assert panel.mag_plot.listDataItems(), "no Bode plot"
    assert tree_row(panel, "relative_c0").background(1).color().alpha() > 0   # differs from device

    session.start_recording(str(tmp_path), "upload")
    assert panel.upload()
    sent_crc = ptable.table_crc(ptable.pack(session.d, panel.values))
    qtbot.waitUntil(lambda: panel.device_crc == sent_crc, timeout=20000)
    assert session.last_uploaded_crc == sent_crc
    assert "verified" in panel.result.text()
    row = tree_row(panel, "relative_c0")
    assert row.text(1) == row.text(2) == row.text(3)                     # design = uploaded = device
    qtbot.waitUntil(lambda: window.status_panel.fields["param_table_crc"].text() == f"{sent_crc:08x}",
                    timeout=10000)
    assert window.status_panel.crc_warning.text() == ""
    path = session.recorder.path
    session.stop_recording()
    with LogReader(path) as log:
        tables = log.journal("parameter_table")
    assert [t.data["crc"] for t in tables] == [sent_crc]
    assert ptable.table_crc(tables[0].blob) == sent_crc and "relative_design2" in tables[0].data["source"]

    # in-place edits: out of range refused, nothing changes; a good value is taken
    before = dict(panel.values)
    assert "outside" in panel.set_value("saturation_fine", "99")
    assert "not a number" in panel.set_value("saturation_fine", "abc")
    assert panel.values == before
    assert panel.set_value("saturation_fine", "12.5") is None and panel.values["saturation_fine"] == 12.5

    panel.rollback()
    qtbot.waitUntil(lambda: panel.device_crc == original_crc, timeout=20000)


def test_an_unstable_design_is_refused_and_nothing_is_sent(qtbot, window, tmp_path):
    panel, session = window.parameters, window.session
    sent = []
    session.connect_sim("profiles/testbeds/relative_2dof.toml")
    qtbot.waitUntil(lambda: panel.device is not None, timeout=60000)
    session.client.add_command_listener(lambda r: sent.append(r.name))
    bad = design2_with_c0_gain(tmp_path, "30801000")      # c0's gain 1000x: unstable
    assert panel.load_design(bad)
    assert panel.report is not None and not panel.report.ok
    assert "REFUSED" in panel.result.text()
    assert not panel.upload()
    assert not [n for n in sent if n.startswith("PARAM_BEGIN")]


def test_a_marginal_design_is_sent_only_with_its_margins_accepted(qtbot, window, tmp_path):
    panel, session = window.parameters, window.session
    sent = []
    session.connect_sim("profiles/testbeds/relative_2dof.toml")
    qtbot.waitUntil(lambda: panel.device is not None, timeout=60000)
    session.client.add_command_listener(lambda r: sent.append(r.name))
    slow = design2_with_c0_gain(tmp_path, "6000")         # stable, phase margin about 6 deg
    assert panel.load_design(slow)
    assert panel.report is not None and not panel.report.ok and not panel.report.problems
    assert panel.result.text().startswith("MARGINAL: stable, but")
    panel.confirm_override = True
    panel.override_reason = ""                      # the operator gives no reason
    assert not panel.upload()
    assert not [n for n in sent if n.startswith("PARAM_BEGIN")]
    panel.override_reason = "slow loop for a bearing run-in"
    assert panel.upload()
    qtbot.waitUntil(lambda: "verified" in panel.result.text(), timeout=20000)
    assert "stable but marginal, margins accepted: slow loop for a bearing run-in" in panel.result.text()


def test_the_numerics_run_off_the_gui_thread_while_it_serves_events(qtbot, window, monkeypatch):
    """Validating (and the Bode data) runs on the panel's pool thread; the GUI thread
    meanwhile serves its events: a timer of the GUI thread releases the validation."""
    import threading

    from PySide6.QtCore import QTimer

    import groundstation.gui.panels.params as panel_module

    panel = window.parameters
    served = threading.Event()
    threads: list[bool] = []
    real_validate = panel_module.validate

    def validate(*args, **kwargs):
        threads.append(threading.current_thread() is threading.main_thread())
        # held until the GUI thread has served a timer: on the GUI thread this would hang
        assert served.wait(60), "the GUI thread served no event while validating"
        return real_validate(*args, **kwargs)

    monkeypatch.setattr(panel_module, "validate", validate)
    QTimer.singleShot(0, served.set)
    assert panel.load_design(CONTROLLERS / "relative_design2.toml")
    assert threads == [False]
    assert panel.report is not None and panel.report.ok and panel.mag_plot.listDataItems()
    assert panel.upload_button.isEnabled() and panel.load_button.isEnabled()   # given back
    # Validate again: the same, and a current report spares Upload a second validation
    served.clear()
    QTimer.singleShot(0, served.set)
    assert panel.run_validation() is panel.report and threads == [False, False]
    assert panel.set_value("saturation_fine", "12.5") is None and panel.report is None
