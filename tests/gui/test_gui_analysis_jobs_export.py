"""The Analysis dock, continued (offscreen, the real window): cancelling a job (no stale
result after it, the next run works), exporting the tables (CSV, JSON: the values the
table holds) and the plots (PNG), FRF and hysteresis of several logs overlaid, and the
Step tab.  Logs of the fast simulator: two open-loop random-current records and a
closed-loop relative step."""

from __future__ import annotations

import csv
import json
import math
import threading
from pathlib import Path

import numpy as np
import pytest
from PySide6.QtCore import Qt
from PySide6.QtGui import QImage
from PySide6.QtWidgets import QApplication

from groundstation import Testbed
from groundstation.analysis import analyze_log
from groundstation.analysis.log_step import step_from_log
from groundstation.gui.analysis import jobs as analysis_jobs
from groundstation.gui.analysis.export import ExportError, rows_csv, rows_json, write_rows
from groundstation.gui.analysis.tables import METRIC_COLUMNS, STEP_COLUMNS, step_row

ROOT = Path(__file__).resolve().parents[2]
TESTBED = ROOT / "profiles/testbeds/relative_2dof.toml"
DESIGN = ROOT / "profiles/controllers/relative_design2.toml"
NOISE_PROFILE = ROOT / "profiles/waveforms/sysid_coarse_noise_1A.toml"
STEP_RAD = 1e-4
WAIT_MS = 30000
PNG_MAGIC = b"\x89PNG\r\n\x1a\n"


@pytest.fixture(scope="module")
def logs(tmp_path_factory):
    """'sysid' (0.5 s at rest, 3 s of random coarse current), 'sysid2' (the same for
    2 s), 'rest' (2 s of zero current), all open loop; 'step' (a 100 µrad relative step
    at 0.5 s, closed loop, 2 s after it)."""
    folder = tmp_path_factory.mktemp("analysis_more")
    out = {}
    with Testbed("sim", testbed=TESTBED, fast=True, generator=None, log_folder=folder,
                 history=folder / "h") as tb:
        tb.set_mode("OPEN_LOOP")
        for name, seconds in (("sysid", 3.0), ("sysid2", 2.0)):
            out[name] = Path(tb.start_recording(name))
            tb.dwell(0.5)
            tb.play(NOISE_PROFILE, max_seconds=seconds)
            tb.stop_recording()
        out["rest"] = Path(tb.start_recording("rest"))
        tb.dwell(2.0)
        tb.stop_recording()
    with Testbed("sim", testbed=TESTBED, fast=True, generator=None, log_folder=folder,
                 history=folder / "h2") as tb:
        tb.upload_design(DESIGN)
        tb.set_mode("RELATIVE")
        tb.arm()
        out["step"] = Path(tb.start_recording("step"))
        tb.dwell(0.5)
        tb.set_reference(STEP_RAD)
        tb.dwell(2.0)
        tb.stop_recording()
    return out


@pytest.fixture
def panel(gui_window):
    return gui_window(30.0).analysis


def press(qtbot, button) -> None:
    qtbot.mouseClick(button, Qt.MouseButton.LeftButton)


def idle(panel) -> bool:
    return panel.jobs.idle() and all(b.isEnabled() for b in (
        panel.metrics_button, panel.frf_button, panel.hysteresis_button, panel.step_button))


def tick_only(panel, *paths) -> None:
    for p in paths:
        panel.add_log(p)
    for p in panel.runs.paths():
        panel.runs.set_checked(p, p in {Path(q).resolve() for q in paths})


