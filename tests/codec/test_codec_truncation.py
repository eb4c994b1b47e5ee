"""SPEC.md §4.2's table of truncated frames and trailing junk, case by case."""

from __future__ import annotations

import pytest

from groundstation.codec import DatagramDecoder, FrameCodec, StreamDeframer


@pytest.fixture
def frames(dictionary):
    codec = FrameCodec(dictionary)
    pkt = dictionary.packet("HIGH_RATE")
    return codec, [codec.frame(pkt.id, bytes(pkt.fixed_payload_size), i, i) for i in (1, 2)]


def counted(counters) -> dict[str, int]:
    return {k: v for k, v in counters.as_dict().items() if v and k not in ("bytes_in", "frames")}


def n_frames(blocks) -> int:
    return sum(len(b) for b in blocks)


def test_stream_cut_frame_then_good_frame(frames):
    codec, (f1, f2) = frames
    s = StreamDeframer(codec)
    assert n_frames(s.feed(f1[:40] + f2, 0.0)) == 1
    assert counted(s.counters) == {"crc_errors": 1, "junk_bytes": 40, "resyncs": 1}


def test_stream_cut_frame_at_the_end_waits_then_is_junk_at_flush(frames):
    codec, (f1, f2) = frames
    s = StreamDeframer(codec)
    assert n_frames(s.feed(f1 + f2[:30], 0.0)) == 1
    assert counted(s.counters) == {}
    s.flush(0.0)
    assert counted(s.counters) == {"junk_bytes": 30, "resyncs": 1}


@pytest.mark.parametrize("path", ["stream", "datagram"])
def test_trailing_junk_is_junk_and_one_resync(frames, path):
    codec, (f1, _) = frames
    junk = b"\x01\x02\x03junk"
    if path == "stream":
        dec = StreamDeframer(codec)
        got = n_frames(dec.feed(f1 + junk, 0.0)) + n_frames(dec.flush(0.0))
    else:
        dec = DatagramDecoder(codec)
        got = n_frames(dec.decode([f1 + junk], 0.0))
    assert got == 1
    assert counted(dec.counters) == {"junk_bytes": len(junk), "resyncs": 1}


def test_datagram_with_a_cut_payload_keeps_the_frames_before_it(frames):
    codec, (f1, f2) = frames
    g = DatagramDecoder(codec)
    assert n_frames(g.decode([f1 + f2[:20]], 0.0)) == 1
    assert counted(g.counters) == {"length_errors": 1, "junk_bytes": 20, "resyncs": 1}


def test_datagram_with_less_than_a_header_left_is_junk(frames):
    codec, (f1, f2) = frames
    g = DatagramDecoder(codec)
    assert n_frames(g.decode([f1 + f2[:5]], 0.0)) == 1
    assert counted(g.counters) == {"junk_bytes": 5, "resyncs": 1}
