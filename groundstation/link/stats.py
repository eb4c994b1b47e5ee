"""Link health as numbers: frame rates, dropped frames, errors, latency.

Drops are counted from sequence gaps per packet (sequence numbers are per packet id
and wrap at 2^32).  Latency needs the device clock on the host's timebase; the device
has no synchronised clock, so `ClockSync` estimates the offset from command round trips
(each RESPONSE carries the device tick): offset = host time at the midpoint of the
round trip minus tick/1200, taking the exchange with the shortest round trip, as NTP
does.  Latency of a frame = arrival time - (tick/1200 + offset).
"""

from __future__ import annotations

import threading
import time
from collections import deque
from dataclasses import dataclass, field

import numpy as np

from ..codec import FramingCounters, TelemetryBlock

SEQ_MOD = 1 << 32


class ClockSync:
    """Device tick -> host time, from round trips of commands."""

    def __init__(self, tick_rate_hz: float, window: int = 32):
        self.tick_rate = tick_rate_hz
        self._samples: deque[tuple[float, float]] = deque(maxlen=window)  # (rtt, offset)
        self._tick_unwrap = TickUnwrapper()

    def observe(self, sent: float, received: float, device_tick: int) -> None:
        rtt = received - sent
        # the answer leaves the device during the period that began at `tick`: +0.5 tick
        t_dev = (self._tick_unwrap.unwrap_scalar(device_tick) + 0.5) / self.tick_rate
        self._samples.append((rtt, sent + rtt / 2 - t_dev))

    @property
    def offset(self) -> float | None:
        if not self._samples:
            return None
        return min(self._samples)[1]

    @property
    def best_rtt(self) -> float | None:
        return min(self._samples)[0] if self._samples else None


