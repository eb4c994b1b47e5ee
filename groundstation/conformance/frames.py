"""Judging the device's bytes against SPEC §2 and §4 ourselves, at the raw level.

The ground station's deframer hides what it drops (it counts and moves on); the suite
needs the opposite: every frame the device sent, good or bad, with enough evidence to
say what was wrong.  So this is a small, plain scanner written from the SPEC, not the
vectorised one the link uses.
"""

from __future__ import annotations

import struct
import zlib
from dataclasses import dataclass, field

SYNC = b"\xEB\x90"
HEADER = struct.Struct(">2sBBHII")      # sync, version, packet_id, length, sequence, tick
HEADER_SIZE = 14
CRC_SIZE = 4


@dataclass
class RawFrame:
    """One frame as it arrived: header fields, payload and the path it came by."""

    packet_id: int
    sequence: int
    tick: int
    payload: bytes
    raw: bytes
    path: str                   # "stream" or "datagram"
    arrival: int                # order of arrival over all paths (no clock needed)


@dataclass
class FramingReport:
    """What the scanner saw, by SPEC §4 kind, with one example of each fault."""

    frames: int = 0
    crc_errors: int = 0
    version_errors: int = 0
    unknown_packet_errors: int = 0
    length_errors: int = 0
    junk_bytes: int = 0
    split_frames: int = 0       # a frame that did not end in its datagram (§1.1)
    examples: dict[str, str] = field(default_factory=dict)

    def note(self, kind: str, text: str) -> None:
        setattr(self, kind, getattr(self, kind) + 1)
        self.examples.setdefault(kind, text)

    @property
    def faults(self) -> int:
        return (self.crc_errors + self.version_errors + self.unknown_packet_errors
                + self.length_errors + self.split_frames)


class FrameJudge:
    """Scan bytes for frames by the rules of SPEC §4.1/§4.2.

    `limits` maps packet id -> (min, max) payload length (the §2 length rules)."""

    def __init__(self, version: int, limits: dict[int, tuple[int, int]], report: FramingReport):
        self.version = version
        self.limits = limits
        self.report = report
        self._buffer = b""

    def feed_stream(self, data: bytes) -> list[tuple[int, int, int, bytes, bytes]]:
        self._buffer += data
        frames, used = self._scan(self._buffer, final=False)
        self._buffer = self._buffer[used:]
        return frames

    def feed_datagram(self, data: bytes) -> list[tuple[int, int, int, bytes, bytes]]:
        frames, _ = self._scan(data, final=True)
        return frames

    def _scan(self, buf: bytes, final: bool):
        out = []
        at = 0
        n = len(buf)
        while True:
            start = buf.find(SYNC, at)
            if start < 0:
                # a lone 0xEB after the last frame may be the first half of a sync word
                keep = n - 1 if (not final and n - 1 >= at and buf[-1] == 0xEB) else n
                self.report.junk_bytes += max(0, keep - at)
                return out, keep
            self.report.junk_bytes += start - at
            if n - start < HEADER_SIZE:
                if final:
                    self.report.junk_bytes += n - start
                    return out, n
                return out, start
            _, version, pid, length, seq, tick = HEADER.unpack_from(buf, start)
            where = f"0x{pid:02X} seq {seq} tick {tick}"
            if version != self.version:
                self.report.note("version_errors", f"frame {where}: version {version}, "
                                                   f"expected {self.version}")
                at = start + 1
                continue
            if pid not in self.limits:
                self.report.note("unknown_packet_errors", f"frame with packet id 0x{pid:02X} "
                                                          f"not in the dictionary")
                at = start + 1
                continue
            lo, hi = self.limits[pid]
            if not lo <= length <= hi:
                self.report.note("length_errors", f"frame {where}: length {length}, the packet "
                                                  f"allows {lo}..{hi}")
                at = start + 1
                continue
            end = start + HEADER_SIZE + length + CRC_SIZE
            if end > n:
                if final:       # a frame must begin and end in its datagram (§4.2)
                    self.report.note("split_frames", f"frame {where}: {length}-byte payload "
                                                     f"runs past the end of its datagram")
                    at = start + 1
                    continue
                return out, start
            body = buf[start:end - CRC_SIZE]
            sent = int.from_bytes(buf[end - CRC_SIZE:end], "little")
            computed = zlib.crc32(body)
            if sent != computed:
                self.report.note("crc_errors", f"frame {where}: trailing CRC 0x{sent:08X}, "
                                               f"CRC-32 of bytes 0..{len(body) - 1} is "
                                               f"0x{computed:08X}")
                at = start + 1              # resynchronise inside the bad frame (§4.1 rule 4)
                continue
            self.report.frames += 1
            out.append((pid, seq, tick, bytes(buf[start + HEADER_SIZE:end - CRC_SIZE]),
                        bytes(buf[start:end])))
            at = end


def command_frame(version: int, command_id: int, sequence: int, token: int, opcode: int,
                  arguments: bytes) -> bytes:
    """A COMMAND frame built by hand (§2, §6.1): nothing checks the arguments, so the
    suite can send what our client would refuse to."""
    payload = struct.pack(">IH", token & 0xFFFFFFFF, opcode) + arguments
    head = HEADER.pack(SYNC, version, command_id, len(payload), sequence & 0xFFFFFFFF, 0)
    body = head + payload
    return body + zlib.crc32(body).to_bytes(4, "little")
