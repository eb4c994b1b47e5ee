"""The dictionary-dependent parts of the exported C source: the CRC table, the packet
length rules, pack/unpack of every layout, and the default parameter table."""

from __future__ import annotations

from ..core.dictionary import Dictionary
from . import c_source_templates as T
from .c_header import CRC_POLY_REFLECTED, Layouts
from .layout import (C_TYPES, Record, c_bound, c_number, c_string, default_table, lower, macro, max_dims,
                     record, type_enum)


def crc_table() -> list[int]:
    """The 256-entry table of the reflected CRC-32 (SPEC.md 2.1), one byte at a time."""
    table = []
    for n in range(256):
        c = n
        for _ in range(8):
            c = (c >> 1) ^ CRC_POLY_REFLECTED if c & 1 else c >> 1
        table.append(c)
    return table


def _rows(values: list[str], per_line: int, indent: str = "    ") -> list[str]:
    return [indent + ", ".join(values[i:i + per_line]) + ("," if i + per_line < len(values) else "")
            for i in range(0, len(values), per_line)]


def crc_block() -> str:
    lines = ["/* CRC-32/ISO-HDLC table: polynomial 0x04C11DB7 reflected (0xEDB88320) */",
             "static const uint32_t hfb_crc_table[256] = {"]
    lines += _rows([f"0x{v:08X}u" for v in crc_table()], 6)
    lines.append("};")
    return "\n".join(lines)


def limits_block(d: Dictionary) -> str:
    lines = ["int hfb_payload_limits(uint8_t packet_id, uint16_t *min_length, uint16_t *max_length)",
             "{", "    switch (packet_id) {"]
    for p in d.packets:
        fixed = p.fixed_payload_size
        hi = d.max_payload if p.variable_item is not None else fixed
        lines += [f"    case {macro('HFB_PKT', p.name, 'ID')}:  /* {p.name} */",
                  f"        *min_length = {fixed}u;",
                  f"        *max_length = {hi}u;",
                  "        return 1;"]
    lines += ["    default:", "        return 0;", "    }", "}"]
    return "\n".join(lines)


def _arg_rows(c) -> tuple[list[str], str]:
    """The states arrays and the hfb_arg_info_t array of one command's arguments; the
    C name of the latter ("NULL" when the command has no arguments)."""
    if not c.args:
        return [], "NULL"
    rec = record(c.args)
    offsets = {f.item.name: f.offset for f in rec.fields}
    base = lower("hfb_args", c.name)
    lines, rows = [], []
    for item in c.args:
        offset = offsets.get(item.name, rec.fixed_size)
        states = "NULL"
        if item.states:
            states = lower("hfb_states", c.name, item.name)
            values = ", ".join(c_number(v, "i64") for v in item.states.values())
            lines.append(f"static const int64_t {states}[{len(item.states)}] = {{{values}}};")
        if item.value_range is not None:
            lo, hi = (c_bound(v, item.type) for v in item.value_range)
        else:
            lo = hi = "0.0"
        rows.append(f"    {{{c_string(item.name)}, {type_enum(item.type)}, {offset}u, "
                    f"{int(item.value_range is not None)}u, {lo}, {hi}, {len(item.states)}u, {states}, "
                    f"{c_string(item.units)}}},")
    lines += [f"static const hfb_arg_info_t {base}[{len(c.args)}] = {{", *rows, "};"]
    return lines, base


def commands_block(d: Dictionary) -> str:
    lines = ["/* every command's arguments in wire order: what check 4 of SPEC.md 6.3 loops over */"]
    entries = []
    for c in d.commands:
        arg_lines, arg_table = _arg_rows(c)
        lines += arg_lines
        args, reply = record(c.args), record(c.reply)
        entries.append(f'    {{"{c.name}", {macro("HFB_CMD", c.name, "OPCODE")}, {args.fixed_size}u, '
                       f"{int(args.variable is not None)}u, {reply.fixed_size}u, "
                       f"{int(reply.variable is not None)}u, {int(c.needs_session)}u, {int(c.critical)}u, "
                       f"{len(c.args)}u, {arg_table}}},")
    lines += ["", "static const hfb_command_info_t hfb_commands[] = {", *entries]
    lines += ["};", "",
              "const hfb_command_info_t *hfb_command_info(uint16_t opcode)", "{",
              "    size_t i;",
              "    for (i = 0; i < sizeof hfb_commands / sizeof hfb_commands[0]; i++) {",
              "        if (hfb_commands[i].opcode == opcode) {",
              "            return &hfb_commands[i];", "        }", "    }",
              "    return NULL;", "}"]
    return "\n".join(lines)


