"""protocol/SPEC.md §2–§4 checked against the ground station's decoder: an encoder written
from SPEC.md alone.

The encoder below uses only `struct`, `zlib` and `tomllib` (to read the normative item
lists in protocol/*.toml, through spec_helpers) and nothing from the groundstation
package. The frames it builds are fed through the real decoder (`StreamDeframer`,
`DatagramDecoder`, `FrameCodec.decode_frame`), and every value must come out as intended.
"""

from __future__ import annotations

import struct
import zlib

import pytest
from spec_helpers import (HEADER, PROTOCOL, RESIDUE, SPEC, STRUCT_CODE, SYNC, VERSION,
                          assert_item, load_toml)

# =====================================================================================
# Independent encoder (SPEC.md + protocol/*.toml; struct and zlib only)
# =====================================================================================

# SPEC §5.1 HIGH_RATE layout, in payload order: (name, type, scale)
ENC = 1.4629180792671596e-09
HIGH_RATE_LAYOUT = [
    ("mode", "u8", None), ("status", "u8", None),
    ("encoder_outer", "i32", ENC), ("encoder_inner", "i32", ENC),
    ("encoder_base", "i32", 1.1984224905356572e-05), ("gyro_rate", "i32", 3e-08),
    ("autocollimator", "i16", 1.7577399614188933e-07), ("los_estimate", "i32", ENC),
    ("reference", "i32", ENC), ("error_angle", "f32", None), ("error_rate", "f32", None),
    ("torque_coarse_cmd", "f32", None), ("torque_fine_cmd", "f32", None),
    ("current_coarse", "i16", 1e-4), ("current_fine", "i16", 1e-4),
    ("voltage_coarse", "i16", 1e-3), ("voltage_fine", "i16", 1e-3),
    ("friction_comp_torque", "f32", None), ("profile_index", "u32", None),
]
HIGH_RATE_MODES = {"IDLE": 0, "OPEN_LOOP": 1, "RELATIVE": 2, "INERTIAL": 3}
HIGH_RATE_BITS = {"armed": 0, "coarse_saturated": 1, "fine_saturated": 2,
                  "profile_active": 3, "friction_comp_on": 4, "fault": 5}


def crc32_table_driven(data: bytes) -> int:
    """The C routine of SPEC §2.1, transliterated."""
    table = []
    for n in range(256):
        c = n
        for _ in range(8):
            c = (0xEDB88320 ^ (c >> 1)) if c & 1 else (c >> 1)
        table.append(c)
    c = 0xFFFFFFFF
    for b in data:
        c = table[(c ^ b) & 0xFF] ^ (c >> 8)
    return c ^ 0xFFFFFFFF


def build_frame(packet_id: int, payload: bytes, sequence: int, tick: int) -> bytes:
    """SPEC §2: big-endian header, payload, CRC-32 least significant byte first."""
    body = HEADER.pack(SYNC, VERSION, packet_id, len(payload),
                       sequence & 0xFFFFFFFF, tick & 0xFFFFFFFF) + payload
    return body + struct.pack("<I", zlib.crc32(body))


def to_counts(value: float, scale: float, offset: float = 0.0) -> int:
    """SPEC §3.2: raw = round((eng - offset) / scale)."""
    return int(round((value - offset) / scale))


def encode_high_rate(values: dict) -> bytes:
    """HIGH_RATE payload straight from the SPEC §5.1 table."""
    status = 0
    for flag, bit in HIGH_RATE_BITS.items():
        if values.get(flag):
            status |= 1 << bit
    out = b""
    for name, type_, scale in HIGH_RATE_LAYOUT:
        if name == "mode":
            raw = HIGH_RATE_MODES[values["mode"]]
        elif name == "status":
            raw = status
        elif scale is not None:
            raw = to_counts(values[name], scale)
        else:
            raw = values[name]
        out += struct.pack(">" + STRUCT_CODE[type_], raw)
    return out


def toml_packet(name: str) -> dict:
    return next(p for p in load_toml("telemetry.toml")["packet"] if p["name"] == name)


def encode_items(items: list[dict], values: dict) -> bytes:
    """Generic payload encoder for an item list read from the TOML (SPEC §3)."""
    out = b""
    for item in items:
        type_ = item["type"]
        if type_ in ("str", "bytes"):               # variable-length last item
            value = values.get(item["name"], "" if type_ == "str" else b"")
            out += value.encode("utf-8") if type_ == "str" else bytes(value)
            continue
        if "bits" in item:
            raw = 0
            for flag, bit in item["bits"].items():
                if values.get(flag):
                    raw |= 1 << bit
        else:
            value = values[item["name"]]
            if isinstance(value, str):
                raw = item["states"][value]
            elif "scale" in item:
                raw = to_counts(value, item["scale"], item.get("offset", 0.0))
            else:
                raw = value
        out += struct.pack(">" + STRUCT_CODE[type_], raw)
    return out


