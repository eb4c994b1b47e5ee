"""The protocol dictionary: `protocol/*.toml` read into typed, validated records.

Everything else (codec, simulated device, logs, GUI channel lists) is built from the
`Dictionary` this module returns, so adding a channel is an edit of one TOML file.
Errors in the files raise DictionaryError naming the file, the packet/command and key.
"""

from __future__ import annotations

import functools
import hashlib
import json
import math
import os
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Callable

import numpy as np

from .errors import DictionaryError
from .tomlfile import read_toml

#: wire type name -> big-endian numpy dtype string
WIRE_TYPES: dict[str, str] = {
    "u8": "u1", "u16": ">u2", "u32": ">u4", "u64": ">u8",
    "i8": "i1", "i16": ">i2", "i32": ">i4", "i64": ">i8",
    "f32": ">f4", "f64": ">f8",
}
VARIABLE_TYPES = ("str", "bytes")

HEADER_SIZE = 14  # sync(2) version(1) packet_id(1) length(2) sequence(4) tick(4)
CRC_SIZE = 4
FRAME_OVERHEAD = HEADER_SIZE + CRC_SIZE

#: Header layout; fixed by SPEC.md, repeated in telemetry.toml's [frame] for readers.
HEADER_DTYPE = np.dtype([
    ("sync", ">u2"), ("version", "u1"), ("packet_id", "u1"),
    ("length", ">u2"), ("sequence", ">u4"), ("tick", ">u4"),
])


def default_protocol_dir() -> Path:
    """`protocol/` beside the package, unless GROUNDSTATION_PROTOCOL_DIR says otherwise."""
    env = os.environ.get("GROUNDSTATION_PROTOCOL_DIR")
    if env:
        return Path(env)
    return Path(__file__).resolve().parents[2] / "protocol"       # repo/groundstation/core/


@dataclass(frozen=True)
class Limits:
    yellow: tuple[float, float] | None = None
    red: tuple[float, float] | None = None


@dataclass(frozen=True)
class Item:
    """One field of a payload, command argument list or reply."""

    name: str
    type: str
    units: str = ""
    description: str = ""
    scale: float | None = None
    offset: float = 0.0
    polynomial: tuple[float, ...] | None = None
    states: dict[str, int] = field(default_factory=dict)
    bits: dict[str, int] = field(default_factory=dict)
    limits: Limits | None = None
    value_range: tuple[float, float] | None = None

    @property
    def is_variable(self) -> bool:
        return self.type in VARIABLE_TYPES

    def in_range(self, value: float) -> bool:
        """Is `value` inside `range`?  An f32 item is compared at f32 precision, so that
        a bound such as 0.349 still admits itself after the trip through the wire."""
        if self.value_range is None:
            return True
        lo, hi = self.value_range
        if self.type == "f32":
            value, lo, hi = np.float32(value), np.float32(lo), np.float32(hi)
        return bool(lo <= value <= hi)

    @property
    def wire_dtype(self) -> np.dtype:
        return np.dtype(WIRE_TYPES[self.type])

    @property
    def has_conversion(self) -> bool:
        return self.scale is not None or self.polynomial is not None

    def to_engineering(self, raw: np.ndarray) -> np.ndarray:
        """Raw wire values -> engineering units (float64 when a conversion applies)."""
        if self.polynomial is not None:
            return np.polynomial.polynomial.polyval(raw.astype(np.float64), self.polynomial)
        if self.scale is not None:
            eng = raw.astype(np.float64)
            eng *= self.scale
            if self.offset:
                eng += self.offset
            return eng
        return raw.astype(raw.dtype.newbyteorder("="), copy=False)

    def to_raw(self, eng: Any) -> np.ndarray:
        """Engineering values -> wire values (rounded; the inverse of to_engineering)."""
        values = np.asarray(eng, dtype=np.float64 if self.has_conversion else None)
        if self.polynomial is not None:
            if len(self.polynomial) > 2:
                raise DictionaryError(
                    f"item '{self.name}': encoding through a polynomial of degree "
                    f"{len(self.polynomial) - 1} is not supported (only linear)")
            c0, c1 = (tuple(self.polynomial) + (0.0, 0.0))[:2]
            values = (values - c0) / c1
        elif self.scale is not None:
            values = (values - self.offset) / self.scale
        dt = self.wire_dtype
        if dt.kind in "iu":
            values = np.rint(values) if values.dtype.kind == "f" else values
        return values


