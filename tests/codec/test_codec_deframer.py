"""Unit tests of deframing: the stream deframer (chunking, junk, resynchronisation,
truncation, sync words inside frames) and the datagram decoder, with their counters."""

from __future__ import annotations

import math

import numpy as np
import pytest
from codec_helpers import (HR_SIZE, NO_ERRORS, all_frames, collect, count_sync, error_counts,
                           event_frame, feed_chunks, hk_frame, hr_frames, patched)

from groundstation.codec import DatagramDecoder, FrameCodec, StreamDeframer
from groundstation.codec.crc import crc_bytes
from groundstation.core.errors import (CrcError, FrameLengthError, ProtocolVersionError,
                                       UnknownPacketError)


@pytest.fixture(scope="module")
def codec(dictionary):
    return FrameCodec(dictionary)


# ------------------------------------------------------------------ stream deframer
@pytest.fixture(scope="module")
def mixed_stream(codec):
    """HIGH_RATE frames with HOUSEKEEPING, EVENT and RESPONSE frames interleaved."""
    hr = hr_frames(codec, 6, seq0=100)
    frames = [hr[0], hr[1], hk_frame(codec, 1), hr[2], event_frame(codec, 3, "état ✓"),
              hr[3], codec.encode_variable("RESPONSE", {"command_sequence": 1, "opcode": 3,
                                                         "stage": 1, "reason": 0}, 1, 2),
              hr[4], hk_frame(codec, 2), hr[5]]
    return frames


def test_clean_stream_in_one_feed(codec, mixed_stream):
    deframer = StreamDeframer(codec)
    blocks = deframer.feed(b"".join(mixed_stream), 1.0)
    assert deframer.buffered == 0
    assert sorted(all_frames(blocks)) == sorted(mixed_stream)
    c = deframer.counters
    assert c.frames == len(mixed_stream) and c.junk_bytes == 0 and c.resyncs == 0
    assert error_counts(c) == NO_ERRORS
    assert c.bytes_in == sum(map(len, mixed_stream))
    assert deframer.flush(2.0) == []


def test_stream_split_at_every_byte_boundary(codec, mixed_stream):
    data = b"".join(mixed_stream)
    for cut in range(len(data) + 1):
        deframer = StreamDeframer(codec)
        blocks = feed_chunks(deframer, data, [cut])
        assert sorted(all_frames(blocks)) == sorted(mixed_stream), cut
        c = deframer.counters
        assert (c.junk_bytes, c.resyncs, c.frames) == (0, 0, len(mixed_stream)), cut
        assert error_counts(c) == NO_ERRORS, cut


def test_stream_byte_by_byte(codec, mixed_stream):
    data = b"".join(mixed_stream)
    deframer = StreamDeframer(codec)
    blocks = feed_chunks(deframer, data, range(1, len(data)))
    assert all_frames(blocks) == mixed_stream        # one frame per block, in arrival order
    assert deframer.counters.junk_bytes == 0 and deframer.counters.resyncs == 0
    assert error_counts(deframer.counters) == NO_ERRORS


def test_frame_split_into_three_reads_keeps_its_arrival_time(codec):
    frame = hr_frames(codec, 1)[0]
    deframer = StreamDeframer(codec)
    assert deframer.feed(frame[:1], 1.0) == []
    assert deframer.feed(frame[1:20], 2.0) == []
    assert deframer.buffered == 20
    block = deframer.feed(frame[20:], 3.0)[0]
    assert block.host_time.tolist() == [3.0] and deframer.buffered == 0


def test_junk_before_between_and_after(codec, mixed_stream):
    junk = [b"\x00\x11\x22\x33", b"junk!", b"\x90\x90\xEB\x00", b"\xEB", b"tail\x01"]
    parts = [junk[0], *mixed_stream[:3], junk[1], *mixed_stream[3:6], junk[2],
             mixed_stream[6], junk[3], *mixed_stream[7:], junk[4]]
    data = b"".join(parts)
    # no sync word in the junk, none formed across a junk/frame boundary
    assert count_sync(data) == sum(map(count_sync, parts)) == sum(map(count_sync, mixed_stream))
    n_junk = sum(map(len, junk))
    for cuts in ([], list(range(1, len(data))), list(range(7, len(data), 13))):
        deframer = StreamDeframer(codec)
        blocks = feed_chunks(deframer, data, cuts)
        assert sorted(all_frames(blocks)) == sorted(mixed_stream)
        c = deframer.counters
        assert c.junk_bytes == n_junk
        assert c.frames == len(mixed_stream)
        assert error_counts(c) == NO_ERRORS
        if not cuts:
            assert c.resyncs == len(junk)
        else:
            assert c.resyncs >= len(junk)       # a junk run split by a read may count twice
        assert c.junk_bytes + sum(map(len, mixed_stream)) == c.bytes_in == len(data)


