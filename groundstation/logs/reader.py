"""Reading a log: packets, channels with units, time and tick ranges, journal, frames.

`LogReader` opens any schema-1 log, also one that is still being written (HDF5 SWMR
read mode; `refresh()` picks up what the writer has flushed since).  It never loads a
whole dataset to answer a range query: the row range of a time window is found by a
binary search that reads one value per probed chunk and then a single chunk, and only
the rows asked for are read.  Everything the file needs to explain itself - units,
descriptions, conversions, the protocol files, the testbed file, the journal - comes
from the file, not from the protocol files installed today.

Time ranges `[start, stop]` are inclusive and in seconds of the chosen timebase:
"device" (`device_time`, the unwrapped device tick / tick rate, monotonic) or "host"
(`host_time`, the host arrival time since the epoch, monotonic up to clock steps of the
host).  Tick ranges `[tick_start, tick_stop)` are half-open, like Python slices.

The parts live beside this module, one job each: opening and damage detection
(opening.py), the row search (rows.py), channel descriptions (channels.py) and the
summary (summary.py).
"""

from __future__ import annotations

import functools
import json
import tomllib
from dataclasses import dataclass
from pathlib import Path
from typing import Any, Iterable

import h5py
import numpy as np

from ..core.dictionary import default_control_rate_hz
from . import schema
from .channels import HEADER_CHANNELS, Channel, packet_channels
from .channels import to_engineering as _to_engineering
from .opening import (H5_READ_ERRORS, LogDamagedError, LogFormatError, LogQueryError, check_layout,
                      first_unreadable, open_log_file, truncated_advice, truncation_text,
                      unreadable_text)
from .opening import attr_text as _text
from .rows import search_sorted as _search
from .summary import LogInfo, scan_sequence, summarize

TIMEBASES = ("device", "host")
TIME_TOLERANCE_S = 1e-9


def _guard(method):
    """Turn an HDF5 read failure inside a public LogReader method into LogDamagedError."""

    @functools.wraps(method)
    def wrapper(self, *args, **kwargs):
        try:
            return method(self, *args, **kwargs)
        except H5_READ_ERRORS as exc:
            raise self._damaged(f"HDF5 cannot read part of the file's structure ({exc})") from None

    return wrapper


@dataclass(frozen=True)
class JournalRecord:
    time: float               # host time, s since the epoch
    kind: str
    data: dict[str, Any]
    blob: bytes



@functools.lru_cache(maxsize=8)
def _item_order_of(telemetry_toml: str) -> dict[str, tuple[str, ...]]:
    """Channel order per packet of a recorded telemetry.toml (items, then flags); {} for
    text that is not one.  Cached: the logs of a batch carry the same text, and parsing
    it was a tenth of a 60 s log's analysis."""
    try:
        doc = tomllib.loads(telemetry_toml)
        order = {}
        for p in doc.get("packet", []):
            items = p.get("items", [])
            names = [i["name"] for i in items]
            names += [flag for i in items for flag in i.get("bits", {})]
            order[p["name"]] = tuple(names)
        return order
    except (tomllib.TOMLDecodeError, KeyError, TypeError, AttributeError):
        return {}

