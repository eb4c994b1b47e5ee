"""Decoded telemetry kept for display: per-packet ring buffers of the last N seconds.

`TelemetryStore` is a subscriber (live link or replay): the receiver thread appends
whole blocks under a lock (a few numpy slice copies, no per-sample Python); the GUI
takes snapshots of the channels it shows on its own timer.  Sequence gaps are kept as
marks so a chart can show them instead of drawing a line across lost data.

No Qt here: the GUI and tests use the same store.
"""

from __future__ import annotations

import threading
from dataclasses import dataclass
from typing import Callable

import numpy as np

from .codec import TelemetryBlock
from .dictionary import Dictionary, PacketDef
from .codec.sequence import SequenceTracker
from .link.stats import TickUnwrapper

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
        self._head = 0                 # next write position
        self._count = 0                # valid samples (<= capacity)
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
            self.total_frames += n
            for at, missing in zip(gaps.gap_index.tolist(), gaps.missing.tolist()):
                self._gaps.append((float(dev[max(0, at - first)]), int(missing)))
            if len(self._gaps) > 10000:
                del self._gaps[:-10000]
            if n >= self.capacity:                     # keep only the newest capacity
                sl = slice(n - self.capacity, n)
                self._write(0, sl, columns, dev, host)
                self._head, self._count = 0, self.capacity
                return
            first = min(n, self.capacity - self._head)
            self._write(self._head, slice(0, first), columns, dev, host)
            if first < n:
                self._write(0, slice(first, n), columns, dev, host)
            self._head = (self._head + n) % self.capacity
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
        if len(dev):
            keep = gaps[:, 0] >= dev[0]
            gaps = gaps[keep]
        return Snapshot(dev, host, values, gaps[:, 0], gaps[:, 1].astype(np.int64), total)

    def _segments(self) -> list[slice]:
        """Physical slices of the ring in time order (oldest first)."""
        if self._count < self.capacity:
            return [slice(0, self._count)]
        return [slice(self._head, self.capacity), slice(0, self._head)]

    def _logical_search(self, parts: list[slice], t: float) -> int:
        """Logical index of the first sample with device time >= t."""
        offset = 0
        for sl in parts:
            seg = self._device_time[sl]
            if len(seg) and seg[-1] >= t:
                return offset + int(np.searchsorted(seg, t, side="left"))
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
            self._head = self._count = 0
            self.total_frames = 0
            self._sequence = SequenceTracker()
            self._unwrap = TickUnwrapper()
            self._gaps.clear()

    def latest(self, channel: str) -> float | None:
        with self._lock:
            if not self._count:
                return None
            return float(self._data[channel][(self._head - 1) % self.capacity])


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
