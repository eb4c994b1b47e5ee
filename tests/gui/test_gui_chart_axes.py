"""The strip chart's axes: a live chart's time axis stays put (seconds before the newest
sample) while its contents move, pausing shows absolute time, and the y autoscale keeps
its range while the data stay inside it."""

from __future__ import annotations

import math

import numpy as np
import pytest

from groundstation.gui.charts.autoscale import (EDGE, FLAT_STEPS, least_span, nice_range, nice_step,
                                                sticky_range)

from conftest import HighRateFeeder

RATE = 1200.0


@pytest.fixture
def panel(strip_chart):
    # a data area as wide as 2 s at 1200 Hz needs undecimated (the legend's column
    # beside the plots takes 150 px of the width)
    return strip_chart(30.0, (1000, 500))


# ---------------------------------------------------------------- y range
def test_nice_steps_and_ranges():
    assert [nice_step(x) for x in (0.7, 1.0, 1.3, 2.0, 4.9, 7.0, 0.013)] == \
        pytest.approx([1.0, 1.0, 2.0, 2.0, 5.0, 10.0, 0.02])
    lo, hi = nice_range(-1e-3, 1e-3)
    assert lo < -1e-3 and hi > 1e-3 and lo == pytest.approx(-1.5e-3) and hi == pytest.approx(1.5e-3)
    assert nice_range(5.0, 5.0)[0] < 5.0 < nice_range(5.0, 5.0)[1]     # constant data
    assert nice_range(0.0, 0.0)[0] < 0.0 < nice_range(0.0, 0.0)[1]


def test_sticky_range_keeps_until_the_data_leave_or_shrink():
    shown = sticky_range(-1.0, 1.0, None)
    assert shown is not None and shown[0] < -1.0 and shown[1] > 1.0
    assert sticky_range(-1.0, 1.0, shown) is None                   # the same data: kept
    assert sticky_range(-1.05, 0.9, shown) is None                  # a little noise: kept
    grown = sticky_range(-1.0, 3.0, shown)                           # the data left it
    assert grown is not None and grown[1] >= 3.0
    small = sticky_range(-0.1, 0.1, shown)                           # shrank a lot
    assert small is not None and small[1] - small[0] < 0.5
    assert sticky_range(math.nan, 1.0, shown) is None


def test_autoscaled_y_range_holds_while_the_data_stay_inside(panel, dictionary):
    feed = HighRateFeeder(dictionary, panel.store)
    panel.stack.add_channel("HIGH_RATE.error_angle")
    panel.set_window_seconds(5.0)
    rng = np.random.default_rng(2)
    total, ranges = 0, []
    for step in range(60):
        s = np.arange(total, total + 40)
        feed(s, error_angle=1e-4 * np.sin(s / 100.0) + 1e-6 * rng.standard_normal(40))
        total += 40
        panel.refresh()
        if total > 1300:                              # a few cycles: the range is set
            ranges.append(panel.stack.plots[0].y_range())
    assert len(set(ranges)) == 1
    lo, hi = ranges[0]
    assert lo < -1e-4 and hi > 1e-4 and hi - lo < 4e-4
    # the round range's ends (where ticks and their labels go) sit inside the view, by
    # EDGE of the range, so a label at an end is not drawn over the neighbouring plot
    a, b = panel.stack.plots[0].getPlotItem().getViewBox()._round_range
    assert lo < a < b < hi
    assert a - lo == pytest.approx(EDGE * (b - a)) and hi - b == pytest.approx(EDGE * (b - a))
    fine = 10.0 ** (math.floor(math.log10(b - a)) - 1)      # the ends are round numbers
    assert a / fine == pytest.approx(round(a / fine)) and b / fine == pytest.approx(round(b / fine))
    feed(np.arange(total, total + 40), error_angle=np.full(40, 5e-4))  # out of the range
    panel.refresh()
    assert panel.stack.plots[0].y_range()[1] >= 5e-4


def test_a_flat_channel_gets_a_least_span_from_its_resolution():
    # an integer channel: FLAT_STEPS of its resolution, in display units
    assert least_span("i16", 1e-4, "A") == pytest.approx(FLAT_STEPS * 1e-4)
    assert least_span("u8", None, "") == pytest.approx(FLAT_STEPS)
    # a float channel: its unit's floor (ms shown as s: the floor in s)
    assert least_span("f32", None, "rad") == pytest.approx(1e-6)
    assert least_span("f32", None, "ms", display_scale=1e-3) == pytest.approx(1e-3)
    assert least_span("f32", None, "furlongs") == 0.0
    # a constant zero: a band of about the least span, not +-0.6 of the unit
    lo, hi = nice_range(0.0, 0.0, least=1e-3)
    assert lo < 0.0 < hi and 1e-3 <= hi - lo <= 2e-3
    # a constant value: centred on it
    lo, hi = nice_range(25.0, 25.0, least=0.1)
    assert lo < 25.0 < hi and hi - lo <= 0.2
    # one count of noise on a flat channel: the range is kept (the least span is filled)
    shown = sticky_range(0.0, 1e-4, None, least=1e-3)
    assert shown is not None and shown[1] - shown[0] <= 2e-3
    assert sticky_range(0.0, 0.0, shown, least=1e-3) is None
    assert sticky_range(-1e-4, 0.0, shown, least=1e-3) is None
    # data wider than the least span: as before
    assert nice_range(-1.0, 1.0, least=1e-3) == nice_range(-1.0, 1.0)


