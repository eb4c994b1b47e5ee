"""The design workbench (offscreen): relative Design #1 and #2 side by side hold the
numbers the PQ modules give; an edit of Q recomputes every view and, with c0 kept
output-equivalent, leaves the loop gain the reference's; save -> load_design round trip;
Send to Parameters validates the saved file in the Parameters dock."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
from PySide6.QtCore import Qt

from groundstation.gui.workbench.workbench import DesignWorkbench
from groundstation.gui.workbench.model import WorkbenchModel
from groundstation.gui.workbench.plots import db
from groundstation.params.design_file import load_design
from groundstation.params.design_writer import transfer_function_mismatch
from groundstation.params.loop import validate
from groundstation.params.pq_design import analyze, dc_input_sensitivity, frequency_grid
from groundstation.params.pq_report import summarize
from groundstation.params.tf_algebra import DesignError

CONTROLLERS = Path(__file__).resolve().parents[2] / "profiles" / "controllers"
FRESH_MS = 120000                   # generous: a shared 2-core machine, a worker process


@pytest.fixture
def make_workbench(qtbot, dictionary):
    made = []

    def make(processes: bool = True, send=None) -> DesignWorkbench:
        wb = DesignWorkbench(dictionary, send=send, processes=processes)
        qtbot.addWidget(wb)
        wb.show()
        made.append(wb)
        return wb

    yield make
    for wb in made:
        wb.shutdown()


def fresh(qtbot, wb: DesignWorkbench) -> None:
    """Wait for the margins and responses of the latest edit of every slot."""
    qtbot.waitUntil(lambda: not wb.stale(), timeout=FRESH_MS)


def both_relative(qtbot, wb: DesignWorkbench):
    assert wb.open_design(0, CONTROLLERS / "relative_design1.toml")
    assert wb.open_design(1, CONTROLLERS / "relative_design2.toml")
    fresh(qtbot, wb)
    return load_design(CONTROLLERS / "relative_design1.toml"), load_design(CONTROLLERS / "relative_design2.toml")


def test_design_1_and_2_side_by_side_show_the_numerics(qtbot, make_workbench, dictionary):
    wb = make_workbench()
    d1, d2 = both_relative(qtbot, wb)
    assert wb.jobs.uses_process
    # T_I(0) as the numerics give it (and as the reference prints it)
    assert wb.value("dc", 0) == dc_input_sensitivity(d1).text() == "[[1, 0], [13.9, 0]]"
    assert wb.value("dc", 1) == dc_input_sensitivity(d2).text() == "[[1, 0], [0, 0]]"
    for design, slot in ((d1, 0), (d2, 1)):
        phi14 = analyze(design, np.array([14.0])).phi_deg[0]
        assert wb.value("phi_14", slot) == f"{phi14:.1f}°"
        a = analyze(design, frequency_grid())
        x, y = wb.plots.curve_data(slot, "phi")
        np.testing.assert_allclose(x, a.freqs_hz, rtol=1e-15)
        np.testing.assert_allclose(y, a.phi_deg, rtol=1e-12, atol=1e-12)
        i = int(np.searchsorted(x, 14.0))               # one grid point, by hand
        assert y[i] == pytest.approx(analyze(design, np.array([x[i]])).phi_deg[0], abs=1e-9)
        for key, want in (("pq_mag", db(a.pq)), ("ti", db(a.functions.ti_norm)),
                          ("ti_bound", db(a.functions.ti_bound)), ("sik", db(a.functions.sik_norm)),
                          ("sik_bound", db(a.functions.sik_bound))):
            np.testing.assert_allclose(wb.plots.curve_data(slot, key)[1], want, rtol=1e-12, atol=1e-12)
        s = summarize(design, dictionary=dictionary)
        m = s.validation.margins
        assert f"PM {m.phase_margin_deg:.1f}° @ {m.crossover_hz:.3g} Hz" in wb.value("margins", slot)
        assert wb.value("verdict", slot).startswith("OK")
        t, u2 = wb.plots.curve_data(slot, "u2_d")
        np.testing.assert_allclose(u2, s.responses.disturbance.u[:, 1], rtol=1e-9, atol=1e-12)
        assert f"{s.saturation.peaks_in_oz[1]:.3g}" in wb.value("dist", slot)
    assert "34.1 SATURATES" in wb.value("dist", 0) and "SATURATES" not in wb.value("dist", 1)
    assert wb.value("pq_cross", 0).startswith("31.6 Hz (-49°)")
    # the contour fills: 11 regions on |PQ| (five bands twice, 75-90 deg once), 11 on the
    # angle, 6 on phi; the limits drawn on both torque plots
    from pyqtgraph import InfiniteLine, LinearRegionItem
    regions = [sum(isinstance(i, LinearRegionItem) for i in p.items)
               for p in (wb.plots.mag, wb.plots.phase, wb.plots.phi)]
    assert regions == [11, 11, 6]
    lines = [i for i in wb.plots.dist_u.items if isinstance(i, InfiniteLine)]
    assert sorted(line.value() for line in lines) == [-81.3, -16.1, 16.1, 81.3]


def test_an_edit_of_q_recomputes_every_view_and_keeps_the_loop(qtbot, make_workbench):
    wb = make_workbench()
    d1, d2 = both_relative(qtbot, wb)
    assert wb.current == 1                  # the design opened last is the one edited
    wb.editor.slot_combo.setCurrentIndex(0)
    assert wb.current == 0
    slot = wb.model.slot(0)
    assert slot.reference is not None and slot.reference.path == d2.path     # as the file says
    assert wb.editor.keep.isChecked()
    c0_gain = wb.editor.table.item(wb.editor.row_of("c0", "gain"), 2)
    assert not c0_gain.flags() & Qt.ItemFlag.ItemIsEditable       # computed, not typed
    q_gain = wb.editor.table.item(wb.editor.row_of("Q", "gain"), 2)
    assert q_gain.flags() & Qt.ItemFlag.ItemIsEditable and q_gain.text() == "13.928"
    before = {k: wb.plots.curve_data(0, k)[1].copy() for k in ("phi", "ti", "ti_bound", "pq_mag", "u2_d", "y_d")}
    dist_before = wb.value("dist", 0)
    ref_loop = analyze(d2, frequency_grid()).functions.loop

    with qtbot.waitSignal(wb.sig_fresh, timeout=FRESH_MS):
        wb.editor.set_value("Q", "gain", None, "20")
        # the fast views changed at once; the slow ones are marked stale until they arrive
        assert wb.stale(0) and "(stale)" in wb.value("dist", 0)
        assert wb.model.slot(0).factors["Q"].gain == 20.0
        assert not np.allclose(wb.plots.curve_data(0, "phi")[1], before["phi"])
        assert not np.allclose(wb.plots.curve_data(0, "ti")[1], before["ti"])
    design = wb.model.slot(0).design
    assert wb.value("dc", 0) == dc_input_sensitivity(design).text() == "[[1, 0], [9.7, 0]]"
    loop = wb.fast[0].analysis.functions.loop
    assert np.max(np.abs(loop / ref_loop - 1)) < 1e-9            # output-equivalent on the grid
    np.testing.assert_allclose(wb.plots.curve_data(0, "ti_bound")[1], before["ti_bound"], rtol=1e-9)
    np.testing.assert_allclose(wb.plots.curve_data(0, "pq_mag")[1], before["pq_mag"] + db(20 / 13.928),
                               rtol=1e-9)
    assert wb.value("dist", 0) != dist_before and "(stale)" not in wb.value("dist", 0)
    assert not np.allclose(wb.plots.curve_data(0, "u2_d")[1], before["u2_d"])
    # the same loop gain: the LOS responds alike (to the discretisation's few per cent)
    y = wb.plots.curve_data(0, "y_d")[1]
    assert np.max(np.abs(y - before["y_d"])) < 0.05 * np.max(np.abs(before["y_d"]))
    assert wb.value("state", 0) == "edited, not saved"

    # c0 no longer kept: the next edit of Q changes the loop gain
    wb.editor.keep.setChecked(False)
    assert wb.model.slot(0).reference is None
    wb.editor.set_value("Q", "gain", None, "30")
    loop = wb.fast[0].analysis.functions.loop
    assert np.max(np.abs(loop / ref_loop - 1)) > 0.1
    # a refused edit changes nothing and says why
    gen = wb.model.slot(0).generation
    wb.editor.set_value("Q", "numerator", 0, "abc")
    assert "not changed" in wb.message.text() and wb.model.slot(0).generation == gen
    assert wb.editor.table.item(wb.editor.row_of("Q", "numerator", 0), 2).text() == "60.27"
    wb.editor.set_value("Q", "denominator", 0, "0")       # two poles at 0: s^2 ...
    wb.editor.set_value("Q", "denominator", 1, "0")
    fresh(qtbot, wb)                                      # ... still a design: views for it


def test_save_reload_and_send_to_the_parameters_dock(qtbot, gui_window, tmp_path):
    window = gui_window(5.0)
    panel = window.parameters
    assert panel.load_design(CONTROLLERS / "relative_design1.toml")
    wb = panel.open_workbench()
    try:
        assert wb.isVisible() and wb.model.slot(0).original.path == (CONTROLLERS / "relative_design1.toml")
        wb.editor.set_value("Q", "gain", None, "16")
        fresh(qtbot, wb)
        edited = wb.model.slot(0).design
        wb.editor.name_edit.setText("Relative Design #1, Q gain 16")
        wb.editor.name_edit.editingFinished.emit()
        out = tmp_path / "edited.toml"
        back = wb.save(out)
        assert back is not None and wb.value("state", 0) == "saved as edited.toml"
        text = out.read_text()
        assert "equivalent_to =" in text and "gain = 16.0" in text
        reread = load_design(out)
        assert reread.name == "Relative Design #1, Q gain 16"
        assert transfer_function_mismatch(edited, reread) < 1e-12
        assert validate(reread).ok                        # the saved design validates
        # Send to Parameters: the dock loads the saved file and validates it
        assert wb.send_to_parameters()
        assert panel.design.path == out.resolve() and panel.source == str(out.resolve())
        assert panel.report is not None and panel.report.ok, panel.result.text()
        # without c0 kept equivalent, c0 is written as its factors
        wb.editor.keep.setChecked(False)
        wb.editor.set_value("c0", "gain", None, "31000")
        back = wb.save(tmp_path / "factors.toml")
        assert "equivalent_to" not in (tmp_path / "factors.toml").read_text()
        assert transfer_function_mismatch(wb.model.slot(0).design, back) < 1e-12
        assert back.c0.gain == 31000.0
    finally:
        wb.shutdown()


def test_inertial_designs_on_a_thread(qtbot, make_workbench):
    """The fallback without a worker process gives the validation's verdict too (the
    inertial designs are refused on the reference's own model: docs/controllers.md)."""
    wb = make_workbench(processes=False)
    assert not wb.jobs.uses_process
    assert wb.open_design(0, CONTROLLERS / "inertial_design1.toml")
    assert wb.open_design(1, CONTROLLERS / "inertial_design2.toml")
    fresh(qtbot, wb)
    assert wb.value("dc", 0) == "[[1, 0], [27.5, 0]]" and wb.value("dc", 1) == "[[1, 0], [0, 0]]"
    assert wb.value("verdict", 0).startswith("REFUSED") and wb.value("inner", 0).startswith("GM")
    assert wb.value("phi_14", 0) == "29.0°"
    wb.select(1)
    wb.editor.set_value("Q", "gain", None, "700")
    fresh(qtbot, wb)
    assert wb.model.slot(1).factors["Q"].gain == 700.0


