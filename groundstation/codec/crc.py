"""Frame CRC: CRC-32/ISO-HDLC (the zlib/Ethernet CRC) over sync..payload, appended
least-significant byte first.

Appending it LSB-first gives the classic property that the CRC register after a whole
valid frame (CRC included) is the constant RESIDUE.  That lets us check a run of
back-to-back frames with a single zlib.crc32 call over the run: no library computes
one CRC per frame over a numpy array of frames, and a Python loop of zlib calls costs
about as much as all the rest of the decoding, so this is written here.  Only when a
run's check fails do we fall back to one zlib call per frame to find the bad frames.
"""

from __future__ import annotations

import zlib
from functools import lru_cache

import numpy as np

RESIDUE = 0x2144DF1C          # zlib.crc32(frame_with_its_crc) for every valid frame
RUN_CHUNK = 32                # at most this many frames per run check
# CRC-32 detects any 3 bit errors in messages up to 91 607 bits (Koopman): a run check
# covers at most that many bits, so it guarantees at least what one CRC over a message of
# that size does; the per-frame checks it stands for guarantee more (HD 6 for HIGH_RATE).
RUN_MAX_BYTES = 91607 // 8


def frame_crc(content: bytes | memoryview) -> int:
    """CRC to append to `content` (= sync .. end of payload)."""
    return zlib.crc32(content)


def crc_bytes(content: bytes | memoryview) -> bytes:
    return zlib.crc32(content).to_bytes(4, "little")


@lru_cache(maxsize=64)
def _run_expectations(frame_len: int) -> tuple[int, ...]:
    """Expected zlib.crc32 over k back-to-back valid frames of `frame_len` bytes, k=0..RUN_CHUNK.

    CRC-32 is affine in (initial register, message): crc(m, v) = crc(m, 0) ^ crc(0^n, v) ^
    crc(0^n, 0).  For a valid frame crc(m, 0) = RESIDUE, so the register after each valid
    frame depends only on the register before it, not on the frame's contents.
    """
    zeros = bytes(frame_len)
    z0 = zlib.crc32(zeros, 0)
    out = [0]
    v = 0
    for _ in range(RUN_CHUNK):
        v = RESIDUE ^ zlib.crc32(zeros, v) ^ z0
        out.append(v)
    return tuple(out)


def valid_frames(buf: bytes | memoryview, starts: np.ndarray, lengths: np.ndarray) -> np.ndarray:
    """Boolean array: does the frame at each start (of the given total length) carry a
    correct CRC?  `starts` must be sorted; back-to-back frames of equal length are checked
    in runs of up to RUN_CHUNK frames."""
    n = len(starts)
    ok = np.zeros(n, dtype=bool)
    if n == 0:
        return ok
    mv = memoryview(buf)
    starts = np.asarray(starts, dtype=np.int64)
    lengths = np.asarray(lengths, dtype=np.int64)
    ends = starts + lengths
    # a run continues while the next frame starts where this one ends, with the same length
    breaks = np.flatnonzero((starts[1:] != ends[:-1]) | (lengths[1:] != lengths[:-1])) + 1
    bounds = np.concatenate(([0], breaks, [n]))
    s_list = starts.tolist()
    l_list = lengths.tolist()
    for a, b in zip(bounds[:-1].tolist(), bounds[1:].tolist()):
        length = l_list[a]
        expect = _run_expectations(length)
        chunk = max(1, min(RUN_CHUNK, RUN_MAX_BYTES // length))
        for c0 in range(a, b, chunk):
            c1 = min(c0 + chunk, b)
            s = s_list[c0]
            if zlib.crc32(mv[s:s + (c1 - c0) * length]) == expect[c1 - c0]:
                ok[c0:c1] = True
            else:
                for i in range(c0, c1):
                    si = s_list[i]
                    ok[i] = zlib.crc32(mv[si:si + length]) == RESIDUE
    return ok