# --- the frames under test ------------------------------------------------------------

HIGH_RATE_VALUES = [
    dict(sequence=0xFFFFFFFE, tick=0xFFFFFFFE, mode="IDLE", encoder_outer=0.0,
         encoder_inner=0.0, encoder_base=0.0, gyro_rate=0.0, autocollimator=0.0,
         los_estimate=0.0, reference=0.0, error_angle=0.0, error_rate=0.0,
         torque_coarse_cmd=0.0, torque_fine_cmd=0.0, current_coarse=0.0, current_fine=0.0,
         voltage_coarse=0.0, voltage_fine=0.0, friction_comp_torque=0.0, profile_index=0),
    dict(sequence=0xFFFFFFFF, tick=0xFFFFFFFF, mode="OPEN_LOOP", armed=True,
         coarse_saturated=True, encoder_outer=-0.3, encoder_inner=-0.2987654,
         encoder_base=0.01234, gyro_rate=-1.5, autocollimator=-0.005, los_estimate=-0.29,
         reference=0.0, error_angle=-1.0e-7, error_rate=0.0, torque_coarse_cmd=81.3,
         torque_fine_cmd=-16.1, current_coarse=2.5, current_fine=-1.0,
         voltage_coarse=28.5, voltage_fine=-6.8, friction_comp_torque=-2.25,
         profile_index=2399999),
    dict(sequence=0, tick=0, mode="RELATIVE", armed=True, friction_comp_on=True,
         profile_active=True, encoder_outer=0.001, encoder_inner=0.0012,
         encoder_base=-0.0005, gyro_rate=-0.0003, autocollimator=0.0001,
         los_estimate=0.0011, reference=0.00125, error_angle=5e-05, error_rate=0.0,
         torque_coarse_cmd=1.25, torque_fine_cmd=-0.5, current_coarse=0.0389,
         current_fine=-0.0311, voltage_coarse=0.187, voltage_fine=-0.211,
         friction_comp_torque=0.75, profile_index=17),
    dict(sequence=1, tick=2, mode="INERTIAL", armed=True, fine_saturated=True, fault=True,
         encoder_outer=0.3403, encoder_inner=0.3399, encoder_base=-0.05, gyro_rate=17.0,
         autocollimator=0.00575, los_estimate=3.0e-6, reference=-0.349,
         error_angle=3.5e-3, error_rate=-0.0123, torque_coarse_cmd=-40.0,
         torque_fine_cmd=8.0, current_coarse=-2.53, current_fine=0.9999,
         voltage_coarse=-12.345, voltage_fine=6.8, friction_comp_torque=1.0e-3,
         profile_index=0xFFFFFFFF),
    dict(sequence=2, tick=4, mode="INERTIAL", armed=True, encoder_outer=-1e-9,
         encoder_inner=1e-9, encoder_base=2.0, gyro_rate=-17.0, autocollimator=-0.00575,
         los_estimate=-3.0e-6, reference=0.349, error_angle=-3.5e-3, error_rate=0.0123,
         torque_coarse_cmd=-81.3, torque_fine_cmd=16.1, current_coarse=-0.0001,
         current_fine=0.0001, voltage_coarse=0.001, voltage_fine=-0.001,
         friction_comp_torque=-1.0e-3, profile_index=1),
]

HOUSEKEEPING_VALUES = dict(
    temp_motor_coarse=23.45, temp_motor_fine=31.2, temp_flexure=27.0, temp_electronics=-5.5,
    supply_motor=28.0, supply_logic=5.01, firmware_version=(1 << 16) | (2 << 8) | 3,
    uptime=3600, param_table_crc=0x005F94DD, param_table_version=3, active_profile=7,
    watchdog="EXPIRED", heartbeat_age=65535, commands_accepted=1234, commands_rejected=5,
    fault_code="WATCHDOG", telemetry_overruns=2)

EVENT_VALUES = dict(level="CRITICAL", code=14,
                    text="watchdog expired: motors off, Δt = 1.0 s, 1 µrad")

TOKEN = 0xCAFEF00D
SET_CURRENTS_ARGS = struct.pack(">ff", 0.5, -0.25)
COMMAND_VALUES = dict(session_token=TOKEN, opcode=0x0015, arguments=SET_CURRENTS_ARGS)