def test_truncated_frame_then_good_one_resynchronises(codec):
    hr = hr_frames(codec, 3)
    data = hr[0] + hr[1][:40] + hr[2]
    for cuts in ([], list(range(1, len(data))), [78, 118]):
        deframer = StreamDeframer(codec)
        got = collect(feed_chunks(deframer, data, cuts))
        assert [s for s, _ in got["HIGH_RATE"]] == [0, 2]
        c = deframer.counters
        assert c.crc_errors == 1                   # the cut frame's claimed span fails its CRC
        assert c.junk_bytes == 40
        assert (c.version_errors, c.unknown_packet_errors, c.length_errors) == (0, 0, 0)
        assert isinstance(c.recent_errors[-1], CrcError)


def test_truncated_frame_then_short_frame_at_end_of_stream(codec):
    """At flush, a truncated frame whose claimed span reaches past the end must not hide
    the complete frame after it."""
    hr = hr_frames(codec, 2)
    ev = event_frame(codec, 9, text="x")            # 22 bytes, shorter than the HIGH_RATE cut
    data = hr[0] + hr[1][:30] + ev
    assert 78 + 30 + 78 > len(data)
    for cuts in ([], list(range(1, len(data)))):
        deframer = StreamDeframer(codec)
        got = collect(feed_chunks(deframer, data, cuts))
        assert [s for s, _ in got["HIGH_RATE"]] == [0]
        assert got["EVENT"] == [(9, ev)]
        assert deframer.counters.junk_bytes == 30
        assert deframer.counters.frames == 2


def test_truncated_frame_at_end_of_stream_is_junk(codec):
    hr = hr_frames(codec, 2)
    deframer = StreamDeframer(codec)
    blocks = deframer.feed(hr[0] + hr[1][:50], 0.0)
    assert collect(blocks)["HIGH_RATE"][0][0] == 0
    assert deframer.buffered == 50                  # waiting for the rest
    assert deframer.flush(1.0) == []
    assert deframer.counters.junk_bytes == 50 and deframer.buffered == 0


def test_sync_word_inside_payload(codec):
    """Payloads carrying EB 90 followed by a plausible header (version 1, HIGH_RATE, 60)."""
    fake_header = int.from_bytes(b"\xEB\x90\x01\x01", "big", signed=True)
    frames = hr_frames(codec, 8, encoder_outer=fake_header * 2 * math.pi / 2**32,
                       encoder_inner=int.from_bytes(b"\x00\x3C\x00\x00", "big") * 2 * math.pi / 2**32,
                       profile_index=0xEB90EB90)
    data = b"".join(frames)
    assert count_sync(data) == 8 * 4          # frame start, fake header, two in profile_index
    assert data[16:22] == b"\xEB\x90\x01\x01\x00\x3C"
    for cuts in ([], list(range(1, len(data))), [17, 30, 78 + 16, 78 + 18, 3 * 78 - 4]):
        deframer = StreamDeframer(codec)
        blocks = feed_chunks(deframer, data, cuts)
        assert all_frames(blocks) == frames
        c = deframer.counters
        assert (c.junk_bytes, c.resyncs, c.frames) == (0, 0, 8)
        assert error_counts(c) == NO_ERRORS


