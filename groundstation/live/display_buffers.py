"""Decoded telemetry kept for display: per-packet ring buffers of the last N seconds.

`TelemetryStore` is a subscriber (live link or replay): the receiver thread appends
whole blocks under a lock (a few numpy slice copies, no per-sample Python); the GUI
takes snapshots of the channels it shows on its own timer.  Sequence gaps are kept as
marks so a chart can show them instead of drawing a line across lost data.

For the strip charts each ring also keeps, per channel shown, a min/max pyramid
(`MinMaxPyramid`): the min and max of aligned blocks of 16, 256 and 4096 samples,
extended with the samples that arrived since the last look when many bins are asked for
(a scrolling frame's few new bins come straight from the samples).  `PacketRing.envelope`
answers "min and max per bin of `per` samples over this window" from it, exactly, in a
time that depends on the number of bins, not on the number of samples in the window.
Bins are aligned to the sample count since the ring was cleared (bin k holds samples
k*per .. k*per+per-1), so a scrolling chart's bins do not shift under the data.  A
complete bin never changes (its samples are written once), so the ring also remembers
the complete bins it answered last per channel (`_BinCache`): a scrolling chart's next
frame reduces only the bins completed since, and the two bins cut by the window's edges.

No Qt here: the GUI and tests use the same store.
"""

from __future__ import annotations

import math
import threading
from dataclasses import dataclass
from typing import Callable

import numpy as np

from ..codec import TelemetryBlock
from ..core.dictionary import Dictionary, PacketDef
from ..codec.sequence import SequenceTracker
from ..codec.ticks import TickUnwrapper

#: device time going back by more than this between frames is a reboot, not reordering
RESTART_BACKSTEP_S = 1.0


@dataclass
class Snapshot:
    """Copies of the newest samples of some channels (oldest first)."""

    device_time: np.ndarray        # s since the device booted
    host_time: np.ndarray          # s since the epoch
    values: dict[str, np.ndarray]
    gap_device_times: np.ndarray   # device time of the first frame after each gap
    gap_sizes: np.ndarray          # frames missing in each gap
    total_frames: int
    first_index: int = 0           # ring index of the first sample (counted since clear)


