"""`groundstation protocol export-wireshark FILE.lua`: a Wireshark/tshark dissector of
the UDP telemetry and the TCP command channel, generated from the dictionary.

Every packet item, command argument and reply item becomes a ProtoField named
`hfb.<packet>.<item>` (`hfb.cmd.<command>.<arg>`, `hfb.reply.<command>.<item>`), with the
item's units in its label and description.  An item with a scale shows its
engineering value (a double, computed as the ground station does: raw * scale +
offset) and, as `<field>.raw`, the counts on the wire.  States and event, reason and
opcode names are value strings; status bits are boolean sub-fields.

The dissector registers on one UDP and one TCP port (default: the simulator's 5020 for
both - the device sends its telemetry from its command port's number, SPEC.md 1.1);
preferences under Protocols > HFB change them.  On every other port heuristic
dissectors recognise the protocol by a whole frame with a good CRC and claim its
conversation (wireshark_lua.py; the preference `hfb.heuristics` turns them off).  The text is a pure function of the
dictionary and the port.
"""

from __future__ import annotations

from pathlib import Path

from ..core.dictionary import CRC_SIZE, HEADER_SIZE, Dictionary, Item
from .layout import C_TYPES, KitError, comment, conversion_text, lower, record
from .wireshark_lua import READERS, WALK

FTYPES = {"u8": "UINT8", "u16": "UINT16", "u32": "UINT32", "u64": "UINT64",
          "i8": "INT8", "i16": "INT16", "i32": "INT32", "i64": "INT64",
          "f32": "FLOAT", "f64": "DOUBLE", "str": "STRING", "bytes": "BYTES"}
DEFAULT_PORT = 5020


def lua_str(text: str) -> str:
    """A Lua string literal (UTF-8 bytes; quotes, backslashes and the rest escaped)."""
    out = []
    for b in str(text).encode("utf-8"):
        ch = chr(b)
        out.append(ch if 32 <= b < 127 and ch not in '"\\' else f"\\{b:03d}")
    return '"' + "".join(out) + '"'


def lua_num(value: float | int) -> str:
    if isinstance(value, int):
        return str(value)
    text = repr(float(value))
    if text in ("inf", "-inf", "nan"):
        raise KitError(f"cannot write the non-finite number {value!r} into the dissector")
    return text


def value_table(mapping: dict[str, int]) -> str:
    """{label: value} -> a Lua value-string table {[value] = "label"}."""
    return "{" + ", ".join(f"[{lua_num(v)}] = {lua_str(k)}" for k, v in mapping.items()) + "}"


