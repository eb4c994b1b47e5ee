"""Link statistics: drops from sequence gaps across the 2^32 wrap, tick unwrapping,
latency from the clock offset."""

from __future__ import annotations

import numpy as np

from groundstation.codec import TelemetryBlock
from groundstation.codec.ticks import TickUnwrapper
from groundstation.link.stats import ClockSync, LinkStatistics


def block(dictionary, seq, ticks, host_time):
    pkt = dictionary.packet("HIGH_RATE")
    seq = np.asarray(seq, dtype=np.uint32)
    return TelemetryBlock(pkt, {"sequence": seq, "tick": np.asarray(ticks, dtype=np.uint32)},
                          np.asarray(host_time, dtype=float))


def test_gaps_duplicates_and_wrap(dictionary):
    st = LinkStatistics()
    top = 2**32 - 3
    st.update(block(dictionary, [top, top + 1, top + 2], [1, 2, 3], [0, 0, 0]))
    # 0 lost at the wrap; the jump to 6 is believed once 7 continues from it
    st.update(block(dictionary, [1, 2, 2, 6, 7], [5, 6, 6, 10, 11], [1, 1, 1, 1, 1]))
    snap = st.snapshot()
    ps = snap.packets["HIGH_RATE"]
    assert ps.frames == 8
    assert ps.dropped == 1 + 3        # 0 across the wrap, then 3, 4, 5
    assert ps.duplicates == 1
    assert [g[2] for g in snap.gap_events] == [1, 3]


def test_tick_unwrapper_continues_across_the_wrap():
    u = TickUnwrapper()
    a = u.unwrap(np.array([2**32 - 2, 2**32 - 1], dtype=np.uint32))
    b = u.unwrap(np.array([0, 1], dtype=np.uint32))
    assert list(np.concatenate([a, b]) - a[0]) == [0, 1, 2, 3]


def test_latency_uses_the_best_round_trip():
    cs = ClockSync(1200.0)
    # device tick 1200 happened at host time 100.0 (+ half a tick); a slow and a fast exchange
    cs.observe(sent=99.99, received=100.05, device_tick=1200)      # rtt 60 ms, biased
    cs.observe(sent=100.999, received=101.001 + 1 / 1200, device_tick=2400)  # rtt ~3 ms
    assert cs.best_rtt < 0.004
    assert abs(cs.offset - 99.0) < 0.002


def test_one_wild_sequence_number_is_an_outlier_not_a_billion_drops(dictionary):
    """A single frame far off the sequence line (forged, or a corrupted header with a
    matching CRC) is not believed: the next frame continues the old line."""
    st = LinkStatistics()
    st.update(block(dictionary, [100, 101, 102], [1, 2, 3], [0, 0, 0]))
    st.update(block(dictionary, [1_234_567_890], [4], [0]))          # the wild one, alone
    st.update(block(dictionary, [103, 104, 106, 107], [5, 6, 8, 9], [0, 0, 0, 0]))
    ps = st.snapshot().packets["HIGH_RATE"]
    assert ps.dropped == 1            # only 105, really missing
    assert ps.outliers == 1
    assert ps.duplicates == 0


def test_a_confirmed_restart_is_not_counted_as_drops(dictionary):
    st = LinkStatistics()
    st.update(block(dictionary, [5000, 5001], [1, 2], [0, 0]))
    st.update(block(dictionary, [0, 1, 2], [1, 2, 3], [0, 0, 0]))     # the device rebooted
    ps = st.snapshot().packets["HIGH_RATE"]
    assert (ps.dropped, ps.outliers, ps.duplicates) == (0, 0, 0)


def test_latency_is_never_negative_when_the_device_clock_runs_fast(dictionary):
    """The round-trip offset goes stale when the device clock runs faster than the
    host's (a drifting crystal, a simulator at --speed 2); the frames themselves bound
    the offset, so latency never reads below zero."""
    st = LinkStatistics()
    st.clock.observe(sent=100.0, received=100.002, device_tick=0)
    # the device clock then runs at twice the host's rate: tick 2400 arrives 1 s later
    ticks = np.arange(1200, 2401, 12)
    host = 100.001 + (ticks / 1200.0) / 2 + 0.0005
    st.update(block(dictionary, np.arange(len(ticks)), ticks, host))
    snap = st.snapshot()
    assert snap.latency_ms_mean is not None and snap.latency_ms_mean >= 0.0
    assert snap.latency_ms_max >= 0.0
