"""Encode and decode frames of one packet, many at a time, with numpy.

A fixed-length packet's frame is one record of `PacketDef.frame_dtype` (header, payload,
CRC, big-endian), so N frames are an (N,) structured array: decoding is a view plus one
vectorised conversion per channel, never a Python object per sample.  Variable-length
packets (EVENT, COMMAND, RESPONSE) are rare and decoded frame by frame.
"""

from __future__ import annotations

import zlib
from dataclasses import dataclass, field
from typing import Any, Mapping

import numpy as np

from ..core.dictionary import (CRC_SIZE, FRAME_OVERHEAD, HEADER_DTYPE, HEADER_SIZE, Dictionary,
                               Item, PacketDef)
from ..core.errors import (CrcError, EncodeError, FrameLengthError, ProtocolVersionError,
                           UnknownPacketError)
from .crc import RESIDUE, crc_bytes, frame_crc
from .packet_encoder import CrcRows, PacketEncoder


@dataclass
class TelemetryBlock:
    """Decoded frames of one packet: columns in engineering units, in arrival order.

    `columns` holds 'sequence' and 'tick' (header counters), one array per item (float64
    where a conversion applies, the wire type otherwise, str/bytes objects for variable
    items) and one bool array per status bit.  `raw` is the structured array of wire
    values for fixed-length packets (the recorder stores the counts from it);
    `host_time` is the host arrival time (s since the epoch) of each frame.
    """

    packet: PacketDef
    columns: dict[str, np.ndarray]
    host_time: np.ndarray
    raw: np.ndarray | None = None
    frames: list[bytes] = field(default_factory=list)   # only for variable-length packets

    def __len__(self) -> int:
        return len(self.columns["sequence"])

    def __getitem__(self, name: str) -> np.ndarray:
        return self.columns[name]

    @property
    def name(self) -> str:
        return self.packet.name


def _item_columns(item: Item, raw: np.ndarray, out: dict[str, np.ndarray]) -> None:
    out[item.name] = item.to_engineering(raw)
    for flag, bit in item.bits.items():
        out[flag] = ((raw >> bit) & 1).astype(bool)