class _Writer:
    """Collects the Lua lines; every field is created once and listed in `F`."""

    def __init__(self, d: Dictionary):
        self.d = d
        self.lines: list[str] = []
        self.abbrevs: set[str] = set()
        # fields whose numbers have names elsewhere in the dictionary (SPEC.md 5.3, 6)
        self.named = {("EVENT", "code"): "EVENT_NAMES", ("COMMAND", "opcode"): "OPCODE_NAMES",
                      ("RESPONSE", "opcode"): "OPCODE_NAMES", ("RESPONSE", "reason"): "ERROR_NAMES"}

    def field(self, label: str, abbrev: str, ftype: str, desc: str, *, values: str = "nil",
              base: str = "base.NONE", mask: str = "nil") -> str:
        if abbrev in self.abbrevs:
            raise KitError(f"two dissector fields would both be named {abbrev}: rename one in the TOML")
        self.abbrevs.add(abbrev)
        return (f"field(ProtoField.new({lua_str(label)}, {lua_str(abbrev)}, ftypes.{ftype}, "
                f"{values}, {base}, {mask}, {lua_str(desc)}))")

    def item_entry(self, owner: str, prefix: str, item: Item, offset: int | None) -> str:
        abbrev = f"{prefix}.{lower(item.name)}"
        units = f" [{item.units}]" if item.units else ""
        label = f"{item.name}{units}"
        scaled = item.scale is not None or item.polynomial is not None
        desc = comment(" - ".join(x for x in (item.description, conversion_text(item) if scaled else "") if x)
                       + (f" [{item.units}]" if item.units and not scaled else ""))
        if item.is_variable:
            f = self.field(label, abbrev, FTYPES[item.type], desc)
            return (f"{{off = {offset}, rest = true, type = {lua_str(item.type)}, "
                    f"label = {lua_str(item.name)}, field = {f}}}")
        size = C_TYPES[item.type][1]
        head = f"off = {offset}, size = {size}, type = {lua_str(item.type)}"
        if item.scale is not None or item.polynomial is not None:
            eng = self.field(label, abbrev, "DOUBLE", desc)
            raw = self.field(f"{item.name} raw counts", f"{abbrev}.raw", FTYPES[item.type],
                             comment(f"on the wire; {conversion_text(item)}"), base="base.DEC")
            conv = (f"poly = {{{', '.join(lua_num(c) for c in item.polynomial)}}}"
                    if item.polynomial is not None
                    else f"scale = {lua_num(item.scale)}, add = {lua_num(item.offset)}")
            return f"{{{head}, {conv}, raw = {raw}, field = {eng}}}"
        if item.type in ("f32", "f64"):
            return f"{{{head}, field = {self.field(label, abbrev, FTYPES[item.type], desc)}}}"
        values = "nil"
        if item.states:
            values = value_table(item.states)
        elif (owner, item.name) in self.named:
            values = self.named[(owner, item.name)]
        # flags, and numbers that are identities rather than quantities, in hex
        hexa = item.bits or any(w in item.name for w in ("hash", "crc", "token"))
        base = "base.HEX" if hexa else "base.DEC"
        f = self.field(label, abbrev, FTYPES[item.type], desc, values=values, base=base)
        if item.name == "dictionary_hash" and item.type == "u32":
            return f"{{{head}, field = {f}, check_hash = true}}"     # SPEC.md 8, at CONNECT
        if not item.bits:
            return f"{{{head}, field = {f}}}"
        flags = [self.field(flag, f"{abbrev}.{lower(flag)}", "BOOLEAN", f"bit {bit} of {item.name}",
                            base=str(size * 8), mask=f"0x{1 << bit:X}")
                 for flag, bit in item.bits.items()]
        return f"{{{head}, field = {f}, flags = {{{', '.join(flags)}}}}}"

    def layout(self, key: str, owner: str, prefix: str, items: tuple[Item, ...]) -> None:
        rec = record(items)
        offsets = {f.item.name: f.offset for f in rec.fields}
        self.lines.append(f"LAYOUTS[{lua_str(key)}] = {{fixed = {rec.fixed_size}, items = {{")
        for item in items:
            off = rec.fixed_size if item.is_variable else offsets[item.name]
            self.lines.append(f"  {self.item_entry(owner, prefix, item, off)},")
        self.lines.append("}}")


def _offset(items: tuple[Item, ...], name: str) -> tuple[int, Item] | None:
    rec = record(items)
    for f in rec.fields:
        if f.item.name == name:
            return f.offset, f.item
    return None


def _extras(d: Dictionary) -> list[str]:
    """Per-packet extras: a COMMAND's arguments and a RESPONSE's reply by opcode, an
    EVENT's level and name in the info column."""
    out = ["local EXTRA = {}"]
    names = {p.name: p for p in d.packets}
    cmd = names.get("COMMAND")
    if cmd and cmd.variable_item is not None and _offset(cmd.items, "opcode"):
        off, _ = _offset(cmd.items, "opcode")
        fixed = cmd.fixed_payload_size
        out += ['EXTRA["COMMAND"] = function(tvb, start, length, tree)',
                f"  local opcode = tvb(start + {off}, 2):uint()",
                '  local name = OPCODE_NAMES[opcode] or string.format("opcode 0x%04X", opcode)',
                '  local layout = LAYOUTS["args:" .. name]',
                "  if layout then",
                f'    local sub = tree:add(hfb, tvb(start + {fixed}, length - {fixed}), name .. " arguments")',
                f"    add_items(tvb, start + {fixed}, length - {fixed}, sub, layout)",
                "  end", "  return name", "end"]
    rsp = names.get("RESPONSE")
    found = rsp and all(_offset(rsp.items, k) for k in ("opcode", "stage", "reason"))
    if found and rsp.variable_item is not None:
        (o_op, _), (o_st, stage), (o_re, _) = (_offset(rsp.items, k) for k in ("opcode", "stage", "reason"))
        fixed = rsp.fixed_payload_size
        completed = stage.states.get("COMPLETED", -1)
        rejected = stage.states.get("REJECTED", -1)
        mismatch = d.error_codes.get("DICTIONARY_MISMATCH", -1)
        not_owner = d.error_codes.get("NOT_SESSION_OWNER", -1)
        out += ['EXTRA["RESPONSE"] = function(tvb, start, length, tree)',
                f"  local opcode = tvb(start + {o_op}, 2):uint()",
                f"  local stage = tvb(start + {o_st}, 1):uint()",
                f"  local reason = tvb(start + {o_re}, 2):uint()",
                '  local name = OPCODE_NAMES[opcode] or string.format("opcode 0x%04X", opcode)',
                f"  local at, n = start + {fixed}, length - {fixed}",
                "  local layout, what",
                f"  if stage == {completed} then",
                '    layout, what = LAYOUTS["reply:" .. name], name .. " reply"',
                f"  elseif stage == {rejected} and reason == {mismatch} then",
                '    layout, what = LAYOUTS["reply:CONNECT"], "the device\'s versions and hash (CONNECT reply layout)"',
                f"  elseif stage == {rejected} and reason == {not_owner} and n > 0 then",
                "    tree:add(F.owner, tvb(at, n), tvb(at, n):string(ENC_UTF_8))",
                "  end",
                "  if layout then add_items(tvb, at, n, tree:add(hfb, tvb(at, n), what), layout) end",
                f"  local text = name .. \" \" .. (({value_table(stage.states)})[stage] or tostring(stage))",
                '  if reason ~= 0 then text = text .. " " .. (ERROR_NAMES[reason] or tostring(reason)) end',
                "  return text", "end"]
    ev = names.get("EVENT")
    if ev and _offset(ev.items, "code") and _offset(ev.items, "level"):
        (o_code, _), (o_lvl, level) = _offset(ev.items, "code"), _offset(ev.items, "level")
        out += ['EXTRA["EVENT"] = function(tvb, start, length, tree)',
                f"  local level = ({value_table(level.states)})[tvb(start + {o_lvl}, 1):uint()] or \"?\"",
                f"  local code = tvb(start + {o_code}, 2):uint()",
                '  return level .. " " .. (EVENT_NAMES[code] or tostring(code))', "end"]
    return out