# ---------------------------------------------------------------------- analyze_log's hook
def test_analyze_log_reports_each_chunk_and_a_raise_in_the_hook_stops_it(logs):
    calls = []
    res = analyze_log(logs["sysid"], sensor="encoder_inner", chunk_rows=1000,
                      on_progress=lambda done, total: calls.append((done, total)))
    assert res.row() == analyze_log(logs["sysid"], sensor="encoder_inner", chunk_rows=1000).row()
    assert len(calls) == math.ceil(res.frames / 1000)
    assert [d for d, _ in calls] == sorted(d for d, _ in calls)
    assert calls[-1] == (res.frames, res.frames)

    class Stop(Exception):
        pass

    def stop(done, total):
        raise Stop

    with pytest.raises(Stop):
        analyze_log(logs["sysid"], sensor="encoder_inner", chunk_rows=1000, on_progress=stop)


# ---------------------------------------------------------------------- cancel
def test_cancel_a_metrics_batch_no_stale_result_and_the_next_run_works(qtbot, panel, logs,
                                                                        monkeypatch):
    """The second of three logs holds in its first chunk until the test has cancelled;
    then its next chunk stops it, the third log is never read, nothing reaches the
    dock, and a Metrics run after it gives the three rows."""
    real = analysis_jobs.analyze_log
    reached, gate = threading.Event(), threading.Event()
    calls: list[tuple[str, str]] = []            # (log, how its analysis ended)

    def held(path, *, on_progress, **options):
        first = [True]

        def progress(done, total):
            on_progress(done, total)             # the job's own: progress, or its cancel
            if Path(path).resolve() == logs["sysid2"].resolve() and first[0] and not gate.is_set():
                first[0] = False
                reached.set()
                gate.wait(WAIT_MS / 1000)
        try:
            res = real(path, on_progress=progress, chunk_rows=500, **options)
        except Exception as exc:
            calls.append((Path(path).name, type(exc).__name__))
            raise
        calls.append((Path(path).name, "done"))
        return res

    monkeypatch.setattr(analysis_jobs, "analyze_log", held)
    order = (logs["sysid"], logs["sysid2"], logs["rest"])
    tick_only(panel, *order)
    panel.sensor.setCurrentText("encoder_inner")
    delivered = []
    panel.jobs.sig_metrics_done.connect(delivered.append)
    assert not panel.cancel_button.isEnabled()
    press(qtbot, panel.metrics_button)
    assert panel.cancel_button.isEnabled() and not panel.metrics_button.isEnabled()
    qtbot.waitUntil(reached.is_set, timeout=WAIT_MS)
    # the progress of the held chunk was sent before it held: logs done, the log and how far
    held_at = f"Metrics: 1/3 logs done - {order[1].name} "
    qtbot.waitUntil(lambda: panel.status.text().startswith(held_at)
                    and panel.status.text().endswith(" %…"), timeout=WAIT_MS)
    with qtbot.waitSignal(panel.jobs.sig_cancelled, timeout=WAIT_MS):
        press(qtbot, panel.cancel_button)
    assert "Metrics cancelled" in panel.status.text()
    assert panel.metrics_button.isEnabled() and not panel.cancel_button.isEnabled()
    assert panel.jobs.idle()
    gate.set()
    assert panel.jobs.join(timeout=WAIT_MS / 1000)        # the cancelled thread has ended
    QApplication.processEvents()                          # anything it posted, delivered
    assert delivered == []
    assert calls == [(order[0].name, "done"), (order[1].name, "Cancelled")]
    assert panel.metrics_table.rowCount() == 0
    assert "Metrics cancelled" in panel.status.text()
    # the next run: all three logs
    with qtbot.waitSignal(panel.jobs.sig_metrics_done, timeout=WAIT_MS):
        press(qtbot, panel.metrics_button)
    qtbot.waitUntil(lambda: idle(panel), timeout=WAIT_MS)
    assert len(delivered) == 1
    rows = panel.metrics_table.rows()
    assert [r["log"] for r in rows] == [p.name for p in order]
    for r, p in zip(rows, order):
        assert r["rms_urad"] == pytest.approx(                  # read in 500-row chunks here
            analyze_log(p, sensor="encoder_inner").row()["rms_urad"], rel=1e-12)
    assert "Metrics of 3 log(s)" in panel.status.text()


