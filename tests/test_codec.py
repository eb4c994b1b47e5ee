"""Unit tests of the codec: frame encode/decode, strict decode errors, CRC run check, stream
and datagram deframing with their counters."""

from __future__ import annotations

import math
import shutil
import zlib

import numpy as np
import pytest

from groundstation.codec import (DatagramDecoder, FrameCodec, StreamDeframer, decode_items,
                                 encode_items)
from groundstation.codec.crc import RESIDUE, RUN_CHUNK, crc_bytes, frame_crc, valid_frames
from groundstation.dictionary import (FRAME_OVERHEAD, HEADER_SIZE, Item, default_protocol_dir,
                                      load_dictionary)
from groundstation.errors import (CrcError, DecodeError, EncodeError, FrameLengthError,
                                  ProtocolVersionError, UnknownPacketError)

HR_SIZE = 78
HK_SIZE = 63


@pytest.fixture(scope="module")
def codec(dictionary):
    return FrameCodec(dictionary)


# ------------------------------------------------------------------------- helpers
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


# ------------------------------------------------------------------ frame encoding
def test_frame_layout_and_crc(codec):
    frame = codec.encode("HIGH_RATE", {"current_coarse": 0.0389}, sequence=0x01020304,
                         tick=0xA0B0C0D0)
    assert len(frame) == HR_SIZE
    assert frame[:2] == b"\xEB\x90" and frame[2] == 1 and frame[3] == 0x01
    assert frame[4:6] == (60).to_bytes(2, "big")
    assert frame[6:10] == bytes([1, 2, 3, 4]) and frame[10:14] == bytes([0xA0, 0xB0, 0xC0, 0xD0])
    assert frame[58:60] == b"\x01\x85"                     # 389 counts, SPEC §3.2 example
    assert frame[-4:] == zlib.crc32(frame[:-4]).to_bytes(4, "little")   # LSB first
    assert frame[-4:] == crc_bytes(frame[:-4])
    assert frame_crc(frame[:-4]) == zlib.crc32(frame[:-4])
    assert zlib.crc32(frame) == RESIDUE


def test_high_rate_round_trip_in_engineering_units(codec, dictionary):
    pkt = dictionary.packet("HIGH_RATE")
    rng = np.random.default_rng(7)
    n = 300
    values: dict[str, np.ndarray] = {}
    for item in pkt.items:
        if item.bits or item.states:
            continue
        if item.scale is not None:
            info = np.iinfo(item.wire_dtype)
            values[item.name] = rng.uniform(info.min + 1, info.max - 1, n) * item.scale
        elif item.wire_dtype.kind == "f":
            values[item.name] = rng.normal(0, 10, n)
        else:
            values[item.name] = rng.integers(0, 2**32, n)
    values["mode"] = rng.integers(0, 4, n)
    values["status"] = rng.integers(0, 64, n)
    seq = np.arange(n) + 2**32 - 100          # wraps through 2^32
    data = codec.encode("HIGH_RATE", values, sequence=seq, tick=seq * 3)
    assert len(data) == n * HR_SIZE

    blocks = StreamDeframer(codec).feed(data, 12.5)
    assert len(blocks) == 1
    block = blocks[0]
    assert block.name == "HIGH_RATE" and len(block) == n
    assert block["sequence"].dtype == np.uint32
    assert np.array_equal(block["sequence"], seq & 0xFFFFFFFF)
    assert np.array_equal(block["tick"], (seq * 3) & 0xFFFFFFFF)
    assert np.all(block.host_time == 12.5)
    for item in pkt.items:
        got = block[item.name]
        want = values[item.name]
        if item.scale is not None:
            assert got.dtype == np.float64
            # within half a count (plus rounding of the float arithmetic)
            assert np.max(np.abs(got - want)) <= item.scale * (0.5 + 1e-6), item.name
            assert np.array_equal(block.raw[item.name], np.rint(want / item.scale))
        elif item.wire_dtype.kind == "f":
            assert np.array_equal(got, want.astype(np.float32)), item.name
        else:
            assert np.array_equal(got, want), item.name
    for flag, bit in pkt.item_by_name["status"].bits.items():
        assert block[flag].dtype == bool
        assert np.array_equal(block[flag], (values["status"] >> bit) & 1 == 1)


