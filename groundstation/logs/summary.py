"""What a log holds, in a few numbers: per packet frames, time spans, rate and the
frames lost in sequence gaps; for the file who, when, which protocol and whether the
recorder closed it (`log info`, `LogReader.summary()`).

The sequence gaps are counted by the live link's rule (codec/sequence.py), reading each
sequence column in bounded pieces, so an hour of telemetry is never in memory at once
and one wild sequence number is an outlier, not a gap of a billion frames.
"""

from __future__ import annotations

from dataclasses import dataclass
from datetime import datetime, timezone
from pathlib import Path
from typing import TYPE_CHECKING

import numpy as np

from ..codec.sequence import SequenceTracker
from ..core.dictionary import default_control_rate_hz
from .opening import attr_text

if TYPE_CHECKING:
    from .reader import LogReader

_SCAN_ROWS = 1 << 20            # rows per read when a whole column must be scanned


@dataclass(frozen=True)
class PacketSummary:
    name: str
    id: int
    description: str
    nominal_rate_hz: float
    frames: int
    first_device_time: float | None
    last_device_time: float | None
    first_host_time: float | None
    last_host_time: float | None
    drops: int                # frames missing according to sequence gaps (mod 2^32)
    gaps: int                 # number of gaps
    duplicates: int           # repeated, out-of-order or wild sequence numbers (not believed)
    rate_hz: float            # frames received per second of device time

    @property
    def duration_s(self) -> float:
        if self.first_device_time is None or self.last_device_time is None:
            return 0.0
        return self.last_device_time - self.first_device_time


@dataclass(frozen=True)
class LogInfo:
    path: Path
    schema_version: int
    uuid: str
    test_name: str
    run: int
    notes: str
    created_utc: str
    created: float            # s since the epoch
    stop_utc: str             # as recorded, or from the last frame if the log was not closed
    stop: float
    clean_close: bool         # False: the recorder crashed (or is still writing)
    software_version: str
    host: str
    user: str
    protocol_version: str
    dictionary_hash: str
    tick_rate_hz: float
    packets: dict[str, PacketSummary]

    @property
    def duration_s(self) -> float:
        return max(0.0, self.stop - self.created)

    @property
    def frames(self) -> int:
        return sum(p.frames for p in self.packets.values())

    @property
    def drops(self) -> int:
        return sum(p.drops for p in self.packets.values())

    def format(self) -> str:
        """A few lines for a terminal."""
        state = "closed cleanly" if self.clean_close else "NOT closed (crash or still recording)"
        lines = [f"{self.path}",
                 f"  test '{self.test_name}' run {self.run}, {self.created_utc} .. {self.stop_utc} "
                 f"({self.duration_s:.1f} s), {state}",
                 f"  protocol {self.protocol_version} (dictionary {self.dictionary_hash}), "
                 f"software {self.software_version} on {self.host}"]
        if self.notes:
            lines.append(f"  notes: {self.notes}")
        for p in self.packets.values():
            span = (f"device t {p.first_device_time:.4f}..{p.last_device_time:.4f} s"
                    if p.frames else "no frames")
            lines.append(f"  {p.name:<13} {p.frames:>9} frames  {p.rate_hz:8.2f}/s  "
                         f"drops {p.drops} in {p.gaps} gap(s)  {span}")
        return "\n".join(lines)


def utc_seconds(text: str) -> float | None:
    try:
        return datetime.fromisoformat(text).timestamp()
    except (TypeError, ValueError):
        return None


def scan_sequence(r: "LogReader", packet: str) -> tuple[np.ndarray, np.ndarray, int]:
    """(row index after each gap, frames missing there, duplicates and outliers) for
    `packet`, reading the sequence column in bounded pieces."""
    n = r.n_frames(packet)
    tracker = SequenceTracker()
    idx, missing, odd = [], [], 0
    for a in range(0, n, _SCAN_ROWS):
        seq = r._read(f"telemetry/{packet}/sequence", slice(a, min(n, a + _SCAN_ROWS)))
        rep = tracker.feed(seq)
        idx.append(rep.gap_index)
        missing.append(rep.missing)
        odd += rep.duplicates + rep.outliers
    end = tracker.finish()
    idx.append(end.gap_index)
    missing.append(end.missing)
    odd += end.outliers
    return np.concatenate(idx), np.concatenate(missing), odd