def test_cancel_an_frf_in_flight_and_start_another_at_once(qtbot, panel, logs, monkeypatch):
    """An FRF cannot stop inside a log: cancelled while one computes, a new FRF starts
    at once, and only the new one's curves are drawn - the old one's never are."""
    from groundstation.analysis import log_frf
    real = log_frf.frf_from_log
    reached, gate = threading.Event(), threading.Event()

    def held(path, **options):
        if Path(path).resolve() == logs["sysid"].resolve():
            reached.set()
            gate.wait(WAIT_MS / 1000)
        return real(path, **options)

    monkeypatch.setattr(log_frf, "frf_from_log", held)
    tick_only(panel, logs["sysid"])
    delivered = []
    panel.jobs.sig_frf_done.connect(delivered.append)
    press(qtbot, panel.frf_button)
    qtbot.waitUntil(reached.is_set, timeout=WAIT_MS)
    assert panel.cancel()
    assert panel.frf_button.isEnabled()
    tick_only(panel, logs["sysid2"])
    with qtbot.waitSignal(panel.jobs.sig_frf_done, timeout=WAIT_MS):
        assert panel.run_frf()                            # while the old thread still holds
    assert list(panel.frf_plots.curves) == [logs["sysid2"].name]
    gate.set()
    assert panel.jobs.join(timeout=WAIT_MS / 1000)
    QApplication.processEvents()
    assert len(delivered) == 1 and delivered[0].requested == (logs["sysid2"].resolve(),)
    assert list(panel.frf_plots.curves) == [logs["sysid2"].name]
    assert not panel.cancel()                             # nothing under way


# ---------------------------------------------------------------------- export
def test_export_the_metrics_table_to_csv_and_json(qtbot, panel, logs, tmp_path):
    tick_only(panel, logs["sysid"], logs["rest"])
    panel.sensor.setCurrentText("encoder_inner")
    assert not panel.export_table("metrics", tmp_path / "early.csv")   # nothing yet
    assert "empty" in panel.status.text()
    press(qtbot, panel.metrics_button)
    qtbot.waitUntil(lambda: idle(panel) and panel.metrics_table.rowCount() == 2, timeout=WAIT_MS)
    table = panel.metrics_table.rows()
    keys = [k for _, k, _ in METRIC_COLUMNS]

    assert panel.export_table("metrics", tmp_path / "m.json")
    assert json.loads((tmp_path / "m.json").read_text()) == table
    assert str(tmp_path / "m.json") in panel.status.text()

    assert panel.export_table("metrics", tmp_path / "m.csv")
    with open(tmp_path / "m.csv", newline="") as f:
        reader = csv.DictReader(f)
        assert reader.fieldnames == keys
        read = list(reader)
    assert len(read) == len(table)
    for got, want in zip(read, table):
        for k in keys:
            v = want[k]
            if v is None or v == "":
                assert got[k] == ""
            elif isinstance(v, float):
                assert float(got[k]) == v                 # full precision, not the shown text
            else:
                assert got[k] == str(v)
    assert read[0]["log"] == logs["sysid"].name and float(read[0]["rms_urad"]) > 0


def test_export_to_a_bad_path_is_said_and_the_dock_goes_on(qtbot, panel, logs, tmp_path):
    tick_only(panel, logs["sysid"])
    panel.sensor.setCurrentText("encoder_inner")
    press(qtbot, panel.metrics_button)
    qtbot.waitUntil(lambda: idle(panel) and panel.metrics_table.rowCount() == 1, timeout=WAIT_MS)
    missing = tmp_path / "no such folder" / "m.csv"
    assert not panel.export_table("metrics", missing)
    assert panel.status.text() == (f"Export failed: cannot write {missing}: "
                                   f"No such file or directory")
    assert not panel.export_table("metrics", tmp_path)                 # a folder, not a file
    assert "Export failed:" in panel.status.text() and "m.csv" not in panel.status.text()
    assert not panel.export_table("metrics", tmp_path / "m.txt")
    assert "written as .csv or .json, not .txt" in panel.status.text()
    panel.tabs.setCurrentIndex(0)                                      # the table: no plots
    assert not panel.export_plots(tmp_path / "x.png")
    assert "has no plots" in panel.status.text()
    # still working: a good export, and another analysis
    assert panel.export_table("metrics", tmp_path / "m.csv")
    press(qtbot, panel.frf_button)
    qtbot.waitUntil(lambda: idle(panel) and bool(panel.frf_plots.curves), timeout=WAIT_MS)