def test_status_bits_by_flag_name(codec, dictionary):
    bits = dictionary.packet("HIGH_RATE").item_by_name["status"].bits
    armed = np.array([1, 0, 1, 0])
    fault = np.array([0, 0, 1, 1])
    data = codec.encode("HIGH_RATE", {"armed": armed, "fault": fault.astype(bool),
                                      "profile_active": True}, sequence=np.arange(4), tick=0)
    block = StreamDeframer(codec).feed(data, 0.0)[0]
    assert np.array_equal(block["armed"], armed.astype(bool))
    assert np.array_equal(block["fault"], fault.astype(bool))
    assert block["profile_active"].all()
    assert not block["coarse_saturated"].any() and not block["friction_comp_on"].any()
    want = (armed << bits["armed"]) | (fault << bits["fault"]) | (1 << bits["profile_active"])
    assert np.array_equal(block["status"], want)


def test_states_are_sent_as_their_raw_value(codec, dictionary):
    states = dictionary.packet("HIGH_RATE").item_by_name["mode"].states
    modes = [states[s] for s in ("IDLE", "OPEN_LOOP", "RELATIVE", "INERTIAL")]
    data = codec.encode("HIGH_RATE", {"mode": modes}, sequence=np.arange(4), tick=0)
    block = StreamDeframer(codec).feed(data, 0.0)[0]
    assert block["mode"].tolist() == [0, 1, 2, 3]
    assert [next(k for k, v in states.items() if v == m) for m in block["mode"]] == [
        "IDLE", "OPEN_LOOP", "RELATIVE", "INERTIAL"]


def test_encoder_limits_cover_one_turn(codec):
    frame = codec.encode("HIGH_RATE", {"encoder_outer": -math.pi, "encoder_inner": math.pi * (1 - 2**-30)},
                         sequence=0, tick=0)
    block = codec.decode_frame(frame)
    assert block["encoder_outer"][0] == -math.pi
    assert block.raw["encoder_outer"][0] == -2**31
    with pytest.raises(EncodeError, match="encoder_outer"):
        codec.encode("HIGH_RATE", {"encoder_outer": math.pi}, sequence=0, tick=0)


def test_housekeeping_round_trip(codec, dictionary):
    hk = dictionary.packet("HOUSEKEEPING").item_by_name
    values = {
        "temp_motor_coarse": 31.27, "temp_motor_fine": -5.5, "temp_flexure": 22.01,
        "temp_electronics": 41.0, "supply_motor": 28.003, "supply_logic": 5.012,
        "firmware_version": (2 << 16) | (7 << 8) | 1, "uptime": 86400 * 30,
        "param_table_crc": 0xDEADBEEF, "param_table_version": 12, "active_profile": 3,
        "watchdog": hk["watchdog"].states["EXPIRED"], "heartbeat_age": 65535,
        "commands_accepted": 1234, "commands_rejected": 5,
        "fault_code": hk["fault_code"].states["WATCHDOG"], "telemetry_overruns": 2**32 - 1,
    }
    assert set(values) == set(hk)
    frame = hk_frame(codec, 77, **values)
    assert len(frame) == HK_SIZE
    block = codec.decode_frame(frame, 3.0)
    assert block.name == "HOUSEKEEPING" and block["sequence"][0] == 77 and block["tick"][0] == 77 * 120
    for name, want in values.items():
        got = block[name][0]
        if hk[name].scale is not None:
            assert abs(got - want) <= hk[name].scale / 2 + 1e-12, name
        else:
            assert got == want, name


def test_event_with_unicode_text(codec, dictionary):
    text = "Δθ = 0.3° — überschritten; 警告 🚀"
    frame = event_frame(codec, 5, text=text, level="WARNING", code=14)
    assert len(frame) == FRAME_OVERHEAD + 3 + len(text.encode("utf-8"))
    block = codec.decode_frame(frame, 9.0)
    assert block.name == "EVENT"
    assert block["text"][0] == text
    assert block["level"][0] == dictionary.packet("EVENT").item_by_name["level"].states["WARNING"]
    assert block["code"][0] == 14 and block["sequence"][0] == 5
    assert block.frames == [frame]
    # the same through the stream deframer, with an empty text too
    empty = event_frame(codec, 6, text="")
    assert len(empty) == FRAME_OVERHEAD + 3
    blocks = StreamDeframer(codec).feed(frame + empty, 1.0)
    assert blocks[0]["text"].tolist() == [text, ""]


