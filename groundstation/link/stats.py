"""Link health as numbers: frame rates, dropped frames, errors, latency.

Drops are counted from sequence gaps per packet (sequence numbers are per packet id
and wrap at 2^32), by the one tracker the display buffers and the log reader also use
(codec/sequence.py: a single wild sequence number is an outlier, not four billion drops).  Latency needs the device clock on the host's timebase; the device
has no synchronised clock, so `ClockSync` estimates the offset from command round trips
(each RESPONSE carries the device tick): offset = host time at the midpoint of the
round trip minus tick/1200, taking the exchange with the shortest round trip, as NTP
does, and bounded by the frames themselves (ClockSync).  Latency of a frame = arrival
time - (tick/1200 + offset).
"""

from __future__ import annotations

import threading
import time
from collections import deque
from dataclasses import dataclass, field

import numpy as np

from ..codec import FramingCounters, TelemetryBlock
from ..codec.sequence import SequenceTracker
from ..codec.ticks import TickUnwrapper
from ..core.dictionary import default_control_rate_hz


class ClockSync:
    """Device tick -> host time, from round trips of commands and from the frames.

    Round trips give the offset to within half the shortest round trip.  That estimate
    goes stale when the device clock runs at another rate than the host's (a crystal's
    drift, a simulator at --speed 2, a device catching up after a stall) and latencies
    would then read negative.  Every received frame also bounds the offset from above:
    it cannot have arrived before it was sent, so offset <= arrival - tick/rate.  The
    offset used is the smaller of the two, the bound taken over the last `bound_window_s`
    of frames, so a latency is never negative and follows a drifting device clock."""

    def __init__(self, tick_rate_hz: float, window: int = 32, bound_window_s: float = 10.0):
        self.tick_rate = tick_rate_hz
        self._samples: deque[tuple[float, float]] = deque(maxlen=window)  # (rtt, offset)
        self._tick_unwrap = TickUnwrapper()
        self._bound_window = bound_window_s
        self._bounds: deque[tuple[float, float]] = deque()    # (monotonic time, bound), increasing bound

    def observe(self, sent: float, received: float, device_tick: int) -> None:
        rtt = received - sent
        # the answer leaves the device during the period that began at `tick`: +0.5 tick
        t_dev = (self._tick_unwrap.unwrap_scalar(device_tick) + 0.5) / self.tick_rate
        self._samples.append((rtt, sent + rtt / 2 - t_dev))

    def bound(self, upper: float, now: float | None = None) -> None:
        """Record that the offset is at most `upper` (from a frame's arrival time)."""
        now = time.monotonic() if now is None else now
        b = self._bounds
        while b and b[-1][1] >= upper:      # a monotonic deque: its head is the window's minimum
            b.pop()
        b.append((now, upper))
        while b[0][0] < now - self._bound_window:
            b.popleft()

    @property
    def offset(self) -> float | None:
        rtt_offset = min(self._samples)[1] if self._samples else None
        frame_bound = self._bounds[0][1] if self._bounds else None
        if rtt_offset is None:
            return None
        return rtt_offset if frame_bound is None else min(rtt_offset, frame_bound)

    @property
    def best_rtt(self) -> float | None:
        return min(self._samples)[0] if self._samples else None


@dataclass
class PacketStats:
    frames: int = 0
    dropped: int = 0           # frames missing according to sequence gaps
    duplicates: int = 0        # repeated or out-of-order sequence numbers
    outliers: int = 0          # single frames with a wild sequence number (not believed)
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

    def __init__(self, tick_rate_hz: float | None = None, rate_window_s: float = 1.0):
        if tick_rate_hz is None:                   # the protocol dictionary's control rate
            tick_rate_hz = default_control_rate_hz()
        self.clock = ClockSync(tick_rate_hz)
        self._tick_rate = tick_rate_hz
        self._lock = threading.Lock()
        self._packets: dict[str, PacketStats] = {}
        self._arrivals: dict[str, deque[tuple[float, int]]] = {}
        self._window = rate_window_s
        self._latency: deque[float] = deque(maxlen=2400)
        self._unwrap: dict[str, TickUnwrapper] = {}
        self._sequences: dict[str, SequenceTracker] = {}
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
            self._sequences.clear()
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
        now = time.monotonic()
        with self._lock:
            ps = self._packets.setdefault(block.name, PacketStats())
            tracker = self._sequences.setdefault(block.name, SequenceTracker())
            first = tracker.fed
            rep = tracker.feed(block.columns["sequence"])
            if len(rep.missing):
                ps.dropped += rep.dropped
                host_t = np.broadcast_to(np.asarray(block.host_time, dtype=np.float64), (n,))
                for at, missing in list(zip(rep.gap_index.tolist(), rep.missing.tolist()))[:100]:
                    self._gaps.append((float(host_t[max(0, at - first)]), block.name, int(missing)))
            ps.duplicates += rep.duplicates
            ps.outliers += rep.outliers
            ps.frames += n
            ps.last_sequence = int(block.columns["sequence"][-1])
            arr = self._arrivals.setdefault(block.name, deque())
            arr.append((now, n))
            if block.name != "RESPONSE":
                ticks = self._unwrap.setdefault(block.name, TickUnwrapper()).unwrap(block.columns["tick"])
                # A frame cannot arrive before the device sent it: arrival - tick/rate is an
                # upper bound of the clock offset, kept over the last few seconds.
                self.clock.bound(float(np.min(block.host_time - ticks / self._tick_rate)))
                offset = self.clock.offset
                if offset is not None:
                    lat = block.host_time - (ticks / self._tick_rate + offset)
                    self._latency.extend(np.atleast_1d(lat)[-64:].tolist())

    def snapshot(self) -> LinkSnapshot:
        now = time.monotonic()
        with self._lock:
            packets = {}
            for name, ps in self._packets.items():
                arr = self._arrivals[name]
                while arr and arr[0][0] < now - self._window:
                    arr.popleft()
                rate = sum(n for _, n in arr) / self._window
                packets[name] = PacketStats(ps.frames, ps.dropped, ps.duplicates, ps.outliers,
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