def high_rate_frame(values: dict) -> bytes:
    return build_frame(0x01, encode_high_rate(values), values["sequence"], values["tick"])


def all_frames() -> dict[str, list[bytes]]:
    return {
        "HIGH_RATE": [high_rate_frame(v) for v in HIGH_RATE_VALUES],
        "HOUSEKEEPING": [build_frame(0x02, encode_items(toml_packet("HOUSEKEEPING")["items"],
                                                        HOUSEKEEPING_VALUES), 77, 120_000)],
        "EVENT": [build_frame(0x03, encode_items(toml_packet("EVENT")["items"], EVENT_VALUES),
                              5, 120_001)],
        "COMMAND": [build_frame(0x10, encode_items(toml_packet("COMMAND")["items"],
                                                   COMMAND_VALUES), 0x80000001, 0)],
    }


# =====================================================================================
# Checking side: the ground station's decoder
# =====================================================================================

from groundstation.codec import DatagramDecoder, FrameCodec, StreamDeframer  # noqa: E402
from groundstation.core.dictionary import load_dictionary  # noqa: E402


@pytest.fixture(scope="module")
def dictionary():
    return load_dictionary(PROTOCOL)


@pytest.fixture(scope="module")
def codec(dictionary):
    return FrameCodec(dictionary)


def merge(blocks) -> dict[str, dict[str, list]]:
    """Blocks from several feed() calls -> packet name -> column -> list of values."""
    out: dict[str, dict[str, list]] = {}
    for block in blocks:
        cols = out.setdefault(block.name, {})
        for name, col in block.columns.items():
            cols.setdefault(name, []).extend(col.tolist())
    return out


def check_high_rate(cols: dict, values: list[dict]) -> None:
    assert len(cols["sequence"]) == len(values)
    for k, v in enumerate(values):
        assert cols["sequence"][k] == v["sequence"] & 0xFFFFFFFF
        assert cols["tick"][k] == v["tick"] & 0xFFFFFFFF
        assert cols["mode"][k] == HIGH_RATE_MODES[v["mode"]]
        for flag in HIGH_RATE_BITS:
            assert cols[flag][k] == bool(v.get(flag)), (k, flag)
        for name, type_, scale in HIGH_RATE_LAYOUT[2:]:
            assert_item(scale, type_, cols[name][k], v[name], f"HIGH_RATE[{k}].{name}")


def check_toml_packet(cols: dict, packet: str, values: dict, k: int = 0) -> None:
    for item in toml_packet(packet)["items"]:
        name = item["name"]
        if "bits" in item:
            for flag in item["bits"]:
                assert cols[flag][k] == bool(values.get(flag))
            continue
        intended = values[name]
        if isinstance(intended, str) and "states" in item:
            intended = item["states"][intended]
        assert_item(item.get("scale"), item["type"], cols[name][k], intended, f"{packet}.{name}")


def check_everything(decoded: dict) -> None:
    assert sorted(decoded) == ["COMMAND", "EVENT", "HIGH_RATE", "HOUSEKEEPING"]
    check_high_rate(decoded["HIGH_RATE"], HIGH_RATE_VALUES)
    hk = decoded["HOUSEKEEPING"]
    assert hk["sequence"] == [77] and hk["tick"] == [120_000]
    check_toml_packet(hk, "HOUSEKEEPING", HOUSEKEEPING_VALUES)
    ev = decoded["EVENT"]
    assert ev["sequence"] == [5] and ev["tick"] == [120_001]
    check_toml_packet(ev, "EVENT", EVENT_VALUES)
    cmd = decoded["COMMAND"]
    assert cmd["sequence"] == [0x80000001] and cmd["tick"] == [0]
    check_toml_packet(cmd, "COMMAND", COMMAND_VALUES)
    assert struct.unpack(">ff", cmd["arguments"][0]) == (0.5, -0.25)


# --- CRC -------------------------------------------------------------------------------

def test_crc_check_value_and_residue():
    assert zlib.crc32(b"123456789") == 0xCBF43926
    assert crc32_table_driven(b"123456789") == 0xCBF43926
    sample = bytes(range(256)) * 3
    assert crc32_table_driven(sample) == zlib.crc32(sample)
    text = SPEC.read_text(encoding="utf-8")
    assert "0xCBF43926" in text and "0x2144DF1C" in text
    for frames in all_frames().values():
        for frame in frames:
            assert zlib.crc32(frame) == RESIDUE


# --- the independent encoder against the decoder --------------------------------------

