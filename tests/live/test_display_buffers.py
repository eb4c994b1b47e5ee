"""Ring buffers for display, peak-keeping decimation, gap breaks."""

from __future__ import annotations

import numpy as np

from groundstation.codec import FrameCodec
from groundstation.live.display_buffers import TelemetryStore, peak_decimate, with_gap_breaks


def hr_block(codec, seq, values=None):
    seq = np.asarray(seq)
    data = codec.encode("HIGH_RATE", values or {"encoder_outer": seq * 1e-6}, seq, seq)
    return codec.decode_frame(data[:78], 1.0) if len(seq) == 1 else _decode(codec, data)


def _decode(codec, data):
    from groundstation.codec import StreamDeframer
    return StreamDeframer(codec).feed(data, 5.0)[0]


def test_ring_keeps_the_newest_and_marks_gaps(dictionary):
    codec = FrameCodec(dictionary)
    store = TelemetryStore(dictionary, seconds=1.0)        # 1260 HIGH_RATE samples
    ring = store.ring("HIGH_RATE")
    store(hr_block(codec, np.arange(0, 1000)))
    store(hr_block(codec, np.arange(1010, 2000)))            # 10 frames lost
    snap = ring.snapshot(["encoder_outer"])
    assert len(snap.device_time) == ring.capacity
    assert snap.device_time[-1] == 1999 / 1200 and np.all(np.diff(snap.device_time) > 0)
    assert np.allclose(snap.values["encoder_outer"], snap.device_time * 1200 * 1e-6)
    assert list(snap.gap_sizes) == [10] and snap.gap_device_times[0] == 1010 / 1200
    assert snap.total_frames == 1990
    last = ring.snapshot(["encoder_outer"], seconds=0.1)
    assert len(last.device_time) == 121
    assert abs(ring.latest("encoder_outer") - 1999e-6) < 1.5e-9     # one encoder count
    big = TelemetryStore(dictionary, seconds=0.5)
    big(hr_block(codec, np.arange(5000)))                    # one block larger than the ring
    assert big.ring("HIGH_RATE").snapshot(["tick"]).values["tick"][-1] == 4999


def test_peak_decimation_keeps_a_one_sample_spike():
    x = np.arange(1_000_000) / 1200.0
    y = np.zeros_like(x)
    y[654_321] = 5.0
    y[10] = -2.0
    xs, ys, dec = peak_decimate(x, y, 800)
    assert dec and len(ys) <= 2 * 800 + 2
    assert ys.max() == 5.0 and ys.min() == -2.0
    small_x, small_y, dec = peak_decimate(x[:100], y[:100], 800)
    assert not dec and len(small_y) == 100


def test_gaps_survive_decimation_and_break_the_line():
    t = np.arange(20.0)
    y = np.ones(20)
    tb, yb = with_gap_breaks(t, y, np.array([10.0]))
    assert np.isnan(yb[10]) and len(yb) == 21 and tb[10] == tb[11] == 10.0
    xs, ys, _ = peak_decimate(tb, yb, 4)
    assert np.isnan(ys).any()


def test_a_device_reboot_restarts_the_display_history(dictionary):
    """Device time going back (a reboot, a fresh simulator after a lost link) must not
    interleave old and new samples on the time axis."""
    codec = FrameCodec(dictionary)
    store = TelemetryStore(dictionary, seconds=10.0)
    seen = []
    store.on_restart = lambda *a: seen.append(a)
    ring = store.ring("HIGH_RATE")
    store(hr_block(codec, np.arange(0, 4000)))
    store(hr_block(codec, np.arange(3998, 4100)))            # two repeated: reordering, not a reboot
    assert ring.restarts == 0 and not seen
    store(hr_block(codec, np.concatenate([np.arange(4100, 5000), np.arange(10, 500)])))
    assert ring.restarts == 1
    assert seen == [("HIGH_RATE", 4999 / 1200, 10 / 1200)]
    snap = ring.snapshot(["encoder_outer"])
    assert snap.device_time[0] == 10 / 1200 and snap.device_time[-1] == 499 / 1200
    assert np.all(np.diff(snap.device_time) > 0) and snap.total_frames == 490
    assert len(snap.gap_sizes) == 0
    store(hr_block(codec, np.arange(500, 600)))
    assert ring.snapshot(["tick"]).values["tick"][-1] == 599 and ring.restarts == 1


def test_windowed_snapshots_match_the_whole_ring_at_every_wrap_position(dictionary):
    codec = FrameCodec(dictionary)
    store = TelemetryStore(dictionary, seconds=1.0)           # capacity 1260
    ring = store.ring("HIGH_RATE")
    rng = np.random.default_rng(7)
    tick = 0
    for _ in range(40):
        n = int(rng.integers(1, 700))
        store(hr_block(codec, np.arange(tick, tick + n)))
        tick += n
        whole = ring.snapshot(["encoder_outer"])
        kept = min(tick, ring.capacity)
        assert np.array_equal(whole.device_time, np.arange(tick - kept, tick) / 1200)
        for seconds in (0.0, 0.01, 0.3, 0.9, 5.0):
            part = ring.snapshot(["encoder_outer"], seconds=seconds)
            keep = whole.device_time >= whole.device_time[-1] - seconds
            assert np.array_equal(part.device_time, whole.device_time[keep])
            assert np.array_equal(part.values["encoder_outer"], whole.values["encoder_outer"][keep])
