"""The Analysis dock in the real window (offscreen): logs the fast simulator recorded,
opened as the Session's replay, as chosen files and from a folder; Metrics gives the
numbers analyze_log gives, a spectrum per ticked log; FRF draws measured, model and
coherence; Hysteresis draws a loop; a broken file or a bad window is said in the panel
and the window goes on working."""

from __future__ import annotations

import shutil
from pathlib import Path

import numpy as np
import pytest
from PySide6.QtCore import Qt

from groundstation import Testbed
from groundstation.analysis import analyze_log
from groundstation.analysis.log_frf import frf_from_log
from groundstation.core.errors import GroundStationError
from groundstation.gui.analysis.tables import METRIC_COLUMNS, VALUE_ROLE
from groundstation.logs import LogReader

ROOT = Path(__file__).resolve().parents[2]
TESTBED = ROOT / "profiles/testbeds/relative_2dof.toml"
NOISE_PROFILE = ROOT / "profiles/waveforms/sysid_coarse_noise_1A.toml"
WAIT_MS = 30000


@pytest.fixture(scope="module")
def logs(tmp_path_factory):
    """Two logs of the fast simulator, open loop: 'sysid' plays 4 s of random coarse
    current after 0.5 s at rest, 'rest' holds zero current for 2 s."""
    folder = tmp_path_factory.mktemp("analysis_logs")
    with Testbed("sim", testbed=TESTBED, fast=True, generator=None, log_folder=folder,
                 history=folder / "h") as tb:
        tb.set_mode("OPEN_LOOP")
        sysid = tb.start_recording("sysid")
        tb.dwell(0.5)
        tb.play(NOISE_PROFILE, max_seconds=4.0)
        tb.stop_recording()
        rest = tb.start_recording("rest")
        tb.dwell(2.0)
        tb.stop_recording()
    return {"sysid": sysid, "rest": rest, "folder": folder}


@pytest.fixture
def window(gui_window):
    return gui_window(30.0)


def press(qtbot, button) -> None:
    qtbot.mouseClick(button, Qt.MouseButton.LeftButton)


def idle(panel) -> bool:
    return panel.jobs.idle() and all(b.isEnabled() for b in (
        panel.metrics_button, panel.frf_button, panel.hysteresis_button, panel.step_button))


def table_rows(panel) -> list[dict]:
    t = panel.metrics_table
    return [{key: t.item(r, c).data(VALUE_ROLE) for c, (_, key, _) in enumerate(METRIC_COLUMNS)}
            for r in range(t.rowCount())]


def test_the_dock_is_in_the_window_with_its_menu(window):
    assert window.docks["Analysis"].widget() is window.analysis
    actions = {a.text(): a for top in window.menuBar().actions() if top.menu() is not None
               for a in top.menu().actions()}
    assert actions["&Analyse logs"].shortcut().toString() == "Ctrl+Shift+A"
    actions["&Analyse logs"].trigger()
    assert window.docks["Analysis"].isVisible()


def test_metrics_of_the_replayed_log_equal_analyze_log(qtbot, window, logs):
    panel = window.analysis
    window.session.open_log(str(logs["sysid"]))
    # the replayed log is listed, ticked and highlighted
    assert panel.runs.paths() == [Path(logs["sysid"]).resolve()]
    assert panel.runs.item(0, 1).text() == "replay"
    panel.sensor.setCurrentText("encoder_inner")
    panel.period.setValue(0.5)
    press(qtbot, panel.metrics_button)
    assert not panel.metrics_button.isEnabled()          # one at a time
    qtbot.waitUntil(lambda: idle(panel) and panel.metrics_table.rowCount() == 1, timeout=WAIT_MS)
    expected = analyze_log(logs["sysid"], sensor="encoder_inner", integration_period_s=0.5).row()
    row = table_rows(panel)[0]
    for _, key, _ in METRIC_COLUMNS:
        assert row[key] == expected[key] or (row[key] in (None, "") and expected[key] in (None, "")), key
    assert row["rms_urad"] > 0 and row["energy_total_j"] > 0
    assert list(panel.spectra.psd_curves) == [Path(logs["sysid"]).name]
    assert len(panel.spectra.csp_curves) == 1
    x, y = panel.spectra.psd_curves[Path(logs["sysid"]).name].getData()
    assert len(x) > 10 and np.all(np.isfinite(y))
    assert "Metrics of 1 log(s)" in panel.status.text()


def test_two_logs_give_two_rows_and_two_curves(qtbot, window, logs):
    panel = window.analysis
    panel.add_log(logs["sysid"])
    panel.add_log(logs["rest"])
    panel.sensor.setCurrentText("encoder_inner")           # the relative rig has no autocollimator
    panel.window_from.setText("0.2")                       # a window applies to each log
    press(qtbot, panel.metrics_button)
    qtbot.waitUntil(lambda: idle(panel) and panel.metrics_table.rowCount() == 2, timeout=WAIT_MS)
    rows = table_rows(panel)
    assert [r["log"] for r in rows] == [Path(logs["sysid"]).name, Path(logs["rest"]).name]
    for r, path in zip(rows, (logs["sysid"], logs["rest"])):
        assert r["rms_urad"] == analyze_log(path, start_s=0.2, sensor="encoder_inner").row()["rms_urad"]
        assert r["from_s"] == pytest.approx(0.2, abs=1e-9)
    assert set(panel.spectra.psd_curves) == {Path(logs["sysid"]).name, Path(logs["rest"]).name}
    # untick one: one row, one curve
    panel.runs.set_checked(logs["rest"], False)
    press(qtbot, panel.metrics_button)
    qtbot.waitUntil(lambda: idle(panel) and panel.metrics_table.rowCount() == 1, timeout=WAIT_MS)
    assert list(panel.spectra.psd_curves) == [Path(logs["sysid"]).name]


