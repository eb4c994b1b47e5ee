"""Finding frames in bytes: a byte stream (TCP, serial) or datagrams (UDP).

The scan is vectorised: candidate sync words are located with numpy, their headers are
checked all at once (version, known packet id, length fitting the packet), and the
candidates of a clean stream - each starting where the previous ends - are accepted in
one pass with a batched CRC check.  Only when something is wrong (junk, a corrupted or
truncated frame, a sync word inside a payload that happens to look like a header) do we
walk the candidates one by one, which is also how the stream resynchronises: skip to
the next sync word after the last good frame and try again.

Nothing here raises on bad input: every rejected candidate is counted by kind and the
last few are kept as specific exceptions (`FramingCounters.recent_errors`) for the link
layer to report.
"""

from __future__ import annotations

from collections import deque
from dataclasses import dataclass, field
from typing import Iterable

import numpy as np

from ..core.dictionary import CRC_SIZE, HEADER_SIZE
from ..core.errors import (CrcError, DecodeError, FrameLengthError, ProtocolVersionError,
                           UnknownPacketError)
from .crc import valid_frames
from .frames import FrameCodec, TelemetryBlock

_SYNC0, _SYNC1 = 0xEB, 0x90


@dataclass
class FramingCounters:
    """What the deframer rejected, by kind (cumulative)."""

    frames: int = 0
    bytes_in: int = 0
    junk_bytes: int = 0            # bytes outside any accepted frame
    resyncs: int = 0               # times the decoder had to skip junk to find a frame
    crc_errors: int = 0
    version_errors: int = 0
    unknown_packet_errors: int = 0
    length_errors: int = 0
    recent_errors: deque = field(default_factory=lambda: deque(maxlen=16))

    def as_dict(self) -> dict[str, int]:
        return {k: v for k, v in self.__dict__.items() if k != "recent_errors"}


@dataclass
class _Scan:
    starts: np.ndarray       # accepted frame starts (sorted)
    ids: np.ndarray          # their packet ids
    lengths: np.ndarray      # their total frame lengths
    consumed: int            # bytes that can be dropped from the front of the buffer