def test_event_with_invalid_utf8_is_decoded_with_replacement(codec):
    payload = bytes([1]) + (2).to_bytes(2, "big") + b"ok \xff\xfe end"
    frame = codec.frame(0x03, payload, 1, 1)
    block = codec.decode_frame(frame)
    assert block["text"][0] == "ok \ufffd\ufffd end"


def test_command_and_response_round_trip(codec, dictionary):
    args = encode_items(dictionary.command("SET_CURRENTS").args,
                        {"current_coarse": 0.5, "current_fine": -0.25}, "SET_CURRENTS")
    assert args == np.array([0.5, -0.25], ">f4").tobytes()
    cmd = codec.encode_variable("COMMAND", {"session_token": 0xCAFEF00D, "opcode": 0x15,
                                            "arguments": args}, 0x80000001, 0)
    block = codec.decode_frame(cmd)
    assert block["session_token"][0] == 0xCAFEF00D and block["opcode"][0] == 0x15
    assert block["arguments"][0] == args
    assert decode_items(dictionary.command("SET_CURRENTS").args, block["arguments"][0],
                        "SET_CURRENTS") == {"current_coarse": 0.5, "current_fine": -0.25}
    resp = codec.encode_variable("RESPONSE", {"command_sequence": 0x80000001, "opcode": 0x15,
                                              "stage": "COMPLETED", "reason": 0,
                                              "data": b"\x00\xEB\x90\x01"}, 9, 10)
    block = codec.decode_frame(resp)
    assert block["stage"][0] == 3 and block["data"][0] == b"\x00\xEB\x90\x01"


def test_encode_items_checks_values(dictionary):
    args = dictionary.command("SET_CURRENTS").args
    with pytest.raises(EncodeError, match="current_coarse"):
        encode_items(args, {"current_coarse": 3.0, "current_fine": 0.0}, "SET_CURRENTS")
    with pytest.raises(EncodeError, match="current_fine"):
        encode_items(args, {"current_coarse": 0.0}, "SET_CURRENTS")
    with pytest.raises(EncodeError, match="bogus"):
        encode_items(args, {"current_coarse": 0.0, "current_fine": 0.0, "bogus": 1}, "X")
    with pytest.raises(EncodeError, match="finite"):
        encode_items(args, {"current_coarse": math.nan, "current_fine": 0.0}, "X")
    mode_args = dictionary.command("SET_MODE").args
    assert encode_items(mode_args, {"mode": "INERTIAL"}, "SET_MODE") == b"\x03"
    with pytest.raises(EncodeError, match="SLEEP"):
        encode_items(mode_args, {"mode": "SLEEP"}, "SET_MODE")
    with pytest.raises(EncodeError, match="fit"):
        encode_items(mode_args, {"mode": 256}, "SET_MODE")
    begin = dictionary.command("PARAM_BEGIN").args
    with pytest.raises(EncodeError, match="table_version"):
        encode_items(begin, {"table_version": -1, "table_length": 10}, "PARAM_BEGIN")
    with pytest.raises(FrameLengthError):
        decode_items(begin, b"\x00" * 5, "PARAM_BEGIN")
    with pytest.raises(FrameLengthError):
        decode_items(begin, b"\x00" * 7, "PARAM_BEGIN")