def test_sync_word_in_the_last_bytes_of_a_frame(codec):
    """A sync word (or a lone 0xEB) in the last header-length bytes of a frame that ends
    a read belongs to the accepted frame: it must not be kept and later counted as junk."""
    tail_sync = hr_frames(codec, 4, profile_index=0x0000EB90)    # EB 90 at frame offset 72
    assert all(f[72:74] == b"\xEB\x90" for f in tail_sync)
    # frames whose last CRC byte is 0xEB
    seqs = [s for s in range(3000) if crc_bytes(hr_frames(codec, 1, seq0=s)[0][:-4])[-1] == 0xEB]
    last_eb = [hr_frames(codec, 1, seq0=s)[0] for s in seqs[:4]]
    assert len(last_eb) == 4
    for frames in (tail_sync, last_eb):
        data = b"".join(frames)
        deframer = StreamDeframer(codec)
        blocks = feed_chunks(deframer, data, [78, 156, 234])         # one read per frame
        assert all_frames(blocks) == frames
        c = deframer.counters
        assert (c.junk_bytes, c.resyncs, c.frames) == (0, 0, 4)
        assert error_counts(c) == NO_ERRORS


def test_counters_for_constructed_faults(codec):
    hr = hr_frames(codec, 10)
    v2 = patched(hr[1], 2, b"\x02")                          # version 2
    unknown = patched(hr[3], 3, b"\x7F")                     # packet id 0x7F
    bad_len = patched(hr[5], 4, (1000).to_bytes(2, "big"))   # HIGH_RATE is 60 bytes
    flipped = bytearray(hr[7])
    flipped[40] ^= 0x02                                       # CRC error
    stream = [hr[0], v2, hr[2], unknown, hr[4], bad_len, hr[6], bytes(flipped), hr[8], hr[9]]
    data = b"".join(stream)
    assert count_sync(data) == 10        # no accidental sync words in the constructed frames
    good = [hr[i] for i in (0, 2, 4, 6, 8, 9)]
    for cuts in ([], list(range(1, len(data))), list(range(50, len(data), 50))):
        deframer = StreamDeframer(codec)
        blocks = feed_chunks(deframer, data, cuts)
        assert all_frames(blocks) == good
        c = deframer.counters
        assert error_counts(c) == {"crc_errors": 1, "version_errors": 1,
                                   "unknown_packet_errors": 1, "length_errors": 1}
        assert c.junk_bytes == 4 * HR_SIZE
        assert c.frames == 6
        if not cuts:
            assert c.resyncs == 4
        kinds = {type(e) for e in c.recent_errors}
        assert kinds == {CrcError, ProtocolVersionError, UnknownPacketError, FrameLengthError}
        messages = " ".join(map(str, c.recent_errors))
        assert "0x7F" in messages and "version 2" in messages and "1000" in messages
        assert c.as_dict()["crc_errors"] == 1 and "recent_errors" not in c.as_dict()


def test_many_rejected_candidates_in_one_read_are_all_counted(codec):
    hr = hr_frames(codec, 200)
    data = b"".join(patched(f, 2, b"\x02") if i % 2 else f for i, f in enumerate(hr))
    deframer = StreamDeframer(codec)
    blocks = deframer.feed(data, 0.0) + deframer.flush(0.0)
    assert len(all_frames(blocks)) == 100
    assert deframer.counters.version_errors == 100
    assert deframer.counters.junk_bytes == 100 * HR_SIZE
    assert len(deframer.counters.recent_errors) == deframer.counters.recent_errors.maxlen


def test_interleaving_keeps_order_within_each_packet(codec):
    n = 480
    hr = hr_frames(codec, n, seq0=2**32 - 200)
    stream, hk_seqs = [], []
    for i, f in enumerate(hr):
        stream.append(f)
        if i % 120 == 17:
            stream.append(hk_frame(codec, i))
            hk_seqs.append(i)
        if i % 97 == 3:
            stream.append(event_frame(codec, i, text=f"event {i}"))
    data = b"".join(stream)
    want_hr = [(2**32 - 200 + i) & 0xFFFFFFFF for i in range(n)]
    rng = np.random.default_rng(3)
    for cuts in ([], sorted(rng.choice(len(data), 60, replace=False).tolist())):
        got = collect(feed_chunks(StreamDeframer(codec), data, cuts))
        assert [s for s, _ in got["HIGH_RATE"]] == want_hr
        assert [s for s, _ in got["HOUSEKEEPING"]] == hk_seqs
        assert [s for s, _ in got["EVENT"]] == [i for i in range(n) if i % 97 == 3]
    decoder = DatagramDecoder(codec)
    got = collect(decoder.decode([b"".join(stream[k:k + 5]) for k in range(0, len(stream), 5)],
                                 1.0))
    assert [s for s, _ in got["HIGH_RATE"]] == want_hr
    assert [s for s, _ in got["HOUSEKEEPING"]] == hk_seqs