@dataclass(frozen=True)
class PacketDef:
    name: str
    id: int
    direction: str
    description: str
    items: tuple[Item, ...]
    rate_hz: float | None = None

    @property
    def fixed_items(self) -> tuple[Item, ...]:
        return tuple(i for i in self.items if not i.is_variable)

    @property
    def variable_item(self) -> Item | None:
        return self.items[-1] if self.items and self.items[-1].is_variable else None

    @property
    def payload_dtype(self) -> np.dtype:
        return np.dtype([(i.name, i.wire_dtype) for i in self.fixed_items])

    @property
    def fixed_payload_size(self) -> int:
        """Payload bytes of the fixed part (the whole payload unless variable)."""
        return self.payload_dtype.itemsize

    @property
    def frame_dtype(self) -> np.dtype:
        """Whole-frame record: header, fixed payload, CRC (fixed-length packets only)."""
        fields = [(n, HEADER_DTYPE.fields[n][0]) for n in HEADER_DTYPE.names]
        fields += [(i.name, i.wire_dtype) for i in self.fixed_items]
        fields.append(("crc", "<u4"))
        return np.dtype(fields)

    @property
    def item_by_name(self) -> dict[str, Item]:
        return {i.name: i for i in self.items}

    def channel_names(self) -> list[str]:
        """Decoded column names: header counters, items, then one per status bit."""
        names = ["sequence", "tick"] + [i.name for i in self.items]
        for item in self.items:
            names += list(item.bits)
        return names


@dataclass(frozen=True)
class CommandDef:
    name: str
    opcode: int
    description: str
    args: tuple[Item, ...]
    reply: tuple[Item, ...]
    critical: bool = False
    needs_session: bool = True
    timeout_s: float = 1.0


@dataclass(frozen=True)
class ParameterDef:
    id: int
    name: str
    type: str
    units: str
    value_range: tuple[float, float]
    default: Any
    description: str
    shape: tuple[int, ...] = ()
    filter: str = ""              # "sos": cascade of second-order sections, rows b0 b1 b2 a0 a1 a2

    @property
    def dtype(self) -> np.dtype:
        return np.dtype(WIRE_TYPES[self.type])

    @property
    def size(self) -> int:
        return int(np.prod(self.shape, dtype=np.int64)) * self.dtype.itemsize


@dataclass(frozen=True)
class Dictionary:
    name: str
    version_major: int
    version_minor: int
    control_rate_hz: float
    sync: int
    max_payload: int
    packets: tuple[PacketDef, ...]
    commands: tuple[CommandDef, ...]
    parameters: tuple[ParameterDef, ...]
    error_codes: dict[str, int]
    event_codes: dict[str, int]
    command_defaults: dict[str, float]
    hash: int
    source_texts: dict[str, str]

    @property
    def version(self) -> str:
        return f"{self.version_major}.{self.version_minor}"

    def packet(self, key: str | int) -> PacketDef:
        for p in self.packets:
            if p.name == key or p.id == key:
                return p
        raise DictionaryError(f"no packet {key!r} in the telemetry dictionary "
                              f"(known: {', '.join(p.name for p in self.packets)})")

    def command(self, key: str | int) -> CommandDef:
        for c in self.commands:
            if c.name == key or c.opcode == key:
                return c
        raise DictionaryError(f"no command {key!r} in the command dictionary")

    def error_name(self, code: int) -> str:
        for name, value in self.error_codes.items():
            if value == code:
                return name
        return f"UNKNOWN_REASON_{code}"

    def event_name(self, code: int) -> str:
        for name, value in self.event_codes.items():
            if value == code:
                return name
        return f"EVENT_{code}"


# ---------------------------------------------------------------------------------------
# loading and validation


def _read_toml(path: Path) -> tuple[dict, str]:
    return read_toml(path, DictionaryError, "protocol file not found")


def _require(table: dict, key: str, where: str, kinds: type | tuple[type, ...]):
    if key not in table:
        raise DictionaryError(f"{where}: missing key '{key}'")
    value = table[key]
    if not isinstance(value, kinds) or isinstance(value, bool) and bool not in (
            kinds if isinstance(kinds, tuple) else (kinds,)):
        raise DictionaryError(f"{where}: '{key}' must be {_kind_names(kinds)}, got {value!r}")
    return value


def _kind_names(kinds) -> str:
    kinds = kinds if isinstance(kinds, tuple) else (kinds,)
    return " or ".join({int: "an integer", float: "a number", str: "a string", list: "a list",
                        dict: "a table", bool: "true/false"}.get(k, k.__name__) for k in kinds)


