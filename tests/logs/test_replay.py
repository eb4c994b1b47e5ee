"""Replay of a recorded log: the same blocks and gaps as live, pause/step/seek, pacing,
speed limits and clear errors.  One 3 s log with sequence gaps serves every test."""

from __future__ import annotations

import math
import threading
import time

import h5py
import numpy as np
import pytest

from groundstation.codec import StreamDeframer
from groundstation.core.errors import GroundStationError
from groundstation.link.stats import LinkStatistics
from groundstation.logs import LogFile, Recorder
from groundstation.logs.replay import ReplaySource
from groundstation.logs.blocks import ReplayError, iter_blocks
from groundstation.sim import SimulatedDevice

from conftest import wait_for

HOST_T0 = 1_700_000_000.0
SECONDS = 3.0
BATCH = 120                      # ticks per simulator batch: 0.1 s, one arrival time each


def _session(dictionary, seconds=SECONDS):
    """Blocks as a live link would deliver them, with frames lost on the way: a few
    HIGH_RATE frames cut out of some batches, one batch lost whole, one batch with a
    damaged stretch of bytes (the deframer drops the frames it cannot check)."""
    dev = SimulatedDevice(dictionary, pacing="manual", seed=1)
    dfr = StreamDeframer(dev.codec)
    width = dictionary.packet("HIGH_RATE").fixed_payload_size + 18
    blocks = []
    count = [0]

    def consume(data: bytes) -> None:
        count[0] += 1
        k = count[0]
        if k == 12:
            return                                        # a whole batch lost
        if k in (5, 22):
            data = data[:10 * width] + data[14 * width:]  # four HIGH_RATE frames lost
        if k == 27:
            data = data[:50 * width + 7] + data[51 * width + 7:]   # a damaged stretch
        blocks.extend(dfr.feed(data, HOST_T0 + 0.1 * k))

    dev.run_fast(seconds, consume, batch=BATCH)
    return blocks


@pytest.fixture(scope="module")
def recorded(dictionary, tmp_path_factory):
    blocks = _session(dictionary)
    rec = Recorder(dictionary, tmp_path_factory.mktemp("replay"), test_name="replay")
    path = rec.start()
    for b in blocks:
        rec(b)
    status = rec.stop()
    assert status.state == "stopped", status.error
    with h5py.File(path, "r") as f:
        hr_dev = f["telemetry/HIGH_RATE/device_time"][:]
    return path, blocks, hr_dev


def _flat(blocks):
    """(packet, sequence) of every frame, in delivery order."""
    return [(b.name, int(s)) for b in blocks for s in b["sequence"]]


def _by_packet(blocks):
    out = {}
    for b in blocks:
        out.setdefault(b.name, []).append(b)
    return out


def _assert_same_frames(got, expected):
    g, e = _by_packet(got), _by_packet(expected)
    assert sorted(g) == sorted(e)
    for name in e:
        gb, eb = g[name], e[name]
        assert set(gb[0].columns) == set(eb[0].columns), name
        for col in eb[0].columns:
            a = np.concatenate([b.columns[col] for b in gb])
            x = np.concatenate([b.columns[col] for b in eb])
            assert a.dtype == x.dtype, (name, col)
            if a.dtype == object:
                assert a.tolist() == x.tolist(), (name, col)
            else:
                np.testing.assert_array_equal(a, x, err_msg=f"{name}.{col}")
        np.testing.assert_array_equal(np.concatenate([b.host_time for b in gb]),
                                      np.concatenate([b.host_time for b in eb]))
        if eb[0].raw is not None:
            assert b"".join(b.raw.tobytes() for b in gb) == b"".join(b.raw.tobytes() for b in eb)
            assert gb[0].raw.dtype == eb[0].raw.dtype
        else:
            assert [f for b in gb for f in b.frames] == [f for b in eb for f in b.frames]


class _Collector:
    def __init__(self, source=None):
        self.blocks = []
        self.states = []
        self.lock = threading.Lock()
        if source is not None:
            source.subscribe(self)
            source.add_link_listener(lambda s, m: self.states.append((s, m)))

    def __call__(self, block):
        with self.lock:
            self.blocks.append(block)

    def frames(self, packet="HIGH_RATE"):
        with self.lock:
            return sum(len(b) for b in self.blocks if b.name == packet)