def test_lone_sync_byte_at_the_end_waits_for_the_next_read(codec):
    hr = hr_frames(codec, 2)
    deframer = StreamDeframer(codec)
    deframer.feed(hr[0] + b"ab\xEB", 0.0)
    assert deframer.buffered == 1 and deframer.counters.junk_bytes == 2
    blocks = deframer.feed(hr[1][1:], 1.0)                   # the 0xEB was the frame's start
    assert all_frames(blocks) == [hr[1]]
    deframer.feed(b"\xEB", 2.0)
    assert deframer.flush(3.0) == []
    assert deframer.counters.junk_bytes == 3 and deframer.counters.frames == 2


# ------------------------------------------------------------------ datagram decoder
def test_datagrams_with_several_frames(codec, mixed_stream):
    datagrams = [b"".join(mixed_stream[0:3]), b"".join(mixed_stream[3:4]),
                 b"".join(mixed_stream[4:9]), mixed_stream[9]]
    times = [10.0, 11.0, 12.0, 13.0]
    decoder = DatagramDecoder(codec)
    blocks = decoder.decode(datagrams, times)
    assert sorted(all_frames(blocks)) == sorted(mixed_stream)
    arrival = {f: t for d, t in zip(datagrams, times) for f in mixed_stream if f in d}
    for b in blocks:
        frames = [r.tobytes() for r in b.raw] if b.raw is not None else b.frames
        assert b.host_time.tolist() == [arrival[f] for f in frames]
    c = decoder.counters
    assert c.frames == 10 and c.junk_bytes == 0 and error_counts(c) == NO_ERRORS
    assert decoder.decode([], []) == []


@pytest.mark.parametrize("position", ["first", "middle", "last"])
def test_datagram_with_frame_truncated_at_its_end(codec, position):
    hr = hr_frames(codec, 9)
    cut = hr[4][:50]
    datagrams = [hr[0] + hr[1], hr[2] + hr[3], hr[5] + hr[6], hr[7] + hr[8]]
    index = {"first": 0, "middle": 1, "last": 3}[position]
    datagrams[index] = datagrams[index] + cut
    decoder = DatagramDecoder(codec)
    got = collect(decoder.decode(datagrams, 1.0))
    assert [s for s, _ in got["HIGH_RATE"]] == [0, 1, 2, 3, 5, 6, 7, 8]
    c = decoder.counters
    assert c.length_errors == 1 and c.crc_errors == 0
    assert c.junk_bytes == 50 and c.frames == 8
    assert isinstance(c.recent_errors[-1], FrameLengthError)
    assert "datagram" in str(c.recent_errors[-1])


def test_datagram_truncated_frame_then_short_frame(codec):
    """Truncated frame, then a short complete frame, in the last datagram of a batch."""
    hr = hr_frames(codec, 2)
    ev = event_frame(codec, 4, "x")
    decoder = DatagramDecoder(codec)
    got = collect(decoder.decode([hr[0], hr[1][:30] + ev], [1.0, 2.0]))
    assert [s for s, _ in got["HIGH_RATE"]] == [0]
    assert got["EVENT"] == [(4, ev)]
    assert decoder.counters.length_errors == 1 and decoder.counters.junk_bytes == 30


def test_frame_spanning_two_datagrams_is_not_reassembled(codec):
    hr = hr_frames(codec, 3)
    decoder = DatagramDecoder(codec)
    got = collect(decoder.decode([hr[0] + hr[1][:30], hr[1][30:] + hr[2]], [1.0, 2.0]))
    assert [s for s, _ in got["HIGH_RATE"]] == [0, 2]
    assert decoder.counters.length_errors == 1
    assert decoder.counters.junk_bytes == 78


def test_datagram_decoder_counts_across_calls(codec):
    hr = hr_frames(codec, 4)
    decoder = DatagramDecoder(codec)
    decoder.decode([hr[0], b"\x00\x01" + hr[1]], 1.0)
    decoder.decode([hr[2] + b"\xEB", hr[3]], 2.0)
    c = decoder.counters
    assert c.frames == 4 and c.junk_bytes == 3 and c.resyncs == 2
    assert c.bytes_in == 4 * 78 + 3