def _pair(value, where: str, key: str) -> tuple[float, float]:
    if (not isinstance(value, list) or len(value) != 2
            or not all(isinstance(v, (int, float)) and not isinstance(v, bool) for v in value)
            or value[0] > value[1]):
        raise DictionaryError(f"{where}: '{key}' must be [min, max] with min <= max, got {value!r}")
    return float(value[0]), float(value[1])


def _parse_item(raw: dict, where: str) -> Item:
    if not isinstance(raw, dict):
        raise DictionaryError(f"{where}: each item must be a table, got {raw!r}")
    name = _require(raw, "name", where, str)
    where = f"{where} item '{name}'"
    type_ = _require(raw, "type", where, str)
    if type_ not in WIRE_TYPES and type_ not in VARIABLE_TYPES:
        raise DictionaryError(f"{where}: unknown type '{type_}' "
                              f"(use one of {', '.join(list(WIRE_TYPES) + list(VARIABLE_TYPES))})")
    known = {"name", "type", "units", "description", "scale", "offset", "polynomial",
             "states", "bits", "limits", "range"}
    unknown = set(raw) - known
    if unknown:
        raise DictionaryError(f"{where}: unknown key(s) {sorted(unknown)}")
    scale = raw.get("scale")
    if scale is not None and (not isinstance(scale, (int, float)) or scale == 0):
        raise DictionaryError(f"{where}: 'scale' must be a non-zero number, got {scale!r}")
    poly = raw.get("polynomial")
    if poly is not None:
        if scale is not None:
            raise DictionaryError(f"{where}: give either 'scale'/'offset' or 'polynomial', not both")
        if not isinstance(poly, list) or not poly or not all(
                isinstance(c, (int, float)) for c in poly):
            raise DictionaryError(f"{where}: 'polynomial' must be a list of coefficients c0, c1, ...")
    if (scale is not None or poly is not None) and type_ in VARIABLE_TYPES:
        raise DictionaryError(f"{where}: a {type_} item cannot have a conversion")
    states = raw.get("states", {})
    bits = raw.get("bits", {})
    if not isinstance(states, dict) or not all(isinstance(v, int) for v in states.values()):
        raise DictionaryError(f"{where}: 'states' must map labels to integers")
    if not isinstance(bits, dict) or not all(isinstance(v, int) for v in bits.values()):
        raise DictionaryError(f"{where}: 'bits' must map flag names to bit numbers")
    if bits and type_ not in WIRE_TYPES:
        raise DictionaryError(f"{where}: 'bits' needs an integer type")
    for flag, bit in bits.items():
        width = np.dtype(WIRE_TYPES[type_]).itemsize * 8
        if not 0 <= bit < width:
            raise DictionaryError(f"{where}: bit '{flag}' = {bit} outside 0..{width - 1}")
    limits = None
    if "limits" in raw:
        lim = raw["limits"]
        if not isinstance(lim, dict) or set(lim) - {"yellow", "red"}:
            raise DictionaryError(f"{where}: 'limits' must be {{ yellow = [lo, hi], red = [lo, hi] }}")
        limits = Limits(
            yellow=_pair(lim["yellow"], where, "limits.yellow") if "yellow" in lim else None,
            red=_pair(lim["red"], where, "limits.red") if "red" in lim else None)
        if limits.yellow and limits.red and not (
                limits.red[0] <= limits.yellow[0] and limits.yellow[1] <= limits.red[1]):
            raise DictionaryError(f"{where}: yellow limits must lie inside the red limits")
    return Item(
        name=name, type=type_, units=str(raw.get("units", "")),
        description=str(raw.get("description", "")),
        scale=float(scale) if scale is not None else None,
        offset=float(raw.get("offset", 0.0)),
        polynomial=tuple(float(c) for c in poly) if poly is not None else None,
        states=dict(states), bits=dict(bits), limits=limits,
        value_range=_pair(raw["range"], where, "range") if "range" in raw else None)


def _parse_items(raw_items, where: str, reserved: set[str] = frozenset()) -> tuple[Item, ...]:
    if not isinstance(raw_items, list):
        raise DictionaryError(f"{where}: 'items' must be a list of tables")
    items = tuple(_parse_item(r, where) for r in raw_items)
    seen = set(reserved)
    for pos, item in enumerate(items):
        for name in [item.name, *item.bits]:
            if name in seen:
                raise DictionaryError(f"{where}: channel name '{name}' is used twice")
            seen.add(name)
        if item.is_variable and pos != len(items) - 1:
            raise DictionaryError(f"{where}: '{item.name}' ({item.type}) must be the last item")
    return items