# ---------------------------------------------------------------------- equality and gaps
def test_replay_at_max_speed_gives_the_recorded_blocks_and_gaps(recorded):
    path, original, _ = recorded
    with ReplaySource(path, speed=None) as src:
        got = _Collector(src)
        assert src.link_state == "up" and not src.finished
        src.play()
        assert src.wait_finished(10)
        assert src.wait_idle(5)
        snap = src.stats.snapshot()
    assert src.link_state == "closed"
    assert got.states == [("finished", ""), ("closed", "")]

    _assert_same_frames(got.blocks, original)
    # merged in arrival order, the same order the link handed them out
    assert _flat(got.blocks) == _flat(original)
    hosts = np.concatenate([b.host_time for b in got.blocks])
    assert np.all(np.diff(hosts) >= 0)

    live = LinkStatistics()
    for b in original:
        live.update(b)
    expected = live.snapshot()
    assert expected.dropped >= 4 + 4 + 120 and expected.packets["HOUSEKEEPING"].dropped >= 1
    for name, ps in expected.packets.items():
        r = snap.packets[name]
        assert (r.frames, r.dropped, r.duplicates, r.last_sequence) == \
            (ps.frames, ps.dropped, ps.duplicates, ps.last_sequence), name
    assert snap.gap_events == expected.gap_events


def test_iter_blocks_whole_log_and_device_time_range(recorded, dictionary):
    path, original, hr_dev = recorded
    _assert_same_frames(list(iter_blocks(path)), original)
    _assert_same_frames(list(iter_blocks(path, dictionary=dictionary)), original)

    part = list(iter_blocks(path, start=1.0, stop=2.0))
    hr = np.concatenate([b["sequence"] for b in part if b.name == "HIGH_RATE"])
    first, stop = int(np.searchsorted(hr_dev, 1.0)), int(np.searchsorted(hr_dev, 2.0))
    all_hr = np.concatenate([b["sequence"] for b in original if b.name == "HIGH_RATE"])
    np.testing.assert_array_equal(hr, all_hr[first:stop])
    assert {b.name for b in part} >= {"HIGH_RATE", "HOUSEKEEPING"}

    assert list(iter_blocks(path, start=hr_dev[-1] + 1.0)) == []


# ---------------------------------------------------------------------- controls
def test_step_pause_and_seek(recorded):
    path, original, hr_dev = recorded
    flat = _flat(original)
    hr_index = [i for i, (name, _) in enumerate(flat) if name == "HIGH_RATE"]
    with ReplaySource(path, speed=1.0) as src:
        got = _Collector(src)
        assert src.position is None
        src.step(5)
        assert src.wait_idle(5)
        assert _flat(got.blocks) == flat[:hr_index[4] + 1]
        assert src.position == pytest.approx(hr_dev[4])

        # the 120 frames of the first batch, then the step that crosses into the second
        # one also brings the housekeeping frame that arrived before it
        src.step(BATCH - 5)
        src.step(1)
        assert src.wait_idle(5)
        assert _flat(got.blocks) == flat[:hr_index[BATCH] + 1]
        between = flat[hr_index[BATCH - 1] + 1:hr_index[BATCH]]
        assert ("HOUSEKEEPING", 0) in between

        # seek: lands on the first HIGH_RATE frame at or after the time
        for target in (1.5, 0.7501, hr_dev[0]):
            src.seek(target)
            src.step(1)
            assert src.wait_idle(5)
            i = int(np.searchsorted(hr_dev, target))
            last_hr = [b for b in got.blocks if b.name == "HIGH_RATE"][-1]
            assert len(last_hr) == 1
            assert int(last_hr["sequence"][0]) == flat[hr_index[i]][1]
            assert src.position == pytest.approx(hr_dev[i])
            assert src.stats.snapshot().packets["HIGH_RATE"].frames == 1   # fresh after a seek

        src.seek_fraction(0.5)
        src.step(2)
        assert src.wait_idle(5)
        i = int(np.searchsorted(hr_dev, hr_dev[0] + 0.5 * (hr_dev[-1] - hr_dev[0])))
        assert src.position == pytest.approx(hr_dev[i + 1])

        # play, then pause: after the pause exactly one step's frame follows
        src.play()
        wait_for(lambda: src.position > hr_dev[i + 1] + 0.02, timeout=5)
        src.pause()
        assert src.wait_idle(5)
        n = got.frames()
        src.step(1)
        assert src.wait_idle(5)
        assert got.frames() == n + 1
        assert not src.finished

        with pytest.raises(ValueError):
            src.step(0)
        with pytest.raises(ValueError):
            src.seek_fraction(1.5)


