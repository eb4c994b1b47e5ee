"""The dictionary-dependent parts of the exported C header: identity, framing constants,
codes, and for every packet, command argument list, reply and parameter its byte
offsets, states, bit masks, scales, units and ranges, plus a plain struct and the
prototypes of its pack/unpack functions (bodies in c_source.py)."""

from __future__ import annotations

import zlib

from ..core.dictionary import CRC_SIZE, FRAME_OVERHEAD, HEADER_DTYPE, HEADER_SIZE, Dictionary, Item
from . import c_templates as T
from .layout import (C_TYPES, Record, c_double, c_number, c_string, check_unique, comment, conversion_text,
                     default_table, hex_u, lower, macro, max_dims, record)

CRC_POLY_REFLECTED = 0xEDB88320
CRC_INIT = CRC_XOROUT = 0xFFFFFFFF
CRC_CHECK = 0xCBF43926           # CRC of b"123456789" (SPEC.md 2.1)
CRC_RESIDUE = 0x2144DF1C         # CRC over a whole valid frame, its CRC included


def define(name: str, value: str, note: str = "") -> str:
    line = f"#define {name} {value}"
    if note:
        line = f"{line:<60} /* {comment(note)} */"
    return line


def _number(value: int | float) -> str:
    """An integer as an unsigned literal, a float (even a whole one) as a double."""
    if isinstance(value, int):
        return f"{value}u" if value >= 0 else f"({value})"
    return c_double(value)


def _bytes(n: int) -> str:
    return f"{n} byte{'' if n == 1 else 's'}"


class Layouts:
    """Every record of the dictionary with its C names, in dictionary order."""

    def __init__(self, d: Dictionary):
        # (struct base name, macro prefix, record, title)
        self.records: list[tuple[str, str, Record, str]] = []
        for p in d.packets:
            self.records.append((lower("hfb_pkt", p.name), macro("HFB_PKT", p.name),
                                 record(p.items), f"packet {p.name} payload"))
        for c in d.commands:
            for part, items in (("args", c.args), ("reply", c.reply)):
                if items:
                    self.records.append((lower("hfb_cmd", c.name, part),
                                         macro("HFB_CMD", c.name, part), record(items),
                                         f"command {c.name} {'arguments' if part == 'args' else 'reply'}"))

    def of(self, prefix: str) -> tuple[str, str, Record, str]:
        return next(r for r in self.records if r[1] == prefix)


def item_defines(prefix: str, rec: Record) -> list[str]:
    out: list[str] = []
    offsets = {f.item.name: f.offset for f in rec.fields}
    for item in rec.items:
        m = macro(prefix, item.name)
        where = (f"offset {offsets[item.name]}" if not item.is_variable
                 else f"the rest, from offset {rec.fixed_size}")
        bits = [item.type, where, conversion_text(item), item.description]
        out.append(f"/* {comment(' - '.join(b for b in bits if b))} */")
        if item.is_variable:
            out.append(define(f"{m}_OFFSET", f"{rec.fixed_size}u",
                              "UTF-8 text, no terminator" if item.type == "str" else "raw bytes"))
        else:
            out.append(define(f"{m}_OFFSET", f"{offsets[item.name]}u", item.type))
        if item.scale is not None:
            out.append(define(f"{m}_SCALE", c_double(item.scale), f"{item.units or 'units'} per count"))
            if item.offset:
                out.append(define(f"{m}_ENG_OFFSET", c_double(item.offset), item.units))
        if item.polynomial is not None:
            for k, coeff in enumerate(item.polynomial):
                out.append(define(f"{m}_POLY_{k}", c_double(coeff), f"coefficient of raw^{k}"))
        if item.value_range is not None:
            lo, hi = item.value_range
            note = "compare the received float with these floats (SPEC.md 3.2)" \
                if item.type == "f32" else f"range in {item.units or 'engineering units'}"
            out.append(define(f"{m}_MIN", c_number(lo, item.type), note))
            out.append(define(f"{m}_MAX", c_number(hi, item.type)))
        for label, value in item.states.items():
            out.append(define(macro(prefix, item.name, label), _number(value), f"state {label}"))
        for flag, bit in item.bits.items():
            out.append(define(macro(prefix, item.name, flag, "BIT"), f"{bit}u"))
            out.append(define(macro(prefix, item.name, flag, "MASK"), hex_u(1 << bit, 2 if bit < 8 else 8),
                              f"flag {flag}"))
        if item.limits is not None:
            lims = [f"{k} [{v[0]!r}, {v[1]!r}]" for k, v in
                    (("yellow", item.limits.yellow), ("red", item.limits.red)) if v]
            out.append(f"/*   display limits {comment(', '.join(lims))} {comment(item.units)} */")
    return out