def _preamble(d: Dictionary, port: int) -> list[str]:
    """The file's comment header, the protocol's constants and preferences, the name
    tables, and the start of the field table F."""
    return [
        f"-- hfb_protocol.lua - Wireshark dissector for the {comment(d.name)} protocol {d.version}",
        "--",
        "-- GENERATED by `groundstation protocol export-wireshark` from protocol/telemetry.toml,",
        f"-- commands.toml and parameters.toml (dictionary hash 0x{d.hash:08X}).  Do not edit:",
        "-- export again after a change of the TOML files.",
        "--",
        "-- Use: tshark -X lua_script:hfb_protocol.lua -r capture.pcap   (or wireshark -X ...),",
        "-- or copy the file into Wireshark's personal Lua plugins folder.  Filter with `hfb`,",
        "-- fields are hfb.<packet>.<item>, hfb.cmd.<command>.<argument>, hfb.reply.<command>.<item>;",
        "-- scaled items show engineering units, their wire counts are <field>.raw.",
        f"-- UDP telemetry and the TCP command channel are decoded on port {port} (the device's",
        "-- command port, and the UDP port its telemetry comes from); preferences change both.",
        "-- On any other port a conversation is recognised by its first whole frame with a good",
        "-- CRC (hfb.heuristics, on by default; docs/firmware.md).",
        "",
        f"local hfb = Proto(\"hfb\", {lua_str(f'HFB testbed protocol ({d.name} {d.version})')})",
        f"local PROTOCOL_MAJOR = {d.version_major}",
        f"local DICTIONARY_HASH = 0x{d.hash:08X}",
        f"local HEADER_SIZE, CRC_SIZE = {HEADER_SIZE}, {CRC_SIZE}",
        f"hfb.prefs.udp_port = Pref.uint(\"UDP telemetry port\", {port}, "
        "\"UDP port the device sends telemetry from (its command port's number)\")",
        f"hfb.prefs.tcp_port = Pref.uint(\"TCP command port\", {port}, "
        "\"TCP port of the device's command channel\")",
        # a switch of our own: tshark's --disable-heuristic runs before Lua scripts load
        "hfb.prefs.heuristics = Pref.bool(\"Find the protocol on any port\", true, "
        "\"Recognise HFB frames on other UDP and TCP ports by their header and CRC\")",
        "",
        f"local PACKET_NAMES = {value_table({p.name: p.id for p in d.packets})}",
        f"local OPCODE_NAMES = {value_table({c.name: c.opcode for c in d.commands})}",
        f"local ERROR_NAMES = {value_table(d.error_codes)}",
        f"local EVENT_NAMES = {value_table(d.event_codes)}",
        "local LIMITS = {" + ", ".join(
            f"[{p.id}] = {{{p.fixed_payload_size}, {d.max_payload if p.variable_item else p.fixed_payload_size}}}"
            for p in d.packets) + "}",
        "",
        "local fields = {}",
        "local function field(f) fields[#fields + 1] = f; return f end",
        "local F = {",
    ]