def _numbered_tables(doc: dict, kind: str, path: Path, code_key: str, code_max: int):
    """Each [[kind]] table of `doc` with where it is (for messages), its name and its
    code (`code_key`, checked to be in 1..code_max); at least one table is required."""
    raw_tables = doc.get(kind)
    if not isinstance(raw_tables, list) or not raw_tables:
        raise DictionaryError(f"{path}: no [[{kind}]] tables")
    for n, raw in enumerate(raw_tables):
        name = _require(raw, "name", f"{path}: {kind} #{n + 1}", str)
        where = f"{path}: {kind} '{name}'"
        code = _require(raw, code_key, where, int)
        if not 0 < code <= code_max:
            raise DictionaryError(f"{where}: {code_key} {code} outside 1..{code_max}")
        yield raw, where, name, code


def _check_unique(defs: list, kind: str, path: Path, code_key: str,
                  show_code: Callable[[int], str]) -> None:
    """No two of `defs` share a name or a code: the first clash is named, with all of its
    holders."""
    for attr in ("name", code_key):
        values = [getattr(d, attr) for d in defs]
        dupes = {v for v in values if values.count(v) > 1}
        if dupes:
            v = min(dupes)
            names = ", ".join(f"'{d.name}'" for d in defs if getattr(d, attr) == v)
            shown = show_code(v) if attr == code_key else f"'{v}'"
            raise DictionaryError(f"{path}: {kind} {attr} {shown} used twice: {kind}s {names}")


def _parse_packets(doc: dict, path: Path) -> tuple[PacketDef, ...]:
    packets = []
    for raw, where, name, pid in _numbered_tables(doc, "packet", path, "id", 255):
        items = _parse_items(raw.get("items", []), where, reserved={"sequence", "tick"})
        packets.append(PacketDef(
            name=name, id=pid, direction=str(raw.get("direction", "device_to_host")),
            description=str(raw.get("description", "")), items=items,
            rate_hz=raw.get("rate_hz")))
    _check_unique(packets, "packet", path, "id", lambda v: f"0x{v:02X}")
    return tuple(packets)


def _parse_commands(doc: dict, path: Path) -> tuple[tuple[CommandDef, ...], dict[str, float]]:
    defaults = {"accept_timeout_s": 0.25, "retries": 3, "timeout_s": 1.0,
                "heartbeat_period_s": 0.2}
    defaults.update(doc.get("defaults", {}))
    commands = []
    for raw, where, name, opcode in _numbered_tables(doc, "command", path, "opcode", 65535):
        commands.append(CommandDef(
            name=name, opcode=opcode, description=str(raw.get("description", "")),
            args=_parse_items(raw.get("args", []), f"{where} args"),
            reply=_parse_items(raw.get("reply", []), f"{where} reply"),
            critical=bool(raw.get("critical", False)),
            needs_session=bool(raw.get("needs_session", True)),
            timeout_s=float(raw.get("timeout_s", defaults["timeout_s"]))))
    _check_unique(commands, "command", path, "opcode", lambda v: f"0x{v:04X} ({v})")
    return tuple(commands), defaults


def _parse_parameters(doc: dict, path: Path) -> tuple[ParameterDef, ...]:
    params = []
    for n, raw in enumerate(doc.get("parameter", [])):
        where = f"{path}: parameter #{n + 1}"
        name = _require(raw, "name", where, str)
        where = f"{path}: parameter '{name}'"
        type_ = _require(raw, "type", where, str)
        if type_ not in WIRE_TYPES:
            raise DictionaryError(f"{where}: unknown type '{type_}'")
        shape = raw.get("shape", [])
        if not isinstance(shape, list) or not all(isinstance(s, int) and s > 0 for s in shape):
            raise DictionaryError(f"{where}: 'shape' must be a list of positive integers")
        lo, hi = _pair(_require(raw, "range", where, list), where, "range")
        filt = str(raw.get("filter", ""))
        if filt not in ("", "sos") or (filt == "sos" and (len(shape) != 2 or shape[1] != 6)):
            raise DictionaryError(f"{where}: filter = \"sos\" needs shape [sections, 6]")
        default = _parameter_default(_require(raw, "default", where, (int, float, list, str)),
                                     tuple(shape), where)
        if not all(lo <= v <= hi for v in np.ravel(default)):
            raise DictionaryError(f"{where}: default {default!r} outside its range [{lo}, {hi}]")
        params.append(ParameterDef(
            id=_require(raw, "id", where, int), name=name, type=type_,
            units=str(raw.get("units", "")), value_range=(lo, hi), default=default,
            description=str(raw.get("description", "")), shape=tuple(shape), filter=filt))
    ids = [p.id for p in params]
    if len(set(ids)) != len(ids) or len({p.name for p in params}) != len(params):
        raise DictionaryError(f"{path}: parameter ids and names must be unique")
    return tuple(sorted(params, key=lambda p: p.id))