def struct_text(base: str, rec: Record) -> list[str]:
    members: list[str] = []
    names: list[str] = []
    for f in rec.fields:
        item = f.item
        note = _member_note(item)
        members.append(f"    {f.c_type + ' ' + lower(item.name) + ';':<32} /* {comment(note)} */")
        names.append(lower(item.name))
    if rec.variable is not None:
        var = lower(rec.variable.name)
        what = "UTF-8 text" if rec.variable.type == "str" else "bytes"
        members.append(f"    {'const uint8_t *' + var + ';':<32} /* {what}, no terminator */")
        members.append(f"    {'size_t ' + var + '_len;':<32} /* its length in bytes */")
        names += [var, f"{var}_len"]
    check_unique(names, f"members of {base}_t")
    return ["typedef struct {", *members, f"}} {base}_t;"]


def _member_note(item: Item) -> str:
    if item.scale is not None or item.polynomial is not None:
        return f"raw counts; {conversion_text(item)}"
    if item.states:
        return "states " + ", ".join(f"{k}={v}" for k, v in item.states.items())
    if item.bits:
        return "bits " + ", ".join(f"{k}={v}" for k, v in item.bits.items())
    return item.units or item.type


def record_block(base: str, prefix: str, rec: Record) -> list[str]:
    size_note = ("fixed part; the last item takes the rest of the payload" if rec.variable
                 else "bytes, fixed")
    out = [define(f"{prefix}_SIZE", f"{rec.fixed_size}u", size_note),
           define(f"{prefix}_VARIABLE", "1" if rec.variable else "0")]
    out += item_defines(prefix, rec)
    out += struct_text(base, rec)
    out.append(f"size_t {base}_pack(const {base}_t *value, uint8_t *out, size_t capacity);")
    out.append(f"int {base}_unpack({base}_t *value, const uint8_t *in, size_t length);")
    return out


def header_text(d: Dictionary, name: str) -> str:
    layouts = Layouts(d)
    hash_hex = f"{d.hash:08X}"
    parts = [T.HEADER_TOP.substitute(name=name, protocol=comment(d.name), version=d.version,
                                     hash_hex=hash_hex, layout_note=T.LAYOUT_NOTE).rstrip("\n")]
    rate = d.control_rate_hz
    ident = [
        "/* ---- protocol identity ----------------------------------------------------------- */",
        define("HFB_PROTOCOL_NAME", c_string(d.name)),
        define("HFB_PROTOCOL_VERSION_MAJOR", f"{d.version_major}u", "carried in every frame header"),
        define("HFB_PROTOCOL_VERSION_MINOR", f"{d.version_minor}u"),
        define("HFB_DICTIONARY_HASH", f"0x{hash_hex}u", "SPEC.md 8: report it, compare CONNECT's"),
        define("HFB_CONTROL_RATE_HZ", _number(int(rate) if float(rate).is_integer() else rate),
               "control periods (device ticks) per second"),
        "/* host timing, commands.toml [defaults] (the device's watchdog timeout is a parameter) */",
    ]
    for key, value in d.command_defaults.items():
        ident.append(define(macro("HFB_DEFAULT", key), _number(value)))
    parts.append("\n".join(ident))

    header_offsets = [define(macro("HFB_HDR", n, "OFFSET"), f"{HEADER_DTYPE.fields[n][1]}u",
                             _bytes(HEADER_DTYPE.fields[n][0].itemsize)) for n in HEADER_DTYPE.names]
    parts.append("\n".join([
        "/* ---- framing (SPEC.md 2) ---------------------------------------------------------- */",
        define("HFB_SYNC", hex_u(d.sync, 4), "first byte 0xEB"),
        define("HFB_SYNC_0", hex_u(d.sync >> 8, 2)),
        define("HFB_SYNC_1", hex_u(d.sync & 0xFF, 2)),
        define("HFB_HEADER_SIZE", f"{HEADER_SIZE}u"),
        define("HFB_CRC_SIZE", f"{CRC_SIZE}u", "after the payload, least significant byte first"),
        define("HFB_FRAME_OVERHEAD", f"{FRAME_OVERHEAD}u"),
        define("HFB_MAX_PAYLOAD", f"{d.max_payload}u"),
        define("HFB_MAX_FRAME", f"{d.max_payload + FRAME_OVERHEAD}u"),
        *header_offsets,
        define("HFB_CRC_POLY_REFLECTED", hex_u(CRC_POLY_REFLECTED, 8), "0x04C11DB7 bit-reflected"),
        define("HFB_CRC_INIT", hex_u(CRC_INIT, 8)),
        define("HFB_CRC_XOROUT", hex_u(CRC_XOROUT, 8)),
        define("HFB_CRC_CHECK", hex_u(CRC_CHECK, 8), 'CRC of the 9 bytes "123456789"'),
        define("HFB_CRC_RESIDUE", hex_u(CRC_RESIDUE, 8), "CRC over a whole valid frame"),
    ]))
    parts.append(T.BYTE_ORDER.rstrip("\n"))

    codes = ["/* ---- RESPONSE reason codes (commands.toml [error_codes]) ------------------------ */"]
    codes += [define(macro("HFB_ERR", k), _number(v)) for k, v in d.error_codes.items()]
    codes.append("/* ---- EVENT codes (commands.toml [event_codes]) ---------------------------------- */")
    codes += [define(macro("HFB_EVT", k), _number(v)) for k, v in d.event_codes.items()]
    parts.append("\n".join(codes))

    for p in d.packets:
        base, prefix, rec, _ = layouts.of(macro("HFB_PKT", p.name))
        rate = f", {p.rate_hz:g} Hz" if p.rate_hz else ""
        head = [f"/* ==== packet {p.name} (id 0x{p.id:02X}, {p.direction}{rate}): {comment(p.description)} */",
                define(f"{prefix}_ID", hex_u(p.id, 2))]
        if rec.variable is None:
            head.append(define(f"{prefix}_FRAME_SIZE", f"{rec.fixed_size + FRAME_OVERHEAD}u"))
        parts.append("\n".join(head + record_block(base, prefix, rec)))

    for c in d.commands:
        flags = [] if c.needs_session else ["no session token needed"]
        flags += ["critical"] if c.critical else []
        head = [f"/* ==== command {c.name} (opcode 0x{c.opcode:04X}{'; ' if flags else ''}"
                f"{', '.join(flags)}): {comment(c.description)} */",
                define(macro("HFB_CMD", c.name, "OPCODE"), hex_u(c.opcode, 4)),
                define(macro("HFB_CMD", c.name, "NEEDS_SESSION"), "1" if c.needs_session else "0"),
                define(macro("HFB_CMD", c.name, "CRITICAL"), "1" if c.critical else "0"),
                define(macro("HFB_CMD", c.name, "TIMEOUT_S"), c_double(c.timeout_s),
                       "host waits this long for COMPLETED/FAILED")]
        for part, items in (("args", c.args), ("reply", c.reply)):
            if not items:
                head.append(define(macro("HFB_CMD", c.name, part, "SIZE"), "0u",
                                   f"no {'arguments' if part == 'args' else 'reply bytes'}"))
                continue
            base, prefix, rec, _ = layouts.of(macro("HFB_CMD", c.name, part))
            head += record_block(base, prefix, rec)
        parts.append("\n".join(head))

    parts.append("\n".join(parameter_defines(d)))
    parts.append(T.API.rstrip("\n"))
    text = "\n\n".join(parts) + "\n\n" + T.HEADER_END
    _check_macros(text)
    return text