class TickUnwrapper:
    """u32 device ticks -> monotonically continuing int64 (handles the 2^32 wrap)."""

    def __init__(self) -> None:
        self._last: int | None = None
        self._base = 0

    def unwrap(self, ticks: np.ndarray) -> np.ndarray:
        t = ticks.astype(np.int64)
        if not len(t):
            return t
        prev = np.concatenate(([self._last if self._last is not None else t[0]], t[:-1]))
        wraps = np.cumsum(((t - prev) < -(SEQ_MOD // 2)).astype(np.int64))
        out = t + (self._base + wraps * SEQ_MOD)
        self._base += int(wraps[-1]) * SEQ_MOD
        self._last = int(t[-1])
        return out

    def unwrap_scalar(self, tick: int) -> int:
        return int(self.unwrap(np.array([tick], dtype=np.int64))[0])


@dataclass
class PacketStats:
    frames: int = 0
    dropped: int = 0           # frames missing according to sequence gaps
    duplicates: int = 0        # repeated or out-of-order sequence numbers
    last_sequence: int | None = None
    rate_hz: float = 0.0


@dataclass
class LinkSnapshot:
    """A copy of the link statistics for display (no shared state)."""

    packets: dict[str, PacketStats]
    framing: dict[str, int]
    latency_ms_mean: float | None
    latency_ms_max: float | None
    clock_offset_s: float | None
    best_rtt_ms: float | None
    uptime_s: float
    gap_events: list[tuple[float, str, int]] = field(default_factory=list)

    @property
    def dropped(self) -> int:
        return sum(p.dropped for p in self.packets.values())


class LinkStatistics:
    """Fed with every decoded block (receiver threads); read by anyone (thread-safe)."""

    def __init__(self, tick_rate_hz: float = 1200.0, rate_window_s: float = 1.0):
        self.clock = ClockSync(tick_rate_hz)
        self._tick_rate = tick_rate_hz
        self._lock = threading.Lock()
        self._packets: dict[str, PacketStats] = {}
        self._arrivals: dict[str, deque[tuple[float, int]]] = {}
        self._window = rate_window_s
        self._latency: deque[float] = deque(maxlen=2400)
        self._unwrap: dict[str, TickUnwrapper] = {}
        self._gaps: deque[tuple[float, str, int]] = deque(maxlen=1000)
        self._framing_sources: list[FramingCounters] = []
        self._started = time.monotonic()

    def reset(self) -> None:
        """Forget the packet counts, rates, latencies and gaps (e.g. after a replay seeks:
        the jump is not a drop).  Framing counters belong to their decoders and stay."""
        with self._lock:
            self._packets.clear()
            self._arrivals.clear()
            self._latency.clear()
            self._unwrap.clear()
            self._gaps.clear()
            self._started = time.monotonic()

    def add_framing_source(self, counters: FramingCounters) -> None:
        with self._lock:
            self._framing_sources.append(counters)

    def recent_errors(self) -> list[Exception]:
        """The last few decode errors (specific exceptions with messages), oldest first."""
        with self._lock:
            return [e for src in self._framing_sources for e in list(src.recent_errors)]

    def update(self, block: TelemetryBlock) -> None:
        n = len(block)
        if not n:
            return
        seq = block.columns["sequence"].astype(np.int64)
        now = time.monotonic()
        with self._lock:
            ps = self._packets.setdefault(block.name, PacketStats())
            prev = np.concatenate(([ps.last_sequence], seq[:-1])) if ps.last_sequence is not None \
                else np.concatenate(([seq[0] - 1], seq[:-1]))
            step = (seq - prev) % SEQ_MOD
            gaps = step - 1
            lost = (step > 1) & (step < SEQ_MOD // 2)
            if lost.any():
                ps.dropped += int(gaps[lost].sum())
                host_t = block.host_time
                for i in np.flatnonzero(lost)[:100]:
                    self._gaps.append((float(host_t[i]), block.name, int(gaps[i])))
            ps.duplicates += int(np.count_nonzero((step == 0) | (step >= SEQ_MOD // 2)))
            ps.frames += n
            ps.last_sequence = int(seq[-1])
            arr = self._arrivals.setdefault(block.name, deque())
            arr.append((now, n))
            offset = self.clock.offset
            if offset is not None and block.name != "RESPONSE":
                ticks = self._unwrap.setdefault(block.name, TickUnwrapper()).unwrap(block.columns["tick"])
                lat = block.host_time - (ticks / self._tick_rate + offset)
                self._latency.extend(lat[-64:].tolist())

    def snapshot(self) -> LinkSnapshot:
        now = time.monotonic()
        with self._lock:
            packets = {}
            for name, ps in self._packets.items():
                arr = self._arrivals[name]
                while arr and arr[0][0] < now - self._window:
                    arr.popleft()
                rate = sum(n for _, n in arr) / self._window
                packets[name] = PacketStats(ps.frames, ps.dropped, ps.duplicates,
                                            ps.last_sequence, rate)
            framing: dict[str, int] = {}
            for src in self._framing_sources:
                for k, v in src.as_dict().items():
                    framing[k] = framing.get(k, 0) + v
            lat = np.array(self._latency) * 1e3 if self._latency else None
            offset, rtt = self.clock.offset, self.clock.best_rtt
            return LinkSnapshot(
                packets=packets, framing=framing,
                latency_ms_mean=float(lat.mean()) if lat is not None else None,
                latency_ms_max=float(lat.max()) if lat is not None else None,
                clock_offset_s=offset, best_rtt_ms=rtt * 1e3 if rtt is not None else None,
                uptime_s=now - self._started, gap_events=list(self._gaps))


def format_snapshot(snap: LinkSnapshot) -> str:
    """One line for a terminal: rates, drops, errors, latency."""
    parts = []
    for name, ps in sorted(snap.packets.items()):
        if name == "RESPONSE":
            continue
        parts.append(f"{name} {ps.rate_hz:7.1f}/s n={ps.frames} drop={ps.dropped}")
    f = snap.framing
    parts.append(f"crc={f.get('crc_errors', 0)} resync={f.get('resyncs', 0)} "
                 f"ver={f.get('version_errors', 0)} junk={f.get('junk_bytes', 0)}B")
    if snap.latency_ms_mean is not None:
        parts.append(f"latency {snap.latency_ms_mean:.2f} ms (max {snap.latency_ms_max:.2f})")
    return " | ".join(parts)