def test_encode_errors(codec):
    with pytest.raises(EncodeError, match="current_coarse"):
        codec.encode("HIGH_RATE", {"current_coarse": 5.0}, sequence=0, tick=0)   # 50000 counts
    with pytest.raises(EncodeError, match="current_fine"):
        codec.encode("HIGH_RATE", {"current_fine": [0.0, -3.3]}, sequence=[0, 1], tick=0)
    with pytest.raises(EncodeError, match="profile_index"):
        codec.encode("HIGH_RATE", {"profile_index": -1}, sequence=0, tick=0)
    with pytest.raises(EncodeError, match="profile_index"):
        codec.encode("HIGH_RATE", {"profile_index": 2**32}, sequence=0, tick=0)
    with pytest.raises(EncodeError, match="mode"):
        codec.encode("HIGH_RATE", {"mode": 256}, sequence=0, tick=0)
    with pytest.raises(EncodeError, match="non-finite"):
        codec.encode("HIGH_RATE", {"gyro_rate": math.inf}, sequence=0, tick=0)
    with pytest.raises(EncodeError, match="gyro_rate"):
        codec.encode("HIGH_RATE", {"gyro_rate": [1.0, math.nan]}, sequence=[0, 1], tick=0)
    with pytest.raises(EncodeError, match="autocollimator"):
        codec.encode("HIGH_RATE", {"autocollimator": 40000}, sequence=0, tick=0, engineering=False)
    with pytest.raises(EncodeError, match="no_such_channel"):
        codec.encode("HIGH_RATE", {"no_such_channel": 1}, sequence=0, tick=0)
    with pytest.raises(EncodeError, match="encode_variable"):
        codec.encode("EVENT", {}, sequence=0, tick=0)
    with pytest.raises(EncodeError, match="1025"):
        codec.frame(0x03, bytes(1025), 0, 0)
    with pytest.raises(EncodeError, match="text"):
        codec.encode_variable("EVENT", {"level": 1, "code": 1, "text": b"bytes"}, 0, 0)
    with pytest.raises(EncodeError, match="arguments"):
        codec.encode_variable("COMMAND", {"session_token": 0, "opcode": 1, "arguments": "str"}, 0, 0)
    with pytest.raises(EncodeError):
        codec.encode_variable("EVENT", {"level": 1, "code": 1, "text": "x" * 1022}, 0, 0)
    with pytest.raises(UnknownPacketError):
        codec.encode(0x55, {}, sequence=0, tick=0)


def test_f32_overflow_is_an_encode_error(codec, dictionary):
    """A finite value beyond the f32 range would silently become infinity on the wire."""
    with pytest.raises(EncodeError, match="torque_fine_cmd"):
        codec.encode("HIGH_RATE", {"torque_fine_cmd": 1e39}, sequence=0, tick=0)
    with pytest.raises(EncodeError, match="gain"):
        encode_items((Item(name="gain", type="f32"),), {"gain": -1e300}, "TEST")
    assert encode_items((Item(name="gain", type="f32"),), {"gain": 3.4e38}, "TEST") == \
        np.array([3.4e38], ">f4").tobytes()
    # infinities and NaN are representable in f32 and pass through
    frame = codec.encode("HIGH_RATE", {"error_angle": math.inf, "error_rate": math.nan},
                         sequence=0, tick=0)
    block = codec.decode_frame(frame)
    assert block["error_angle"][0] == math.inf and math.isnan(block["error_rate"][0])


def test_raw_encoding_bypasses_conversion(codec):
    frame = codec.encode("HIGH_RATE", {"encoder_outer": 123456, "current_coarse": -32768},
                         sequence=1, tick=2, engineering=False)
    block = codec.decode_frame(frame)
    assert block.raw["encoder_outer"][0] == 123456
    assert block["encoder_outer"][0] == 123456 * 2 * math.pi / 2**32
    assert block["current_coarse"][0] == pytest.approx(-3.2768)


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


# ------------------------------------------------------------------ scaled items in a
#                                                                    variable packet
def test_variable_packet_with_scaled_item(tmp_path, dictionary):
    """Conversions apply once to every item, whether the packet is fixed or variable."""
    for name in ("telemetry.toml", "commands.toml", "parameters.toml"):
        shutil.copy(default_protocol_dir() / name, tmp_path / name)
    path = tmp_path / "telemetry.toml"
    text = path.read_text(encoding="utf-8")
    old = '{ name = "code", type = "u16", description'
    assert text.count(old) == 1
    text = text.replace(old, '{ name = "temperature", type = "i16", units = "degC", scale = 0.01, '
                             'bits = { negative = 15 }, description = "scaled" },\n  ' + old)
    path.write_text(text, encoding="utf-8")
    local = FrameCodec(load_dictionary(tmp_path))
    frame = local.encode_variable("EVENT", {"level": 1, "temperature": 23.45, "code": 7,
                                            "text": "warm"}, 1, 2)
    assert frame[HEADER_SIZE + 1:HEADER_SIZE + 3] == (2345).to_bytes(2, "big")
    for block in (local.decode_frame(frame), DatagramDecoder(local).decode([frame], 0.0)[0]):
        assert block["temperature"][0] == pytest.approx(23.45)
        assert block["code"][0] == 7 and block["text"][0] == "warm"
        assert not block["negative"][0]
    frame = local.encode_variable("EVENT", {"level": 1, "temperature": -1.5, "code": 7}, 1, 2)
    block = local.decode_frame(frame)
    assert block["temperature"][0] == pytest.approx(-1.5) and block["negative"][0]
    assert block["text"][0] == ""


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