class FrameScanner:
    """Stateless frame finder shared by the stream and datagram decoders."""

    def __init__(self, codec: FrameCodec, counters: FramingCounters):
        self.codec = codec
        self.counters = counters
        self._version = codec.version
        self._known = np.zeros(256, dtype=bool)
        self._min_len = np.zeros(256, dtype=np.int64)
        self._max_len = np.zeros(256, dtype=np.int64)
        for pid, (lo, hi) in codec.payload_limits.items():
            self._known[pid] = True
            self._min_len[pid] = lo
            self._max_len[pid] = hi

    def scan(self, arr: np.ndarray, final: bool, segment: np.ndarray | None = None) -> _Scan:
        """Find the frames in `arr` (uint8).  With final=False, a frame that may still be
        completed by more bytes is left in place (`consumed` stops before it).
        `segment[i]` = index of the datagram byte i belongs to: frames may not span two."""
        n = len(arr)
        empty = np.zeros(0, np.int64)
        cand = np.flatnonzero(arr[:-1] == _SYNC0) if n > 1 else empty
        cand = cand[arr[cand + 1] == _SYNC1]
        full_hdr = cand + HEADER_SIZE <= n
        head_cut = n  # first candidate whose header is not complete yet
        if not final and not full_hdr.all():
            head_cut = int(cand[~full_hdr][0])
        cand = cand[full_hdr]
        version = arr[cand + 2]
        pid = arr[cand + 3]
        length = (arr[cand + 4].astype(np.int64) << 8) | arr[cand + 5]
        known = self._known[pid]
        len_ok = (length >= self._min_len[pid]) & (length <= self._max_len[pid])
        good_hdr = (version == self._version) & known & len_ok
        frame_len = length + HEADER_SIZE + CRC_SIZE
        complete = cand + frame_len <= n
        if segment is not None and len(cand):
            # a frame must begin and end in the same datagram (the last one included)
            last = np.minimum(cand + frame_len, n) - 1
            good_hdr &= complete & (segment[cand] == segment[last])

        hs, hl, hc, hp = cand[good_hdr], frame_len[good_hdr], complete[good_hdr], pid[good_hdr]
        if len(hs) and hc.all() and np.array_equal(hs[1:], hs[:-1] + hl[:-1]):
            # clean stream: back-to-back frames; check CRCs in one batched pass
            ok = valid_frames(arr, hs, hl)
            if ok.all():
                acc = np.arange(len(hs))
                pending = n
            else:
                acc, pending = self._walk(arr, hs, hl, hc, ok, final)
        else:
            acc, pending = self._walk(arr, hs, hl, hc, None, final)
        starts, lengths, ids = hs[acc], hl[acc], hp[acc]

        consumed = n if final else min(pending, head_cut, n - 1 if n and arr[-1] == _SYNC0 else n)
        if len(starts):
            # a sync pattern (or lone 0xEB) inside the last accepted frame is payload: never
            # keep the tail of an accepted frame for the next scan
            consumed = max(consumed, int(starts[-1] + lengths[-1]))
        self._count_rejects(arr, cand, good_hdr, version, pid, length, starts, lengths, consumed)
        # junk = bytes consumed outside accepted frames; each junk region is one resync
        ends = starts + lengths
        prev_end = np.concatenate(([0], ends[:-1]))
        tail = consumed - (int(ends[-1]) if len(ends) else 0)
        self.counters.junk_bytes += int(np.sum(starts - prev_end)) + max(tail, 0)
        self.counters.resyncs += int(np.count_nonzero(starts != prev_end)) + (tail > 0)
        self.counters.frames += len(starts)
        return _Scan(starts, ids, lengths, consumed)

    def _walk(self, arr, hs, hl, hc, ok, final=False):
        """Greedy left-to-right acceptance; CRC checked per candidate as needed.  With
        final=True no more bytes will come: an incomplete candidate is junk, not a wait."""
        accepted = []
        pos = 0
        pending = len(arr)
        bad_crc = []
        for i in range(len(hs)):
            s = int(hs[i])
            if s < pos:
                continue           # a sync-like pattern inside an accepted frame
            if not hc[i]:
                if final:
                    continue       # truncated at the end of the stream: look further on
                pending = s        # may be a frame still arriving
                break
            good = bool(ok[i]) if ok is not None else bool(
                valid_frames(arr, hs[i:i + 1], hl[i:i + 1])[0])
            if good:
                accepted.append(i)
                pos = s + int(hl[i])
            else:
                bad_crc.append(i)
        for i in bad_crc:
            self.counters.crc_errors += 1
            self._remember(CrcError(
                f"CRC mismatch in a {self.codec.packet(int(arr[hs[i] + 3])).name} frame "
                f"at stream offset +{int(hs[i])} (frame dropped, decoder resynchronised)"))
        return np.asarray(accepted, dtype=np.int64), pending

    def _count_rejects(self, arr, cand, good_hdr, version, pid, length, starts, lengths, consumed):
        bad = ~good_hdr & (cand < consumed)
        if not bad.any():
            return
        # ignore sync-like patterns that lie inside accepted frames (payload bytes)
        if len(starts):
            k = np.searchsorted(starts, cand, side="right") - 1
            inside = (k >= 0) & (cand < starts[np.maximum(k, 0)] + lengths[np.maximum(k, 0)])
            bad &= ~inside
        bad_idx = np.flatnonzero(bad)
        wrong_version = version[bad_idx] != self._version
        unknown = ~wrong_version & ~self._known[pid[bad_idx]]
        self.counters.version_errors += int(np.count_nonzero(wrong_version))
        self.counters.unknown_packet_errors += int(np.count_nonzero(unknown))
        self.counters.length_errors += int(np.count_nonzero(~wrong_version & ~unknown))
        # messages only for the last few (recent_errors keeps no more)
        for i in bad_idx[-self.counters.recent_errors.maxlen:]:
            off, v, p, ln = int(cand[i]), int(version[i]), int(pid[i]), int(length[i])
            if v != self._version:
                err = ProtocolVersionError(
                    f"frame at stream offset +{off} is protocol version {v}; this ground "
                    f"station speaks version {self._version}"
                    + (" - update the ground station" if v > self._version else ""))
                err.version = v           # the sender's major version, for the link's message
                self._remember(err)
            elif not self._known[p]:
                self._remember(UnknownPacketError(
                    f"frame at stream offset +{off} has packet id 0x{p:02X}, which is not in "
                    f"the telemetry dictionary"))
            else:
                lo, hi = self._min_len[p], self._max_len[p]
                if lo <= ln <= hi:       # only a datagram boundary makes a fitting length bad
                    self._remember(FrameLengthError(
                        f"{self.codec.packet(p).name} frame at offset +{off}: its length {ln} "
                        f"reaches beyond the end of its datagram (frame truncated or split)"))
                    continue
                self._remember(FrameLengthError(
                    f"{self.codec.packet(p).name} frame at stream offset +{off} has length "
                    f"{ln}, expected {lo}{'' if lo == hi else f'..{hi}'} bytes"))

    def _remember(self, error: DecodeError) -> None:
        self.counters.recent_errors.append(error)

    def decode(self, arr: np.ndarray, scan: _Scan, host_time: np.ndarray | float) -> list[TelemetryBlock]:
        """Accepted frames -> one block per packet, frames in order within each block."""
        blocks = []
        if not len(scan.starts):
            return blocks
        times = np.broadcast_to(np.asarray(host_time, dtype=np.float64), (len(arr),)) \
            if np.ndim(host_time) == 0 else host_time
        for pid in np.unique(scan.ids).tolist():
            sel = scan.ids == pid
            starts = scan.starts[sel]
            pkt = self.codec.packet(pid)
            t = np.ascontiguousarray(times[starts])
            if pkt.variable_item is None:
                size = int(scan.lengths[sel][0])
                window = np.lib.stride_tricks.sliding_window_view(arr, size)
                blocks.append(self.codec.decode_fixed(pkt, window[starts], t))
            else:
                lens = scan.lengths[sel]
                frames = [arr[s:s + ln].tobytes() for s, ln in zip(starts.tolist(), lens.tolist())]
                blocks.append(self.codec.decode_variable(pkt, frames, t))
        return blocks


