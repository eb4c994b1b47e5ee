"""The Analysis dock's Identify action in the real window (offscreen).

A hidden rig - the relative testbed with J1 and the flexure stiffness moved - is run as
the fast simulator, and short open-loop identification logs are recorded on it.  The
dock must identify it from the base file the operator names (under Options, the
session's, or asked for in a dialog; never the hidden file the logs recorded), show the
table the report gives and the overlays the curves give, write a testbed file that
loads, open the design workbench on it, and say in its own words why logs that cannot
identify the rig, a base of another kind, no logs or a refused write come to nothing.
"""

from __future__ import annotations

import re
from pathlib import Path

import numpy as np
import pytest
from PySide6.QtCore import Qt
from PySide6.QtWidgets import QFileDialog

from groundstation import Testbed
from groundstation.gui.analysis.identify import HELD_COLOUR
from groundstation.gui.analysis.tables import IDENTIFY_COLUMNS, VALUE_ROLE
from groundstation.identification.pipeline import IdentificationError, identify
from groundstation.identification.report import parameter_rows
from groundstation.plant.testbed import load_testbed

ROOT = Path(__file__).resolve().parents[2]
TESTBEDS = ROOT / "profiles/testbeds"
BASE = TESTBEDS / "relative_2dof.toml"
WAVEFORMS = ROOT / "profiles/waveforms"
PROFILES = ("sysid_coarse_noise_1A", "sysid_fine_noise_1A")
RECORD_S = 3.0                       # device seconds of each excitation
#: the hidden rig: [mechanics] keys and their factors on the base file
HIDDEN = {"J1": 1.08, "flexure_stiffness": 0.88}
WAIT_MS = 180000                     # a hang guard on a loaded machine, not an expectation


def hidden_rig(folder: Path) -> Path:
    """The base file with HIDDEN applied (its slope table named by absolute path)."""
    lines = []
    for line in BASE.read_text().splitlines():
        m = re.match(r"^([A-Za-z0-9_]+) = ([0-9.e+-]+)", line)
        if m and m.group(1) in HIDDEN:
            line = f"{m.group(1)} = {float(m.group(2)) * HIDDEN[m.group(1)]!r}"
        elif line.startswith("slope_table = "):
            table = (TESTBEDS / "../friction_slope_lut.csv").resolve().as_posix()
            line = f'slope_table = "{table}"'
        lines.append(line)
    out = folder / "hidden_relative_2dof.toml"
    out.write_text("\n".join(lines) + "\n")
    return out


@pytest.fixture(scope="module")
def logs(tmp_path_factory):
    """The coarse and the fine motor's random excitation (1 A) and a log at rest, all
    open loop on the hidden rig (the fast simulator)."""
    folder = tmp_path_factory.mktemp("identify_gui")
    hidden = hidden_rig(folder)
    out = {}
    with Testbed("sim", testbed=hidden, fast=True, generator=None, log_folder=folder / "logs",
                 history=folder / "history") as tb:
        tb.set_mode("OPEN_LOOP")
        for profile in PROFILES:
            out[profile] = Path(tb.start_recording(profile))
            tb.dwell(0.2)
            tb.play(WAVEFORMS / f"{profile}.toml", max_seconds=RECORD_S)
            tb.stop_recording()
        out["rest"] = Path(tb.start_recording("rest"))
        tb.dwell(1.0)
        tb.stop_recording()
    out["hidden"] = load_testbed(hidden)
    return out


@pytest.fixture
def window(gui_window):
    return gui_window(30.0)


@pytest.fixture
def dialogs(monkeypatch):
    """The open-file dialog answered by the test: set `answer`; `asked` counts."""
    state = {"answer": "", "asked": 0}

    def fake(*_args, **_kwargs):
        state["asked"] += 1
        return state["answer"], ""
    monkeypatch.setattr(QFileDialog, "getOpenFileName", fake)
    return state


def press(qtbot, button) -> None:
    qtbot.mouseClick(button, Qt.MouseButton.LeftButton)


def finished(panel) -> bool:
    return panel.jobs.idle() and panel.identify_button.isEnabled()


def choose_base(panel, stem: str) -> None:
    panel.testbed.setCurrentIndex(panel.testbed.findText(stem))
    assert panel.options.testbed_file() == str(TESTBEDS / f"{stem}.toml")


