"""The protocol dictionary: the real protocol/*.toml, and errors in broken copies of it."""

from __future__ import annotations

import math
import re
import shutil
from pathlib import Path

import numpy as np
import pytest

from groundstation.core.dictionary import (FRAME_OVERHEAD, HEADER_SIZE, default_protocol_dir,
                                           load_dictionary)
from groundstation.core.errors import DictionaryError

PROTOCOL_FILES = ("telemetry.toml", "commands.toml", "parameters.toml")

REQUIRED_COMMANDS = (
    "CONNECT", "DISCONNECT", "HEARTBEAT", "GET_INFO", "SET_MODE", "ARM", "DISARM", "ABORT",
    "PARAM_BEGIN", "PARAM_WRITE", "PARAM_COMMIT", "PARAM_READ",
    "PROFILE_BEGIN", "PROFILE_WRITE", "PROFILE_COMMIT", "PROFILE_START", "PROFILE_STOP",
    "FRICTION_COMP",
)


# ------------------------------------------------------------------------- helpers
@pytest.fixture
def proto_copy(tmp_path: Path) -> Path:
    """A private copy of the three protocol files, to be broken by a test."""
    for name in PROTOCOL_FILES:
        shutil.copy(default_protocol_dir() / name, tmp_path / name)
    return tmp_path


def edit(directory: Path, filename: str, old: str | re.Pattern, new: str) -> None:
    """Replace `old` (text, or a regular expression) by `new` in one protocol file; it
    must match exactly once, so a test cannot silently pass because its edit matched
    nothing."""
    path = directory / filename
    text = path.read_text(encoding="utf-8")
    if isinstance(old, re.Pattern):
        text, n = old.subn(new, text)
    else:
        n = text.count(old)
        text = text.replace(old, new)
    assert n == 1, f"{old!r} matches {n} times in {filename}"
    path.write_text(text, encoding="utf-8")


def load_error(directory: Path) -> str:
    with pytest.raises(DictionaryError) as info:
        load_dictionary(directory)
    return str(info.value)


# ------------------------------------------------------------------ the real files
def test_protocol_header(dictionary):
    assert dictionary.version_major == 1
    assert dictionary.version == f"{dictionary.version_major}.{dictionary.version_minor}"
    assert dictionary.sync == 0xEB90
    assert dictionary.max_payload == 1024
    assert dictionary.control_rate_hz == 1200
    assert HEADER_SIZE == 14 and FRAME_OVERHEAD == 18


def test_packet_ids_and_sizes(dictionary):
    expected = {  # name: (id, fixed payload bytes, variable?)
        "HIGH_RATE": (0x01, 60, False),
        "HOUSEKEEPING": (0x02, 45, False),
        "EVENT": (0x03, 3, True),
        "COMMAND": (0x10, 6, True),
        "RESPONSE": (0x11, 9, True),
    }
    assert {p.name for p in dictionary.packets} == set(expected)
    for name, (pid, size, variable) in expected.items():
        pkt = dictionary.packet(name)
        assert dictionary.packet(pid) is pkt
        assert pkt.id == pid
        assert pkt.fixed_payload_size == size
        assert (pkt.variable_item is not None) == variable
        if not variable:
            assert pkt.frame_dtype.itemsize == size + FRAME_OVERHEAD
    assert dictionary.packet("HIGH_RATE").rate_hz == 1200
    assert dictionary.packet("HIGH_RATE").frame_dtype.itemsize == 78
    assert dictionary.packet("HOUSEKEEPING").frame_dtype.itemsize == 63


def test_unknown_packet_lookup_names_the_known_ones(dictionary):
    with pytest.raises(DictionaryError, match="HIGH_RATE"):
        dictionary.packet("NO_SUCH_PACKET")
    with pytest.raises(DictionaryError, match="NO_SUCH_COMMAND"):
        dictionary.command("NO_SUCH_COMMAND")


