"""Shared helpers of the tests/codec/test_codec_*.py files: frames built with the codec, patched
with a fresh CRC, fed to a deframer in chunks, and the deframers' counters read back."""

from __future__ import annotations

import zlib

import numpy as np

from groundstation.codec import StreamDeframer

HR_SIZE = 78
HK_SIZE = 63


def refresh_crc(frame: bytes | bytearray) -> bytes:
    """Recompute the trailing CRC of a (patched) frame with zlib."""
    body = bytes(frame[:-4])
    return body + zlib.crc32(body).to_bytes(4, "little")


def patched(frame: bytes, offset: int, value: bytes, fix_crc: bool = True) -> bytes:
    out = bytearray(frame)
    out[offset:offset + len(value)] = value
    return refresh_crc(out) if fix_crc else bytes(out)


def hr_frames(codec, n: int, seq0: int = 0, **values) -> list[bytes]:
    data = codec.encode("HIGH_RATE", values, sequence=np.arange(seq0, seq0 + n),
                        tick=np.arange(seq0, seq0 + n) + 1000)
    return [data[i * HR_SIZE:(i + 1) * HR_SIZE] for i in range(n)]


def hk_frame(codec, seq: int, **values) -> bytes:
    return codec.encode("HOUSEKEEPING", values, sequence=seq, tick=seq * 120)


def event_frame(codec, seq: int, text: str = "hello", level: str = "INFO", code: int = 1) -> bytes:
    return codec.encode_variable("EVENT", {"level": level, "code": code, "text": text}, seq, seq)


def collect(blocks) -> dict[str, list[tuple]]:
    """Blocks -> {packet: [(sequence, frame bytes), ...]} in arrival order."""
    out: dict[str, list[tuple]] = {}
    for b in blocks:
        if b.raw is not None:
            frames = [r.tobytes() for r in b.raw]
        else:
            frames = list(b.frames)
        out.setdefault(b.name, []).extend(zip(b["sequence"].tolist(), frames))
    return out


def all_frames(blocks) -> list[bytes]:
    """Frames of all blocks, block after block (so grouped by packet within one read)."""
    out: list[bytes] = []
    for b in blocks:
        out += [r.tobytes() for r in b.raw] if b.raw is not None else list(b.frames)
    return out


def feed_chunks(deframer: StreamDeframer, data: bytes, cuts) -> list:
    blocks = []
    cuts = [0, *sorted(cuts), len(data)]
    for t, (a, b) in enumerate(zip(cuts[:-1], cuts[1:])):
        blocks += deframer.feed(data[a:b], float(t))
    blocks += deframer.flush(float(len(cuts)))
    return blocks


def error_counts(c) -> dict[str, int]:
    return {k: getattr(c, k) for k in ("crc_errors", "version_errors",
                                        "unknown_packet_errors", "length_errors")}


NO_ERRORS = {"crc_errors": 0, "version_errors": 0, "unknown_packet_errors": 0,
             "length_errors": 0}


def count_sync(data: bytes) -> int:
    return sum(1 for i in range(len(data) - 1) if data[i] == 0xEB and data[i + 1] == 0x90)