class StreamDeframer:
    """Byte stream -> decoded blocks; keeps an incomplete tail for the next feed()."""

    def __init__(self, codec: FrameCodec, max_buffer: int = 1 << 24):
        self.counters = FramingCounters()
        self._scanner = FrameScanner(codec, self.counters)
        self._buf = bytearray()
        self._max_buffer = max_buffer

    def feed(self, data: bytes | bytearray | memoryview, host_time: float) -> list[TelemetryBlock]:
        self.counters.bytes_in += len(data)
        self._buf += data
        arr = np.frombuffer(self._buf, dtype=np.uint8)
        scan = self._scanner.scan(arr, final=False)
        blocks = self._scanner.decode(arr, scan, host_time)
        del arr
        del self._buf[:scan.consumed]
        if len(self._buf) > self._max_buffer:        # cannot happen with sane headers
            self.counters.junk_bytes += len(self._buf)
            self._buf.clear()
        return blocks

    def flush(self, host_time: float) -> list[TelemetryBlock]:
        """End of stream: decode what can be, count the rest as junk."""
        arr = np.frombuffer(self._buf, dtype=np.uint8)
        scan = self._scanner.scan(arr, final=True)
        blocks = self._scanner.decode(arr, scan, host_time)
        del arr
        self._buf.clear()
        return blocks

    @property
    def buffered(self) -> int:
        return len(self._buf)


class DatagramDecoder:
    """Datagrams (each one or more whole frames) -> decoded blocks, many at a time."""

    def __init__(self, codec: FrameCodec):
        self.counters = FramingCounters()
        self._scanner = FrameScanner(codec, self.counters)

    def decode(self, datagrams: Iterable[bytes], host_times: Iterable[float] | float) -> list[TelemetryBlock]:
        datagrams = list(datagrams)
        if not datagrams:
            return []
        sizes = np.fromiter((len(d) for d in datagrams), dtype=np.int64, count=len(datagrams))
        data = b"".join(datagrams)
        self.counters.bytes_in += len(data)
        arr = np.frombuffer(data, dtype=np.uint8)
        segment = np.repeat(np.arange(len(datagrams)), sizes)
        if np.ndim(host_times) == 0:
            times = float(host_times)
        else:
            times = np.repeat(np.fromiter(host_times, dtype=np.float64, count=len(datagrams)), sizes)
        scan = self._scanner.scan(arr, final=True, segment=segment)
        return self._scanner.decode(arr, scan, times)