def pack_functions(base: str, prefix: str, rec: Record) -> str:
    size = f"{prefix}_SIZE"
    lines = [f"size_t {base}_pack(const {base}_t *value, uint8_t *out, size_t capacity)", "{"]
    if rec.variable is not None:
        var = lower(rec.variable.name)
        lines += [f"    if (capacity < {size} || value->{var}_len > capacity - {size}) {{",
                  "        return 0;", "    }"]
    else:
        lines += [f"    if (capacity < {size}) {{", "        return 0;", "    }"]
    if rec.variable is not None:
        # the tail first: it may already sit in `out` (memmove copies overlapping bytes)
        lines += [f"    if (value->{var}_len > 0u) {{",
                  f"        memmove(out + {size}, value->{var}, value->{var}_len);",
                  "    }"]
    for f in rec.fields:
        name = lower(f.item.name)
        lines.append(f"    hfb_put_{f.item.type}(out + {macro(prefix, f.item.name, 'OFFSET')}, value->{name});")
    if rec.variable is not None:
        lines.append(f"    return {size} + value->{var}_len;")
    else:
        if not rec.fields:
            lines.append("    (void)value;")
        lines.append(f"    return {size};")
    lines += ["}", "",
              f"int {base}_unpack({base}_t *value, const uint8_t *in, size_t length)", "{"]
    check = "<" if rec.variable is not None else "!="
    lines += [f"    if (length {check} {size}) {{", "        return -1;", "    }"]
    for f in rec.fields:
        name = lower(f.item.name)
        lines.append(f"    value->{name} = hfb_get_{f.item.type}(in + {macro(prefix, f.item.name, 'OFFSET')});")
    if rec.variable is not None:
        lines += [f"    value->{var} = in + {size};",
                  f"    value->{var}_len = length - {size};"]
    elif not rec.fields:
        lines += ["    (void)value;", "    (void)in;"]
    lines += ["    return 0;", "}"]
    return "\n".join(lines)


def params_block(d: Dictionary) -> str:
    """hfb_params[]: the entries in id order with their offsets, as SPEC.md 11.1 packs."""
    dims = max_dims(d)
    lines = ["/* the parameter table's entries in id (= table) order: what validation and",
             " * activation loop over */",
             "const hfb_param_info_t hfb_params[HFB_PARAM_ENTRIES] = {"]
    offset = 0
    for p in d.parameters:
        count = 1
        for n in p.shape:
            count *= n
        size = C_TYPES[p.type][1]
        shape = ", ".join(f"{n}u" for n in list(p.shape) + [0] * (dims - len(p.shape)))
        lo, hi = (c_bound(v, p.type) for v in p.value_range)
        lines.append(f"    {{{p.id}u, {c_string(p.name)}, {type_enum(p.type)}, {size}u, {offset}u, "
                     f"{count}u, {len(p.shape)}u, {{{shape}}}, {lo}, {hi}, {int(p.filter == 'sos')}u, "
                     f"hfb_param_default_table + {offset}, {c_string(p.units)}}},")
        offset += count * size
    lines.append("};")
    return "\n".join(lines)


def default_table_block(d: Dictionary) -> str:
    data = default_table(d)
    lines = ["/* the parameter table of all defaults (SPEC.md 11.1), big-endian as on the wire */",
             "const uint8_t hfb_param_default_table[HFB_PARAM_TABLE_SIZE] = {"]
    lines += _rows([f"0x{b:02X}" for b in data], 16)
    lines.append("};")
    return "\n".join(lines)


def source_text(d: Dictionary, name: str) -> str:
    parts = [T.SOURCE_TOP.substitute(name=name, protocol=d.name, version=d.version,
                                     hash_hex=f"{d.hash:08X}").rstrip("\n"),
             crc_block(), limits_block(d), commands_block(d), params_block(d), T.CODEC.rstrip("\n"),
             "/* ---- pack/unpack: native struct <-> big-endian bytes, offsets from the header ---- */"]
    for base, prefix, rec, title in Layouts(d).records:
        parts.append(f"/* {title} */\n" + pack_functions(base, prefix, rec))
    parts.append(default_table_block(d))
    return "\n\n".join(parts) + "\n"
