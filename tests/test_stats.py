"""Link statistics: drops from sequence gaps across the 2^32 wrap, tick unwrapping,
latency from the clock offset."""

from __future__ import annotations

import numpy as np

from groundstation.codec import TelemetryBlock
from groundstation.link.stats import ClockSync, LinkStatistics, TickUnwrapper


def block(dictionary, seq, ticks, host_time):
    pkt = dictionary.packet("HIGH_RATE")
    seq = np.asarray(seq, dtype=np.uint32)
    return TelemetryBlock(pkt, {"sequence": seq, "tick": np.asarray(ticks, dtype=np.uint32)},
                          np.asarray(host_time, dtype=float))


def test_gaps_duplicates_and_wrap(dictionary):
    st = LinkStatistics()
    top = 2**32 - 3
    st.update(block(dictionary, [top, top + 1, top + 2], [1, 2, 3], [0, 0, 0]))
    st.update(block(dictionary, [1, 2, 2, 6], [5, 6, 6, 10], [1, 1, 1, 1]))   # 0 lost at the wrap
    snap = st.snapshot()
    ps = snap.packets["HIGH_RATE"]
    assert ps.frames == 7
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