def run(qtbot, panel) -> None:
    press(qtbot, panel.identify_button)
    assert not panel.identify_button.isEnabled()           # one at a time
    qtbot.waitUntil(lambda: finished(panel), timeout=WAIT_MS)


def shown_rows(panel) -> list[dict]:
    t = panel.identify_view.table
    return [{key: t.item(r, c).data(VALUE_ROLE) for c, (_, key, _) in enumerate(IDENTIFY_COLUMNS)}
            for r in range(t.rowCount())]


def test_identify_finds_the_hidden_rig_from_a_base_asked_for(qtbot, window, logs, dialogs):
    panel, view = window.analysis, window.analysis.identify_view
    for profile in PROFILES:
        panel.add_log(logs[profile])
    assert panel.options.testbed_file() is None            # "the log's": the session has none
    dialogs["answer"] = str(BASE)
    run(qtbot, panel)
    assert dialogs["asked"] == 1                           # asked, never the logs' own file
    assert view.result is not None, panel.status.text()
    assert panel.tabs.currentWidget() is view
    expected = parameter_rows(identify([logs[p] for p in PROFILES], BASE))
    rows = shown_rows(panel)
    assert [r["name"] for r in rows] == [e["name"] for e in expected]
    for row, want in zip(rows, expected):
        assert (row["base"], row["value"], row["status"]) == (want["base"], want["value"],
                                                              want["status"])
    by_name = {r["name"]: r for r in rows}
    hidden = logs["hidden"].mechanics
    for key in HIDDEN:
        row = by_name[f"mechanics.{key}"]
        assert row["status"] == "identified" and row["interval"].startswith("[")
        assert row["base"] == load_testbed(BASE).mechanics[key]      # the base, not the truth
        assert row["value"] == pytest.approx(hidden[key], rel=0.03)
        assert row["change_pct"] == pytest.approx(100 * (row["value"] / row["base"] - 1))
    # a held parameter looks different from an identified one
    table = view.table
    held_row = [r["name"] for r in rows].index("motor_coarse.torque_constant")
    fitted_row = [r["name"] for r in rows].index("mechanics.J1")
    assert by_name["motor_coarse.torque_constant"]["status"] == "held (scale)"
    assert table.item(held_row, 0).font().italic()
    assert table.item(held_row, 0).foreground().color() == HELD_COLOUR
    assert not table.item(fitted_row, 0).font().italic()
    assert "held (scale)" in table.item(held_row, 3).toolTip()
    assert "2 of 2 log(s) used, base relative_2dof.toml" in view.summary.text()
    assert "not saved" in view.summary.text()
    assert "not written" in view.notes.toPlainText()
    assert panel.status.text().startswith("Identify: ")
    assert "identified from 2 of 2 log(s)" in panel.status.text()
    # the overlays: every response with its measured curve and both models
    curves = view.result.curves
    assert view.response.count() == len(curves) == 4
    for i, c in enumerate(curves):
        view.response.setCurrentIndex(i)
        assert set(view.curves) == {"magnitude", "phase", "residual"}
        assert set(view.curves["magnitude"]) == {"measured", "fitted bins", "base", "identified"}
        for plot in ("magnitude", "phase"):
            for item in view.curves[plot].values():
                x, y = item.getData()
                assert len(x) > 20 and np.all(np.isfinite(y)) and np.all(x > 0)
        x, y = view.curves["magnitude"]["identified"].getData()
        ok = (c.freq_hz > 0) & np.isfinite(c.magnitude_db("identified"))
        np.testing.assert_array_equal(y, c.magnitude_db("identified")[ok])
        _, dots = view.curves["magnitude"]["fitted bins"].getData()
        assert len(dots) == int(np.count_nonzero(c.fitted))
        assert set(view.curves["residual"]) == {"base", "identified"}
    assert len(view.plot_widgets()) == 3


