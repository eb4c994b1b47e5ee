"""protocol/SPEC.md checked against the ground station's decoder.

The first half of this file is an encoder written from SPEC.md alone. It uses only
`struct`, `zlib` and `tomllib` (to read the normative item lists in protocol/*.toml) and
nothing from the groundstation package. The frames it builds are fed through the real
decoder (`StreamDeframer`, `DatagramDecoder`, `FrameCodec.decode_frame`), and every value
must come out as intended.

The second half reads the worked examples, the HIGH_RATE layout table and the parameter
table (layout, size, CRC and first bytes of the defaults, named defaults, validation
rules) out of SPEC.md itself, so the document cannot drift from the code.  The default
parameter table is packed from parameters.toml with `struct` alone, following §11.1.
"""

from __future__ import annotations

import re
import struct
import tomllib
import zlib
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parent.parent
PROTOCOL = ROOT / "protocol"
SPEC = PROTOCOL / "SPEC.md"

# =====================================================================================
# Independent encoder (SPEC.md + protocol/*.toml; struct and zlib only)
# =====================================================================================

SYNC = b"\xEB\x90"
VERSION = 1
RESIDUE = 0x2144DF1C
HEADER = struct.Struct(">2sBBHII")          # sync, version, packet_id, length, sequence, tick

# SPEC §3.1 wire types -> struct codes (always used with ">")
STRUCT_CODE = {"u8": "B", "i8": "b", "u16": "H", "i16": "h", "u32": "I", "i32": "i",
               "u64": "Q", "i64": "q", "f32": "f", "f64": "d"}

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


def load_toml(name: str) -> dict:
    return tomllib.loads((PROTOCOL / name).read_text(encoding="utf-8"))


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
from groundstation.dictionary import load_dictionary  # noqa: E402


@pytest.fixture(scope="module")
def dictionary():
    return load_dictionary(PROTOCOL)


@pytest.fixture(scope="module")
def codec(dictionary):
    return FrameCodec(dictionary)


def f32(x: float) -> float:
    return struct.unpack(">f", struct.pack(">f", x))[0]


def merge(blocks) -> dict[str, dict[str, list]]:
    """Blocks from several feed() calls -> packet name -> column -> list of values."""
    out: dict[str, dict[str, list]] = {}
    for block in blocks:
        cols = out.setdefault(block.name, {})
        for name, col in block.columns.items():
            cols.setdefault(name, []).extend(col.tolist())
    return out


def assert_item(item_scale, type_, decoded, intended, where):
    if item_scale is not None:
        assert abs(decoded - intended) <= abs(item_scale) * (1 + 1e-9), (where, decoded, intended)
    elif type_ == "f32":
        assert decoded == f32(intended), (where, decoded, intended)
    else:
        assert decoded == intended, (where, decoded, intended)


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


# --- SPEC.md's own examples -------------------------------------------------------------

def spec_text() -> str:
    return SPEC.read_text(encoding="utf-8")


def spec_hex_examples() -> list[tuple[str, bytes, list[tuple[str, str, str]]]]:
    """```hex blocks: (title, frame bytes, [(field, value text, rest of annotation)])."""
    examples = []
    for block in re.findall(r"^```hex\n(.*?)^```", spec_text(), re.S | re.M):
        title, data, notes = "", bytearray(), []
        for line in block.splitlines():
            if line.startswith("#"):
                title = line[1:].strip()
                continue
            if not line.strip():
                continue
            code, _, note = line.partition(";")
            fields = code.split()
            assert int(fields[0]) == len(data), f"{title}: offset column out of step: {line}"
            data += bytes(int(x, 16) for x in fields[1:])
            m = re.match(r"\s*(\w+) = (\S+)\s*(.*)", note)
            assert m, f"{title}: annotation not 'name = value': {line}"
            notes.append(m.groups())
        examples.append((title, bytes(data), notes))
    return examples


def parse_number(text: str):
    return int(text, 16) if text.lower().startswith("0x") else (
        float(text) if any(ch in text for ch in ".e") else int(text))


