"""Encoding N frames of one fixed-length packet in one pass, with the per-item work
looked up once.

`FrameCodec.encode` is called for every batch the simulator sends (and by tests and
tools for a frame or two): the dictionary's per-call lookups - each item's wire dtype,
its integer limits, the packet's channel names - used to cost more than the numpy work
on a batch of a few hundred frames.  A `PacketEncoder` resolves them when it is built,
so a call is the vectorised conversion, the range check and the CRCs, nothing else.

The CRCs are one zlib call per frame by default; a caller that encodes large batches
(the simulator) passes `crc_rows`, a function computing the CRC of every row of an
(N, L) byte array at once (`sim/frame_crc.py`), which gives the same values.
"""

from __future__ import annotations

import zlib
from typing import Any, Callable, Mapping

import numpy as np

from ..core.dictionary import CRC_SIZE, Dictionary, Item, PacketDef
from ..core.errors import EncodeError

#: rows (N, L) uint8 -> (N,) uint32: the frame CRC of each row
CrcRows = Callable[[np.ndarray], np.ndarray]


def zlib_crc_rows(rows: np.ndarray) -> np.ndarray:
    """One zlib call per row: ~0.3-1 us a frame, small beside the 833 us between frames
    on the link, and what an encoder of a few frames needs."""
    n, length = rows.shape
    mv = memoryview(np.ascontiguousarray(rows).reshape(-1))
    crc32 = zlib.crc32
    return np.fromiter((crc32(mv[off:off + length]) for off in range(0, n * length, length)),
                       dtype=np.uint32, count=n)


class _ItemPlan:
    """One item's conversion and wire limits, resolved once."""

    __slots__ = ("item", "name", "dtype", "integer", "lo", "hi", "float_max", "linear", "bits",
                 "bounds")

    def __init__(self, item: Item):
        self.item = item
        self.name = item.name
        self.dtype = item.wire_dtype
        self.integer = self.dtype.kind in "iu"
        self.bits = tuple(item.bits.items())
        if self.integer:
            info = np.iinfo(self.dtype)
            self.lo, self.hi = info.min, info.max
            self.float_max = None
        else:
            self.lo = self.hi = None
            self.float_max = float(np.finfo(self.dtype).max) if self.dtype.kind == "f" else None
        # (lowest, highest) raw value that passes `checked` for sure (None: check alone)
        self.bounds = ((float(self.lo), float(self.hi)) if self.integer and self.dtype.itemsize <= 4 else
                       None if self.integer else
                       (-self.float_max, self.float_max) if self.float_max is not None else None)
        # (subtract, divide) of the engineering -> raw conversion, as Item.to_raw does it
        if item.polynomial is not None:
            self.linear = None if len(item.polynomial) > 2 else \
                tuple((tuple(item.polynomial) + (0.0, 0.0))[:2])
        elif item.scale is not None:
            self.linear = (item.offset, item.scale)
        else:
            self.linear = False

    def to_raw(self, eng: Any) -> np.ndarray:
        """Item.to_raw with the lookups done: the same arithmetic, so the same bits."""
        if self.linear is None:
            return self.item.to_raw(eng)             # raises: only linear polynomials encode
        if self.linear is False:
            values = np.asarray(eng)
        else:
            c0, c1 = self.linear
            values = (np.asarray(eng, dtype=np.float64) - c0) / c1
        if self.integer and values.dtype.kind == "f":
            values = np.rint(values)
        return values

    def checked(self, pkt_name: str, raw: np.ndarray) -> np.ndarray:
        if self.integer:
            raw = np.asarray(raw)
            if not raw.size:
                return raw
            lo, hi = raw.min(), raw.max()            # NaN and inf show up in min/max
            if raw.dtype.kind == "f" and not (np.isfinite(lo) and np.isfinite(hi)):
                raise EncodeError(f"{pkt_name}.{self.name}: non-finite value for an integer field")
            if lo < self.lo or hi > self.hi:
                raise EncodeError(
                    f"{pkt_name}.{self.name}: value outside the wire range of {self.item.type} "
                    f"({self.lo}..{self.hi} counts)")
        elif self.float_max is not None:
            raw = np.asarray(raw, dtype=np.float64)
            if not raw.size:
                return raw
            peak = np.abs(raw).max()
            if not np.isfinite(peak):                # inf/NaN pass; look at the finite rest
                finite = np.abs(raw[np.isfinite(raw)])
                peak = finite.max() if finite.size else 0.0
            if peak > self.float_max:
                raise EncodeError(
                    f"{pkt_name}.{self.name}: value outside the range of {self.item.type} "
                    f"(+-{self.float_max:.4g})")
        return raw


