"""Channel tree, strip charts and spectrum view, offscreen, fed through the real codec."""

from __future__ import annotations

import json
import sys
import time

import numpy as np
import pytest
from PySide6.QtCore import QMimeData, QPointF, Qt
from PySide6.QtGui import QDropEvent

from groundstation.codec import StreamDeframer
from groundstation.gui.charts.channel_tree import ChannelTree, display_unit, format_value
from groundstation.gui.charts.panel import StripChartPanel
from groundstation.gui.charts.spectrum import SpectrumView
from groundstation.sim import SimulatedDevice
from groundstation.live.display_buffers import TelemetryStore

from conftest import HighRateFeeder

RATE = 1200.0


def simulated(dictionary, store, seconds):
    dev = SimulatedDevice(dictionary, pacing="manual", seed=3)
    deframer = StreamDeframer(dev.codec)
    dev.run_fast(seconds, lambda data: [store(b) for b in deframer.feed(data, time.time())])


@pytest.fixture
def store(dictionary):
    return TelemetryStore(dictionary, seconds=60.0)


@pytest.fixture
def panel(qtbot, store, dictionary):
    p = StripChartPanel(store, dictionary)
    qtbot.addWidget(p)
    p.resize(1000, 700)
    p.show()
    qtbot.waitExposed(p)
    return p


def curve_data(panel, plot, cid):
    x, y = panel.stack.plots[plot].curves[cid].getData()
    if x is None:
        return np.empty(0), np.empty(0)
    return np.asarray(x), np.asarray(y)


# ---------------------------------------------------------------- channel tree
def test_tree_lists_channels_filters_and_drags(qtbot, dictionary):
    tree = ChannelTree(dictionary)
    qtbot.addWidget(tree)
    tree.show()
    ids = tree.channel_ids()
    assert "HIGH_RATE.encoder_outer" in ids and "HOUSEKEEPING.temp_flexure" in ids
    assert "HIGH_RATE.armed" in ids                                 # a status bit
    assert tree.item_for("HIGH_RATE.armed").parent() is tree.item_for("HIGH_RATE.status")
    assert not any(i.startswith(("EVENT.", "RESPONSE.", "COMMAND.")) for i in ids)
    assert tree.units_of("HIGH_RATE.encoder_outer") == "rad"
    assert "absolute optical encoder" in tree.item_for("HIGH_RATE.encoder_outer").toolTip(0)

    tree.set_filter("gyro")                    # by name, and by description ("integrated gyro")
    assert set(tree.visible_ids()) >= {"HIGH_RATE.gyro_rate", "HIGH_RATE.los_estimate"}
    assert "HIGH_RATE.encoder_outer" not in tree.visible_ids()
    tree.set_filter("flexure temp")            # every word must match
    assert tree.visible_ids() == ["HOUSEKEEPING.temp_flexure"]
    tree.set_filter("")
    assert len(tree.visible_ids()) == len(ids)

    tree.select(["HIGH_RATE.encoder_outer", "HIGH_RATE.gyro_rate"])
    mime = tree.tree.mimeData(tree.tree.selectedItems())
    assert mime.text().splitlines() == ["HIGH_RATE.encoder_outer", "HIGH_RATE.gyro_rate"]

    row = tree.item_for("HIGH_RATE.gyro_rate")
    tree.tree.scrollToItem(row)
    centre = tree.tree.visualItemRect(row).center()
    qtbot.mouseClick(tree.tree.viewport(), Qt.MouseButton.LeftButton, pos=centre)
    with qtbot.waitSignal(tree.sig_channel_activated, timeout=5000) as sig:
        qtbot.mouseDClick(tree.tree.viewport(), Qt.MouseButton.LeftButton, pos=centre)
    assert sig.args == ["HIGH_RATE.gyro_rate"]


