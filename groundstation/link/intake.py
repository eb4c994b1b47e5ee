"""What the link lets in: telemetry only from the device, only packets it may send.

Two rules, both from SPEC.md §1.1:

* **Source.**  Telemetry datagrams come from the device the session is connected to:
  the IP address of the command connection's peer, sent from the device's command port
  number (UDP and TCP port numbers are separate spaces, so the device binds its UDP
  socket to the same number).  Anything else is *foreign*: another program, a second
  simulator, or someone injecting frames with a valid CRC.  Foreign datagrams are
  counted and never decoded, so they reach neither the statistics nor the log.
* **Packet type.**  On the telemetry path the device sends HIGH_RATE, HOUSEKEEPING and
  EVENT; on the command path it also sends RESPONSE.  A host-to-device packet (COMMAND)
  arriving at the host, or a RESPONSE on the UDP path, is *unexpected*: counted, named in
  the link's recent errors, dropped.

The counters look like the deframer's (`as_dict`, `recent_errors`), so the link
statistics add them to the framing counts that the window, `monitor` and the log's link
records show.
"""

from __future__ import annotations

import logging
from collections import deque
from dataclasses import dataclass, field

from ..codec import TelemetryBlock
from ..core.dictionary import Dictionary
from ..core.errors import GroundStationError

log = logging.getLogger(__name__)

#: The command channel's answer packet: it belongs on the command path only.
RESPONSE = "RESPONSE"


class ForeignTelemetry(GroundStationError):
    """Telemetry from a sender that is not the connected device (message says who)."""


class UnexpectedPacket(GroundStationError):
    """A packet the device does not send on that path (message says which)."""


@dataclass
class IntakeCounters:
    foreign_datagrams: int = 0
    foreign_bytes: int = 0
    unexpected_packets: int = 0
    recent_errors: deque = field(default_factory=lambda: deque(maxlen=16))

    def as_dict(self) -> dict[str, int]:
        return {k: v for k, v in self.__dict__.items() if k != "recent_errors"}


class TelemetryIntake:
    """Filters datagrams by source and decoded blocks by packet type."""

    def __init__(self, dictionary: Dictionary, device_source: tuple[str, int] | None = None):
        self.counters = IntakeCounters()
        #: (ip, port) telemetry must come from; None accepts any sender (no command link
        #: to learn it from, e.g. a receiver used on its own)
        self.device_source = device_source
        from_device = {p.name for p in dictionary.packets if p.direction == "device_to_host"}
        self.allowed = {"datagram": from_device - {RESPONSE}, "stream": from_device}
        self._named_sources: set[tuple[str, int]] = set()

    def datagrams(self, datagrams: list[bytes], times: list[float],
                  sources: list[tuple[str, int]]) -> tuple[list[bytes], list[float]]:
        """The datagrams (and their arrival times) that came from the device."""
        if self.device_source is None:
            return datagrams, times
        # the usual case, all from the device: one comparison per datagram in C, no copies
        if sources.count(self.device_source) == len(sources):
            return datagrams, times
        keep_d, keep_t = [], []
        for data, when, src in zip(datagrams, times, sources):
            if src is not None and tuple(src[:2]) == self.device_source:
                keep_d.append(data)
                keep_t.append(when)
                continue
            self.counters.foreign_datagrams += 1
            self.counters.foreign_bytes += len(data)
            src = tuple(src[:2]) if src is not None else ("?", 0)
            if src not in self._named_sources:          # name each sender once
                self._named_sources.add(src)
                ip, port = self.device_source
                msg = (f"telemetry from {src[0]}:{src[1]} ignored: only the connected "
                       f"device ({ip}, sending from port {port}) is accepted - another "
                       f"program or host is sending to this ground station's telemetry port")
                self.counters.recent_errors.append(ForeignTelemetry(msg))
                log.warning("%s", msg)
        return keep_d, keep_t

    def blocks(self, blocks: list[TelemetryBlock], path: str) -> list[TelemetryBlock]:
        """The decoded blocks the device may send on `path` ('datagram' or 'stream')."""
        allowed = self.allowed[path]
        if all(b.name in allowed for b in blocks):
            return blocks
        kept = []
        for b in blocks:
            if b.name in allowed:
                kept.append(b)
                continue
            self.counters.unexpected_packets += len(b)
            where = "telemetry (UDP)" if path == "datagram" else "command"
            msg = (f"{len(b)} {b.name} frame(s) arrived on the {where} path, where the device "
                   f"never sends them: dropped")
            self.counters.recent_errors.append(UnexpectedPacket(msg))
            log.warning("%s", msg)
        return kept