def test_spec_worked_examples_decode_as_stated(codec, dictionary):
    examples = spec_hex_examples()
    titles = [t for t, _, _ in examples]
    assert len(examples) >= 4, titles
    assert any(t.startswith("HIGH_RATE") for t in titles)
    assert any("ARM" in t and t.startswith("COMMAND") for t in titles)
    assert any("ACCEPTED" in t for t in titles) and any("COMPLETED" in t for t in titles)

    for title, frame, notes in examples:
        block = codec.decode_frame(frame)
        pkt = block.packet
        assert title.split()[0] == pkt.name
        assert zlib.crc32(frame) == RESIDUE
        # the annotated fields are the frame's fields, in wire order
        expected_order = ["sync", "version", "packet_id", "length", "sequence", "tick"]
        expected_order += [i.name for i in pkt.fixed_items] + ["crc"]
        assert [n for n, _, _ in notes] == expected_order, title
        sync, version, pid, length, seq, tick = HEADER.unpack_from(frame)
        header = {"sync": int.from_bytes(sync, "big"), "version": version, "packet_id": pid,
                  "length": length, "sequence": seq, "tick": tick,
                  "crc": struct.unpack("<I", frame[-4:])[0]}
        assert header["crc"] == zlib.crc32(frame[:-4])
        assert length == len(frame) - 18
        items = pkt.item_by_name
        for name, value_text, rest in notes:
            value = parse_number(value_text)
            if name in header:
                assert header[name] == value, (title, name)
                if name in ("sequence", "tick"):
                    assert block.columns[name][0] == value
                continue
            item = items[name]
            decoded = block.columns[name][0]
            assert_item(item.scale, item.type, decoded, value, f"{title}: {name}")
            label = re.match(r"\((\w+)", rest)
            if item.states and label:
                assert item.states[label.group(1)] == value, (title, name)
            if item.bits:
                named = {flag: int(bit) for bit, flag in re.findall(r"(\d+) (\w+)", rest)}
                for flag, bit in item.bits.items():
                    assert bool(block.columns[flag][0]) == (flag in named), (title, flag)
                    if flag in named:
                        assert named[flag] == bit
            if name == "opcode" and label:
                assert dictionary.command(label.group(1)).opcode == value
            if "raw" in rest:                               # "(raw N counts)"
                raw = int(re.search(r"raw (-?\d+)", rest).group(1))
                assert int(block.raw[name][0]) == raw, (title, name)
        if pkt.name == "COMMAND":
            assert block.columns["arguments"][0] == b""
        if pkt.name == "RESPONSE":
            assert block.columns["data"][0] == b""


def test_arm_exchange_is_consistent():
    """The three ARM frames of §13.2 belong together (sequence, token, opcode, stages)."""
    frames = {t: f for t, f, _ in spec_hex_examples()}
    cmd = frames["COMMAND example frame: ARM"]
    acc = frames["RESPONSE example frame: ARM ACCEPTED"]
    com = frames["RESPONSE example frame: ARM COMPLETED"]
    assert HEADER.unpack_from(cmd)[4] == 7 and HEADER.unpack_from(cmd)[5] == 0
    assert struct.unpack_from(">IH", cmd, 14) == (0x1234ABCD, 0x0011)
    assert struct.unpack_from(">IHBH", acc, 14) == (7, 0x0011, 1, 0)
    assert struct.unpack_from(">IHBH", com, 14) == (7, 0x0011, 3, 0)
    assert HEADER.unpack_from(com)[4] == HEADER.unpack_from(acc)[4] + 1


def test_spec_high_rate_table_matches_codec(dictionary):
    """§5.1's layout table agrees with PacketDef.frame_dtype and the TOML scales."""
    pkt = dictionary.packet("HIGH_RATE")
    dt = pkt.frame_dtype
    section = spec_text().split("### 5.1 HIGH_RATE")[1].split("### 5.2")[0]
    rows = re.findall(r"^\| (\d+) \| (\d+|—) \| [`*](\w+)[`*][^|]*\| ([^|]+)\| (\d+) \| ([^|]+)\|",
                      section, re.M)
    assert [r[2] for r in rows] == list(dt.names)
    for frame_off, payload_off, name, _type, size, conv in rows:
        assert int(frame_off) == dt.fields[name][1], name
        assert int(size) == dt.fields[name][0].itemsize, name
        if payload_off != "—":
            assert int(payload_off) == dt.fields[name][1] - 14, name
            item = pkt.item_by_name[name]
            m = re.match(r"\s*([0-9.]+e-?\d+|[0-9.]+)\b", conv)
            if item.scale is not None:
                assert m and float(m.group(1)) == item.scale, name
            else:
                assert not m, name
    assert dt.itemsize == 78