class PacketRing:
    """Ring buffer of one packet's numeric channels."""

    def __init__(self, packet: PacketDef, capacity: int, tick_rate_hz: float):
        self.packet = packet
        self.capacity = capacity
        self.rate = tick_rate_hz
        self.channels = [c for c in packet.channel_names() if not self._is_text(packet, c)]
        self._data = {c: np.full(capacity, np.nan) for c in self.channels}
        self._device_time = np.full(capacity, np.nan)
        self._host_time = np.full(capacity, np.nan)
        self._head = 0                 # next write position (= _written % capacity)
        self._count = 0                # valid samples (<= capacity)
        self._written = 0              # samples written since clear: the next sample's index
        self._pyramids: dict[str, MinMaxPyramid] = {}   # channels a chart looked at
        self._bin_cache: dict[str, _BinCache] = {}      # their last complete bins
        #: counts appends and clears: a chart with nothing new to show need not redraw
        self.changes = 0
        self.total_frames = 0
        self._sequence = SequenceTracker()
        self._unwrap = TickUnwrapper()
        self._gaps: list[tuple[float, int]] = []
        self._lock = threading.Lock()
        self.restarts = 0              # times the device clock went back (reboots)
        #: called (receiver thread) with (packet, old newest time s, new first time s)
        self.on_restart: Callable[[str, float, float], None] | None = None

    @staticmethod
    def _is_text(packet: PacketDef, name: str) -> bool:
        item = packet.item_by_name.get(name)
        return item is not None and item.is_variable

    def append(self, block: TelemetryBlock) -> None:
        n = len(block)
        if not n:
            return
        ticks = block.columns["tick"]
        dev = self._unwrap.unwrap(ticks) / self.rate
        with self._lock:
            newest = float(self._device_time[(self._head - 1) % self.capacity]) if self._count else None
        before = np.concatenate(([newest if newest is not None else dev[0]], dev[:-1]))
        restart = np.flatnonzero(dev < before - RESTART_BACKSTEP_S)
        if not len(restart):
            self._append_range(block, 0, n, dev)
            return
        # The device's clock went back: it rebooted (or a fresh simulator answered a
        # reconnect).  Its old and new times would interleave on the time axis, so the
        # old history is dropped from the display; the recording keeps all of it.
        r = int(restart[0])
        if r:
            self._append_range(block, 0, r, dev[:r])
        with self._lock:
            old_end = float(self._device_time[(self._head - 1) % self.capacity]) if self._count else 0.0
        self.clear()
        self.restarts += 1
        dev = self._unwrap.unwrap(ticks[r:]) / self.rate
        self._append_range(block, r, n, dev)
        if self.on_restart is not None:
            self.on_restart(self.packet.name, old_end, float(dev[0]))

    def _append_range(self, block: TelemetryBlock, a: int, b: int, dev: np.ndarray) -> None:
        """Store block rows a..b-1 (dev: their device times)."""
        n = b - a
        first = self._sequence.fed
        gaps = self._sequence.feed(block.columns["sequence"][a:b])
        host_all = np.asarray(block.host_time, dtype=np.float64)
        host = np.broadcast_to(host_all, (len(block),))[a:b] if host_all.ndim == 0 else host_all[a:b]
        columns = {c: block.columns[c][a:b] for c in self.channels}
        with self._lock:
            self.changes += 1
            self.total_frames += n
            for at, missing in zip(gaps.gap_index.tolist(), gaps.missing.tolist()):
                self._gaps.append((float(dev[max(0, at - first)]), int(missing)))
            if len(self._gaps) > 10000:
                del self._gaps[:-10000]
            # Sample number g (counted since clear) lives at g % capacity, always, so
            # the min/max pyramids can address samples by their number.
            skip = max(0, n - self.capacity)           # keep only the newest capacity
            at = (self._written + skip) % self.capacity
            first = min(n - skip, self.capacity - at)
            self._write(at, slice(skip, skip + first), columns, dev, host)
            if skip + first < n:
                self._write(0, slice(skip + first, n), columns, dev, host)
            self._written += n
            self._head = self._written % self.capacity
            self._count = min(self.capacity, self._count + n)

    def _write(self, at: int, src: slice, columns: dict[str, np.ndarray], dev, host) -> None:
        k = src.stop - src.start
        self._device_time[at:at + k] = dev[src]
        self._host_time[at:at + k] = host[src]
        for c in self.channels:
            self._data[c][at:at + k] = columns[c][src]

    def snapshot(self, channels: list[str], seconds: float | None = None) -> Snapshot:
        """The newest `seconds` of device time (all that is kept if None).

        Copies only the samples asked for: the ring holds ten minutes, a chart shows
        one, and copying the whole ring on every redraw made the GUI slower the longer
        it ran (measured with benchmarks/bench_gui.py)."""
        with self._lock:
            parts = self._segments()
            start = 0
            if seconds is not None and self._count:
                newest = self._device_time[(self._head - 1) % self.capacity]
                start = self._logical_search(parts, newest - seconds)
            pieces = self._from(parts, start)
            dev = self._gather(self._device_time, pieces)
            host = self._gather(self._host_time, pieces)
            values = {c: self._gather(self._data[c], pieces) for c in channels if c in self._data}
            gaps = np.array(self._gaps, dtype=np.float64).reshape(-1, 2)
            total = self.total_frames
            first_index = self._written - self._count + start
        if len(dev):
            keep = gaps[:, 0] >= dev[0]
            gaps = gaps[keep]
        return Snapshot(dev, host, values, gaps[:, 0], gaps[:, 1].astype(np.int64), total,
                        first_index)

    def _segments(self) -> list[slice]:
        """Physical slices of the ring in time order (oldest first)."""
        if self._count < self.capacity:
            return [slice(0, self._count)]
        return [slice(self._head, self.capacity), slice(0, self._head)]

    def _logical_search(self, parts: list[slice], t: float, side: str = "left") -> int:
        """Logical index of the first sample with device time >= t (> t: side "right")."""
        offset = 0
        for sl in parts:
            seg = self._device_time[sl]
            if len(seg) and (seg[-1] >= t if side == "left" else seg[-1] > t):
                return offset + int(np.searchsorted(seg, t, side=side))
            offset += len(seg)
        return offset

    @staticmethod
    def _from(parts: list[slice], start: int) -> list[slice]:
        out = []
        for sl in parts:
            n = sl.stop - sl.start
            if start < n:
                out.append(slice(sl.start + start, sl.stop))
                start = 0
            else:
                start -= n
        return out

    @staticmethod
    def _gather(arr: np.ndarray, pieces: list[slice]) -> np.ndarray:
        if len(pieces) == 1:
            return arr[pieces[0]].copy()
        if not pieces:
            return arr[:0].copy()
        return np.concatenate([arr[sl] for sl in pieces])

    def clear(self) -> None:
        with self._lock:
            self._head = self._count = self._written = 0
            self.changes += 1
            self._pyramids.clear()
            self._bin_cache.clear()
            self.total_frames = 0
            self._sequence = SequenceTracker()
            self._unwrap = TickUnwrapper()
            self._gaps.clear()

    # ------------------------------------------------------------ for the strip charts
    def newest_time(self) -> float | None:
        """Device time of the newest sample (None when empty)."""
        with self._lock:
            return float(self._device_time[(self._head - 1) % self.capacity]) if self._count else None

    def host_offset(self, seconds: float) -> float:
        """Smallest host time − device time over the newest `seconds` (0 without host times)."""
        with self._lock:
            if not self._count:
                return 0.0
            parts = self._segments()
            newest = self._device_time[(self._head - 1) % self.capacity]
            pieces = self._from(parts, self._logical_search(parts, newest - seconds))
            d = np.concatenate([self._host_time[sl] - self._device_time[sl] for sl in pieces])
        return float(np.nanmin(d)) if np.isfinite(d).any() else 0.0

    def envelope(self, channels: list[str], t0: float, t1: float, bins: int,
                 before: bool = True) -> "Envelope | None":
        """What a chart draws of `channels` between device times t0 and t1, about two
        points per bin: the samples themselves while they are at most 2*bins (plus the
        one before t0 unless `before` is false, and the one after t1, so the line reaches
        the edges of a zoomed view), else the min
        and max of each aligned bin of `per` samples (a power of two), exact, at the
        device time of the bin's first sample in the span.  None when the span is empty."""
        with self._lock:
            if not self._count:
                return None
            parts = self._segments()
            i0 = max(self._logical_search(parts, t0) - int(before), 0)
            i1 = min(self._logical_search(parts, t1, side="right") + 1, self._count)
            if i1 <= i0:
                return None
            oldest = self._written - self._count
            ga, gb = oldest + i0, oldest + i1
            n = gb - ga
            names = [c for c in channels if c in self._data]
            gaps = np.array(self._gaps, dtype=np.float64).reshape(-1, 2)
            first_t = self._device_time[ga % self.capacity]
            last_t = self._device_time[(gb - 1) % self.capacity]
            if bins <= 0 or n <= 2 * bins:
                x = self._take(self._device_time, ga, gb)
                values = {c: self._take(self._data[c], ga, gb) for c in names}
                per = 1
            else:
                per = bin_factor(n, bins)
                ka, kb = ga // per, (gb - 1) // per          # first and last bin (inclusive)
                starts = np.maximum(np.arange(ka, kb + 1, dtype=np.int64) * per, ga)
                x = self._device_time[starts % self.capacity]
                values = {c: self._bins(c, ga, gb, per) for c in names}
        keep = (gaps[:, 0] >= first_t) & (gaps[:, 0] <= last_t)
        gap_t, gap_n = gaps[keep, 0], gaps[keep, 1].astype(np.int64)
        if per == 1:
            at = np.searchsorted(x, gap_t, side="left")
            breaks = at[(at > 0) & (at < len(x))]
        else:
            b = np.searchsorted(x, gap_t, side="right") - 1          # the bin holding the gap
            breaks = 2 * np.unique(b[b >= 1])
            x = np.repeat(x, 2)
        return Envelope(x, values, per, gap_t, gap_n, breaks, ga, n)

    def _take(self, arr: np.ndarray, ga: int, gb: int) -> np.ndarray:
        """Copy of samples ga..gb-1 (numbers since clear; lock held)."""
        a, n = ga % self.capacity, gb - ga
        if a + n <= self.capacity:
            return arr[a:a + n].copy()
        return np.concatenate((arr[a:], arr[:a + n - self.capacity]))

    def _bins(self, channel: str, ga: int, gb: int, per: int) -> np.ndarray:
        """Min, max interleaved for each bin of `per` samples meeting ga..gb-1 (lock held)."""
        data = self._data[channel]
        ka, kb = ga // per, (gb - 1) // per
        fa, fb = -(-ga // per), gb // per                  # whole bins: fa .. fb-1
        out = np.empty(2 * (kb - ka + 1))
        mn, mx = out[0::2], out[1::2]
        if fb > fa:
            cache = self._bin_cache.get(channel)
            if cache is None or cache.per != per:
                cache = self._bin_cache[channel] = _BinCache(per)
            mn[fa - ka:fb - ka], mx[fa - ka:fb - ka] = cache.bins(
                fa, fb, lambda k0, k1: self._whole_bins(channel, k0, k1, per))
        if fa > ka:                                         # the first bin, cut by ga
            part = self._take(data, ga, min(gb, (ka + 1) * per))
            mn[0], mx[0] = part.min(), part.max()
        if kb >= fb and not (kb == ka and fa > ka):         # the last bin, cut by gb
            part = self._take(data, kb * per, gb)
            mn[-1], mx[-1] = part.min(), part.max()
        return out

    def _whole_bins(self, channel: str, k0: int, k1: int, per: int) -> tuple[np.ndarray, np.ndarray]:
        """Min and max of complete bins k0 .. k1-1 of `per` samples (lock held).  A few
        bins (a scrolling frame's newly completed ones) straight from the samples; many
        (a new window, a new width) from the pyramid, which is fed only then: feeding it
        the samples of every frame cost more than reducing the bins they complete."""
        block = max((b for b in PYRAMID_BLOCKS if b <= per), default=0)
        if block and (k1 - k0) * per > DIRECT_REDUCE_MAX:
            return self._pyramid(channel).bins(PYRAMID_BLOCKS.index(block), k0 * per, k1 * per, per)
        whole = self._take(self._data[channel], k0 * per, k1 * per).reshape(-1, per)
        return whole.min(axis=1), whole.max(axis=1)

    def _pyramid(self, channel: str) -> "MinMaxPyramid":
        """The channel's pyramid, extended with the samples since the last look (lock held)."""
        oldest = self._written - self._count
        pyr = self._pyramids.get(channel)
        if pyr is None or not oldest <= pyr.fed <= self._written:
            pyr = self._pyramids[channel] = MinMaxPyramid(self.capacity, oldest)
        if pyr.fed < self._written:
            pyr.feed(self._take(self._data[channel], pyr.fed, self._written), pyr.fed)
        return pyr

    def sample_at(self, channel: str, t: float) -> tuple[float, float] | None:
        """(device time, value) of the newest sample at or before device time t."""
        with self._lock:
            parts = self._segments()
            i = self._logical_search(parts, t, side="right") - 1
            if i < 0 or not self._count:
                return None
            at = (self._written - self._count + i) % self.capacity
            return float(self._device_time[at]), float(self._data[channel][at])

    def latest(self, channel: str) -> float | None:
        with self._lock:
            if not self._count:
                return None
            return float(self._data[channel][(self._head - 1) % self.capacity])


@dataclass
class Envelope:
    """What `PacketRing.envelope` returns for one packet's channels over one span."""

    x: np.ndarray                  # device time of each point (s)
    values: dict[str, np.ndarray]  # per channel: the samples, or min, max per bin
    per: int                       # samples per bin (1: the samples themselves)
    gap_times: np.ndarray          # device time of the first sample after each gap in the span
    gap_sizes: np.ndarray          # frames missing in each gap
    breaks: np.ndarray             # point indices before which a gap breaks the line
    first_index: int               # number (since clear) of the span's first sample
    samples: int                   # samples in the span


class _BinCache:
    """The min and max of complete bins ka .. ka+len-1 of `per` samples of one channel,
    as last answered: complete bins never change, so only the others are reduced again."""

    def __init__(self, per: int):
        self.per = per
        self.ka = 0
        self.mn = self.mx = np.empty(0)

    def bins(self, fa: int, fb: int, reduce) -> tuple[np.ndarray, np.ndarray]:
        """Bins fa .. fb-1; `reduce(k0, k1)` gives (min, max) of bins k0 .. k1-1."""
        a, b = max(fa, self.ka), min(fb, self.ka + len(self.mn))
        if a >= b:                                   # nothing to reuse
            mn, mx = reduce(fa, fb)
        else:
            parts_mn, parts_mx = [], []
            if fa < a:
                lo = reduce(fa, a)
                parts_mn.append(lo[0])
                parts_mx.append(lo[1])
            parts_mn.append(self.mn[a - self.ka:b - self.ka])
            parts_mx.append(self.mx[a - self.ka:b - self.ka])
            if b < fb:
                hi = reduce(b, fb)
                parts_mn.append(hi[0])
                parts_mx.append(hi[1])
            mn, mx = np.concatenate(parts_mn), np.concatenate(parts_mx)
        self.ka, self.mn, self.mx = fa, mn, mx
        return mn, mx


#: block sizes (samples) of a pyramid's levels; each block is 16 blocks of the level below
PYRAMID_BLOCKS = (16, 256, 4096)
#: complete bins of at most this many samples in all are reduced from the samples, not
#: from the pyramid (a scrolling frame completes one or two)
DIRECT_REDUCE_MAX = 4096


class _MinMaxLevel:
    """Min and max of aligned blocks of 16 children (samples, or blocks of the level
    below), in a ring addressed by block number (block k: children 16k .. 16k+15)."""

    FACTOR = 16

    def __init__(self, size: int):
        self.size = size
        self.mn = np.full(size, np.nan)
        self.mx = np.full(size, np.nan)
        self._p0 = 0                              # number of the first pending child
        self._pmn = self._pmx = np.empty(0)       # children of the block not yet complete

    def reset(self, child: int) -> None:
        self._p0 = child
        self._pmn = self._pmx = np.empty(0)

    def push(self, mn: np.ndarray, mx: np.ndarray, c0: int):
        """Children c0, c0+1, ... (they continue the pending ones).  Returns the blocks
        they complete as (min, max, number of the first block), or None.  A block whose
        first children came before the level was reset covers only those after it."""
        if len(self._pmn):
            mn, mx, c0 = np.concatenate((self._pmn, mn)), np.concatenate((self._pmx, mx)), self._p0
        f = self.FACTOR
        done = (c0 + len(mn)) // f * f            # children before this are in complete blocks
        if done <= c0:
            self._p0, self._pmn, self._pmx = c0, mn, mx
            return None
        first = c0 // f
        starts = np.concatenate(([0], np.arange((first + 1) * f, done, f) - c0))
        k = done - c0
        bmn = np.minimum.reduceat(mn[:k], starts)          # NaN propagates, as in np.min
        bmx = np.maximum.reduceat(mx[:k], starts)
        at = np.arange(first, first + len(starts)) % self.size
        self.mn[at], self.mx[at] = bmn, bmx
        self._p0, self._pmn, self._pmx = done, mn[k:].copy(), mx[k:].copy()
        return bmn, bmx, first


class MinMaxPyramid:
    """Min and max of one channel over aligned blocks of each size in PYRAMID_BLOCKS,
    fed incrementally with the samples as they arrive (numbered since the ring's clear).
    Holds at least `capacity` samples' worth of blocks at each level."""

    def __init__(self, capacity: int, start: int):
        self.levels = [_MinMaxLevel(capacity // b + 3) for b in PYRAMID_BLOCKS]
        self.fed = start                          # number of the next sample to feed
        for level, block in zip(self.levels, PYRAMID_BLOCKS):
            level.reset(start // (block // _MinMaxLevel.FACTOR))

    def feed(self, y: np.ndarray, first: int) -> None:
        if first != self.fed:
            raise ValueError(f"pyramid fed sample {first}, expected {self.fed}")
        self.fed = first + len(y)
        done = (y, y, first)
        for level in self.levels:
            done = level.push(*done)
            if done is None:
                break

    def bins(self, level: int, ga: int, gb: int, per: int) -> tuple[np.ndarray, np.ndarray]:
        """Min and max of each bin of `per` samples (a multiple of the level's block)
        over ga..gb-1, which must be whole bins of samples already fed."""
        block = PYRAMID_BLOCKS[level]
        lv = self.levels[level]
        at = np.arange(ga // block, gb // block) % lv.size
        r = per // block
        return lv.mn[at].reshape(-1, r).min(axis=1), lv.mx[at].reshape(-1, r).max(axis=1)


class TelemetryStore:
    """Ring buffers for every device-to-host packet; call it with each block."""

    def __init__(self, dictionary: Dictionary, seconds: float = 600.0):
        self.dictionary = dictionary
        self.rings: dict[str, PacketRing] = {}
        for p in dictionary.packets:
            if p.direction != "device_to_host" or p.name == "RESPONSE":
                continue
            rate = p.rate_hz or 10.0
            cap = max(1024, int(seconds * rate * 1.05))
            ring = PacketRing(p, cap, dictionary.control_rate_hz)
            ring.on_restart = self._restarted
            self.rings[p.name] = ring
        #: called from the receiver thread when a packet's device time goes back (reboot)
        self.on_restart: Callable[[str, float, float], None] | None = None

    def _restarted(self, packet: str, old_end_s: float, new_start_s: float) -> None:
        if self.on_restart is not None:
            self.on_restart(packet, old_end_s, new_start_s)

    def __call__(self, block: TelemetryBlock) -> None:
        ring = self.rings.get(block.name)
        if ring is not None:
            ring.append(block)

    def ring(self, packet: str) -> PacketRing:
        return self.rings[packet]

    def clear(self) -> None:
        for r in self.rings.values():
            r.clear()


def peak_decimate(x: np.ndarray, y: np.ndarray, bins: int) -> tuple[np.ndarray, np.ndarray, bool]:
    """Min/max per bin, so a one-sample spike survives any zoom level.

    Returns (x, y, decimated): with more samples than 2*bins, each bin of consecutive
    samples becomes two points at the bin's first x, its min then its max.  NaN marks a
    gap and survives: a bin holding a NaN yields NaN, so the chart does not bridge it."""
    n = len(y)
    if bins <= 0 or n <= 2 * bins:
        return x, y, False
    per = int(np.ceil(n / bins))
    m = n // per
    yb = y[:m * per].reshape(m, per)
    # Plain min/max, not nanmin: NaN propagates, which is exactly the gap rule above,
    # and it is four times faster than masking (this runs for every curve every frame).
    xs = np.repeat(x[:m * per:per], 2)
    ys = np.empty(2 * m)
    np.min(yb, axis=1, out=ys[0::2])
    np.max(yb, axis=1, out=ys[1::2])
    if m * per < n:                                 # the tail bin, exactly
        tail = y[m * per:]
        xs = np.concatenate([xs, x[m * per:m * per + 1].repeat(2)])
        ys = np.concatenate([ys, [tail.min(), tail.max()]])
    return xs, ys, True


def with_gap_breaks(t: np.ndarray, y: np.ndarray, gap_times: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Insert a NaN before every sample that follows a sequence gap, so a line plot
    (connect='finite') shows a break where frames were lost."""
    if not len(gap_times) or not len(t):
        return t, y
    idx = np.searchsorted(t, gap_times, side="left")
    idx = idx[(idx > 0) & (idx < len(t))]
    if not len(idx):
        return t, y
    return np.insert(t, idx, t[idx]), np.insert(y.astype(np.float64), idx, np.nan)


def aligned_envelope(x: np.ndarray, y: np.ndarray, first_index: int,
                     per: int) -> tuple[np.ndarray, np.ndarray]:
    """Min and max of y per bin of `per` samples aligned as in `PacketRing.envelope`
    (sample i of y is number first_index + i), each bin as two points at the x of its
    first sample in y.  A plain reduction over all of y (for frozen data)."""
    if not len(y):
        return x[:0], y[:0]
    cut = np.arange(-(-first_index // per) * per, first_index + len(y), per) - first_index
    starts = np.unique(np.concatenate(([0], cut[cut > 0])))
    ys = np.empty(2 * len(starts))
    ys[0::2] = np.minimum.reduceat(y, starts)
    ys[1::2] = np.maximum.reduceat(y, starts)
    return np.repeat(x[starts], 2), ys


def bin_factor(samples: int, bins: int) -> int:
    """Samples per bin for `bins` bins: 1 up to 2*bins samples, else the smallest power
    of two giving at most `bins` whole bins."""
    if bins <= 0 or samples <= 2 * bins:
        return 1
    return 1 << int(math.ceil(math.log2(samples / bins)))


def insert_breaks(x: np.ndarray, y: np.ndarray, breaks: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """A NaN point before each index in `breaks` (at the x of the point after it), so a
    line drawn with connect='finite' breaks there."""
    if not len(breaks):
        return x, y
    return np.insert(x, breaks, x[breaks]), np.insert(y.astype(np.float64), breaks, np.nan)