def test_save_writes_a_file_that_loads_and_the_workbench_opens_on_it(qtbot, window, logs,
                                                                       tmp_path):
    panel, view = window.analysis, window.analysis.identify_view
    for profile in PROFILES:
        panel.add_log(logs[profile])
    choose_base(panel, "relative_2dof")
    run(qtbot, panel)
    assert view.result is not None, panel.status.text()
    assert view.result.base_path == BASE
    # a refused write is said, and nothing else changes
    nowhere = tmp_path / "no_such_folder" / "rig.toml"
    assert not panel.save_testbed(nowhere)
    assert panel.status.text().startswith("Save testbed file: ")
    assert "cannot write" in panel.status.text()
    assert not nowhere.exists() and view.result is not None and view.saved is None
    # written: a testbed file like any other, with the identified values
    out = tmp_path / "my_rig.toml"
    assert panel.save_testbed(out)
    assert f"written to {out.resolve()}" in panel.status.text()
    rig = load_testbed(out)
    values = {r["name"]: r["value"] for r in shown_rows(panel)}
    assert rig.mechanics["J1"] == pytest.approx(values["mechanics.J1"], rel=1e-6)
    assert rig.name == f"{load_testbed(BASE).name} (identified)"
    assert "[identification]" in out.read_text()
    assert "saved as my_rig.toml" in view.summary.text()
    # Open in design workbench: a shipped design on its base (#1) and on the file (#2)
    press(qtbot, view.open_button)
    workbench = window.parameters.workbench
    try:
        assert workbench is not None and workbench.isVisible()
        assert workbench.model.slot(1).original.testbed.path == out.resolve()
        assert workbench.model.slot(0).original.testbed.path == BASE.resolve()
        assert workbench.value("testbed", 1) == "my_rig.toml"
        assert workbench.value("testbed", 0) == "relative_2dof.toml"
        assert workbench.model.slot(0).original.path == workbench.model.slot(1).original.path
        assert "design workbench opened on my_rig.toml" in panel.status.text()
    finally:
        workbench.shutdown()


def test_the_session_testbed_is_the_base_and_a_dialog_left_empty_runs_nothing(
        qtbot, window, logs, dialogs):
    panel = window.analysis
    panel.add_log(logs[PROFILES[0]])
    window.session.testbed = str(BASE)
    assert panel.run_identify()
    assert "(the session's testbed)" in panel.status.text() and dialogs["asked"] == 0
    assert panel.cancel()
    assert panel.status.text() == "Identify cancelled: nothing shown from it"
    assert panel.identify_button.isEnabled() and not panel.cancel_button.isEnabled()
    qtbot.waitUntil(lambda: panel.jobs.join(0.0), timeout=WAIT_MS)    # its worker has ended
    assert panel.identify_view.result is None              # what it computed was dropped
    window.session.testbed = None
    assert not panel.run_identify()                        # the dialog is answered with nothing
    assert dialogs["asked"] == 1 and panel.jobs.idle()
    assert panel.status.text().startswith("Identify: no base testbed chosen")


def test_logs_that_cannot_identify_the_rig_say_why_and_nothing_is_written(
        qtbot, window, logs, tmp_path):
    panel, view = window.analysis, window.analysis.identify_view
    panel.add_log(logs["rest"])
    choose_base(panel, "relative_2dof")
    run(qtbot, panel)
    with pytest.raises(IdentificationError) as refused:
        identify([logs["rest"]], BASE)
    assert panel.status.text() == f"Identify failed: {refused.value}; nothing written"
    assert "none of the logs is an open-loop random excitation" in panel.status.text()
    assert view.result is None and view.table.rowCount() == 0
    assert not view.save_button.isEnabled() and not view.open_button.isEnabled()
    assert str(refused.value) in view.summary.text()
    out = tmp_path / "rig.toml"
    assert not panel.save_testbed(out) and not out.exists()
    assert "nothing identified yet" in panel.status.text()
    assert not panel.open_in_workbench() and window.parameters.workbench is None


def test_a_base_testbed_of_another_kind_is_refused(qtbot, window, logs):
    panel = window.analysis
    panel.add_log(logs[PROFILES[0]])
    choose_base(panel, "inertial_2dof")
    run(qtbot, panel)
    assert panel.status.text().startswith("Identify failed: ")
    assert "identify each rig from its own logs" in panel.status.text()
    assert panel.identify_view.result is None


def test_no_logs_no_identification(qtbot, window, dialogs):
    panel = window.analysis
    press(qtbot, panel.identify_button)
    assert panel.status.text() == "Identify: tick at least one log"
    assert panel.jobs.idle() and panel.identify_button.isEnabled() and dialogs["asked"] == 0