# --- §11.1 parameter table, packed from parameters.toml with struct alone -----------------

def spec_section(start: str, end: str) -> str:
    text = spec_text()
    return text.split(start, 1)[1].split(end, 1)[0]


def spec_named_defaults() -> dict[str, tuple[list[float], list[float]]]:
    """§11.1's named-default table: name -> (row 0, rows 1 … n-1)."""
    section = spec_section("### 11.1 Parameter table", "### 11.2")
    rows = re.findall(r"^\| `(\w+)` \| `\[([^\]]*)\]` \| `\[([^\]]*)\]` \|", section, re.M)
    assert rows, "no named-default table in §11.1"
    return {name: ([float(x) for x in first.split(",")], [float(x) for x in rest.split(",")])
            for name, first, rest in rows}


def flatten(value) -> list:
    """Row-major (SPEC §11.1): nested lists in order, rows one after the other."""
    if isinstance(value, list):
        return [x for v in value for x in flatten(v)]
    return [value]


def toml_parameter_table() -> tuple[bytes, list[dict]]:
    """The default table per SPEC §11.1, from parameters.toml: (bytes, layout rows)."""
    named = spec_named_defaults()
    params = sorted(load_toml("parameters.toml")["parameter"], key=lambda p: p["id"])
    packed, layout = b"", []
    for p in params:
        shape = list(p.get("shape", []))
        count = 1
        for n in shape:
            count *= n
        default = p["default"]
        if isinstance(default, str):
            assert len(shape) == 2 and shape[1] == 6, f"{p['name']}: named default on {shape}"
            first, rest = named[default]
            values = first + rest * (shape[0] - 1)
        else:
            values = flatten(default)
        assert len(values) == count, p["name"]
        code = ">" + STRUCT_CODE[p["type"]]
        layout.append(dict(offset=len(packed), id=p["id"], name=p["name"], type=p["type"],
                           shape=shape, size=count * struct.calcsize(code), code=code,
                           default=default))
        packed += b"".join(struct.pack(code, v) for v in values)
    return packed, layout


def spec_stated_table_size() -> int:
    section = spec_section("### 11.1 Parameter table", "### 11.2")
    sizes = {int(n) for n in re.findall(r"table is\s+\*\*(\d+)\*\* bytes long", section)}
    sizes |= {int(n) for n in re.findall(r"It is (\d+) bytes long", section)}
    assert len(sizes) == 1, f"§11.1 states table sizes {sizes}"
    return sizes.pop()


def test_spec_parameter_layout_table(dictionary):
    """§11.1's layout table lists every entry, in id order, at the offsets of the packing."""
    from groundstation.params.table import table_size

    packed, layout = toml_parameter_table()
    section = spec_section("### 11.1 Parameter table", "**Defaults.**")
    rows = re.findall(r"^\| (\d+) \| (\d+) \| `(\w+)` \| (\w+) \| ([^|]+)\| (\d+) \| ([^|]+)\|",
                      section, re.M)
    assert [r[2] for r in rows] == [e["name"] for e in layout]
    for (off, id_, name, type_, shape, size, default), e in zip(rows, layout):
        assert (int(off), int(id_), type_, int(size)) == (e["offset"], e["id"], e["type"],
                                                           e["size"]), name
        stated_shape = [int(n) for n in re.findall(r"\d+", shape)]
        assert stated_shape == e["shape"], name
        default = default.strip()
        if isinstance(e["default"], str):
            assert default == f"`{e['default']}`", name
        elif not isinstance(e["default"], list):
            assert parse_number(default) == e["default"], name
    assert spec_stated_table_size() == len(packed) == table_size(dictionary)
    # the prose's "today 1–8, 10–15 and 20–26": the runs of consecutive ids in the TOML
    ids = [e["id"] for e in layout]
    runs, start = [], ids[0]
    for a, b in zip(ids, ids[1:] + [None]):
        if b != a + 1:
            runs.append(f"{start}–{a}" if a != start else f"{a}")
            start = b
    stated = re.search(r"Ids need not be consecutive \(today\s+(.*?)\)\.", section, re.S)
    assert stated, "§11.1 no longer states the id ranges"
    assert re.split(r",\s*|\s+and\s+", stated.group(1).replace("\n", " ")) == runs


