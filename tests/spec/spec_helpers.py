"""Shared helpers of the tests/spec/test_spec_*.py files (protocol/SPEC.md checked against the
ground station).

Everything here is written from SPEC.md and protocol/*.toml alone: it uses only `struct`,
`tomllib` and `pathlib` and nothing from the groundstation package, so what the spec tests
build with it stays independent of the code under test.
"""

from __future__ import annotations

import struct
import tomllib
from pathlib import Path

ROOT = Path(__file__).resolve().parents[2]
PROTOCOL = ROOT / "protocol"
SPEC = PROTOCOL / "SPEC.md"

# --- wire constants (SPEC §2, §3.1) ---------------------------------------------------

SYNC = b"\xEB\x90"
VERSION = 1
RESIDUE = 0x2144DF1C
HEADER = struct.Struct(">2sBBHII")          # sync, version, packet_id, length, sequence, tick

# SPEC §3.1 wire types -> struct codes (always used with ">")
STRUCT_CODE = {"u8": "B", "i8": "b", "u16": "H", "i16": "h", "u32": "I", "i32": "i",
               "u64": "Q", "i64": "q", "f32": "f", "f64": "d"}


def load_toml(name: str) -> dict:
    return tomllib.loads((PROTOCOL / name).read_text(encoding="utf-8"))


def f32(x: float) -> float:
    return struct.unpack(">f", struct.pack(">f", x))[0]


def assert_item(item_scale, type_, decoded, intended, where):
    if item_scale is not None:
        assert abs(decoded - intended) <= abs(item_scale) * (1 + 1e-9), (where, decoded, intended)
    elif type_ == "f32":
        assert decoded == f32(intended), (where, decoded, intended)
    else:
        assert decoded == intended, (where, decoded, intended)


# --- SPEC.md's own text ----------------------------------------------------------------

def spec_text() -> str:
    return SPEC.read_text(encoding="utf-8")


def spec_section(start: str, end: str) -> str:
    text = spec_text()
    return text.split(start, 1)[1].split(end, 1)[0]


def parse_number(text: str):
    return int(text, 16) if text.lower().startswith("0x") else (
        float(text) if any(ch in text for ch in ".e") else int(text))