class PacketEncoder:
    """Frames of one fixed-length packet from columns of values (see FrameCodec.encode)."""

    def __init__(self, dictionary: Dictionary, pkt: PacketDef, crc_rows: CrcRows | None = None):
        if pkt.variable_item is not None:
            raise EncodeError(f"{pkt.name} is variable-length: use encode_variable()")
        self.packet = pkt
        self.frame_dtype = pkt.frame_dtype
        self.frame_size = self.frame_dtype.itemsize
        self._header = (dictionary.sync, dictionary.version_major, pkt.id, pkt.fixed_payload_size)
        self._channels = frozenset(pkt.channel_names())
        self._items = tuple(_ItemPlan(i) for i in pkt.items)
        self._crc_rows = crc_rows or zlib_crc_rows

    def records(self, values: Mapping[str, Any], sequence: Any, tick: Any, *,
                engineering: bool = True) -> np.ndarray:
        """The (N,) structured array of whole frames, CRCs filled in."""
        seq = np.atleast_1d(np.asarray(sequence, dtype=np.int64))
        unknown = set(values) - self._channels
        if unknown:
            raise EncodeError(f"{self.packet.name}: no channel(s) {sorted(unknown)}")
        rec = np.zeros(len(seq), dtype=self.frame_dtype)
        rec["sync"], rec["version"], rec["packet_id"], rec["length"] = self._header
        rec["sequence"] = seq & 0xFFFFFFFF
        rec["tick"] = np.asarray(tick, dtype=np.int64) & 0xFFFFFFFF
        name = self.packet.name
        batched: list[tuple[_ItemPlan, np.ndarray]] = []
        for plan in self._items:
            if plan.name in values:
                given = values[plan.name]
                raw = plan.to_raw(given) if engineering else np.asarray(given)
                if plan.bounds is not None and raw.dtype == np.float64 and raw.shape == seq.shape:
                    batched.append((plan, raw))          # checked with the others, below
                else:
                    rec[plan.name] = plan.checked(name, raw)
        if batched:
            self._check_together(name, batched)
            for plan, raw in batched:
                rec[plan.name] = raw
        for plan in self._items:
            flags = [(values[flag], bit) for flag, bit in plan.bits if flag in values]
            if flags:
                word = rec[plan.name].astype(np.int64)
                for flag_values, bit in flags:
                    word |= (np.asarray(flag_values).astype(np.int64) & 1) << bit
                rec[plan.name] = word
        rows = rec.view(np.uint8).reshape(len(rec), self.frame_size)
        rec["crc"] = self._crc_rows(rows[:, :self.frame_size - CRC_SIZE])
        return rec

    @staticmethod
    def _check_together(pkt_name: str, batched: list[tuple[_ItemPlan, np.ndarray]]) -> None:
        """The range checks of many float64 columns in two reductions over one array
        instead of two per item (the per-call cost dominated a batch of a second's
        frames).  A column outside its bounds - or holding NaN or inf, which compare
        false - is checked again alone, which raises the item's own error or, for a
        float item's inf/NaN, passes as before."""
        block = np.stack([raw for _, raw in batched])
        if not block.shape[1]:
            return
        lows, highs = block.min(axis=1), block.max(axis=1)
        bounds = np.array([plan.bounds for plan, _ in batched])
        inside = (lows >= bounds[:, 0]) & (highs <= bounds[:, 1])
        for j in np.flatnonzero(~inside):
            plan, raw = batched[j]
            plan.checked(pkt_name, raw)

    def encode(self, values: Mapping[str, Any], sequence: Any, tick: Any, *,
               engineering: bool = True) -> bytes:
        """N concatenated frames."""
        return self.records(values, sequence, tick, engineering=engineering).tobytes()
