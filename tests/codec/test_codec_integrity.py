"""Unit tests of the codec's integrity checks: strict decoding of one frame (version,
packet id, length, CRC errors) and the CRC run check over many frames at once."""

from __future__ import annotations

import zlib

import numpy as np
import pytest
from codec_helpers import HR_SIZE, event_frame, hk_frame, hr_frames, patched, refresh_crc

from groundstation.codec import FrameCodec
from groundstation.codec.crc import RESIDUE, RUN_CHUNK, valid_frames
from groundstation.core.errors import (CrcError, DecodeError, FrameLengthError, ProtocolVersionError,
                                       UnknownPacketError)


@pytest.fixture(scope="module")
def codec(dictionary):
    return FrameCodec(dictionary)


# ------------------------------------------------------------------ strict decoding
def test_decode_frame_protocol_version_error(codec):
    good = hr_frames(codec, 1)[0]
    v2 = patched(good, 2, b"\x02")
    assert zlib.crc32(v2) == RESIDUE
    with pytest.raises(ProtocolVersionError) as info:
        codec.decode_frame(v2)
    message = str(info.value)
    assert "version 2" in message and "version 1" in message
    assert isinstance(info.value, DecodeError)


def test_decode_frame_unknown_packet(codec):
    bad = patched(hr_frames(codec, 1)[0], 3, b"\x7F")
    with pytest.raises(UnknownPacketError, match="0x7F"):
        codec.decode_frame(bad)


def test_decode_frame_length_errors(codec):
    good = hr_frames(codec, 1)[0]
    with pytest.raises(FrameLengthError, match="HIGH_RATE"):
        codec.decode_frame(patched(good, 4, (59).to_bytes(2, "big")))       # length field
    with pytest.raises(FrameLengthError):
        codec.decode_frame(refresh_crc(good[:-5] + good[-4:]))            # frame too short
    with pytest.raises(FrameLengthError):
        codec.decode_frame(good + b"\x00")                                 # frame too long
    with pytest.raises(FrameLengthError, match="shorter"):
        codec.decode_frame(good[:17])
    with pytest.raises(FrameLengthError, match="sync"):
        codec.decode_frame(patched(good, 0, b"\xEB\x91"))
    ev = event_frame(codec, 1)
    with pytest.raises(FrameLengthError, match="EVENT"):
        codec.decode_frame(patched(ev, 4, (2).to_bytes(2, "big")))         # below fixed part


def test_decode_frame_crc_error(codec):
    good = hr_frames(codec, 1)[0]
    for pos in (0 + 14, 40, 73, 74, 77):
        bad = bytearray(good)
        bad[pos] ^= 0x10
        with pytest.raises(CrcError, match="HIGH_RATE"):
            codec.decode_frame(bytes(bad))
    ev = bytearray(event_frame(codec, 1, text="abc"))
    ev[-6] ^= 1
    with pytest.raises(CrcError, match="EVENT"):
        codec.decode_frame(bytes(ev))


# ------------------------------------------------------------------ CRC run check
def test_valid_frames_run_check_matches_zlib(codec):
    n = 3 * RUN_CHUNK + 7
    frames = hr_frames(codec, n)
    base = b"".join(frames)
    starts = np.arange(n) * HR_SIZE
    lengths = np.full(n, HR_SIZE)
    assert valid_frames(base, starts, lengths).all()
    for bad_index in (0, RUN_CHUNK - 1, RUN_CHUNK, n // 2, n - 1):
        for pos in (2, 30, HR_SIZE - 1):
            buf = bytearray(base)
            buf[bad_index * HR_SIZE + pos] ^= 0x80
            ok = valid_frames(bytes(buf), starts, lengths)
            reference = np.array([zlib.crc32(buf[s:s + HR_SIZE]) == RESIDUE for s in starts])
            assert np.array_equal(ok, reference)
            assert np.flatnonzero(~ok).tolist() == [bad_index]


def test_valid_frames_two_bad_frames_in_one_chunk(codec):
    frames = hr_frames(codec, 2 * RUN_CHUNK)
    buf = bytearray(b"".join(frames))
    buf[5 * HR_SIZE + 20] ^= 0x01
    buf[9 * HR_SIZE + 20] ^= 0x01
    n = len(frames)
    ok = valid_frames(bytes(buf), np.arange(n) * HR_SIZE, np.full(n, HR_SIZE))
    assert np.flatnonzero(~ok).tolist() == [5, 9]


def test_valid_frames_mixed_lengths_and_gaps(codec):
    hr = hr_frames(codec, 40)
    pieces, starts, lengths = [], [], []
    pos = 0
    for i, f in enumerate(hr):
        if i % 7 == 3:
            pieces.append(b"\x00" * 3)
            pos += 3
        if i % 11 == 5:
            f = hk_frame(codec, i)
        pieces.append(f)
        starts.append(pos)
        lengths.append(len(f))
        pos += len(f)
    buf = bytearray(b"".join(pieces))
    buf[starts[20] + 50] ^= 4
    ok = valid_frames(bytes(buf), np.array(starts), np.array(lengths))
    reference = [zlib.crc32(buf[s:s + ln]) == RESIDUE for s, ln in zip(starts, lengths)]
    assert ok.tolist() == reference
    assert not ok[20] and ok.sum() == 39
    assert valid_frames(b"", np.zeros(0, np.int64), np.zeros(0, np.int64)).shape == (0,)