def test_frame_dtype_layout_matches_spec(dictionary):
    """Offsets of the HIGH_RATE frame record (SPEC.md §5.1): packed, big-endian, LE CRC."""
    dt = dictionary.packet("HIGH_RATE").frame_dtype
    offsets = {name: dt.fields[name][1] for name in dt.names}
    assert offsets["sync"] == 0 and offsets["version"] == 2 and offsets["packet_id"] == 3
    assert offsets["length"] == 4 and offsets["sequence"] == 6 and offsets["tick"] == 10
    assert offsets["mode"] == 14 and offsets["status"] == 15 and offsets["encoder_outer"] == 16
    assert offsets["autocollimator"] == 32 and offsets["profile_index"] == 70
    assert offsets["crc"] == 74
    assert dt["encoder_outer"] == np.dtype(">i4") and dt["crc"] == np.dtype("<u4")


def test_high_rate_items(dictionary):
    hr = dictionary.packet("HIGH_RATE")
    items = hr.item_by_name
    required = [
        "mode", "status", "encoder_outer", "encoder_inner", "encoder_base", "gyro_rate",
        "autocollimator", "los_estimate", "reference", "error_angle", "error_rate",
        "torque_coarse_cmd", "torque_fine_cmd", "current_coarse", "current_fine",
        "voltage_coarse", "voltage_fine", "friction_comp_torque", "profile_index",
    ]
    for name in required:
        assert name in items, name
    # header counters are channels of every packet
    channels = hr.channel_names()
    assert channels[:2] == ["sequence", "tick"]

    assert items["mode"].states == {"IDLE": 0, "OPEN_LOOP": 1, "RELATIVE": 2, "INERTIAL": 3}
    assert items["status"].bits == {"armed": 0, "coarse_saturated": 1, "fine_saturated": 2,
                                    "profile_active": 3, "friction_comp_on": 4, "fault": 5}
    for flag in items["status"].bits:
        assert flag in channels

    for name in ("encoder_outer", "encoder_inner", "los_estimate", "reference"):
        assert items[name].type == "i32"
        assert items[name].units == "rad"
        assert items[name].scale == 2 * math.pi / 2**32      # exactly, not approximately
        assert items[name].offset == 0.0
    assert items["encoder_base"].type == "i32"
    assert items["encoder_base"].scale == 2 * math.pi / 2**19

    # the i32 encoders cover exactly one turn, [-pi, pi)
    enc = items["encoder_outer"]
    assert enc.to_engineering(np.array([-2**31], ">i4"))[0] == -math.pi
    assert enc.to_engineering(np.array([2**31 - 1], ">i4"))[0] < math.pi

    ac = items["autocollimator"]
    assert ac.type == "i16" and ac.units == "rad"
    full = math.radians(0.33)
    one_count = ac.scale * (1 + 1e-9)
    assert abs(32767 * ac.scale - full) <= one_count
    assert abs(-32768 * ac.scale + full) <= one_count

    assert items["gyro_rate"].units == "rad/s" and items["gyro_rate"].type == "i32"
    for name in ("error_angle", "error_rate", "torque_coarse_cmd", "torque_fine_cmd",
                 "friction_comp_torque"):
        assert items[name].type == "f32"
    for name in ("torque_coarse_cmd", "torque_fine_cmd", "friction_comp_torque"):
        assert items[name].units == "in-oz"
    for name in ("current_coarse", "current_fine"):
        assert items[name].units == "A" and items[name].type == "i16"
    for name in ("voltage_coarse", "voltage_fine"):
        assert items[name].units == "V" and items[name].type == "i16"
    assert items["profile_index"].type == "u32"

    lim = items["encoder_outer"].limits
    assert lim.red[0] <= lim.yellow[0] < lim.yellow[1] <= lim.red[1]