# ---------------------------------------------------------------- strip charts
def test_panel_draws_store_data_over_the_window(panel, store, dictionary):
    simulated(dictionary, store, 3.0)
    panel.set_layout([["HIGH_RATE.encoder_outer", "HIGH_RATE.reference"],
                      ["HIGH_RATE.current_coarse"]])
    panel.set_window_seconds(1.0)
    panel.refresh()
    snap = store.ring("HIGH_RATE").snapshot(["encoder_outer"], seconds=1.0)
    x, y = curve_data(panel, 0, "HIGH_RATE.encoder_outer")
    assert len(x) == len(snap.device_time) and np.array_equal(y, snap.values["encoder_outer"])
    assert x[-1] == snap.device_time[-1] == pytest.approx(3.0, abs=2 / RATE)
    lo, hi = panel.stack.plots[1].x_range()                      # X-linked: every plot
    assert hi == pytest.approx(x[-1]) and hi - lo == pytest.approx(1.0)
    assert len(curve_data(panel, 1, "HIGH_RATE.current_coarse")[1]) == len(x)
    pens = {c.opts["pen"].color().name() for c in panel.stack.plots[0].curves.values()}
    assert len(pens) == 2
    assert panel.stack.plots[0].info_text() == ""                # 1200 samples: no decimation
    assert panel.stack.layout_ids() == [["HIGH_RATE.encoder_outer", "HIGH_RATE.reference"],
                                  ["HIGH_RATE.current_coarse"]]
    assert panel.stats.fps >= 1 and panel.stats.last_refresh_ms > 0
    with pytest.raises(ValueError):
        panel.set_window_seconds(601)
    with pytest.raises(ValueError):
        panel.stack.add_channel("HIGH_RATE.no_such_channel")


def test_one_sample_spike_survives_ten_minutes(qtbot, dictionary):
    store = TelemetryStore(dictionary, seconds=600.0)
    feed = HighRateFeeder(dictionary, store)
    n = int(600 * RATE)
    spike_at = 456_789
    for start in range(0, n, 120_000):
        seq = np.arange(start, start + 120_000)
        feed.high_rate(seq, error_angle=np.where(seq == spike_at, 2.5e-3, 1e-6 * np.sin(seq)))
    panel = StripChartPanel(store, dictionary)
    qtbot.addWidget(panel)
    panel.resize(1000, 600)
    panel.show()
    panel.set_window_seconds(600)
    panel.stack.add_channel("HIGH_RATE.error_angle")
    panel.refresh()
    x, y = curve_data(panel, 0, "HIGH_RATE.error_angle")
    assert len(y) <= 2 * panel.stack.plots[0].plot_width() + 2          # ~2 points per pixel
    assert y.max() == np.float32(2.5e-3)                          # exact f32 value, not averaged
    assert x[-1] - x[0] == pytest.approx(600, abs=1)
    assert "decimated ×" in panel.stack.plots[0].info_text()
    assert panel.stack.plots[0].info.isVisible()
    assert panel.stats.decimation > 100


def test_gap_breaks_the_line_and_is_marked(panel, store, dictionary):
    feed = HighRateFeeder(dictionary, store)
    feed.high_rate(np.arange(0, 600), encoder_outer=np.full(600, 1e-4))
    feed.high_rate(np.arange(610, 1200), encoder_outer=np.full(590, 1e-4))   # 10 lost
    panel.stack.add_channel("HIGH_RATE.encoder_outer")
    panel.set_window_seconds(1.0)
    panel.refresh()
    x, y = curve_data(panel, 0, "HIGH_RATE.encoder_outer")
    nan = np.flatnonzero(np.isnan(y))
    assert len(nan) == 1 and x[nan[0] + 1] == pytest.approx(610 / RATE)
    assert x[nan[0] - 1] == pytest.approx(599 / RATE)            # no line across the gap
    shown = [line for line in panel.stack.plots[0].gap_lines if line.isVisible()]
    assert len(shown) == 1 and shown[0].value() == pytest.approx(610 / RATE)
    assert "1 gap(s), 10 frames lost" in panel.stack.plots[0].info_text()
    assert np.isnan(panel.value_at("HIGH_RATE.encoder_outer", 605 / RATE))


def test_paused_view_does_not_change_while_data_arrives(panel, store, dictionary):
    feed = HighRateFeeder(dictionary, store)
    feed.high_rate(np.arange(0, 2400), encoder_outer=np.arange(2400) * 1e-7)
    panel.stack.add_channel("HIGH_RATE.encoder_outer")
    panel.set_window_seconds(1.0)
    panel.refresh()
    panel.set_paused(True)
    assert panel.settings.paused and panel.settings.pause_button.isChecked()
    before = curve_data(panel, 0, "HIGH_RATE.encoder_outer")
    feed.high_rate(np.arange(2400, 4800), encoder_outer=np.arange(2400, 4800) * 1e-7)
    panel.refresh()
    after = curve_data(panel, 0, "HIGH_RATE.encoder_outer")
    assert np.array_equal(before[0], after[0]) and np.array_equal(before[1], after[1])
    panel.stack.plots[0].getPlotItem().setXRange(1.0, 1.5, padding=0)   # zoom into the frozen data
    panel.refresh()
    x, _ = curve_data(panel, 0, "HIGH_RATE.encoder_outer")
    assert x[-1] <= 2399 / RATE + 1e-9 and x[0] >= 1.0 - 2 / RATE
    panel.set_paused(False)
    panel.refresh()
    assert curve_data(panel, 0, "HIGH_RATE.encoder_outer")[0][-1] == pytest.approx(4799 / RATE)