def parameter_defines(d: Dictionary) -> list[str]:
    out = ["/* ==== parameter table (parameters.toml, SPEC.md 11.1): the entries in increasing id",
           " * order, each element big-endian, arrays row-major, no padding; HFB_PARAM_*_MIN/MAX",
           " * are the validation ranges (f32 ones already rounded to float) */"]
    offset = 0
    for p in d.parameters:
        m = macro("HFB_PARAM", p.name)
        count = 1
        for s in p.shape:
            count *= s
        shape = "x".join(str(s) for s in p.shape) or "scalar"
        filt = ", cascade of second-order sections b0 b1 b2 a0 a1 a2" if p.filter == "sos" else ""
        out.append(f"/* {comment(p.name)}: {p.type} {shape}{filt}, {comment(p.units) or 'no units'} - "
                   f"{comment(p.description)} */")
        out.append(define(f"{m}_ID", f"{p.id}u"))
        out.append(define(f"{m}_OFFSET", f"{offset}u", "byte offset in the table"))
        out.append(define(f"{m}_COUNT", f"{count}u", f"elements of {C_TYPES[p.type][1]} bytes"))
        if len(p.shape) == 2:
            out.append(define(f"{m}_ROWS", f"{p.shape[0]}u"))
            out.append(define(f"{m}_COLS", f"{p.shape[1]}u"))
        out.append(define(f"{m}_MIN", c_number(p.value_range[0], p.type)))
        out.append(define(f"{m}_MAX", c_number(p.value_range[1], p.type)))
        if not p.shape:
            out.append(define(f"{m}_DEFAULT", c_number(p.default, p.type)))
        offset += count * C_TYPES[p.type][1]
    out.append(define("HFB_PARAM_TABLE_SIZE", f"{offset}u", "PARAM_BEGIN's table_length"))
    out.append(define("HFB_PARAM_ENTRIES", f"{len(d.parameters)}u", "entries of hfb_params[]"))
    out.append(define("HFB_PARAM_MAX_DIMS", f"{max_dims(d)}u", "length of hfb_param_info_t.shape"))
    out.append(define("HFB_PARAM_DEFAULT_TABLE_CRC", hex_u(zlib.crc32(default_table(d)), 8),
                      "CRC-32 of the table of defaults"))
    out.append("/* the table of all defaults: the active table at boot, version 0 (SPEC.md 11.1) */")
    out.append("extern const uint8_t hfb_param_default_table[HFB_PARAM_TABLE_SIZE];")
    return out


def _check_macros(text: str) -> None:
    names = [line.split()[1] for line in text.splitlines() if line.startswith("#define ")]
    # the capacity default sits inside #ifndef and is defined once
    check_unique(names, "C macros")