def test_frf_draws_measured_model_and_coherence(qtbot, window, logs):
    panel = window.analysis
    panel.add_log(logs["rest"])
    panel.add_log(logs["sysid"])
    panel.segments.setCurrentText("512")
    press(qtbot, panel.frf_button)                         # both ticked: rest has no excitation
    qtbot.waitUntil(lambda: idle(panel) and bool(panel.frf_plots.curves), timeout=WAIT_MS)
    name = Path(logs["sysid"]).name
    assert list(panel.frf_plots.curves) == [name]
    assert "FRF of 1 of 2 log(s)" in panel.status.text()
    assert f"{Path(logs['rest']).name}: current_coarse is constant" in panel.status.text()
    curves, model = panel.frf_plots.curves[name], panel.frf_plots.model
    assert set(curves) == {"magnitude", "phase", "coherence"} and set(model) == {"magnitude", "phase"}
    for item in [*curves.values(), *model.values()]:
        x, y = item.getData()
        assert len(x) > 50 and np.all(np.isfinite(y))
    expected = frf_from_log(logs["sysid"], nperseg=512)
    f, coh = expected.measured.freq_hz, expected.measured.coherence
    ok = (f > 0) & np.isfinite(coh)
    _, drawn = curves["coherence"].getData()
    np.testing.assert_array_equal(drawn, coh[ok])
    assert np.median(coh[(f >= 10) & (f <= 300)]) > 0.95   # the excited band
    assert model["magnitude"].name() == "model T1->phi1"
    assert curves["magnitude"].name() == name
    assert "x K_t 32.1 in-oz/A" in panel.frf_plots.caption.text()
    assert panel.tabs.currentWidget() is panel.frf_plots


def test_hysteresis_draws_a_loop_and_says_why_not(qtbot, window, logs):
    panel = window.analysis
    panel.add_log(logs["sysid"])
    press(qtbot, panel.hysteresis_button)
    qtbot.waitUntil(lambda: idle(panel) and panel.hysteresis_plot.branches_drawn > 0,
                    timeout=WAIT_MS)
    assert "branches" in panel.status.text()
    curves = panel.hysteresis_plot.curves[Path(logs["sysid"]).name]
    assert {"lead-in", "angle rising", "angle falling"} <= set(curves)
    x, y = curves["angle rising"].getData()
    assert len(x) > 100 and np.isfinite(y).any()
    # the rest before the profile: no current, no loop - said in the panel
    panel.window_to.setText("0.3")
    press(qtbot, panel.hysteresis_button)
    qtbot.waitUntil(lambda: idle(panel) and "failed" in panel.status.text(), timeout=WAIT_MS)
    assert "Hysteresis failed:" in panel.status.text()
    assert "no torque, no loop" in panel.status.text()
    assert "Traceback" not in panel.status.text()


def test_a_broken_file_is_said_in_the_panel_and_the_window_goes_on(qtbot, window, logs, tmp_path):
    panel = window.analysis
    broken = tmp_path / "broken.h5"
    broken.write_bytes(b"this is no HDF5 file" * 100)
    with pytest.raises(GroundStationError) as info:
        analyze_log(broken)
    panel.add_log(broken)
    press(qtbot, panel.metrics_button)
    qtbot.waitUntil(lambda: idle(panel) and panel.metrics_table.rowCount() == 1, timeout=WAIT_MS)
    assert str(info.value) in panel.status.text()
    assert table_rows(panel)[0]["notes"] == str(info.value)
    press(qtbot, panel.frf_button)
    qtbot.waitUntil(lambda: idle(panel) and "FRF failed" in panel.status.text(), timeout=WAIT_MS)
    assert str(info.value) in panel.status.text()
    # a bad window is refused before anything runs
    panel.window_from.setText("soon")
    assert not panel.run_metrics()
    assert "not a number" in panel.status.text()
    panel.window_from.setText("")
    # and the panel still works: the broken log and a good one side by side
    panel.add_log(logs["sysid"])
    panel.sensor.setCurrentText("encoder_inner")
    press(qtbot, panel.metrics_button)
    qtbot.waitUntil(lambda: idle(panel) and panel.metrics_table.rowCount() == 2, timeout=WAIT_MS)
    assert len(panel.spectra.psd_curves) == 1
    assert "Metrics of 1 of 2 log(s)" in panel.status.text()


def test_a_folder_of_logs_is_listed(qtbot, window, logs, tmp_path):
    panel = window.analysis
    campaign = tmp_path / "campaign"
    (campaign / "run2").mkdir(parents=True)
    shutil.copy(logs["sysid"], campaign / "a.h5")
    shutil.copy(logs["rest"], campaign / "run2" / "b.h5")
    assert panel.add_folder(campaign)
    qtbot.waitUntil(lambda: panel.runs.rowCount() == 2, timeout=WAIT_MS)
    assert panel.runs.checked_paths() == [(campaign / "a.h5").resolve(),
                                          (campaign / "run2" / "b.h5").resolve()]
    assert panel.runs.item(0, 1).text() == "campaign"
    with LogReader(campaign / "a.h5") as r:
        assert r.n_frames("HIGH_RATE") > 0