class FrameCodec:
    """Encoder/decoder of whole frames for every packet of a dictionary."""

    def __init__(self, dictionary: Dictionary):
        self.dictionary = dictionary
        self.version = dictionary.version_major
        self._by_id = {p.id: p for p in dictionary.packets}
        self._frame_dtypes = {p.id: p.frame_dtype for p in dictionary.packets
                              if p.variable_item is None}
        self._encoders: dict[int, PacketEncoder] = {}
        # packet id -> (min, max) payload length accepted on the wire
        self.payload_limits: dict[int, tuple[int, int]] = {}
        for p in dictionary.packets:
            fixed = p.fixed_payload_size
            hi = dictionary.max_payload if p.variable_item else fixed
            self.payload_limits[p.id] = (fixed, hi)

    def packet(self, key: str | int) -> PacketDef:
        if isinstance(key, int) and key not in self._by_id:
            raise UnknownPacketError(f"packet id 0x{key:02X} is not in the telemetry dictionary")
        return self.dictionary.packet(key)

    # ---------------------------------------------------------------- encoding
    def encoder(self, packet: str | int | PacketDef, crc_rows: CrcRows | None = None) -> PacketEncoder:
        """The encoder of a fixed-length packet, its lookups done once (kept per packet;
        with `crc_rows`, a new one that computes its CRCs with it)."""
        pkt = packet if isinstance(packet, PacketDef) else self.packet(packet)
        if crc_rows is not None:
            return PacketEncoder(self.dictionary, pkt, crc_rows)
        enc = self._encoders.get(pkt.id)
        if enc is None:
            enc = self._encoders[pkt.id] = PacketEncoder(self.dictionary, pkt)
        return enc

    def encode(self, packet: str | int | PacketDef, values: Mapping[str, Any],
               sequence: Any, tick: Any, *, engineering: bool = True) -> bytes:
        """Encode N frames of a fixed-length packet from columns (or scalars) of values.

        `values` maps item names to engineering values (or raw counts with
        engineering=False); items left out are sent as zero; status bits may be given
        by flag name instead of the raw item.  Returns N concatenated frames.
        """
        return self.encoder(packet).encode(values, sequence, tick, engineering=engineering)

    def encode_variable(self, packet: str | int | PacketDef, values: Mapping[str, Any],
                        sequence: int, tick: int) -> bytes:
        """Encode one frame of any packet (variable-length ones included)."""
        pkt = packet if isinstance(packet, PacketDef) else self.packet(packet)
        payload = encode_items(pkt.items, values, f"{pkt.name}")
        return self.frame(pkt.id, payload, sequence, tick)

    def frame(self, packet_id: int, payload: bytes, sequence: int, tick: int) -> bytes:
        """Wrap a payload in header and CRC."""
        if len(payload) > self.dictionary.max_payload:
            raise EncodeError(f"payload of {len(payload)} bytes exceeds the maximum of "
                              f"{self.dictionary.max_payload}")
        header = np.zeros(1, HEADER_DTYPE)
        header[0] = (self.dictionary.sync, self.version, packet_id, len(payload),
                     sequence & 0xFFFFFFFF, tick & 0xFFFFFFFF)
        content = header.tobytes() + payload
        return content + crc_bytes(content)

    # ---------------------------------------------------------------- decoding
    def decode_fixed(self, pkt: PacketDef, frames: np.ndarray, host_time: np.ndarray) -> TelemetryBlock:
        """(N, frame_size) uint8 array of checked frames of one fixed packet -> block."""
        rec = np.ascontiguousarray(frames).view(self._frame_dtypes[pkt.id]).reshape(-1)
        cols: dict[str, np.ndarray] = {
            "sequence": rec["sequence"].astype(np.uint32),
            "tick": rec["tick"].astype(np.uint32),
        }
        for item in pkt.items:
            _item_columns(item, rec[item.name], cols)
        return TelemetryBlock(pkt, cols, host_time, raw=rec)

    def decode_variable(self, pkt: PacketDef, frames: list[bytes], host_time: np.ndarray) -> TelemetryBlock:
        """Checked frames of one variable-length packet -> block (one Python parse each)."""
        header = np.frombuffer(b"".join(f[:HEADER_SIZE] for f in frames), HEADER_DTYPE)
        fixed_end = HEADER_SIZE + pkt.fixed_payload_size
        # the fixed items as raw wire values (converted once, by _item_columns)
        fixed = np.frombuffer(b"".join(f[HEADER_SIZE:fixed_end] for f in frames),
                              pkt.payload_dtype)
        cols: dict[str, np.ndarray] = {
            "sequence": header["sequence"].astype(np.uint32),
            "tick": header["tick"].astype(np.uint32),
        }
        for item in pkt.items:
            if item.is_variable:
                arr = np.empty(len(frames), dtype=object)
                rests = [bytes(f[fixed_end:-CRC_SIZE]) for f in frames]
                arr[:] = [r.decode("utf-8", errors="replace") for r in rests] \
                    if item.type == "str" else rests
                cols[item.name] = arr
            else:
                _item_columns(item, fixed[item.name], cols)
        return TelemetryBlock(pkt, cols, host_time, frames=list(frames))

    def decode_frame(self, frame: bytes, host_time: float = 0.0) -> TelemetryBlock:
        """Strictly decode exactly one frame; raises a specific DecodeError if it is bad."""
        if len(frame) < FRAME_OVERHEAD:
            raise FrameLengthError(f"{len(frame)} bytes is shorter than a frame's "
                                   f"{FRAME_OVERHEAD}-byte header and CRC")
        hdr = np.frombuffer(frame[:HEADER_SIZE], HEADER_DTYPE)[0]
        if int(hdr["sync"]) != self.dictionary.sync:
            raise FrameLengthError(f"frame starts with 0x{int(hdr['sync']):04X}, not the sync "
                                   f"word 0x{self.dictionary.sync:04X}")
        if int(hdr["version"]) != self.version:
            raise ProtocolVersionError(
                f"frame is protocol version {int(hdr['version'])}; this ground station speaks "
                f"version {self.version} ({'update the ground station' if hdr['version'] > self.version else 'update the firmware'})")
        pid = int(hdr["packet_id"])
        pkt = self.packet(pid)
        lo, hi = self.payload_limits[pid]
        length = int(hdr["length"])
        if not lo <= length <= hi or len(frame) != FRAME_OVERHEAD + length:
            raise FrameLengthError(
                f"{pkt.name} frame: length field {length}, frame of {len(frame)} bytes; "
                f"expected a payload of {lo}..{hi} bytes")
        if zlib.crc32(frame) != RESIDUE:
            raise CrcError(f"{pkt.name} frame seq {int(hdr['sequence'])}: CRC mismatch "
                           f"(got 0x{int.from_bytes(frame[-4:], 'little'):08X}, computed "
                           f"0x{frame_crc(frame[:-4]):08X})")
        t = np.array([host_time])
        if pkt.variable_item is None:
            return self.decode_fixed(pkt, np.frombuffer(frame, np.uint8).reshape(1, -1), t)
        return self.decode_variable(pkt, [bytes(frame)], t)