def _header_fields(d: Dictionary, w: _Writer) -> list[tuple[str, str]]:
    """(key in F, ProtoField expression) of the frame header's fields and the other
    fields every frame may show."""
    return [
        ("sync", w.field("Sync word", "hfb.sync", "UINT16", "always 0xEB90", base="base.HEX")),
        ("version", w.field("Protocol major version", "hfb.version", "UINT8",
                            "protocol major version of the sender", base="base.DEC")),
        ("packet_id", w.field("Packet", "hfb.packet_id", "UINT8", "packet id from telemetry.toml",
                              values="PACKET_NAMES", base="base.HEX")),
        ("length", w.field("Payload length [bytes]", "hfb.length", "UINT16",
                           "payload bytes, without header and CRC [bytes]", base="base.DEC")),
        ("sequence", w.field("Sequence", "hfb.sequence", "UINT32",
                             "per-packet sequence number (COMMAND: the command sequence number)",
                             base="base.DEC")),
        ("tick", w.field("Tick [ticks]", "hfb.tick", "UINT32",
                         f"device control period, {d.control_rate_hz:g} per second [ticks]", base="base.DEC")),
        ("crc", w.field("CRC-32", "hfb.crc", "UINT32",
                        "CRC-32/ISO-HDLC of sync..payload, sent least significant byte first", base="base.HEX")),
        ("crc_good", w.field("CRC correct", "hfb.crc.good", "BOOLEAN", "the CRC matches the frame")),
        ("junk", w.field("Junk", "hfb.junk", "BYTES", "bytes outside any frame")),
        ("owner", w.field("Session owner", "hfb.response.owner", "STRING",
                          "NOT_SESSION_OWNER rejection: who owns the session")),
    ]


def _expert_lines() -> list[str]:
    """The close of F, the expert-info definitions and their registration."""
    experts = [("E_CRC", "hfb.crc.bad", "CRC mismatch", "CHECKSUM", "ERROR"),
               ("E_JUNK", "hfb.junk.expert", "Junk", "MALFORMED", "WARN"),
               ("E_LENGTH", "hfb.length.short", "Too short", "MALFORMED", "ERROR"),
               ("E_HASH", "hfb.hash.differs", "Dictionary hash differs from this dissector's",
                "PROTOCOL", "WARN")]
    lines = ["}"] + [f"local {var} = ProtoExpert.new({lua_str(abbrev)}, {lua_str(text)}, "
                     f"expert.group.{group}, expert.severity.{level})"
                     for var, abbrev, text, group, level in experts]
    return lines + [f"hfb.experts = {{{', '.join(e[0] for e in experts)}}}",
                    "", "local LAYOUTS = {}"]


def render_lua(d: Dictionary, port: int = DEFAULT_PORT) -> str:
    """The Wireshark dissector for dictionary `d`, as Lua source, decoding `port`."""
    if not 0 < port < 65536:
        raise KitError(f"port {port} is not a TCP/UDP port number (1..65535)")
    w = _Writer(d)
    head = _preamble(d, port)
    head += [f"  {k} = {v}," for k, v in _header_fields(d, w)]
    head += _expert_lines()
    w.lines = head
    for p in d.packets:
        w.layout(f"pkt:{p.name}", p.name, f"hfb.{lower(p.name)}", p.items)
    for c in d.commands:
        if c.args:
            w.layout(f"args:{c.name}", "", f"hfb.cmd.{lower(c.name)}", c.args)
        if c.reply:
            w.layout(f"reply:{c.name}", "", f"hfb.reply.{lower(c.name)}", c.reply)
    w.lines.append("hfb.fields = fields")
    # the item reader, then the per-packet extras that use it, then the walks over
    # datagrams and streams that use both
    return "\n".join(w.lines) + READERS + "\n" + "\n".join(_extras(d)) + "\n" + WALK


def export_wireshark(d: Dictionary, path: str | Path, port: int = DEFAULT_PORT) -> Path:
    """Write the dissector to `path` (its folder made if missing); returns the path."""
    out = Path(path)
    out.parent.mkdir(parents=True, exist_ok=True)
    out.write_bytes(render_lua(d, port).encode("ascii"))
    return out