def test_generic_toml_encoder_matches_spec_table():
    """The §5.1 table and the TOML item list give the same HIGH_RATE bytes."""
    items = toml_packet("HIGH_RATE")["items"]
    assert [(i["name"], i["type"], i.get("scale")) for i in items] == HIGH_RATE_LAYOUT
    for v in HIGH_RATE_VALUES:
        assert encode_items(items, v) == encode_high_rate(v)


def test_each_frame_decodes_strictly(codec):
    for name, frames in all_frames().items():
        blocks = [codec.decode_frame(f, 1.0) for f in frames]
        assert all(b.name == name for b in blocks)
    decoded = merge(codec.decode_frame(f) for fs in all_frames().values() for f in fs)
    check_everything(decoded)


def junky_stream() -> tuple[bytes, int, int]:
    """All frames with junk between them; returns (stream, junk bytes, junk runs)."""
    fr = all_frames()
    hr = fr["HIGH_RATE"]
    corrupted = bytearray(hr[2])
    corrupted[30] ^= 0x04                                   # payload bit flip: CRC error
    truncated = hr[3][:40]                                  # cut short: CRC error
    pieces = [
        (b"\x00\x11\x22", True),                            # leading junk
        (hr[0], False),
        (b"\xEB\x55", True),                                # lone first sync byte
        (hr[1], False),
        (b"\xEB\x90\x07\x01\x00\x3C" + bytes(8), True),    # version 7
        (fr["HOUSEKEEPING"][0], False),
        (b"\xEB\x90\x01\x7F\x00\x00\x12\x34", True),        # unknown packet id 0x7F
        (fr["EVENT"][0], False),
        (b"\xEB\x90\x01\x01\x00\x10" + bytes(10), True),   # HIGH_RATE with length 16
        (bytes(corrupted), True),
        (hr[2], False),
        (truncated, True),
        (hr[3], False),
        (fr["COMMAND"][0], False),
        (b"\xEB", True),
        (hr[4], False),
        (b"\x01\x02\x03", True),                            # trailing junk
    ]
    stream = b"".join(p for p, _ in pieces)
    junk = sum(len(p) for p, is_junk in pieces if is_junk)
    flags = [is_junk for _, is_junk in pieces]
    runs = sum(1 for k, j in enumerate(flags) if j and (k == 0 or not flags[k - 1]))
    return stream, junk, runs


def chunks(data: bytes, sizes) -> list[bytes]:
    out, pos, k = [], 0, 0
    while pos < len(data):
        n = sizes[k % len(sizes)]
        out.append(data[pos:pos + n])
        pos += n
        k += 1
    return out


ODD_SIZES = [1, 3, 5, 7, 11, 13, 17, 19, 23, 29, 31, 37, 41, 43, 47, 53, 59, 61, 67,
             71, 73, 79, 83, 89, 97, 101, 151, 2]


@pytest.mark.parametrize("split", ["whole", "odd_chunks", "byte_by_byte"])
def test_stream_with_junk(codec, split):
    stream, junk, runs = junky_stream()
    sizes = {"whole": [len(stream)], "odd_chunks": ODD_SIZES, "byte_by_byte": [1]}[split]
    deframer = StreamDeframer(codec)
    blocks = []
    for t, piece in enumerate(chunks(stream, sizes)):
        blocks += deframer.feed(piece, 1000.0 + t)
    blocks += deframer.flush(2000.0)
    check_everything(merge(blocks))
    c = deframer.counters
    assert c.frames == 8
    assert c.bytes_in == len(stream)
    assert c.junk_bytes == junk
    if split == "whole":
        assert c.resyncs == runs
    else:
        assert c.resyncs >= runs        # a run split across feeds may count twice (SPEC §4.1)
    assert c.crc_errors == 2
    assert c.version_errors == 1
    assert c.unknown_packet_errors == 1
    assert c.length_errors == 1


def test_datagrams(codec):
    fr = all_frames()
    hr = fr["HIGH_RATE"]
    datagrams = [hr[0], hr[1] + fr["HOUSEKEEPING"][0] + hr[2],
                 fr["EVENT"][0] + hr[3], fr["COMMAND"][0], hr[4]]
    decoder = DatagramDecoder(codec)
    check_everything(merge(decoder.decode(datagrams, 5.0)))
    assert decoder.counters.junk_bytes == 0 and decoder.counters.frames == 8

    # a frame split over two datagrams is never reassembled (SPEC §4.2)
    split = [hr[0][:30], hr[0][30:] + hr[1]]
    decoder = DatagramDecoder(codec)
    decoded = merge(decoder.decode(split, 5.0))
    assert decoded["HIGH_RATE"]["sequence"] == [HIGH_RATE_VALUES[1]["sequence"]]
    assert decoder.counters.length_errors == 1
