"""The suite's own frame scanner (conformance/frames.py): it must find what SPEC §2/§4
call good frames and count, with an example, every kind of bad one."""

from __future__ import annotations

import zlib

from groundstation.codec import FrameCodec
from groundstation.conformance.frames import FrameJudge, FramingReport, command_frame
from groundstation.core.dictionary import load_dictionary

D = load_dictionary()
CODEC = FrameCodec(D)
LIMITS = {p.id: (p.fixed_payload_size, D.max_payload if p.variable_item else p.fixed_payload_size)
          for p in D.packets}


def judge():
    report = FramingReport()
    return FrameJudge(D.version_major, LIMITS, report), report


def high_rate(seq: int) -> bytes:
    return CODEC.encode("HIGH_RATE", {"mode": 2}, [seq], [seq + 100])


def test_good_frames_in_pieces_are_found_with_their_header_fields():
    j, report = judge()
    data = high_rate(1) + high_rate(2) + high_rate(3)
    found = []
    for i in range(0, len(data), 7):               # a stream cut anywhere
        found += j.feed_stream(data[i:i + 7])
    assert [(pid, seq, tick) for pid, seq, tick, _, _ in found] == \
        [(1, 1, 101), (1, 2, 102), (1, 3, 103)]
    assert report.frames == 3 and report.faults == 0 and report.junk_bytes == 0


def test_a_wrong_crc_is_counted_with_evidence_and_the_next_frame_still_found():
    j, report = judge()
    bad = bytearray(high_rate(1))
    body = bytes(bad[:-4])
    bad[-4:] = zlib.crc32(body[2:]).to_bytes(4, "little")      # CRC without the sync word
    found = j.feed_stream(bytes(bad) + high_rate(2))
    assert [seq for _, seq, _, _, _ in found] == [2]
    assert report.crc_errors == 1
    assert "CRC-32 of bytes 0..73" in report.examples["crc_errors"]


def test_version_length_and_split_datagram_errors_are_counted():
    j, report = judge()
    other_version = bytearray(high_rate(1))
    other_version[2] = D.version_major + 1
    j.feed_datagram(bytes(other_version))
    j.feed_datagram(high_rate(2)[:40])                          # cut inside its datagram
    assert report.version_errors == 1 and report.split_frames == 1
    assert report.frames == 0


def test_the_command_frame_is_the_spec_example():
    """SPEC §13.2: ARM as command 7 with token 0x1234ABCD."""
    frame = command_frame(1, 0x10, 7, 0x1234ABCD, 0x0011, b"")
    assert frame.hex(" ").upper() == ("EB 90 01 10 00 06 00 00 00 07 00 00 00 00 "
                                      "12 34 AB CD 00 11 40 BB D1 70")
