"""protocol/SPEC.md §11.1 checked against the ground station: the parameter table packed
from parameters.toml with `struct` alone, following the SPEC (layout, size, CRC and first
bytes of the defaults, named defaults), and the validation rules written from the text
against the device's check."""

from __future__ import annotations

import re
import struct
import zlib

import pytest
from spec_helpers import (PROTOCOL, STRUCT_CODE, f32, load_toml, parse_number, spec_section,
                          spec_text)

from groundstation.core.dictionary import load_dictionary


@pytest.fixture(scope="module")
def dictionary():
    return load_dictionary(PROTOCOL)


# --- §11.1 parameter table, packed from parameters.toml with struct alone -----------------

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