class LogReader:
    """A recorded session, read lazily.  Use as a context manager or call close().

    A damaged file raises LogDamagedError (which names the damage) where it is found:
    on opening (empty, not HDF5 any more, truncated) or on reading (a dataset or an
    attribute HDF5 cannot read).  With `salvage=True` a truncated file is opened anyway
    (`truncated` then says by how much) so that what is readable can be read."""

    def __init__(self, path: str | Path, *, salvage: bool = False):
        self.path = Path(path)
        self.salvage = salvage
        self._f, self.truncated = open_log_file(self.path, salvage=salvage)
        self.unreadable_attrs: list[str] = []
        self._ds: dict[str, h5py.Dataset] = {}
        self._channels: dict[str, list[Channel]] = {}
        self._info: LogInfo | None = None
        self._origin: dict[str, float] = {}
        self._order: dict[str, list[str]] | None = None
        try:
            self.schema_version = self._check()
        except H5_READ_ERRORS as exc:
            self._f.close()
            raise self._damaged(f"its root attributes cannot be read ({exc})",
                                salvageable=False) from None
        except BaseException:
            self._f.close()
            raise

    # ------------------------------------------------------------------ damage
    def _damaged(self, what: str, *, salvageable: bool = True) -> LogDamagedError:
        advice = None
        if self.truncated is not None:
            what = f"{what}; the file is {truncation_text(*self.truncated)}"
            if not salvageable:
                advice = truncated_advice(*self.truncated)
        return LogDamagedError(self.path, what, salvageable=salvageable, advice=advice)

    def _read(self, path: str, sel) -> np.ndarray:
        """ds[sel] of the dataset at `path`; LogDamagedError naming the dataset and the
        first unreadable row if HDF5 cannot read it."""
        ds = self._dataset(path)
        try:
            return ds[sel]
        except H5_READ_ERRORS as exc:
            n = ds.shape[0] if ds.shape else 0
            if isinstance(sel, slice):
                a, b, _ = sel.indices(n)
                row, _ = first_unreadable(ds, a, b)
            elif isinstance(sel, (list, np.ndarray)):
                row = int(np.min(sel)) if len(sel) else 0
            else:
                row = int(sel) if isinstance(sel, (int, np.integer)) else 0
            raise self._damaged(unreadable_text(ds, row, exc)) from None

    @_guard
    def readable_rows(self, path: str, start: int = 0, stop: int | None = None) -> tuple[int, str]:
        """(k, error): rows [start, k) of the dataset at `path` read (k == stop and error ''
        when all of [start, stop) do).  A compressed chunk that was cut off or overwritten
        fails to decompress; an uncompressed one past the end of a truncated file would
        read as zeros (the recorder compresses every per-frame dataset)."""
        ds = self._dataset(path)
        n = ds.shape[0]
        stop = n if stop is None else min(stop, n)
        return first_unreadable(ds, start, stop)

    # ------------------------------------------------------------------ file
    def _check(self) -> int:
        return check_layout(self._f, self.path)

    def close(self) -> None:
        self._ds.clear()
        self._f.close()

    def __enter__(self) -> "LogReader":
        return self

    def __exit__(self, *exc) -> None:
        self.close()

    def __repr__(self) -> str:
        return f"LogReader('{self.path}')"

    @_guard
    def refresh(self) -> None:
        """See what a writer has flushed since the file was opened (or last refreshed).
        Root attributes stay as they were at opening (a clean close shows on reopening)."""
        for ds in self._ds.values():
            ds.refresh()
        self._info = None
        self._origin.clear()

    @property
    def h5(self) -> h5py.File:
        """The open HDF5 file, for the package's own low-level readers (log check,
        replay) that walk its structure; read it, never write it."""
        return self._f

    def dataset(self, path: str) -> h5py.Dataset:
        """The dataset at `path` (e.g. 'frames/HIGH_RATE/host_time'), opened once and
        kept, so refresh() brings it up to date; LogFormatError if the log lacks it."""
        return self._dataset(path)

    def _dataset(self, path: str) -> h5py.Dataset:
        ds = self._ds.get(path)
        if ds is None:
            try:
                ds = self._f[path]
            except KeyError:
                raise LogFormatError(f"{self.path}: damaged log, dataset /{path} missing") from None
            if not isinstance(ds, h5py.Dataset):
                raise LogFormatError(f"{self.path}: /{path} is not a dataset")
            self._ds[path] = ds
        return ds

    @property
    @_guard
    def attrs(self) -> dict[str, Any]:
        """The root attributes as Python values.  One HDF5 cannot read raises
        LogDamagedError; with salvage=True it is left out (and named in
        `unreadable_attrs`)."""
        out = {}
        for k in self._f.attrs.keys():
            try:
                v = self._f.attrs[k]
            except H5_READ_ERRORS as exc:
                if not self.salvage:
                    raise self._damaged(f"attribute '{k}' of / unreadable ({exc})") from None
                if k not in self.unreadable_attrs:
                    self.unreadable_attrs.append(k)
                continue
            out[k] = v.item() if isinstance(v, np.generic) else _text(v) if isinstance(v, bytes) else v
        return out

    @property
    def tick_rate_hz(self) -> float:
        # a log written before the attribute existed: the protocol dictionary's rate
        return float(self._f.attrs.get("tick_rate_hz", default_control_rate_hz()))

    # ------------------------------------------------------------------ packets and channels
    @_guard
    def packets(self) -> list[str]:
        """Packets recorded (every device-to-host packet of the dictionary), by id."""
        tel = self._f["telemetry"]
        return sorted(tel.keys(), key=lambda n: (int(tel[n].attrs.get("id", 0)), n))

    def _packet_group(self, packet: str) -> h5py.Group:
        tel = self._f["telemetry"]
        if not isinstance(packet, str) or packet not in tel:
            raise LogQueryError(f"{self.path}: no packet {packet!r} in this log "
                                f"(packets: {', '.join(self.packets())})")
        return tel[packet]

    def _item_order(self) -> dict[str, list[str]]:
        """Channel order per packet from the recorded telemetry.toml (items, then flags)."""
        if self._order is None:
            self._order = self._parse_item_order()
        return self._order

    def _parse_item_order(self) -> dict[str, list[str]]:
        order = _item_order_of(self.protocol_files().get("telemetry.toml", ""))
        return {packet: list(names) for packet, names in order.items()}

    @_guard
    def channels(self, packet: str) -> list[Channel]:
        """Every column of `packet`: header counters and times, items, flags, text items,
        then the raw counts (named raw/<item>)."""
        if packet in self._channels:
            return self._channels[packet]
        out = packet_channels(self._packet_group(packet), self._item_order().get(packet, []))
        self._channels[packet] = out
        return out

    def channel(self, packet: str, name: str) -> Channel:
        return self.resolve_channels(packet, [name])[0]

    def resolve_channels(self, packet: str, channels: str | Iterable[str] | None) -> list[Channel]:
        """The Channel records of `channels` (None: every non-raw column but the times);
        LogQueryError listing the valid names for an unknown one."""
        chans = self.channels(packet)
        if channels is None:
            return [c for c in chans if c.kind != "raw" and c.name not in ("device_time", "host_time")]
        if isinstance(channels, str):
            channels = [channels]
        by_name = {c.name: c for c in chans}
        wanted = list(channels)
        unknown = [c for c in wanted if c not in by_name]
        if unknown:
            raise LogQueryError(
                f"{self.path}: packet {packet} has no channel(s) {', '.join(map(repr, unknown))} "
                f"(channels: {', '.join(c.name for c in chans)})")
        return [by_name[c] for c in wanted]

    # ------------------------------------------------------------------ sizes and ranges
    @_guard
    def n_frames(self, packet: str) -> int:
        """Rows of `packet` every header column holds (a live file may be mid-append)."""
        self._packet_group(packet)
        return min(self._dataset(f"telemetry/{packet}/{n}").shape[0] for n in HEADER_CHANNELS)

    def _time_ds(self, packet: str, timebase: str) -> h5py.Dataset:
        if timebase not in TIMEBASES:
            raise LogQueryError(f"timebase must be 'device' or 'host', not {timebase!r}")
        return self._dataset(f"telemetry/{packet}/{timebase}_time")

    @_guard
    def origin(self, timebase: str = "device") -> float:
        """The earliest time of any packet in `timebase` (zero of relative ranges)."""
        if timebase not in self._origin:
            firsts = []
            for p in self.packets():
                if not self.n_frames(p):
                    continue
                try:
                    firsts.append(float(self._time_ds(p, timebase)[0]))
                except H5_READ_ERRORS:
                    if not self.salvage:      # salvage: the packets that can say so decide
                        raise
            self._origin[timebase] = min(firsts) if firsts else 0.0
        return self._origin[timebase]

    @_guard
    def index_range(self, packet: str, start: float | None = None, stop: float | None = None,
                    timebase: str = "device", *, relative: bool = False,
                    limit: int | None = None) -> tuple[int, int]:
        """Rows [i0, i1) of `packet` whose time lies in [start, stop] (None: open end),
        among the first `limit` rows only if given (the readable part of a damaged log)."""
        ds = self._time_ds(packet, timebase)
        if start is not None and stop is not None and start > stop:
            raise LogQueryError(f"range start {start} s is after its stop {stop} s")
        n = self.n_frames(packet)
        if limit is not None:
            n = max(0, min(n, limit))
        shift = self.origin(timebase) if relative else 0.0
        # times are whole ticks (or arrival stamps); a bound computed as origin + 0.5 s can
        # miss a tick by one rounding step, so bounds admit what is within 1 ns of them
        i0 = 0 if start is None else _search(ds, n, start + shift - TIME_TOLERANCE_S, "left")
        i1 = n if stop is None else _search(ds, n, stop + shift + TIME_TOLERANCE_S, "right")
        return i0, max(i0, i1)

    @_guard
    def tick_index_range(self, packet: str, tick_start: int | None,
                         tick_stop: int | None) -> tuple[int, int]:
        """Rows [i0, i1) whose unwrapped tick lies in [tick_start, tick_stop)."""
        ds = self._time_ds(packet, "device")
        n = self.n_frames(packet)
        rate = self.tick_rate_hz
        # device_time = tick / rate exactly; half a tick of margin makes rounding harmless
        i0 = 0 if tick_start is None else _search(ds, n, (tick_start - 0.5) / rate, "left")
        i1 = n if tick_stop is None else _search(ds, n, (tick_stop - 0.5) / rate, "left")
        return i0, max(i0, i1)

    @_guard
    def describe_range(self, packet: str, start, stop, timebase: str = "device",
                       relative: bool = False) -> str:
        """'device time 1 .. 2 s (the log holds 0.0008 .. 5 s)' for messages."""
        n = self.n_frames(packet)
        unit = "s" + (" from the start" if relative else "")
        want = f"{timebase} time {'-' if start is None else start} .. {'-' if stop is None else stop} {unit}"
        if not n:
            return f"{want} (the log holds no {packet} frames)"
        ds = self._time_ds(packet, timebase)
        shift = self.origin(timebase) if relative else 0.0
        return (f"{want} (the log holds {float(ds[0]) - shift!r} .. "
                f"{float(ds[n - 1]) - shift!r} {unit})")

    # ------------------------------------------------------------------ reading
    @_guard
    def read(self, packet: str, channels: str | Iterable[str] | None = None, *,
             start: float | None = None, stop: float | None = None, timebase: str = "device",
             with_time: bool = True, raw: bool = False, relative: bool = False) -> dict[str, np.ndarray]:
        """Columns of `packet` for the time range [start, stop] of `timebase`.

        Returns {name: array} with device_time and host_time first (with_time=True);
        raw=True gives wire counts for converted items; text items come as object arrays
        of str (bytes items as bytes).  An empty range gives empty arrays."""
        chans = self.resolve_channels(packet, channels)
        i0, i1 = self.index_range(packet, start, stop, timebase, relative=relative)
        return self._read_rows(packet, chans, i0, i1, raw=raw, with_time=with_time)

    @_guard
    def read_ticks(self, packet: str, channels: str | Iterable[str] | None, tick_start: int | None,
                   tick_stop: int | None, *, with_time: bool = True, raw: bool = False) -> dict[str, np.ndarray]:
        """Like read() for unwrapped device ticks (device_time * tick rate) in
        [tick_start, tick_stop)."""
        chans = self.resolve_channels(packet, channels)
        i0, i1 = self.tick_index_range(packet, tick_start, tick_stop)
        return self._read_rows(packet, chans, i0, i1, raw=raw, with_time=with_time)

    @_guard
    def read_rows(self, packet: str, channels: str | Iterable[str] | None, i0: int, i1: int | None,
                  *, with_time: bool = True, raw: bool = False) -> dict[str, np.ndarray]:
        """Like read() for row indices [i0, i1)."""
        chans = self.resolve_channels(packet, channels)
        n = self.n_frames(packet)
        i1 = n if i1 is None else i1
        return self._read_rows(packet, chans, i0, i1, raw=raw, with_time=with_time)

    def _read_rows(self, packet: str, chans: list[Channel], i0: int, i1: int, *, raw: bool,
                   with_time: bool) -> dict[str, np.ndarray]:
        n = self.n_frames(packet)
        i0, i1 = max(0, min(i0, n)), max(0, min(i1, n))
        i1 = max(i0, i1)
        base = f"telemetry/{packet}"
        out: dict[str, np.ndarray] = {}
        if with_time:
            out["device_time"] = self._read(f"{base}/device_time", slice(i0, i1))
            out["host_time"] = self._read(f"{base}/host_time", slice(i0, i1))
        for ch in chans:
            if ch.kind == "text":
                out[ch.name] = self._stream_records(f"{base}/{ch.name}", i0, i1,
                                                    decode=ch.encoding == "utf-8" and not raw)
            elif raw and ch.has_raw:
                out[ch.name] = self._read(f"{base}/raw/{ch.name}", slice(i0, i1))
            elif ch.from_raw:
                out[ch.name] = _to_engineering(self._read(f"{base}/raw/{ch.name}", slice(i0, i1)),
                                               ch.conversion)
            else:
                out[ch.name] = self._read(f"{base}/{ch.name}", slice(i0, i1))
        short = min((len(v) for v in out.values()), default=0)
        if any(len(v) != short for v in out.values()):   # a writer was mid-append: cut to the common rows
            out = {k: v[:short] for k, v in out.items()}
        return out

    def _stream_records(self, path: str, i0: int, i1: int, decode: bool) -> np.ndarray:
        """Records [i0, i1) of a byte stream group as an object array of bytes (or str)."""
        offsets = self._read(f"{path}/offset", slice(i0, i1)).astype(np.int64)
        lengths = self._read(f"{path}/length", slice(i0, i1)).astype(np.int64)
        k = min(len(offsets), len(lengths))
        offsets, lengths = offsets[:k], lengths[:k]
        out = np.empty(k, dtype=object)
        if not k:
            return out
        data_ds = self._dataset(f"{path}/data")
        lo, hi = int(offsets[0]), int((offsets + lengths).max())
        if hi > data_ds.shape[0]:        # index flushed ahead of its data: keep complete records
            ok = offsets + lengths <= data_ds.shape[0]
            k = int(np.argmin(ok)) if not ok.all() else k
            offsets, lengths, out = offsets[:k], lengths[:k], out[:k]
            if not k:
                return out
            hi = int((offsets + lengths).max())
        blob = self._read(f"{path}/data", slice(lo, hi)).tobytes()
        rel = offsets - lo
        # one Python object per record is the result type; text packets are rare
        records = [blob[o:o + n] for o, n in zip(rel.tolist(), lengths.tolist())]
        out[:] = [r.decode("utf-8", errors="replace") for r in records] if decode else records
        return out

    @_guard
    def frames(self, packet: str, start_index: int = 0, stop_index: int | None = None):
        """The frames [start_index, stop_index) as received, header to CRC: an (n,
        frame_length) uint8 array for fixed-length packets (row i is frame i), a list of
        bytes for variable-length ones."""
        self._packet_group(packet)
        fg = self._f["frames"].get(packet)
        if fg is None:
            raise LogFormatError(f"{self.path}: damaged log, /frames/{packet} missing")
        n = self.n_frames(packet)
        stop_index = n if stop_index is None else min(stop_index, n)
        start_index = max(0, min(start_index, stop_index))
        if "data" in fg:
            return self._read(f"frames/{packet}/data", slice(start_index, stop_index))
        return list(self._stream_records(f"frames/{packet}/stream", start_index, stop_index,
                                         decode=False))

    @_guard
    def is_variable(self, packet: str) -> bool:
        self._packet_group(packet)
        return "data" not in self._f["frames"][packet]

    # ------------------------------------------------------------------ gaps and summary
    def _scan_sequence(self, packet: str) -> tuple[np.ndarray, np.ndarray, int]:
        return scan_sequence(self, packet)

    @_guard
    def gaps(self, packet: str) -> dict[str, np.ndarray]:
        """Sequence gaps of `packet`: index (row of the first frame after the gap),
        missing (frames lost there), device_time and host_time of that frame."""
        idx, missing, _ = self._scan_sequence(packet)
        base = f"telemetry/{packet}"
        if len(idx):
            rows = idx.tolist()
            dev = self._read(f"{base}/device_time", rows)
            host = self._read(f"{base}/host_time", rows)
        else:
            dev = host = np.zeros(0)
        return {"index": idx, "missing": missing, "device_time": dev, "host_time": host}

    @_guard
    def summary(self) -> LogInfo:
        """Root attributes and per-packet statistics (reads each sequence column once)."""
        return summarize(self)

    @property
    def info(self) -> LogInfo:
        """summary(), computed once (again after refresh())."""
        if self._info is None:
            self._info = self.summary()
        return self._info

    # ------------------------------------------------------------------ the rest of the file
    @_guard
    def journal(self, kinds: str | Iterable[str] | None = None) -> list[JournalRecord]:
        """Journal records (notes, commands, events, parameter tables, profiles, ...) in
        the order written, optionally only the given kinds."""
        j = self._f["journal"]
        names = json.loads(_text(j.attrs.get("kinds", json.dumps(list(schema.JOURNAL_KINDS)))))
        if isinstance(kinds, str):
            kinds = [kinds]
        if kinds is not None:
            kinds = list(kinds)
            bad = [k for k in kinds if k not in names]
            if bad:
                raise LogQueryError(f"{self.path}: no journal kind(s) {', '.join(map(repr, bad))} "
                                    f"(kinds: {', '.join(names)})")
        t_ds, k_ds = self._dataset("journal/time"), self._dataset("journal/kind")
        n = min(t_ds.shape[0], k_ds.shape[0],
                *(self._dataset(f"journal/{s}/{c}").shape[0] for s in ("text", "blob")
                  for c in ("offset", "length")))
        times = self._read("journal/time", slice(0, n))
        kind_idx = self._read("journal/kind", slice(0, n)).astype(np.int64)
        if kinds is not None:
            wanted = np.array([names.index(k) for k in kinds], dtype=np.int64)
            rows = np.flatnonzero(np.isin(kind_idx, wanted))
        else:
            rows = np.arange(n)
        if not len(rows):
            return []
        lo, hi = int(rows[0]), int(rows[-1]) + 1
        texts = self._stream_records("journal/text", lo, hi, decode=True)
        blobs = self._stream_records("journal/blob", lo, hi, decode=False)
        rows = rows[rows - lo < min(len(texts), len(blobs))]
        label = [names[k] if k < len(names) else f"kind{k}" for k in range(int(kind_idx.max()) + 1)]
        return [JournalRecord(float(times[r]), label[kind_idx[r]], json.loads(texts[r - lo]),
                              blobs[r - lo]) for r in rows.tolist()]

    @_guard
    def protocol_files(self) -> dict[str, str]:
        """The protocol TOML files as recorded: name -> text."""
        proto = self._f["protocol"]
        return {name: _text(proto[name][()]) for name in proto.keys()
                if isinstance(proto[name], h5py.Dataset)}

    @_guard
    def testbed(self) -> tuple[str, str, str]:
        """(name, path, text) of the testbed configuration recorded ('' where unknown)."""
        tb = self._f.get("testbed")
        if tb is None:
            return "", "", ""
        text = _text(tb["config"][()]) if "config" in tb else ""
        return _text(tb.attrs.get("name", "")), _text(tb.attrs.get("path", "")), text


__all__ = ["JournalRecord", "LogReader", "TIMEBASES", "TIME_TOLERANCE_S"]
