"""The low-level log file: creates the layout of schema.py and appends to it.

No threads and no queue here (the Recorder adds those): this is a plain object a test
or a script can drive directly.  Every dataset is created up front, then SWMR mode is
switched on; from then on data are only appended, and flush() makes them visible to
readers and durable against a crash of this process.
"""

from __future__ import annotations

import getpass
import json
import socket
import time
import uuid
from collections import defaultdict
from datetime import datetime, timezone
from pathlib import Path
from typing import Any

import h5py
import numpy as np
from h5py import h5s

from .. import __version__
from ..codec import TelemetryBlock
from ..core.dictionary import CRC_SIZE, HEADER_SIZE, Dictionary, Item, PacketDef
from ..codec.ticks import TickUnwrapper
from . import schema


def _text_dataset(group: h5py.Group, name: str, text: str) -> None:
    data = text.encode("utf-8")
    group.create_dataset(name, data=np.array(data, dtype=f"S{max(1, len(data))}"))


def _appendable(group: h5py.Group, name: str, dtype, row_shape: tuple = (), chunk_rows=None,
                compression: dict | None = None):
    chunk_rows = chunk_rows or schema.CHUNK_ROWS
    row_bytes = int(np.prod(row_shape, dtype=np.int64)) * np.dtype(dtype).itemsize if row_shape else np.dtype(dtype).itemsize
    if row_shape:   # keep chunks near 0.5 MB for wide rows (raw frames)
        chunk_rows = max(64, min(chunk_rows, schema.WIDE_ROW_CHUNK_BYTES // max(1, row_bytes)))
    return group.create_dataset(name, shape=(0, *row_shape), maxshape=(None, *row_shape),
                                dtype=dtype, chunks=(chunk_rows, *row_shape),
                                **(schema.COMPRESSION if compression is None else compression))


def _stream(group: h5py.Group, name: str, compression: dict | None = None) -> h5py.Group:
    g = group.create_group(name)
    g.create_dataset("data", shape=(0,), maxshape=(None,), dtype=np.uint8,
                     chunks=(schema.STREAM_CHUNK,),
                     **(schema.COMPRESSION if compression is None else compression))
    _appendable(g, "offset", np.uint64, compression=compression)
    _appendable(g, "length", np.uint32, compression=compression)
    g.attrs["layout"] = "stream: record i is data[offset[i] : offset[i] + length[i]]"
    return g


class _Column:
    """One appendable dataset of an open log: its row count is kept here, and rows are
    written with h5py's low-level calls.  The high-level ones (a group lookup by name,
    `shape`, `resize`, slicing) cost about 0.3 ms of Python per dataset and append: with
    some 70 datasets a flush, more than HDF5 takes to write and compress the rows of a
    fast campaign (docs/campaigns.md, "Speed")."""

    __slots__ = ("id", "rows", "row_shape", "dtype")

    def __init__(self, ds: h5py.Dataset):
        self.id = ds.id
        self.rows = ds.shape[0]
        self.row_shape = tuple(ds.shape[1:])
        self.dtype = ds.dtype

    def append(self, values) -> None:
        # the cast h5py's slice assignment makes (numpy, to the dataset's type), then
        # resize + one hyperslab write, as `ds.resize(); ds[a:b] = values` do
        values = np.ascontiguousarray(values, dtype=self.dtype)
        n = len(values)
        if not n:
            return
        start = self.rows
        shape = (start + n, *self.row_shape)
        self.id.set_extent(shape)
        fspace = self.id.get_space()
        fspace.select_hyperslab((start,) + (0,) * len(self.row_shape), (n, *self.row_shape))
        self.id.write(h5s.create_simple(values.shape), fspace, values)
        self.rows = start + n


def _append(col: _Column, values: np.ndarray) -> None:
    col.append(values)


def _append_stream(cols: tuple[_Column, _Column, _Column], records: list[bytes]) -> None:
    """Records onto a byte stream: (data, offset, length) columns."""
    if not records:
        return
    data, offset, length = cols
    start = data.rows
    lengths = np.fromiter((len(r) for r in records), dtype=np.uint32, count=len(records))
    offsets = start + np.concatenate(([0], np.cumsum(lengths[:-1], dtype=np.uint64))).astype(np.uint64)
    _append(data, np.frombuffer(b"".join(records), dtype=np.uint8))
    _append(offset, offsets)
    _append(length, lengths)


def engineering_dtype(item: Item) -> np.dtype:
    """Stored type of an item in engineering units: float32 when the wire carries at most
    16-bit counts (float32 keeps every count distinct, half the bytes), float64 for
    32-bit counts such as the encoders' 1.46 nrad steps, the wire type when there is no
    conversion."""
    if not item.has_conversion:
        return item.wire_dtype.newbyteorder("=")
    return np.dtype(np.float32) if item.wire_dtype.itemsize <= 2 else np.dtype(np.float64)


def _item_attrs(ds: h5py.Dataset, item: Item) -> None:
    ds.attrs["units"] = item.units
    ds.attrs["description"] = item.description
    ds.attrs["wire_type"] = item.type
    if item.polynomial is not None:
        ds.attrs["conversion"] = json.dumps({"polynomial": list(item.polynomial)})
    elif item.scale is not None:
        ds.attrs["conversion"] = json.dumps({"scale": item.scale, "offset": item.offset})
    if item.states:
        ds.attrs["states"] = json.dumps(item.states)
    if item.limits is not None:
        ds.attrs["limits"] = json.dumps({"yellow": item.limits.yellow, "red": item.limits.red})


class LogFile:
    """One HDF5 recording: create(), append(), journal(), flush(), close()."""

    def __init__(self, path: Path, dictionary: Dictionary, *, test_name: str = "", run: int = 1,
                 notes: str = "", testbed_text: str = "", testbed_name: str = "",
                 testbed_path: str = "", compression: dict | None = None,
                 created_utc: str | None = None, chunk_rows: int | None = None):
        """`created_utc` (ISO 8601) overrides the start time recorded: a file written
        from another one (log redecode) keeps the session's own start, not its own.
        `chunk_rows`: rows per chunk of the per-frame datasets (schema.CHUNK_ROWS; a
        fast campaign uses schema.FAST_CHUNK_ROWS).  Readers take the chunking from
        the file, so every value gives the same layout and content."""
        self.path = Path(path)
        if chunk_rows is not None and chunk_rows < 1:
            raise ValueError(f"chunk_rows must be >= 1, not {chunk_rows!r}")
        self.chunk_rows = chunk_rows or schema.CHUNK_ROWS
        self.created_utc = created_utc
        self.d = dictionary
        self.compression = dict(schema.COMPRESSION if compression is None else compression)
        self.frames_written = 0
        self.last_host_time: float | None = None
        self._unwrap: dict[str, TickUnwrapper] = defaultdict(TickUnwrapper)
        self._cols: dict[str, _Column] = {}
        f = h5py.File(self.path, "w", libver=schema.LIBVER)
        self.f = f
        try:
            self._create(test_name, run, notes, testbed_text, testbed_name, testbed_path)
            f.swmr_mode = True
        except BaseException:
            f.close()
            raise
        self.created = time.time()

    # ------------------------------------------------------------------ layout
    def _create(self, test_name, run, notes, testbed_text, testbed_name, testbed_path) -> None:
        f, d = self.f, self.d
        a = f.attrs
        a["schema"] = schema.SCHEMA
        a["schema_version"] = schema.SCHEMA_VERSION
        a["uuid"] = str(uuid.uuid4())
        a["created_utc"] = self.created_utc or datetime.now(timezone.utc).isoformat()
        a["software_version"] = __version__
        a["host"] = socket.gethostname()
        try:
            a["user"] = getpass.getuser()
        except (KeyError, OSError):
            a["user"] = ""
        a["test_name"] = test_name
        a["run"] = run
        a["notes"] = notes
        a["protocol_version"] = d.version
        a["dictionary_hash"] = f"{d.hash:08x}"
        a["tick_rate_hz"] = d.control_rate_hz
        a["clean_close"] = False
        a["compression"] = json.dumps(self.compression)
        proto = f.create_group("protocol")
        for name, text in d.source_texts.items():
            _text_dataset(proto, name, text)
        tb = f.create_group("testbed")
        tb.attrs["name"] = testbed_name
        tb.attrs["path"] = testbed_path
        _text_dataset(tb, "config", testbed_text or "")
        tel = f.create_group("telemetry")
        frames = f.create_group("frames")
        for pkt in d.packets:
            if pkt.direction != "device_to_host":
                continue
            self._create_packet(tel.create_group(pkt.name), pkt)
            fg = frames.create_group(pkt.name)
            if pkt.variable_item is None:
                _appendable(fg, "data", np.uint8, (pkt.fixed_payload_size + HEADER_SIZE + CRC_SIZE,),
                            chunk_rows=self.chunk_rows, compression=self.compression)
                fg.attrs["layout"] = "fixed: one row per frame, header to CRC"
            else:
                _stream(fg, "stream", self.compression)
                fg.attrs["layout"] = "stream: frames in the 'stream' byte stream"
            _appendable(fg, "host_time", np.float64, chunk_rows=self.chunk_rows,
                        compression=self.compression)
        j = f.create_group("journal")
        j.attrs["kinds"] = json.dumps(list(schema.JOURNAL_KINDS))
        j.attrs["description"] = ("one row per record: time (host s), kind (index into "
                                  "'kinds'), JSON text and an optional binary blob")
        _appendable(j, "time", np.float64, chunk_rows=1024, compression=self.compression)
        _appendable(j, "kind", np.uint8, chunk_rows=1024, compression=self.compression)
        _stream(j, "text", self.compression)
        _stream(j, "blob", self.compression)

    def _create_packet(self, g: h5py.Group, pkt: PacketDef) -> None:
        g.attrs["id"] = pkt.id
        g.attrs["description"] = pkt.description
        g.attrs["rate_hz"] = pkt.rate_hz or 0.0
        for name, dt, units, desc in (
                ("sequence", np.uint32, "counts", "per-packet sequence number (gaps = frames lost)"),
                ("tick", np.uint32, "ticks", "device tick (1200 Hz) as on the wire"),
                ("device_time", np.float64, "s", "unwrapped device tick / tick rate: device time since boot"),
                ("host_time", np.float64, "s", "host arrival time, seconds since the Unix epoch")):
            ds = _appendable(g, name, dt, chunk_rows=self.chunk_rows, compression=self.compression)
            ds.attrs["units"], ds.attrs["description"] = units, desc
        raw = g.create_group("raw")
        for item in pkt.items:
            if item.is_variable:
                s = _stream(g, item.name, self.compression)
                s.attrs["encoding"] = "utf-8" if item.type == "str" else "binary"
                s.attrs["description"] = item.description
                continue
            _item_attrs(_appendable(g, item.name, engineering_dtype(item), chunk_rows=self.chunk_rows,
                                    compression=self.compression), item)
            if item.has_conversion:
                r = _appendable(raw, item.name, item.wire_dtype.newbyteorder("="),
                                chunk_rows=self.chunk_rows, compression=self.compression)
                r.attrs["units"] = "counts"
                r.attrs["description"] = f"wire counts of {item.name}"
            for flag, bit in item.bits.items():
                ds = _appendable(g, flag, np.bool_, chunk_rows=self.chunk_rows,
                                 compression=self.compression)
                ds.attrs["description"] = f"bit {bit} of {item.name}"
                ds.attrs["units"] = ""

    # ------------------------------------------------------------------ appending
    def _col(self, path: str) -> _Column:
        """The appendable dataset at `path`, looked up once per file."""
        col = self._cols.get(path)
        if col is None:
            col = self._cols[path] = _Column(self.f[path])
        return col

    def _stream_cols(self, path: str) -> tuple[_Column, _Column, _Column]:
        return self._col(f"{path}/data"), self._col(f"{path}/offset"), self._col(f"{path}/length")

    def append(self, blocks: list[TelemetryBlock]) -> None:
        """Append blocks (any packets, arrival order) - one write per dataset per packet."""
        by_packet: dict[str, list[TelemetryBlock]] = defaultdict(list)
        for b in blocks:
            if len(b):
                by_packet[b.name].append(b)
        col = self._col
        for name, group in by_packet.items():
            pkt = group[0].packet
            g, fg = f"telemetry/{name}", f"frames/{name}"
            cat = {k: np.concatenate([b.columns[k] for b in group]) for k in group[0].columns}
            host = np.concatenate([np.broadcast_to(b.host_time, (len(b),)) for b in group])
            ticks = cat["tick"]
            _append(col(f"{g}/sequence"), cat["sequence"])
            _append(col(f"{g}/tick"), ticks)
            _append(col(f"{g}/device_time"), self._unwrap[name].unwrap(ticks) / self.d.control_rate_hz)
            _append(col(f"{g}/host_time"), host)
            if pkt.variable_item is None:
                # concatenate the bytes, not the records: numpy would convert big-endian
                # records to native order, and the frames must stay as received
                frame_bytes = np.concatenate([b.raw.view(np.uint8).reshape(len(b), -1) for b in group])
                raw = frame_bytes.view(group[0].raw.dtype).reshape(-1)
                for item in pkt.items:
                    _append(col(f"{g}/{item.name}"), cat[item.name])
                    if item.has_conversion:
                        _append(col(f"{g}/raw/{item.name}"), raw[item.name].astype(item.wire_dtype.newbyteorder("=")))
                    for flag in item.bits:
                        _append(col(f"{g}/{flag}"), cat[flag])
                _append(col(f"{fg}/data"), frame_bytes)
            else:
                for item in pkt.items:
                    if item.is_variable:
                        values = cat[item.name]
                        _append_stream(self._stream_cols(f"{g}/{item.name}"),
                                       [v.encode("utf-8") if isinstance(v, str) else bytes(v)
                                        for v in values])
                    else:
                        _append(col(f"{g}/{item.name}"), cat[item.name])
                        if item.has_conversion:
                            _append(col(f"{g}/raw/{item.name}"), np.asarray(item.to_raw(cat[item.name])).astype(
                                item.wire_dtype.newbyteorder("=")))
                        for flag in item.bits:
                            _append(col(f"{g}/{flag}"), cat[flag])
                _append_stream(self._stream_cols(f"{fg}/stream"), [fr for b in group for fr in b.frames])
            _append(col(f"{fg}/host_time"), host)
            self.frames_written += len(host)
            # the newest arrival of any packet: blocks of one append are grouped by
            # packet, so the last group's last time may be older than another group's
            newest = float(host.max())
            if self.last_host_time is None or newest > self.last_host_time:
                self.last_host_time = newest

    def journal(self, records: list[tuple[float, str, dict[str, Any], bytes]]) -> None:
        """Append journal records (time, kind, JSON-able dict, blob)."""
        if not records:
            return
        kinds = list(schema.JOURNAL_KINDS)
        _append(self._col("journal/time"), np.array([r[0] for r in records], dtype=np.float64))
        _append(self._col("journal/kind"), np.array([kinds.index(r[1]) for r in records], dtype=np.uint8))
        _append_stream(self._stream_cols("journal/text"),
                       [json.dumps(r[2], default=_json_default).encode("utf-8") for r in records])
        _append_stream(self._stream_cols("journal/blob"), [bytes(r[3]) for r in records])

    def flush(self) -> None:
        self.f.flush()

    @property
    def size_bytes(self) -> int:
        try:
            return self.path.stat().st_size
        except OSError:
            return 0

    def close(self, clean: bool = True, stop_utc: str | None = None) -> None:
        """Close; a clean close reopens the file to mark it complete (not possible in
        SWMR write mode, which allows no new attributes).  `stop_utc` overrides the end
        time recorded (now), as `created_utc` does the start."""
        try:
            self.f.close()
        finally:
            if clean:
                try:
                    f = h5py.File(self.path, "r+", libver=schema.LIBVER)
                except BlockingIOError:
                    # a reader elsewhere holds HDF5's file lock (h5dump, another tool);
                    # the attributes below are the only change, safe without the lock
                    f = h5py.File(self.path, "r+", libver=schema.LIBVER, locking=False)
                with f:
                    f.attrs["clean_close"] = True
                    f.attrs["stop_utc"] = stop_utc or datetime.now(timezone.utc).isoformat()
                    f.attrs["frames"] = self.frames_written


def _json_default(obj):
    if isinstance(obj, np.generic):
        return obj.item()
    if isinstance(obj, np.ndarray):
        return obj.tolist()
    if isinstance(obj, (bytes, bytearray)):
        return obj.hex()
    if isinstance(obj, Path):
        return str(obj)
    raise TypeError(f"cannot record a {type(obj).__name__} in the journal")
