"""The strip chart's min/max envelope against a brute-force one.

The ring keeps a min/max pyramid per channel shown, extended block by block as data
arrive; these tests check that what it answers - and what the chart then draws - is the
min and max of every bin of the raw samples, at every window position, while the ring
wraps, with spikes, NaN and lost frames."""

from __future__ import annotations

import numpy as np
import pytest

from groundstation.live.display_buffers import (PYRAMID_BLOCKS, TelemetryStore, aligned_envelope,
                                                bin_factor)
from groundstation.gui.charts.panel import StripChartPanel

from conftest import HighRateFeeder

RATE = 1200.0


def brute_force(number, t, y, t0, t1, bins, before=True):
    """(x, points, per) as the chart should draw y between t0 and t1, one bin at a time
    with plain Python over the raw samples (number: each sample's number since clear).
    `before`: with the sample before t0 (a zoomed view), or from t0 on (the live window)."""
    i0 = max(int(np.searchsorted(t, t0, side="left")) - int(before), 0)
    i1 = min(int(np.searchsorted(t, t1, side="right")) + 1, len(t))
    per = bin_factor(i1 - i0, bins)
    if per == 1:
        return t[i0:i1], y[i0:i1], 1
    xs, ps = [], []
    i = i0
    while i < i1:
        end = i
        while end < i1 and number[end] // per == number[i] // per:
            end += 1
        seg = [float(v) for v in y[i:end]]
        lo = float("nan") if any(v != v for v in seg) else min(seg)
        hi = float("nan") if any(v != v for v in seg) else max(seg)
        xs += [t[i], t[i]]
        ps += [lo, hi]
        i = end
    return np.array(xs), np.array(ps), per


def test_pyramid_envelope_equals_brute_force_at_every_window_position(dictionary):
    """Blocks of random size stream into a ring that wraps several times; after each
    block the envelope of the newest window (and of windows ending earlier, as a paused
    or zoomed chart asks) equals the brute-force min/max of the raw samples."""
    store = TelemetryStore(dictionary, seconds=8.0)            # 10,080 HIGH_RATE samples
    ring = store.ring("HIGH_RATE")
    feed = HighRateFeeder(dictionary, store)
    rng = np.random.default_rng(11)
    history_t, history_y, history_n = [], [], []
    seq, number = 0, 0
    checked = {1: 0, 4: 0, 16: 0, 64: 0, 256: 0, 4096: 0}
    for step in range(160):
        n = int(rng.choice([1, 7, 12, 40, 333, 1200, 2500]))
        if step % 37 == 36:
            seq += int(rng.integers(1, 30))                   # frames lost: a gap
        s = np.arange(seq, seq + n)
        y = 1e-3 * np.sin(s / 90.0) + 1e-5 * rng.standard_normal(n)
        y[rng.random(n) < 0.002] = 3e-3                       # one-sample spikes
        y[rng.random(n) < 0.002] = -3e-3
        feed(s, error_angle=y)
        y32 = y.astype(np.float32).astype(np.float64)         # as the wire carries it
        history_t.append(s / RATE)
        history_y.append(y32)
        history_n.append(np.arange(number, number + n))
        seq += n
        number += n
        t = np.concatenate(history_t)[-ring.capacity:]
        yy = np.concatenate(history_y)[-ring.capacity:]
        nn = np.concatenate(history_n)[-ring.capacity:]
        for window, bins, back in ((8.0, 300, 0.0), (8.0, 37, 1.3), (2.0, 400, 0.0),
                                   (5.0, 64, 0.4), (1.0, 3, 0.0), (8.0, 1, 0.0)):
            end = t[-1] - back
            env = ring.envelope(["error_angle"], end - window, end, bins)
            x, p, per = brute_force(nn, t, yy, end - window, end, bins)
            assert env.per == per
            if per > 1:
                assert len(p) <= 2 * bins + 2
            assert np.array_equal(env.x, x)
            assert np.array_equal(env.values["error_angle"], p, equal_nan=True)
            checked[min((k for k in checked if k >= per), default=4096)] += 1
    assert min(checked.values()) > 0, checked                # raw, and every level used