def test_flat_channels_autoscale_to_a_readable_span(panel, dictionary):
    """A motor current at rest (0 A, 0.1 mA per count), the angle error at 0 (f32 rad)
    and the mode (an unscaled integer): each plot spans about FLAT_STEPS counts or its
    unit's floor - the old rule made every flat channel +-0.6 of its unit."""
    feed = HighRateFeeder(dictionary, panel.store)
    panel.stack.set_layout([["HIGH_RATE.current_coarse"], ["HIGH_RATE.error_angle"],
                            ["HIGH_RATE.mode"]])
    panel.set_window_seconds(2.0)
    n = 1200
    feed(np.arange(n), current_coarse=np.zeros(n), error_angle=np.zeros(n), mode=np.zeros(n))
    panel.refresh()
    (clo, chi), (rlo, rhi), (mlo, mhi) = (p.y_range() for p in panel.stack.plots)
    assert clo < 0.0 < chi and 1e-3 <= chi - clo <= 3e-3           # +- about 1 mA
    assert rlo < 0.0 < rhi and 1e-6 <= rhi - rlo <= 3e-6           # +- about 1 urad
    assert mlo < 0.0 < mhi and 10 <= mhi - mlo <= 30               # an integer: 10 counts
    # the current moves by one count: still the same range
    before = panel.stack.plots[0].y_range()
    feed(np.arange(n, n + 40), current_coarse=np.full(40, 1e-4), error_angle=np.zeros(40),
         mode=np.zeros(40))
    panel.refresh()
    assert panel.stack.plots[0].y_range() == before


# ---------------------------------------------------------------- time axis
def test_live_time_axis_stays_put_and_times_stay_absolute(panel, dictionary):
    feed = HighRateFeeder(dictionary, panel.store)
    panel.stack.add_channel("HIGH_RATE.error_angle")
    panel.stack.add_channel("HIGH_RATE.encoder_outer", 1)
    panel.set_window_seconds(2.0)
    feed(np.arange(0, 1200), error_angle=np.zeros(1200), encoder_outer=np.zeros(1200))
    panel.refresh()
    changes = []
    for plot in panel.stack.plots:
        plot.getPlotItem().getViewBox().sigXRangeChanged.connect(lambda *a: changes.append(a))
    for k in range(1, 6):
        s = np.arange(1200 + 40 * (k - 1), 1200 + 40 * k)
        seq = s + (100 if k >= 3 else 0)                     # 100 frames lost: a gap
        feed(seq, error_angle=np.zeros(40), encoder_outer=np.zeros(40))
        panel.refresh()
    assert changes == []                                     # the view's x range never moved
    newest = panel.store.ring("HIGH_RATE").newest_time()
    for plot in panel.stack.plots:
        vb = plot.getPlotItem().getViewBox()
        assert vb.viewRange()[0] == pytest.approx([-2.0, 0.0])
        assert plot.x_range() == pytest.approx((newest - 2.0, newest))
        assert plot.time_axis.relative
    shown = [line for line in panel.stack.plots[0].gap_lines if line.isVisible()]
    assert len(shown) == 1 and shown[0].value() == pytest.approx((1280 + 100) / RATE)
    # where the gap line is on screen: its absolute time minus the newest one
    vb = panel.stack.plots[0].getPlotItem().getViewBox()
    vb.updateMatrix()                                        # as the next paint would
    at = vb.mapSceneToView(shown[0].mapToScene(0.0, 0.0)).x()
    assert at == pytest.approx(shown[0].value() - newest)
    x, _ = panel.stack.plots[0].curves["HIGH_RATE.error_angle"].getData()
    assert x[-1] == pytest.approx(newest)                    # the curve's data: absolute
    panel.set_cursor(newest - 0.5)
    assert panel.stack.plots[1].cursor.value() == pytest.approx(newest - 0.5)
    assert "newest" in panel._newest_text()

    panel.set_paused(True)
    panel.refresh()
    for plot in panel.stack.plots:
        assert not plot.time_axis.relative and plot.origin == 0.0
        assert plot.getPlotItem().getViewBox().viewRange()[0] == pytest.approx(
            [newest - 2.0, newest])
        assert plot.x_range() == pytest.approx((newest - 2.0, newest))
    panel.set_paused(False)
    panel.refresh()
    assert panel.stack.plots[0].time_axis.relative
    assert panel.stack.plots[0].getPlotItem().getViewBox().viewRange()[0] == pytest.approx([-2.0, 0.0])
