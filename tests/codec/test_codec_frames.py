"""Unit tests of the codec's frames: encode and decode in engineering and raw units, every
packet kind (fixed and variable), and the encoder's refusals."""

from __future__ import annotations

import math
import shutil
import zlib

import numpy as np
import pytest
from codec_helpers import HK_SIZE, HR_SIZE, event_frame, hk_frame

from groundstation.codec import (DatagramDecoder, FrameCodec, StreamDeframer, decode_items,
                                 encode_items)
from groundstation.codec.crc import RESIDUE, crc_bytes, frame_crc
from groundstation.core.dictionary import (FRAME_OVERHEAD, HEADER_SIZE, Item, default_protocol_dir,
                                           load_dictionary)
from groundstation.core.errors import EncodeError, FrameLengthError, UnknownPacketError


@pytest.fixture(scope="module")
def codec(dictionary):
    return FrameCodec(dictionary)


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