def test_housekeeping_items(dictionary):
    hk = dictionary.packet("HOUSEKEEPING").item_by_name
    for name in ("temp_motor_coarse", "temp_motor_fine", "temp_flexure", "temp_electronics"):
        assert hk[name].units == "degC"
        assert hk[name].limits is not None
    for name in ("supply_motor", "supply_logic"):
        assert hk[name].units == "V"
    for name in ("firmware_version", "uptime", "param_table_crc", "param_table_version",
                 "active_profile", "watchdog", "commands_accepted", "commands_rejected",
                 "fault_code"):
        assert name in hk, name
    assert hk["param_table_crc"].type == "u32"
    assert hk["uptime"].units == "s"
    assert hk["watchdog"].states["OK"] == 0 and "EXPIRED" in hk["watchdog"].states
    assert hk["fault_code"].states["NONE"] == 0
    assert "WATCHDOG" in hk["fault_code"].states


def test_variable_items_are_last(dictionary):
    assert dictionary.packet("EVENT").variable_item.name == "text"
    assert dictionary.packet("EVENT").variable_item.type == "str"
    assert dictionary.packet("COMMAND").variable_item.type == "bytes"
    assert dictionary.packet("RESPONSE").variable_item.type == "bytes"


def test_required_commands(dictionary):
    names = {c.name for c in dictionary.commands}
    for name in REQUIRED_COMMANDS:
        assert name in names, name
    opcodes = [c.opcode for c in dictionary.commands]
    assert len(set(opcodes)) == len(opcodes)
    for c in dictionary.commands:
        assert dictionary.command(c.opcode) is c
    # commands that must work without a session
    for name in ("CONNECT", "GET_INFO", "ABORT"):
        assert dictionary.command(name).needs_session is False
    assert dictionary.command("HEARTBEAT").needs_session is True
    assert dictionary.command("ARM").critical is True
    connect = dictionary.command("CONNECT")
    assert [a.name for a in connect.args][:3] == ["protocol_major", "protocol_minor",
                                                  "dictionary_hash"]
    assert dictionary.command("PARAM_COMMIT").timeout_s == 2.0
    assert dictionary.command("HEARTBEAT").timeout_s == dictionary.command_defaults["timeout_s"]
    assert dictionary.command("FRICTION_COMP").args[0].value_range == (0.0, 1.0)
    assert dictionary.command("PARAM_WRITE").args[-1].type == "bytes"
    assert dictionary.error_codes["OK"] == 0
    assert dictionary.error_name(dictionary.error_codes["CRC_MISMATCH"]) == "CRC_MISMATCH"
    assert dictionary.error_name(9999) == "UNKNOWN_REASON_9999"
    assert dictionary.event_name(dictionary.event_codes["BOOT"]) == "BOOT"


def test_parameters(dictionary):
    ids = [p.id for p in dictionary.parameters]
    assert ids == sorted(ids) and len(set(ids)) == len(ids)
    wd = next(p for p in dictionary.parameters if p.name == "watchdog_timeout")
    assert wd.type == "f32" and wd.size == 4 and wd.units == "s"
    assert wd.value_range[0] <= wd.default <= wd.value_range[1]


def test_source_texts_are_the_files(dictionary):
    for name in PROTOCOL_FILES:
        assert dictionary.source_texts[name] == (default_protocol_dir() / name).read_text(
            encoding="utf-8")


def test_protocol_dir_from_environment(proto_copy, monkeypatch):
    edit(proto_copy, "telemetry.toml", 'name = "hfb-testbed"', 'name = "env-testbed"')
    monkeypatch.setenv("GROUNDSTATION_PROTOCOL_DIR", str(proto_copy))
    assert load_dictionary().name == "env-testbed"