#: named defaults for array parameters (a 12x6 identity cascade is unreadable as a literal)
_SOS_ROWS = {"sos_zero": [0.0, 0.0, 0.0, 1.0, 0.0, 0.0], "sos_identity": [1.0, 0.0, 0.0, 1.0, 0.0, 0.0]}


def _parameter_default(default, shape: tuple[int, ...], where: str):
    if isinstance(default, str):
        if default in _SOS_ROWS and len(shape) == 2 and shape[1] == 6:
            rows = [list(_SOS_ROWS["sos_identity"]) for _ in range(shape[0])]
            rows[0] = list(_SOS_ROWS[default])
            return rows
        raise DictionaryError(f"{where}: unknown named default {default!r} "
                              f"(known for [n, 6] cascades: {', '.join(_SOS_ROWS)})")
    if np.shape(default) != shape:
        raise DictionaryError(f"{where}: default has shape {np.shape(default)}, expected {shape}")
    return default


def dictionary_hash(docs: dict[str, dict]) -> int:
    """32-bit hash of the parsed dictionaries: sha256 of their canonical JSON, first 4
    bytes big-endian.  Comments and formatting do not change it; any value does."""
    canonical = json.dumps(docs, sort_keys=True, separators=(",", ":"), ensure_ascii=True)
    return int.from_bytes(hashlib.sha256(canonical.encode()).digest()[:4], "big")


def load_dictionary(protocol_dir: str | Path | None = None) -> Dictionary:
    """Read and check telemetry.toml, commands.toml and parameters.toml."""
    base = Path(protocol_dir) if protocol_dir is not None else default_protocol_dir()
    tlm, tlm_text = _read_toml(base / "telemetry.toml")
    cmd, cmd_text = _read_toml(base / "commands.toml")
    par, par_text = _read_toml(base / "parameters.toml")
    tpath = base / "telemetry.toml"
    proto = _require(tlm, "protocol", str(tpath), dict)
    frame = _require(tlm, "frame", str(tpath), dict)
    major = _require(proto, "version_major", f"{tpath}: [protocol]", int)
    if not 0 < major < 256:
        raise DictionaryError(f"{tpath}: [protocol] version_major must be 1..255")
    sync = _require(frame, "sync", f"{tpath}: [frame]", int)
    if sync != 0xEB90:
        raise DictionaryError(f"{tpath}: [frame] sync must be 0xEB90 (SPEC.md fixes the framing)")
    control_rate = float(_require(proto, "control_rate_hz", f"{tpath}: [protocol]", (int, float)))
    if not (math.isfinite(control_rate) and control_rate > 0):
        raise DictionaryError(f"{tpath}: [protocol] control_rate_hz must be a positive number, "
                              f"got {control_rate!r}")
    max_payload = int(frame.get("max_payload_bytes", 1024))
    packets = _parse_packets(tlm, tpath)
    for p in packets:
        if p.variable_item is None and p.fixed_payload_size > max_payload:
            raise DictionaryError(f"{tpath}: packet '{p.name}' payload of {p.fixed_payload_size} "
                                  f"bytes exceeds max_payload_bytes = {max_payload}")
    commands, defaults = _parse_commands(cmd, base / "commands.toml")
    return Dictionary(
        name=str(proto.get("name", "")), version_major=major,
        version_minor=int(proto.get("version_minor", 0)),
        control_rate_hz=control_rate,
        sync=sync, max_payload=max_payload, packets=packets, commands=commands,
        parameters=_parse_parameters(par, base / "parameters.toml"),
        error_codes=dict(cmd.get("error_codes", {})),
        event_codes=dict(cmd.get("event_codes", {})),
        command_defaults=defaults,
        hash=dictionary_hash({"telemetry": tlm, "commands": cmd, "parameters": par}),
        source_texts={"telemetry.toml": tlm_text, "commands.toml": cmd_text,
                      "parameters.toml": par_text})


@functools.cache
def default_control_rate_hz() -> float:
    """The controller's rate (control periods, device ticks, profile samples per second):
    `[protocol] control_rate_hz` of the dictionary `load_dictionary()` reads, loaded once.

    The one source of the rate for code that has no Dictionary at hand: module constants
    (params.tf_algebra.CONTROL_RATE_HZ, profiles.waveforms.RATE_HZ) and default
    arguments take it from here, never from a literal."""
    return load_dictionary().control_rate_hz