# ---------------------------------------------------------------------- item lists
def encode_items(items: tuple[Item, ...], values: Mapping[str, Any], where: str) -> bytes:
    """Pack one record of `items` (engineering values; states by label or number).

    Used for variable-length packets and for command arguments/replies; checks ranges
    and reports the first bad value by name."""
    unknown = set(values) - {i.name for i in items}
    if unknown:
        raise EncodeError(f"{where}: unknown field(s) {sorted(unknown)}")
    out = bytearray()
    for item in items:
        if item.name not in values:
            if item.is_variable:
                value = b"" if item.type == "bytes" else ""
            else:
                raise EncodeError(f"{where}: missing value for '{item.name}'")
        else:
            value = values[item.name]
        if item.is_variable:
            if item.type == "str":
                if not isinstance(value, str):
                    raise EncodeError(f"{where}.{item.name}: expected text, got {type(value).__name__}")
                out += value.encode("utf-8")
            else:
                if not isinstance(value, (bytes, bytearray, memoryview)):
                    raise EncodeError(f"{where}.{item.name}: expected bytes, got {type(value).__name__}")
                out += bytes(value)
            continue
        if isinstance(value, str):
            if value not in item.states:
                raise EncodeError(f"{where}.{item.name}: '{value}' is not one of "
                                  f"{', '.join(item.states) or '(no states defined)'}")
            value = item.states[value]
        if isinstance(value, bool):
            value = int(value)
        if not isinstance(value, (int, float, np.integer, np.floating)):
            raise EncodeError(f"{where}.{item.name}: expected a number, got {value!r}")
        if not np.isfinite(value):
            raise EncodeError(f"{where}.{item.name}: {value} is not a finite number")
        if item.value_range is not None and not item.value_range[0] <= value <= item.value_range[1]:
            raise EncodeError(f"{where}.{item.name} = {value} {item.units} is outside its range "
                              f"[{item.value_range[0]}, {item.value_range[1]}]")
        raw = np.asarray(item.to_raw(value))
        dt = item.wire_dtype
        if dt.kind in "iu":
            info = np.iinfo(dt)
            if not info.min <= raw <= info.max:
                raise EncodeError(f"{where}.{item.name} = {value} does not fit {item.type}")
        elif abs(float(raw)) > float(np.finfo(dt).max):
            raise EncodeError(f"{where}.{item.name} = {value} does not fit {item.type}")
        out += np.asarray(raw, dtype=dt).tobytes()
    return bytes(out)


def decode_items(items: tuple[Item, ...], payload: bytes, where: str) -> dict[str, Any]:
    """Unpack one record of `items` into engineering values (Python scalars)."""
    fixed = [i for i in items if not i.is_variable]
    dt = np.dtype([(i.name, i.wire_dtype) for i in fixed])
    if len(payload) < dt.itemsize or (len(payload) != dt.itemsize and not (items and items[-1].is_variable)):
        raise FrameLengthError(f"{where}: {len(payload)} payload bytes, expected "
                               f"{dt.itemsize}{' or more' if items and items[-1].is_variable else ''}")
    out: dict[str, Any] = {}
    if fixed:
        rec = np.frombuffer(payload[:dt.itemsize], dt)
        for item in fixed:
            out[item.name] = item.to_engineering(rec[item.name])[0].item()
    if items and items[-1].is_variable:
        rest = bytes(payload[dt.itemsize:])
        var = items[-1]
        if var.type == "str":
            out[var.name] = rest.decode("utf-8", errors="replace")
        else:
            out[var.name] = rest
    return out