# ------------------------------------------------------------------ broken copies
# (file, old text, new text, fragments the message must contain besides the file name)
BROKEN = {
    "syntax_error": (
        "telemetry.toml", '[[packet]]\nname = "EVENT"', '[[packet]\nname = "EVENT"',
        ["malformed TOML", "line"]),
    "unknown_type": (
        "telemetry.toml", '{ name = "uptime", type = "u32"', '{ name = "uptime", type = "u33"',
        ["HOUSEKEEPING", "uptime", "u33"]),
    "duplicate_packet_id": (
        "telemetry.toml", 'name = "EVENT"\nid = 0x03', 'name = "EVENT"\nid = 0x02',
        ["id", "HOUSEKEEPING", "EVENT"]),
    "duplicate_packet_name": (
        "telemetry.toml", 'name = "EVENT"\nid = 0x03', 'name = "HOUSEKEEPING"\nid = 0x03',
        ["name", "HOUSEKEEPING"]),
    "duplicate_channel_name": (
        "telemetry.toml", '{ name = "encoder_inner"', '{ name = "encoder_outer"',
        ["HIGH_RATE", "encoder_outer", "twice"]),
    "bit_name_clashes_with_item": (
        "telemetry.toml", "bits = { armed = 0,", "bits = { gyro_rate = 0,",
        ["HIGH_RATE", "gyro_rate", "twice"]),
    "reserved_channel_name": (
        "telemetry.toml", '{ name = "uptime"', '{ name = "tick"',
        ["HOUSEKEEPING", "tick"]),
    "str_item_not_last": (       # swap EVENT's code and text lines
        "telemetry.toml",
        re.compile(r'(?m)^(\s*\{ name = "code",.*\n)(\s*\{ name = "text",.*\n)'), r"\2\1",
        ["EVENT", "text", "last"]),
    "yellow_outside_red": (
        "telemetry.toml", "limits = { yellow = [15.0, 40.0], red = [5.0, 50.0] }",
        "limits = { yellow = [15.0, 60.0], red = [5.0, 50.0] }",
        ["HOUSEKEEPING", "temp_flexure", "yellow", "red"]),
    "limits_reversed": (
        "telemetry.toml", "yellow = [-15.0, 15.0], red = [-17.0, 17.0]",
        "yellow = [15.0, -15.0], red = [-17.0, 17.0]",
        ["HIGH_RATE", "gyro_rate", "yellow"]),
    "missing_item_type": (
        "telemetry.toml", '{ name = "code", type = "u16", ', '{ name = "code", ',
        ["EVENT", "code", "missing key 'type'"]),
    "missing_packet_id": (
        "telemetry.toml", 'name = "EVENT"\nid = 0x03\n', 'name = "EVENT"\n',
        ["EVENT", "missing key 'id'"]),
    "misspelt_item_key": (
        "telemetry.toml", 'scale = 3.0e-08', 'scael = 3.0e-08',
        ["HIGH_RATE", "gyro_rate", "scael"]),
    "bit_outside_type": (
        "telemetry.toml", "fault = 5 }", "fault = 8 }",
        ["HIGH_RATE", "status", "fault"]),
    "zero_scale": (
        "telemetry.toml", re.compile(r'(name = "voltage_fine",.*?)scale = [^,]+,'),
        r"\1scale = 0.0,", ["HIGH_RATE", "voltage_fine", "scale"]),
    "packet_id_out_of_range": (
        "telemetry.toml", 'name = "EVENT"\nid = 0x03', 'name = "EVENT"\nid = 0x100',
        ["EVENT", "256"]),
    "missing_command_opcode": (
        "commands.toml", 'name = "SET_MODE"\nopcode = 0x0010\n', 'name = "SET_MODE"\n',
        ["SET_MODE", "missing key 'opcode'"]),
    "duplicate_opcode": (
        "commands.toml", "opcode = 0x0034", "opcode = 0x0033",
        ["opcode", "0x0033", "PROFILE_START", "PROFILE_STOP"]),
    "duplicate_command_name": (
        "commands.toml", 'name = "SET_MODE"\nopcode', 'name = "ARM"\nopcode',
        ["command name 'ARM' used twice", "commands 'ARM', 'ARM'"]),
    "opcode_out_of_range": (
        "commands.toml", "opcode = 0x0034", "opcode = 0x10000",
        ["opcode 65536 outside 1..65535"]),
    "command_arg_unknown_type": (
        "commands.toml", '{ name = "enable", type = "u8"', '{ name = "enable", type = "bool"',
        ["FRICTION_COMP", "enable", "bool"]),
    "command_bytes_not_last": (  # swap PARAM_WRITE's offset and data lines
        "commands.toml",
        re.compile(r'(?m)(name = "PARAM_WRITE"\n(?:.*\n)*?)^(\s*\{ name = "offset",.*\n)'
                   r'(\s*\{ name = "data",.*\n)'), r"\1\3\2",
        ["PARAM_WRITE", "data", "last"]),
    "parameter_default_out_of_range": (
        "parameters.toml", "range = [0.0, 16.1]\ndefault = 16.1", "range = [0.0, 16.1]\ndefault = 17.0",
        ["saturation_fine", "default"]),
    "parameter_missing_range": (
        "parameters.toml", 'units = "Hz"\nrange = [0.01, 50.0]\n', 'units = "Hz"\n',
        ["complementary_crossover", "missing key 'range'"]),
    "parameter_syntax_error": (
        "parameters.toml", "format_version = 1", "format_version = ",
        ["malformed TOML"]),
}