def test_state_round_trips_through_json(panel, store, dictionary, qtbot):
    panel.set_layout([["HIGH_RATE.encoder_outer", "HIGH_RATE.encoder_inner"],
                      ["HIGH_RATE.gyro_rate"], ["HOUSEKEEPING.temp_flexure"]])
    panel.set_window_seconds(120)
    panel.settings.set_timebase("host")
    panel.settings.set_y_range(1, -0.5, 0.5)
    state = json.loads(json.dumps(panel.settings.state()))
    other = StripChartPanel(TelemetryStore(dictionary, seconds=1.0), dictionary)
    qtbot.addWidget(other)
    other.settings.restore_state(state)
    assert other.stack.layout_ids() == panel.stack.layout_ids()
    assert other.settings.window_seconds == 120 and other.settings.timebase == "host"
    assert other.settings.window_combo.currentData() == 120.0
    assert [p.autoscale for p in other.stack.plots] == [True, False, True]
    assert other.stack.plots[1].y_range() == pytest.approx((-0.5, 0.5))
    state["layout"][0].append("HIGH_RATE.gone_in_a_newer_protocol")
    other.settings.restore_state(state)                              # stale settings: dropped, no crash
    assert other.stack.layout_ids()[0] == ["HIGH_RATE.encoder_outer", "HIGH_RATE.encoder_inner"]


def test_drop_move_and_menu(panel, store, dictionary):
    plot = panel.stack.plots[0]
    mime = QMimeData()
    mime.setText("HIGH_RATE.encoder_outer\nHIGH_RATE.gyro_rate\nnot a channel\n")
    event = QDropEvent(QPointF(50, 50), Qt.DropAction.CopyAction, mime,
                       Qt.MouseButton.LeftButton, Qt.KeyboardModifier.NoModifier)
    plot.dropEvent(event)
    assert panel.stack.layout_ids() == [["HIGH_RATE.encoder_outer", "HIGH_RATE.gyro_rate"]]
    assert plot.getPlotItem().getAxis("left").labelText == "mixed units"
    panel.stack.move_channel("HIGH_RATE.gyro_rate", 0, 1)                 # to a new plot
    assert panel.stack.layout_ids() == [["HIGH_RATE.encoder_outer"], ["HIGH_RATE.gyro_rate"]]
    assert panel.stack.add_channel("HIGH_RATE.encoder_inner") == 0        # joins the rad plot
    panel.stack._fill_menu(panel.stack.plots[0])
    texts = [a.text() for a in panel.stack.plots[0].chart_menu.actions()]
    assert "Autoscale Y" in texts and "Remove this plot" in texts
    sub = panel.stack.plots[0].channel_menus["HIGH_RATE.encoder_inner"]
    assert sub.menuAction() in panel.stack.plots[0].chart_menu.actions()
    sub.actions()[0].trigger()                                      # "Move to plot 2"
    assert panel.stack.layout_ids() == [["HIGH_RATE.encoder_outer"],
                                  ["HIGH_RATE.gyro_rate", "HIGH_RATE.encoder_inner"]]
    panel.stack.remove_plot(0)
    assert panel.stack.layout_ids() == [["HIGH_RATE.gyro_rate", "HIGH_RATE.encoder_inner"]]
    assert panel.stack.plots[0].time_axis.isVisibleTo(panel.stack.plots[0].getPlotItem())


def test_cursor_readout_and_host_timebase(panel, store, dictionary):
    feed = HighRateFeeder(dictionary, store)
    host0 = 1.7e9
    for k in range(10):                        # 100-frame datagrams arriving 5 ms late
        seq = np.arange(k * 100, (k + 1) * 100)
        feed.high_rate(seq, host_time=host0 + (k + 1) * 100 / RATE + 0.005,
                       encoder_outer=seq * 1e-6)
    panel.stack.add_channel("HIGH_RATE.encoder_outer")
    panel.refresh()
    panel.set_cursor(500 / RATE)
    assert panel.value_at("HIGH_RATE.encoder_outer", 500.4 / RATE) == pytest.approx(500e-6, abs=2e-9)
    text = panel.readout.text()
    assert "encoder_outer" in text and "µrad" in text and "0.4167 s" in text
    assert panel.stack.plots[0].cursor.isVisible()
    panel.settings.set_timebase("host")
    panel.refresh()
    x, _ = curve_data(panel, 0, "HIGH_RATE.encoder_outer")
    # device time + the smallest host-device offset: a datagram's last frame, 5 ms late
    assert x[0] == pytest.approx(host0 + 0.005 + 1 / RATE, abs=1e-6)
    assert np.all(np.diff(x) > 0)
    assert panel.stack.plots[0].time_axis.host