def test_nan_in_a_bin_is_kept_as_in_np_min(dictionary):
    """A NaN sample (a channel the device could not measure) makes its bin NaN at every
    level of the pyramid, as np.min over the bin does: the line breaks, nothing is made up."""
    store = TelemetryStore(dictionary, seconds=60.0)
    ring = store.ring("HIGH_RATE")
    feed = HighRateFeeder(dictionary, store)
    y = np.cos(np.arange(60_000) / 500.0)
    y[33_333] = np.nan
    for a in range(0, 60_000, 1000):
        feed(np.arange(a, a + 1000), error_angle=y[a:a + 1000])
    snap = ring.snapshot(["error_angle"])
    for bins in (4000, 200, 10):
        env = ring.envelope(["error_angle"], 0.0, 60.0, bins)
        x, p, per = brute_force(np.arange(60_000), snap.device_time, snap.values["error_angle"],
                                0.0, 60.0, bins)
        assert per > 1 and np.array_equal(env.values["error_angle"], p, equal_nan=True)
        assert np.isnan(env.values["error_angle"]).sum() == 2


def test_aligned_envelope_of_frozen_data_matches_the_ring(dictionary):
    store = TelemetryStore(dictionary, seconds=10.0)
    ring = store.ring("HIGH_RATE")
    feed = HighRateFeeder(dictionary, store)
    rng = np.random.default_rng(3)
    for a in range(0, 30_000, 777):
        feed(np.arange(a, a + 777), error_angle=rng.standard_normal(777))
    snap = ring.snapshot(["error_angle"], seconds=6.0)
    t = snap.device_time
    for per in (2, 16, 64, 1024):
        i0 = 5
        x, y = aligned_envelope(t[i0:], snap.values["error_angle"][i0:], snap.first_index + i0, per)
        numbers = snap.first_index + np.arange(len(t))
        bx, by, _ = brute_force(numbers[i0:], t[i0:], snap.values["error_angle"][i0:],
                                t[i0], t[-1], (len(t) - i0) // per)
        if _ != per:
            continue
        assert np.array_equal(x, bx) and np.array_equal(y, by)
    assert PYRAMID_BLOCKS == (16, 256, 4096)


@pytest.fixture
def panel(qtbot, dictionary):
    store = TelemetryStore(dictionary, seconds=30.0)
    p = StripChartPanel(store, dictionary)
    qtbot.addWidget(p)
    p.resize(700, 400)
    p.show()
    qtbot.waitExposed(p)
    p._timer.stop()                    # the test refreshes by hand
    return p


def test_drawn_curve_is_the_brute_force_envelope_as_the_window_scrolls(panel, dictionary):
    """Live at 1200 Hz in 40-frame steps (one 30 Hz chart frame each) with a 20 s window:
    at every step the curve handed to pyqtgraph is the brute-force min/max envelope of
    the raw samples in the window, and a spike stays visible while it is in the window."""
    store = panel.store
    feed = HighRateFeeder(dictionary, store)
    panel.stack.add_channel("HIGH_RATE.error_angle")
    panel.set_window_seconds(20.0)
    rng = np.random.default_rng(5)
    total = 0
    ys = []
    spike_at = 30_000
    for step in range(1200):
        n = 40 if step > 10 else 2400
        s = np.arange(total, total + n)
        y = 1e-4 * np.sin(s / 700.0) + 1e-6 * rng.standard_normal(n)
        y[s == spike_at] = 2.5e-3
        feed(s, error_angle=y)
        ys.append(y.astype(np.float32).astype(np.float64))
        total += n
        if step % 7 and step < 1190:
            continue                                         # every 7th step, and the last ten
        panel.refresh()
        x, drawn = panel.stack.plots[0].curves["HIGH_RATE.error_angle"].getData()
        yy = np.concatenate(ys)[-store.ring("HIGH_RATE").capacity:]
        nn = np.arange(total - len(yy), total)
        t = nn / RATE
        lo, hi = panel.stack.plots[0].x_range()
        bins = max(64, int(panel.stack.plots[0].plot_width()))
        bx, by, per = brute_force(nn, t, yy, lo, hi, bins, before=False)
        assert np.array_equal(np.asarray(x), bx)
        assert np.array_equal(np.asarray(drawn), by)
        assert per > 1 or total < 2 * bins
        if t[-1] - 20.0 <= spike_at / RATE <= t[-1]:
            assert np.nanmax(drawn) == np.float32(2.5e-3)


def test_nothing_new_nothing_redrawn(panel, dictionary):
    """The timer redraws a live chart only when a shown packet got data or a setting
    changed (a stopped link or replay costs no redraws)."""
    feed = HighRateFeeder(dictionary, panel.store)
    feed(np.arange(2400), error_angle=np.zeros(2400))
    panel.stack.add_channel("HIGH_RATE.error_angle")
    calls = []
    inner = panel.refresh
    panel.refresh = lambda: (calls.append(1), inner())
    panel._on_timer()
    panel._on_timer()
    assert len(calls) == 1
    feed(np.arange(2400, 2440), error_angle=np.zeros(40))
    panel._on_timer()
    panel._on_timer()
    assert len(calls) == 2
    panel.set_window_seconds(2.0)
    panel._on_timer()
    assert len(calls) == 3
    assert panel.stack.plots[0].x_range() == pytest.approx((2439 / RATE - 2.0, 2439 / RATE))


def test_pyramid_fed_only_for_wide_requests_catches_up_exactly(dictionary):
    """A scrolling chart's frames complete a bin or two, reduced from the samples; the
    pyramid is fed only when many bins are asked for (a new window or width) - after a
    few seconds of scrolling, and after the ring wrapped past what it had been fed."""
    import groundstation.live.display_buffers as db

    store = TelemetryStore(dictionary, seconds=5.0)             # 6,000 HIGH_RATE samples
    ring = store.ring("HIGH_RATE")
    feed = HighRateFeeder(dictionary, store)
    rng = np.random.default_rng(8)
    ts, ys = [], []
    total = 0

    def check(window, bins):
        t, y = np.concatenate(ts)[-ring.capacity:], np.concatenate(ys)[-ring.capacity:]
        nn = np.arange(total - len(t), total)
        end = t[-1]
        env = ring.envelope(["error_angle"], end - window, end, bins, before=False)
        x, p, per = brute_force(nn, t, y, end - window, end, bins, before=False)
        assert env.per == per
        assert np.array_equal(env.x, x) and np.array_equal(env.values["error_angle"], p)
        return per

    fed = []
    for step in range(400):
        s = np.arange(total, total + 40)
        y = np.sin(s / 300.0) + 0.1 * rng.standard_normal(40)
        feed(s, error_angle=y)
        ts.append(s / RATE)
        ys.append(y.astype(np.float32).astype(np.float64))
        total += 40
        check(5.0, 90)                       # the scrolling frame: a few new bins
        if step in (200, 399):               # a wide request: many bins, from the pyramid
            assert check(5.0, 200) == 32 and check(5.0, 20) == 512
        pyr = ring._pyramids.get("error_angle")
        fed.append(pyr.fed if pyr is not None else None)
    # The window was full (6,000 samples, 64 a bin) from step 150 on.  The pyramid was
    # fed up to the newest sample for the wide requests, once more for the next frame
    # (its bins of 64 were all reduced again after the wide requests' 32 and 512), and
    # not while scrolling in between; at step 399 the ring had wrapped past what it had
    # been fed: built anew.
    assert fed[200] == 201 * 40 and fed[201] == 202 * 40 and fed[399] == 400 * 40
    assert fed[202:399] == [fed[201]] * 197
    assert 6000 > db.DIRECT_REDUCE_MAX