def test_spec_default_parameter_table(dictionary):
    """§11.1's default table (size, CRC, first bytes) = parameters.toml packed per the SPEC
    = the ground station's own packing."""
    from groundstation.params.table import default_values, pack

    packed, layout = toml_parameter_table()
    assert pack(dictionary, default_values(dictionary)) == packed
    text = spec_text()
    stated = re.search(r"its CRC-32 \(§2\.1\) is\s+`0x([0-9A-F]{8})`", text).group(1)
    assert zlib.crc32(packed) == int(stated, 16)
    assert len(packed) == spec_stated_table_size()

    block = re.search(r"^```paramhex\n(.*?)^```", text, re.S | re.M).group(1)
    shown, annotated = bytearray(), []
    for line in block.splitlines():
        if not line.strip() or line.startswith("#"):
            continue
        code, _, note = line.partition(";")
        fields = code.split()
        assert int(fields[0]) == len(shown), f"offset column out of step: {line}"
        m = re.match(r"\s*(\w+)((?:\[\d+\])*) = (\S+)", note)
        assert m, f"annotation not 'element = value': {line}"
        annotated.append((len(shown), m.group(1), m.group(2), m.group(3)))
        shown += bytes(int(x, 16) for x in fields[1:])
    assert len(shown) >= 25 and packed.startswith(bytes(shown))
    # every annotation names the element at its offset, and the value it encodes
    entries = {e["name"]: e for e in layout}
    for off, name, index, value in annotated:
        e = entries[name]
        idx = [int(i) for i in re.findall(r"\d+", index)]
        assert len(idx) == len(e["shape"]), (name, index)
        flat = 0
        for i, n in zip(idx, e["shape"]):
            assert i < n
            flat = flat * n + i
        itemsize = struct.calcsize(e["code"])
        assert off == e["offset"] + flat * itemsize, (name, index)
        (decoded,) = struct.unpack_from(e["code"], shown, off)
        assert decoded == struct.unpack(e["code"], struct.pack(e["code"], parse_number(value)))[0]


# --- §11.1 validation rules, written from the SPEC, against the device's check ------------

def spec_refuses(blob: bytes) -> bool:
    """SPEC §11.1 "Validation at PARAM_COMMIT", from the text: True if refused."""
    import cmath
    import math

    _, layout = toml_parameter_table()
    params = {p["name"]: p for p in load_toml("parameters.toml")["parameter"]}
    values = {}
    for e in layout:
        n = e["size"] // struct.calcsize(e["code"])
        vals = list(struct.unpack_from(">" + str(n) + e["code"][1:], blob, e["offset"]))
        lo, hi = params[e["name"]]["range"]
        if e["type"] in ("f32", "f64"):
            if not all(math.isfinite(v) for v in vals):
                return True
            if e["type"] == "f32":            # bounds rounded to f32; values already are
                lo, hi = f32(lo), f32(hi)
        if any(v < lo or v > hi for v in vals):
            return True
        values[e["name"]] = vals
        if params[e["name"]].get("filter") == "sos":
            cols = e["shape"][1]
            for r in range(e["shape"][0]):
                b0, b1, b2, a0, a1, a2 = vals[r * cols:(r + 1) * cols]
                if a0 != 1.0:
                    return True
                if a1 == 0.0 and a2 == 0.0:
                    continue
                root = cmath.sqrt(a1 * a1 - 4.0 * a2)
                for p in ((-a1 + root) / 2.0, (-a1 - root) / 2.0):
                    inside = abs(p) <= 1.0 - 1e-9
                    integrator = abs(p - 1.0) <= 1e-6 and abs(p) <= 1.0 + 1e-9
                    if not (inside or integrator):
                        return True
    n = values["friction_comp_table_points"][0]
    x = values["friction_comp_table_x"][:n]
    s = values["friction_comp_table_slope"][:n]
    if x[0] != 0.0 or abs(x[-1] - 2.0) > 1e-6:
        return True
    if any(b <= a for a, b in zip(x, x[1:])) or any(b > a for a, b in zip(s, s[1:])):
        return True
    return False