def test_the_model_refuses_what_load_design_would(dictionary):
    m = WorkbenchModel(dictionary)
    s = m.open(0, CONTROLLERS / "relative_design2.toml")
    assert s.reference is None and [k for k in s.keys] == ["c0", "Q"]
    with pytest.raises(DesignError, match="proper"):
        m.add_factor(0, "Q", "numerator")
        m.add_factor(0, "Q", "numerator")
    assert len(m.slot(0).factors["Q"].numerator) == 4          # the first was fine
    m.remove_factor(0, "Q", "numerator", 3)
    assert transfer_function_mismatch(m.slot(0).design, s.original) < 1e-12
    with pytest.raises(DesignError, match="switch the loop off"):
        m.edit(0, "c0", "gain", None, "0")
    with pytest.raises(DesignError, match="1-DOF|two inputs"):
        m.open(1, CONTROLLERS / "rigid_pid.toml")
    m.open(1, CONTROLLERS / "relative_design1.toml")
    labels = [label for label, _ in m.references(0)]
    assert labels == ["Relative Design #2 as loaded", "#2 Relative Design #1 as loaded"]
    m.set_reference(0, m.references(0)[1][1])
    assert m.slot(0).design.c0_equivalent_to == (CONTROLLERS / "relative_design1.toml").resolve()
    with pytest.raises(DesignError, match="output-equivalent"):
        m.edit(0, "c0", "gain", None, "2")
    assert m.reset(0).design is m.slot(0).original


def test_a_worker_process_that_dies_is_replaced_by_a_thread(qtbot, make_workbench):
    import os
    import signal

    wb = make_workbench()
    assert wb.open_design(0, CONTROLLERS / "relative_design2.toml")
    fresh(qtbot, wb)
    assert wb.jobs.uses_process
    pids = list(wb.jobs._pool._processes)            # the one process this test started
    assert len(pids) == 1
    os.kill(pids[0], signal.SIGKILL)
    wb.editor.set_value("Q", "gain", None, "3000")
    fresh(qtbot, wb)                                 # answered all the same, on a thread
    assert not wb.jobs.uses_process
    assert wb.value("verdict", 0).startswith(("OK", "MARGINAL", "REFUSED"))
    assert "3000" in wb.editor.table.item(wb.editor.row_of("Q", "gain"), 2).text()
