"""What the generators share: wire types in C, byte offsets of an item list, and the
spelling of names, numbers and comments in generated text.

Everything here is a pure function of the dictionary, so the generated files are the
same bytes for the same TOML (no dates, paths or set iteration order in them).
"""

from __future__ import annotations

import math
import re
from dataclasses import dataclass

import numpy as np

from ..core.dictionary import Dictionary, Item
from ..core.errors import DictionaryError

#: wire type -> (C type, bytes); str/bytes are (pointer, length) pairs in C
C_TYPES: dict[str, tuple[str, int]] = {
    "u8": ("uint8_t", 1), "u16": ("uint16_t", 2), "u32": ("uint32_t", 4), "u64": ("uint64_t", 8),
    "i8": ("int8_t", 1), "i16": ("int16_t", 2), "i32": ("int32_t", 4), "i64": ("int64_t", 8),
    "f32": ("float", 4), "f64": ("double", 8),
}


class KitError(DictionaryError):
    """The dictionary cannot be written as a kit (e.g. two names give one C macro)."""


@dataclass(frozen=True)
class Field:
    """One fixed-size item at its byte offset in a payload / argument list / reply."""

    item: Item
    offset: int

    @property
    def c_type(self) -> str:
        return C_TYPES[self.item.type][0]

    @property
    def size(self) -> int:
        return C_TYPES[self.item.type][1]


@dataclass(frozen=True)
class Record:
    """An item list laid out on the wire: fixed fields, then maybe a variable tail."""

    items: tuple[Item, ...]
    fields: tuple[Field, ...]
    fixed_size: int
    variable: Item | None

    @property
    def empty(self) -> bool:
        return not self.items


def record(items: tuple[Item, ...]) -> Record:
    """Offsets exactly as SPEC §3 packs them: in order, back to back, no padding."""
    fields, offset = [], 0
    variable = None
    for item in items:
        if item.is_variable:
            variable = item
            continue
        fields.append(Field(item, offset))
        offset += C_TYPES[item.type][1]
    return Record(tuple(items), tuple(fields), offset, variable)


def ident(name: str) -> str:
    """A C identifier fragment for a dictionary name (letters, digits, underscores)."""
    text = re.sub(r"[^A-Za-z0-9_]", "_", name)
    return f"_{text}" if not text or text[0].isdigit() else text


def macro(*parts: str) -> str:
    return "_".join(ident(p).upper() for p in parts if p)


def lower(*parts: str) -> str:
    return "_".join(ident(p).lower() for p in parts if p)


def comment(text: str) -> str:
    """Text safe inside a C /* */ comment or a Lua string: ASCII, one line, no '*/'."""
    text = " ".join(str(text).split())
    text = text.encode("ascii", "backslashreplace").decode("ascii")
    return text.replace("*/", "* /")


def c_string(text: str) -> str:
    """A C string literal of `text`'s UTF-8 bytes (non-printable ones as octal escapes)."""
    out = []
    for b in text.encode("utf-8"):
        ch = chr(b)
        out.append(ch if 32 <= b < 127 and ch not in '"\\?' else f"\\{b:03o}")
    return '"' + "".join(out) + '"'


def c_double(value: float) -> str:
    """A double literal that reads back as exactly `value` (Python's repr rounds trip)."""
    value = float(value)
    if not math.isfinite(value):
        raise KitError(f"cannot write the non-finite number {value!r} as a C constant")
    text = repr(value)
    return f"({text})" if text.startswith("-") else text


def c_number(value: float, wire_type: str) -> str:
    """A bound or scale in the item's own type: integers exact, f32 as (float)double so
    it rounds as the SPEC's 'bounds rounded to f32' does (decimal -> double -> float)."""
    if wire_type in ("f32",):
        return f"((float){c_double(value)})"
    if wire_type == "f64" or not float(value).is_integer():
        return c_double(value)
    n = int(value)
    unsigned = wire_type.startswith("u") and n >= 0
    if wire_type in ("u64", "i64"):
        suffix = "ull" if unsigned else "ll"
    else:
        suffix = "u" if unsigned else ""
    if wire_type == "i32" and n == -2**31:
        return "(-2147483647 - 1)"
    if wire_type == "i64" and n == -2**63:
        return "(-9223372036854775807ll - 1)"
    return f"({n}{suffix})" if n < 0 else f"{n}{suffix}"


def c_bound(value: float, wire_type: str) -> str:
    """A range bound as the double literal of the tables: an f32 item's bound already
    rounded to float (decimal -> double -> float, as SPEC 3.2 and numpy round it), so a
    comparison in double gives the float comparison's answer; others as written."""
    value = float(value)
    if wire_type == "f32":
        rounded = float(np.float32(value))
        if math.isfinite(value) and not math.isfinite(rounded):
            raise KitError(f"the bound {value!r} does not fit an f32")
        value = rounded
    return c_double(value)


def type_enum(wire_type: str) -> str:
    """The hfb_type_t constant of a wire type."""
    return f"HFB_TYPE_{wire_type.upper()}"


def max_dims(d: Dictionary) -> int:
    """HFB_PARAM_MAX_DIMS: the most dimensions of a parameter's shape (at least 1, so the
    shape array of the entry struct is never empty)."""
    return max([1] + [len(p.shape) for p in d.parameters])


def hex_u(value: int, digits: int) -> str:
    return f"0x{value:0{digits}X}u"


def conversion_text(item: Item) -> str:
    """'eng = raw * 1e-4 A' style text for comments and field descriptions."""
    units = f" {item.units}" if item.units else ""
    if item.polynomial is not None:
        terms = " + ".join(f"{c!r}*raw^{k}" if k else repr(c) for k, c in enumerate(item.polynomial))
        return f"eng = {terms}{units}"
    if item.scale is not None:
        off = f" + {item.offset!r}" if item.offset else ""
        return f"eng = raw * {item.scale!r}{off}{units}"
    return item.units


def check_unique(names: list[str], what: str) -> None:
    seen: set[str] = set()
    for name in names:
        if name in seen:
            raise KitError(f"two {what} would both be named {name}: rename one in the TOML")
        seen.add(name)


def default_table(d: Dictionary) -> bytes:
    """The parameter table of all defaults (SPEC.md 11.1): entries in id order, each
    element big-endian in its type, arrays row-major."""
    return b"".join(np.asarray(p.default, dtype=p.dtype).reshape(-1).tobytes()
                    for p in sorted(d.parameters, key=lambda p: p.id))