def patched(blob: bytes, name: str, index: tuple[int, ...], value) -> bytes:
    """Write one element, addressed row-major per SPEC §11.1."""
    _, layout = toml_parameter_table()
    e = next(e for e in layout if e["name"] == name)
    flat = 0
    for i, n in zip(index, e["shape"]):
        flat = flat * n + i
    off = e["offset"] + flat * struct.calcsize(e["code"])
    out = bytearray(blob)
    struct.pack_into(e["code"], out, off, value)
    return bytes(out)


def patched_section(blob: bytes, name: str, row: int, coeffs) -> bytes:
    for j, c in enumerate(coeffs):
        blob = patched(blob, name, (row, j), c)
    return blob


def validation_cases() -> list[tuple[str, bytes, bool]]:
    """(what, table, refused per the SPEC's rules as read by a person)."""
    base, _ = toml_parameter_table()
    nan, inf = float("nan"), float("inf")
    above_81_3 = struct.unpack(">f", (struct.unpack(">I", struct.pack(">f", 81.3))[0] + 1)
                               .to_bytes(4, "big"))[0]
    cases = [
        ("defaults", base, False),
        ("saturation_coarse = f32(81.3), its own bound", patched(base, "saturation_coarse", (), 81.3), False),
        ("saturation_coarse one f32 step above 81.3", patched(base, "saturation_coarse", (), above_81_3), True),
        ("travel_limit NaN", patched(base, "travel_limit", (), nan), True),
        ("friction_comp_enabled = 2", patched(base, "friction_comp_enabled", (), 2), True),
        ("unused slope point infinite", patched(base, "friction_comp_table_slope", (40,), inf), True),
        ("unused slope point out of range", patched(base, "friction_comp_table_slope", (40,), 2000.0), True),
        ("unused slope point rising", patched(base, "friction_comp_table_slope", (40,), 5.0), False),
        ("f64 coefficient at the range bound", patched_section(base, "relative_c0", 5, [1e12, 0, 0, 1, 0, 0]), False),
        ("f64 coefficient beyond the range", patched_section(base, "relative_c0", 5, [1.0000001e12, 0, 0, 1, 0, 0]), True),
        ("integrator in the last section", patched_section(base, "relative_c0", 11, [2.0, -1.9, 0, 1, -1.0, 0]), False),
        ("double integrator", patched_section(base, "inertial_c0", 3, [1, 0, 0, 1, -2.0, 1.0]), False),
        ("stable complex pair", patched_section(base, "inertial_c1", 0, [0.1, 0.2, 0.1, 1, -1.6, 0.81]), False),
        ("pole at z = -1", patched_section(base, "relative_c1", 2, [1, 0, 0, 1, 1.0, 0]), True),
        ("poles on the unit circle at ±j", patched_section(base, "relative_c2", 7, [1, 0, 0, 1, 0, 1.0]), True),
        ("unstable real pole 1.001", patched_section(base, "inertial_c2", 1, [1, 0, 0, 1, -1.001, 0]), True),
        ("pole 1 + 1e-7: near z = 1 but outside", patched_section(base, "relative_c0", 0, [1, 0, 0, 1, -(1 + 1e-7), 0]), True),
        ("pole 1 - 1e-7: inside", patched_section(base, "relative_c0", 0, [1, 0, 0, 1, -(1 - 1e-7), 0]), False),
        ("a0 = 2 (not normalised)", patched_section(base, "relative_c0", 4, [2, 0, 0, 2, 0, 0]), True),
        ("a0 = 0.5, poles fine", patched_section(base, "inertial_c0", 4, [1, 0, 0, 0.5, 0.1, 0]), True),
        ("FIR section", patched_section(base, "relative_c1", 1, [0.5, 0.3, 0.2, 1, 0, 0]), False),
        ("slope x repeated", patched(base, "friction_comp_table_x", (3,), 0.05), True),
        ("slope x not starting at 0", patched(base, "friction_comp_table_x", (0,), 0.01), True),
        ("slope rising over the used points", patched(base, "friction_comp_table_slope", (5,), 4.0), True),
        ("slope flat over the used points", patched(base, "friction_comp_table_slope", (5,), 2.1), False),
        ("13 points: x[12] repeats 2.0", patched(base, "friction_comp_table_points", (), 13), True),
        ("11 points: x[10] = 1.85, not 2", patched(base, "friction_comp_table_points", (), 11), True),
    ]
    short = patched(patched(base, "friction_comp_table_points", (), 2), "friction_comp_table_x", (1,), 2.0)
    cases.append(("2 points: x = 0, 2", short, False))
    return cases