def test_subscriber_may_pause_from_the_replay_thread(recorded):
    path, _, _ = recorded
    with ReplaySource(path, speed=None) as src:
        got = _Collector(src)
        src.subscribe(lambda block: src.pause())
        src.play()
        assert src.wait_idle(5)
        assert len(got.blocks) == 1 and not src.finished      # stopped after that block
        src.seek(1e9)                     # past the end: finished at once
        assert src.wait_idle(5) and src.finished
        assert ("finished", "") in got.states


# ---------------------------------------------------------------------- pacing
def test_ten_times_speed_plays_three_seconds_in_about_a_third(recorded):
    path, original, hr_dev = recorded
    with ReplaySource(path, speed=10) as src:
        got = _Collector(src)
        t0 = time.monotonic()
        src.play()
        assert src.wait_finished(10)
        elapsed = time.monotonic() - t0
    span = hr_dev[-1] - hr_dev[0]
    assert span / 10 - 0.02 <= elapsed < 2.0
    assert got.frames() == sum(len(b) for b in original if b.name == "HIGH_RATE")
    # paced deliveries come in blocks of at most 1/60 s of device time
    assert max(len(b) for b in got.blocks if b.name == "HIGH_RATE") <= 21


def test_tenth_speed_delivers_little_and_can_switch_to_max(recorded):
    path, original, hr_dev = recorded
    total = sum(len(b) for b in original if b.name == "HIGH_RATE")
    with ReplaySource(path, speed=0.1) as src:
        got = _Collector(src)
        t0 = time.monotonic()
        src.play()
        assert not src.wait_finished(0.3)
        elapsed = time.monotonic() - t0
        assert (src.position or hr_dev[0]) - hr_dev[0] <= 0.1 * elapsed + 0.05
        assert got.frames() < total / 10
        src.speed = "max"
        assert src.speed is None
        assert src.wait_finished(10)
        assert got.frames() == total


@pytest.mark.parametrize("bad", [0.05, 0, -1, 50.5, math.nan, math.inf, "fast", True])
def test_speed_out_of_range_raises(recorded, bad):
    path, _, _ = recorded
    with pytest.raises(ValueError):
        ReplaySource(path, speed=bad)
    with ReplaySource(path) as src:
        with pytest.raises(ValueError):
            src.speed = bad
        assert src.speed == 1.0
        for good in (0.1, 50, 2.5):
            src.speed = good
            assert src.speed == good
        src.speed = None
        assert src.speed is None


# ---------------------------------------------------------------------- a log still growing
def test_replay_follows_a_log_that_is_still_written(dictionary, tmp_path):
    blocks = _session(dictionary, seconds=1.0)
    half = len(blocks) // 2
    lf = LogFile(tmp_path / "growing.h5", dictionary)
    try:
        lf.append(blocks[:half])
        lf.flush()
        with ReplaySource(tmp_path / "growing.h5", speed=None) as src:
            got = _Collector(src)
            src.play()
            assert src.wait_finished(5)
            assert _flat(got.blocks) == _flat(blocks[:half])
            lf.append(blocks[half:])
            lf.flush()
            src.play()                        # at the end: looks again and plays on
            wait_for(lambda: len(_flat(got.blocks)) == len(_flat(blocks)), timeout=5)
            assert src.wait_finished(5)
            assert _flat(got.blocks) == _flat(blocks)
            hr_frames = sum(len(b) for b in blocks if b.name == "HIGH_RATE")
            assert src.duration == pytest.approx((hr_frames - 1) / 1200, abs=0.1)
            assert [s for s, _ in got.states] == ["finished", "up", "finished"]
    finally:
        lf.close()


# ---------------------------------------------------------------------- errors
def test_missing_file_and_non_logs_give_clear_errors(tmp_path):
    missing = tmp_path / "nope.h5"
    with pytest.raises(ReplayError, match="no such log file") as err:
        ReplaySource(missing)
    assert isinstance(err.value, GroundStationError) and str(missing) in str(err.value)
    with pytest.raises(ReplayError, match="no such log file"):
        next(iter_blocks(missing))

    with pytest.raises(ReplayError, match="folder"):
        ReplaySource(tmp_path)

    text = tmp_path / "notes.h5"
    text.write_text("not HDF5 at all")
    with pytest.raises(ReplayError, match="not an HDF5 file"):
        ReplaySource(text)

    other = tmp_path / "other.h5"
    with h5py.File(other, "w") as f:
        f["x"] = np.arange(3)
    with pytest.raises(ReplayError, match="not a ground-station log"):
        ReplaySource(other)