@pytest.mark.parametrize("case", sorted(BROKEN))
def test_broken_dictionary_names_file_and_culprit(proto_copy, case):
    filename, old, new, fragments = BROKEN[case]
    edit(proto_copy, filename, old, new)
    message = load_error(proto_copy)
    assert str(proto_copy / filename) in message
    for fragment in fragments:
        assert fragment in message, f"{fragment!r} not in {message!r}"


def test_missing_file_is_named(proto_copy):
    (proto_copy / "commands.toml").unlink()
    message = load_error(proto_copy)
    assert "commands.toml" in message and "not found" in message


def test_too_large_fixed_packet(proto_copy):
    edit(proto_copy, "telemetry.toml", "max_payload_bytes = 1024", "max_payload_bytes = 50")
    message = load_error(proto_copy)
    assert "telemetry.toml" in message and "HIGH_RATE" in message and "60" in message


def test_copy_loads_like_the_original(proto_copy, dictionary):
    copy = load_dictionary(proto_copy)
    assert copy.hash == dictionary.hash
    assert copy.packets == dictionary.packets
    assert copy.commands == dictionary.commands


# ------------------------------------------------------------------ dictionary hash
def test_hash_is_a_stable_u32(dictionary):
    assert 0 <= dictionary.hash < 2**32
    assert load_dictionary().hash == dictionary.hash


@pytest.mark.parametrize("filename", PROTOCOL_FILES)
def test_hash_ignores_comments_and_whitespace(proto_copy, dictionary, filename):
    path = proto_copy / filename
    text = path.read_text(encoding="utf-8")
    path.write_text("# a new comment at the top\n\n" + text.replace("\n[[", "\n\n# comment\n[[")
                    + "\n# trailing comment\n", encoding="utf-8")
    assert load_dictionary(proto_copy).hash == dictionary.hash


def test_hash_ignores_number_spelling_and_key_order(proto_copy, dictionary):
    edit(proto_copy, "telemetry.toml", 'name = "EVENT"\nid = 0x03', 'id = 3\nname = "EVENT"')
    assert load_dictionary(proto_copy).hash == dictionary.hash


@pytest.mark.parametrize("filename, old, new", [
    ("telemetry.toml", "scale = 3.0e-08", "scale = 3.1e-08"),
    ("telemetry.toml", "Severity", "Severity level"),               # a description
    ("telemetry.toml", "version_minor = 0", "version_minor = 1"),
    ("commands.toml", "heartbeat_period_s = 0.2", "heartbeat_period_s = 0.3"),
    ("parameters.toml", "default = 25.0", "default = 26.0"),
])
def test_hash_changes_with_any_value(proto_copy, dictionary, filename, old, new):
    edit(proto_copy, filename, old, new)
    assert load_dictionary(proto_copy).hash != dictionary.hash