def test_spec_validation_rules_match_device_check(dictionary):
    """§11.1's validation rules, implemented from the text, agree with the device's
    `problems()` on tables patched byte by byte at SPEC-computed offsets."""
    from groundstation.params.table import problems, unpack

    for what, blob, refused in validation_cases():
        assert spec_refuses(blob) == refused, f"SPEC reading: {what}"
        device = problems(dictionary, unpack(dictionary, blob))
        assert bool(device) == refused, (what, device)


def test_spec_row_major_addressing(dictionary):
    """Element [i][j] of a cascade sits at offset + (i·6 + j)·8 (§11.1)."""
    from groundstation.params.table import unpack

    base, _ = toml_parameter_table()
    blob = patched(base, "inertial_c2", (7, 4), -0.25)
    values, defaults = unpack(dictionary, blob), unpack(dictionary, base)
    changed = [(i, j) for i in range(12) for j in range(6)
               if values["inertial_c2"][i][j] != defaults["inertial_c2"][i][j]]
    assert changed == [(7, 4)] and values["inertial_c2"][7][4] == -0.25
    assert all(values[k] == defaults[k] for k in values if k != "inertial_c2")
    blob = patched(base, "friction_comp_table_x", (63,), 1.5)
    assert unpack(dictionary, blob)["friction_comp_table_x"][63] == f32(1.5)


# --- §10.1 control law: the section recursion ----------------------------------------------

def spec_cascade(sos: list[list[float]], xs: list[float]) -> list[float]:
    """§10.1's direct form II transposed cascade, states committed every period."""
    state = [[0.0, 0.0] for _ in sos]
    out = []
    for x in xs:
        for k, (b0, b1, b2, _a0, a1, a2) in enumerate(sos):
            s1, s2 = state[k]
            y = b0 * x + s1
            state[k] = [b1 * x - a1 * y + s2, b2 * x - a2 * y]
            x = y
        out.append(x)
    return out


def test_spec_cascade_recursion_matches_core():
    """The SOS equations of §10.1 give the simulated firmware's filter outputs."""
    import numpy as np

    from groundstation.sim.core import sos_run

    sos = [[0.2, 0.1, -0.05, 1, -1.0, 0.0],            # integrator section
           [0.5, 0.3, 0.2, 1, 0.0, 0.0],               # FIR section
           [0.1, 0.2, 0.1, 1, -1.6, 0.81],             # complex poles
           [1, 0, 0, 1, 0, 0]]                         # identity
    xs = [1.0, 0.0, -0.5, 0.25, 2.0, 0.0, 0.0, -1.0, 0.125, 0.0]
    arr = np.array(sos, dtype=np.float64)
    z = np.zeros((len(sos), 2))
    z_new = np.zeros_like(z)
    got = []
    for x in xs:
        got.append(sos_run(arr, z, z_new, x))
        z[:] = z_new
    assert got == pytest.approx(spec_cascade(sos, xs), rel=1e-12, abs=1e-15)


def test_spec_dictionary_hash_recipe(dictionary):
    """§8's recipe, followed with hashlib + json + tomllib, gives the codec's hash."""
    import hashlib
    import json

    docs = {"telemetry": load_toml("telemetry.toml"), "commands": load_toml("commands.toml"),
            "parameters": load_toml("parameters.toml")}
    canonical = json.dumps(docs, sort_keys=True, separators=(",", ":"), ensure_ascii=True)
    digest = hashlib.sha256(canonical.encode("ascii")).digest()
    assert struct.unpack(">I", digest[:4])[0] == dictionary.hash