def test_axis_labels_use_si_prefixes_for_si_units(panel, store, dictionary, qtbot):
    feed = HighRateFeeder(dictionary, store)
    seq = np.arange(1200)
    feed.high_rate(seq, error_angle=20e-6 * np.sin(seq / 50), torque_coarse_cmd=np.sin(seq / 50))
    panel.set_layout([["HIGH_RATE.error_angle"], ["HIGH_RATE.torque_coarse_cmd"]])
    panel.refresh()
    rad_axis = panel.stack.plots[0].getPlotItem().getAxis("left")
    torque_axis = panel.stack.plots[1].getPlotItem().getAxis("left")
    qtbot.waitUntil(lambda: rad_axis.labelUnitPrefix == "µ", timeout=5000)
    assert rad_axis.labelUnits == "rad" and rad_axis.autoSIPrefixScale == pytest.approx(1e6)
    assert "µrad" in rad_axis.labelString()
    assert torque_axis.labelUnits == "in-oz" and torque_axis.autoSIPrefixScale == 1.0
    feed.high_rate(np.arange(1200, 2400), error_angle=np.full(1200, 5e-3))
    panel.refresh()
    qtbot.waitUntil(lambda: rad_axis.labelUnitPrefix == "m", timeout=5000)
    assert display_unit("degC").units == "°C" and not display_unit("counts").si_prefix
    assert display_unit("ms").scale == 1e-3 and display_unit("ms").units == "s"
    assert format_value(12.5e-6, display_unit("rad")) == "12.5 µrad"
    assert format_value(3600.0, display_unit("s")) == "3600 s"


# ---------------------------------------------------------------- spectrum
def test_spectrum_of_a_sine_peaks_at_its_frequency(qtbot, store, dictionary):
    feed = HighRateFeeder(dictionary, store)
    seq = np.arange(int(10 * RATE))
    amplitude, f0 = 50e-6, 37.0
    feed.high_rate(seq[:6000], error_angle=amplitude * np.sin(2 * np.pi * f0 * seq[:6000] / RATE))
    rest = seq[6050:]                                            # 50 frames lost: not spliced
    feed.high_rate(rest, error_angle=amplitude * np.sin(2 * np.pi * f0 * rest / RATE))
    view = SpectrumView(store, dictionary)
    qtbot.addWidget(view)
    view.set_seconds(10)
    view.set_channel("HIGH_RATE.error_angle")
    assert abs(view.peak_frequency() - f0) < 1.0
    assert view.total_rms == pytest.approx(amplitude / np.sqrt(2), rel=0.05)
    assert "µrad" in view.rms_label.text()
    assert view.plot.getPlotItem().getAxis("left").labelText == "PSD (rad²/Hz)"
    with pytest.raises(ValueError):
        view.set_channel("HIGH_RATE.nope")


def test_redrawing_keeps_references_to_none(panel, store, dictionary, qtbot):
    """PySide6 6.12.0 on Python 3.11 drops a reference to None on every call of a void
    method (~500 per redraw here): a 30 Hz chart aborts with none_dealloc in a minute.
    (From Python 3.12 None is immortal, its count never falls, and this holds anyway.)"""
    simulated(dictionary, store, 2.0)
    panel.set_layout([["HIGH_RATE.encoder_outer", "HIGH_RATE.reference"], ["HIGH_RATE.gyro_rate"]])
    qtbot.wait(10)
    before = sys.getrefcount(None)
    for _ in range(20):
        panel.refresh()
        panel.repaint()
    assert sys.getrefcount(None) - before > -50       # a few temporaries, not ~500 per frame


def test_timer_redraws_only_while_visible(panel, store, dictionary, qtbot):
    feed = HighRateFeeder(dictionary, store)
    feed.high_rate(np.arange(1200), encoder_outer=np.zeros(1200))
    panel.stack.add_channel("HIGH_RATE.encoder_outer")
    right_edge = lambda: panel.stack.plots[0].x_range()[1]        # noqa: E731
    qtbot.waitUntil(lambda: right_edge() == pytest.approx(1199 / RATE), timeout=5000)
    panel.hide()
    feed.high_rate(np.arange(1200, 2400), encoder_outer=np.zeros(1200))
    qtbot.wait(150)
    assert right_edge() == pytest.approx(1199 / RATE)
    panel.show()
    qtbot.waitUntil(lambda: right_edge() == pytest.approx(2399 / RATE), timeout=5000)