def test_the_writers_alone(tmp_path):
    rows = [{"log": "a.h5", "x": 1.5, "n": None}, {"log": "b,c.h5", "x": float("nan"), "n": 3}]
    assert rows_csv(["log", "x", "n"], rows) == 'log,x,n\na.h5,1.5,\n"b,c.h5",nan,3\n'
    assert json.loads(rows_json(["log", "n"], rows)) == [{"log": "a.h5", "n": None},
                                                         {"log": "b,c.h5", "n": 3}]
    assert json.loads(rows_json(["x"], rows)) == [{"x": 1.5}, {"x": None}]     # no NaN in JSON
    with pytest.raises(ExportError, match="not a file without a suffix"):
        write_rows(tmp_path / "table", ["log"], rows)
    assert write_rows(tmp_path / "t", ["log"], rows, "csv").read_text() == 'log\na.h5\n"b,c.h5"\n'


def test_png_export_of_the_frf_plots(qtbot, panel, logs, tmp_path):
    tick_only(panel, logs["sysid"])
    press(qtbot, panel.frf_button)
    qtbot.waitUntil(lambda: idle(panel) and bool(panel.frf_plots.curves), timeout=WAIT_MS)
    assert panel.tabs.currentWidget() is panel.frf_plots
    out = tmp_path / "frf.png"
    assert panel.export_plots(out)
    data = out.read_bytes()
    assert data.startswith(PNG_MAGIC)
    image = QImage(str(out))
    assert not image.isNull()
    assert image.width() == 3 * 900 and image.height() > 100           # three plots side by side
    # not one colour: something is drawn
    assert len({image.pixel(x, image.height() // 2) for x in range(0, image.width(), 7)}) > 2
    missing = tmp_path / "gone" / "frf.png"
    assert not panel.export_plots(missing)
    assert f"cannot write {missing}" in panel.status.text()


# ---------------------------------------------------------------------- overlays
def test_frf_of_two_logs_two_curves_and_the_model_once(qtbot, panel, logs):
    tick_only(panel, logs["sysid"], logs["sysid2"])
    panel.segments.setCurrentText("512")
    press(qtbot, panel.frf_button)
    qtbot.waitUntil(lambda: idle(panel) and len(panel.frf_plots.curves) == 2, timeout=WAIT_MS)
    plots = panel.frf_plots
    names = [logs["sysid"].name, logs["sysid2"].name]
    assert list(plots.curves) == names
    assert len(plots.magnitude.getPlotItem().listDataItems()) == 3      # two logs and the model
    assert len(plots.phase.getPlotItem().listDataItems()) == 3
    assert len(plots.coherence.getPlotItem().listDataItems()) == 2
    legend = [label.text for _, label in plots.magnitude.getPlotItem().legend.items]
    assert legend == ["model T1->phi1", *names]
    pens = {plots.curves[n]["magnitude"].opts["pen"].color().name() for n in names}
    assert len(pens) == 2
    for n in names:
        x, y = plots.curves[n]["magnitude"].getData()
        assert len(x) > 50 and np.all(np.isfinite(y))
    assert "FRF of 2 log(s)" in panel.status.text()
    for n in names:
        assert n in plots.caption.text()


def test_hysteresis_loops_of_two_logs(qtbot, panel, logs):
    tick_only(panel, logs["sysid"], logs["sysid2"])
    press(qtbot, panel.hysteresis_button)
    qtbot.waitUntil(lambda: idle(panel) and len(panel.hysteresis_plot.curves) == 2,
                    timeout=WAIT_MS)
    curves = panel.hysteresis_plot.curves
    assert list(curves) == [logs["sysid"].name, logs["sysid2"].name]
    for c in curves.values():
        assert {"angle rising", "angle falling"} <= set(c)
    assert "Hysteresis of 2 log(s)" in panel.status.text()


def test_the_step_tab_shows_the_figures_of_a_step_log(qtbot, panel, logs, tmp_path):
    tick_only(panel, logs["step"], logs["rest"])
    press(qtbot, panel.step_button)
    qtbot.waitUntil(lambda: idle(panel) and panel.step_plots.table.count() == 2,
                    timeout=WAIT_MS)
    assert panel.tabs.currentWidget() is panel.step_plots
    rows = panel.step_plots.table.rows()
    expected = step_row(step_from_log(logs["step"]))
    assert rows[0] == expected
    assert rows[0]["step_urad"] == pytest.approx(STEP_RAD * 1e6, rel=1e-3)
    assert rows[0]["rise_ms"] > 0 and rows[0]["overshoot_pct"] >= 0
    assert rows[0]["settling_ms"] is not None and rows[0]["effort"] == "current_coarse (A)"
    assert rows[1]["log"] == logs["rest"].name and "makes no step" in rows[1]["notes"]
    assert "Step of 1 of 2 log(s)" in panel.status.text()
    # the curves: the reference steps at t = 0 by the step size; the response follows it
    curves = panel.step_plots.curves[logs["step"].name]
    t, ref = curves["reference"].getData()
    _, resp = curves["response"].getData()
    assert t[0] < 0 < t[-1]
    after, before = ref[t >= 0.0][0], ref[t < 0.0][-1]
    assert after - before == pytest.approx(STEP_RAD * 1e6, rel=1e-3)
    assert resp[-1] == pytest.approx(ref[-1], abs=0.1 * STEP_RAD * 1e6)
    # the figures shown are the table's; the step table exports like the metrics one
    table = panel.step_plots.table
    assert table.horizontalHeaderItem(0).text() == logs["step"].name
    for _, key, fmt in STEP_COLUMNS[1:]:
        if isinstance(expected[key], float):
            assert table.item_of(key, 0).text() == format(expected[key], fmt), key
    assert panel.export_table("step", tmp_path / "step.json")
    assert json.loads((tmp_path / "step.json").read_text()) == rows


def test_the_measured_phase_is_drawn_about_the_model_so_no_noisy_bin_costs_a_turn():
    """A model whose phase falls through -540 deg, a measurement equal to it within a few
    degrees except one wild bin (an antiresonance): drawn about the model, every other
    bin stays within those degrees of the model's unwrapped phase - unwrapping the
    measurement alone would carry the wild bin's turn into everything after it."""
    from groundstation.gui.analysis.plots import _phase_about_model
    f = np.linspace(0.0, 200.0, 401)
    model = np.exp(-1j * 2 * np.pi * f * 0.008) / (1 + 1j * f / 30.0)      # delay + lag
    rng = np.random.default_rng(4)
    wobble = np.radians(rng.uniform(-5, 5, len(f)))
    measured = model * np.exp(1j * wobble)
    measured[200] = -measured[200] * 0.01                                # the wild bin
    naive = np.degrees(np.unwrap(np.angle(measured)))
    drawn = _phase_about_model(f, measured, model, naive)
    model_phase = np.degrees(np.unwrap(np.angle(model[1:])))
    others = np.r_[1:200, 201:401]
    assert np.max(np.abs(drawn[others] - model_phase[others - 1])) < 5.01
    assert model_phase[-1] < -540