def summarize(r: "LogReader") -> LogInfo:
    """Root attributes and per-packet statistics of the log open in `r` (reads each
    sequence column once, and two rows of each time column)."""
    a = r.attrs
    packets: dict[str, PacketSummary] = {}
    for name in r.packets():
        g = r.h5["telemetry"][name]
        n = r.n_frames(name)
        base = f"telemetry/{name}"
        if n:
            ends = [0, n - 1] if n > 1 else [0]
            dev, host = r._read(f"{base}/device_time", ends), r._read(f"{base}/host_time", ends)
            fd, ld, fh, lh = float(dev[0]), float(dev[-1]), float(host[0]), float(host[-1])
        else:
            fd = ld = fh = lh = None
        idx, missing, dups = scan_sequence(r, name)
        span = (ld - fd) if n > 1 else 0.0
        packets[name] = PacketSummary(
            name=name, id=int(g.attrs.get("id", 0)), description=attr_text(g.attrs.get("description", "")),
            nominal_rate_hz=float(g.attrs.get("rate_hz", 0.0)), frames=n,
            first_device_time=fd, last_device_time=ld, first_host_time=fh, last_host_time=lh,
            drops=int(missing.sum()), gaps=len(idx), duplicates=dups,
            rate_hz=(n - 1) / span if span > 0 else 0.0)
    created_utc = attr_text(a.get("created_utc", ""))
    created = utc_seconds(created_utc)
    clean = bool(a.get("clean_close", False))
    stop_utc = attr_text(a.get("stop_utc", "")) if clean else ""
    stop = utc_seconds(stop_utc) if stop_utc else None
    if stop is None:      # not closed: the last frame (or journal record) says when it ended
        lasts = [p.last_host_time for p in packets.values() if p.last_host_time is not None]
        if not lasts:
            jt = r.dataset("journal/time")
            lasts = [float(jt[jt.shape[0] - 1])] if jt.shape[0] else []
        stop = max(lasts) if lasts else (created or 0.0)
        stop_utc = datetime.fromtimestamp(stop, timezone.utc).isoformat()
    if created is None:
        firsts = [p.first_host_time for p in packets.values() if p.first_host_time is not None]
        created = min(firsts) if firsts else stop
    return LogInfo(
        path=r.path, schema_version=r.schema_version, uuid=attr_text(a.get("uuid", "")),
        test_name=attr_text(a.get("test_name", "")), run=int(a.get("run", 0)),
        notes=attr_text(a.get("notes", "")), created_utc=created_utc, created=created,
        stop_utc=stop_utc, stop=stop, clean_close=clean,
        software_version=attr_text(a.get("software_version", "")), host=attr_text(a.get("host", "")),
        user=attr_text(a.get("user", "")), protocol_version=attr_text(a.get("protocol_version", "")),
        dictionary_hash=attr_text(a.get("dictionary_hash", "")),
        tick_rate_hz=float(a.get("tick_rate_hz", default_control_rate_hz())), packets=packets)


__all__ = ["LogInfo", "PacketSummary", "scan_sequence", "summarize"]


def event_markers(path: str | Path) -> list[tuple[float, int, str]]:
    """(device time, level, text) of a log's EVENT frames: the markers a replay's timeline
    shows.  Raises the reader's GroundStationError for a log it cannot open."""
    from .reader import LogReader

    with LogReader(path) as r:
        if "EVENT" not in r.packets() or not r.n_frames("EVENT"):
            return []
        ev = r.read("EVENT", ["level", "text"])
        return [(float(t), int(lvl), str(text)) for t, lvl, text in
                zip(ev["device_time"], ev["level"], ev["text"])]
