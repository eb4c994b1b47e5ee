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
"""

from __future__ import annotations

import functools
import json
import os
import tomllib
from dataclasses import dataclass, field
from datetime import datetime, timezone
from pathlib import Path
from typing import Any, Iterable

import h5py
import numpy as np

from ..codec.sequence import SequenceTracker
from ..errors import GroundStationError
from . import schema

HEADER_CHANNELS = ("sequence", "tick", "device_time", "host_time")
TIMEBASES = ("device", "host")
_SCAN_ROWS = 1 << 20            # rows per read when a whole column must be scanned


TIME_TOLERANCE_S = 1e-9


class LogError(GroundStationError):
    """A log cannot be opened or a request to it cannot be answered (message says why)."""


class LogFormatError(LogError):
    """The file is not a ground-station log this version can read (not HDF5, another
    schema, a newer schema version, or a damaged layout)."""


class LogQueryError(LogError):
    """A request names a packet, channel, timebase or journal kind the log does not have."""


class EmptyRangeError(LogQueryError):
    """A time or tick range holds no frames of the packet."""


class LogDamagedError(LogFormatError):
    """The file is (or was) a log but part of it cannot be read: empty, superblock
    destroyed, truncated, or a dataset / attribute that HDF5 cannot read any more.

    `what` names the damage; the message adds the file and what to do about it
    (`groundstation log check`, and `log export --salvage` when something is readable)."""

    def __init__(self, path: str | Path, what: str, *, salvageable: bool = True):
        self.path = Path(path)
        self.what = what
        self.salvageable = salvageable
        if salvageable:
            advice = (f"run `groundstation log check {self.path}` to see what is readable, and "
                      f"`groundstation log export {self.path} --salvage` to export it")
        else:
            advice = (f"nothing in it can be read (`groundstation log check {self.path}` "
                      f"says what was found)")
        super().__init__(f"{self.path}: damaged log, {what}; {advice}")


#: what h5py raises when the bytes under a read are not what HDF5 wrote (a filter fails,
#: a signature or checksum does not match, an address lies past the end of the file)
H5_READ_ERRORS = (OSError, RuntimeError)
#: signatures of HDF5 structures (object header, B-trees, heaps, chunk index) that show
#: a file without a valid superblock once was an HDF5 file
_HDF5_SIGNATURES = (b"OHDR", b"TREE", b"GCOL", b"FRHP", b"BTHD", b"EAHD", b"FAHD")


def truncation_text(actual: int, expected: int) -> str:
    return f"truncated: file ends at byte {actual}, HDF5 expects {expected}"


def file_truncation(f: h5py.File, path: Path) -> tuple[int, int] | None:
    """(bytes on disk, bytes HDF5 expects) if the file is shorter than its superblock's
    end-of-file address says, else None.  HDF5 itself refuses such a file in normal read
    mode ("truncated file: eof = ..."), but not in the SWMR read mode we use (a writer
    may be extending it), so we ask: H5Fget_filesize is max(end of allocated space,
    end of file), larger than the size on disk exactly when the file was cut short."""
    try:
        expected = int(f.id.get_filesize())
        actual = os.stat(path).st_size
    except (OSError, RuntimeError):
        return None
    return (actual, expected) if expected > actual else None


def _superblock_eof(path: Path) -> int | None:
    """End-of-file address from a version 2/3 superblock at offset 0 (the format our
    logs use), for when HDF5 cannot open the file to say it: signature (8 bytes),
    version, sizes of offsets and lengths, flags, then base, extension and EOF addresses."""
    try:
        with open(path, "rb") as fh:
            head = fh.read(48)
    except OSError:
        return None
    if len(head) < 12 or head[:8] != b"\x89HDF\r\n\x1a\n" or head[8] not in (2, 3):
        return None
    size = head[9]
    at = 12 + 2 * size
    if size not in (4, 8) or len(head) < at + size:
        return None
    return int.from_bytes(head[at:at + size], "little")


def _looks_like_hdf5_body(path: Path, limit: int = 4 << 20) -> bool:
    try:
        with open(path, "rb") as fh:
            body = fh.read(limit)
    except OSError:
        return False
    return any(sig in body for sig in _HDF5_SIGNATURES)


def first_unreadable(ds: h5py.Dataset, start: int, stop: int) -> tuple[int, str]:
    """(k, error) for rows [start, stop) of `ds`: rows start..k-1 read, row k's chunk does
    not (k == stop and error '' when all read).  Reads many chunks at a time and narrows
    down to one chunk only where a read fails."""
    step = ds.chunks[0] if ds.chunks else max(1, stop - start)
    block = step * 256
    a = start
    while a < stop:
        b = min(stop, a + block)
        try:
            ds[a:b]
        except H5_READ_ERRORS as exc:
            first_error = str(exc)
            c = a
            while c < b:
                d = min(b, (c // step + 1) * step)
                try:
                    ds[c:d]
                except H5_READ_ERRORS as exc2:
                    return c, str(exc2)
                c = d
            return a, first_error          # only the large read fails: be conservative
        a = b
    return stop, ""


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
class Channel:
    """One column of a packet as recorded."""

    name: str                 # dataset name ("raw/<item>" for wire counts)
    units: str
    description: str
    dtype: np.dtype           # object for text/bytes items
    kind: str                 # header | eng | flag | raw | text
    conversion: dict | None = None
    states: dict[str, int] = field(default_factory=dict)
    limits: dict | None = None
    encoding: str = ""        # text items: "utf-8" (str) or "binary" (bytes)
    has_raw: bool = False     # an eng channel whose wire counts are in raw/<name>
    from_raw: bool = False    # read() computes it from raw/<name> with `conversion`, in
                              # float64 exactly as the live decoder does (the stored column
                              # is a narrower float, kept for h5dump and direct readers)


@dataclass(frozen=True)
class PacketSummary:
    name: str
    id: int
    description: str
    nominal_rate_hz: float
    frames: int
    first_device_time: float | None
    last_device_time: float | None
    first_host_time: float | None
    last_host_time: float | None
    drops: int                # frames missing according to sequence gaps (mod 2^32)
    gaps: int                 # number of gaps
    duplicates: int           # repeated, out-of-order or wild sequence numbers (not believed)
    rate_hz: float            # frames received per second of device time

    @property
    def duration_s(self) -> float:
        if self.first_device_time is None or self.last_device_time is None:
            return 0.0
        return self.last_device_time - self.first_device_time


@dataclass(frozen=True)
class LogInfo:
    path: Path
    schema_version: int
    uuid: str
    test_name: str
    run: int
    notes: str
    created_utc: str
    created: float            # s since the epoch
    stop_utc: str             # as recorded, or from the last frame if the log was not closed
    stop: float
    clean_close: bool         # False: the recorder crashed (or is still writing)
    software_version: str
    host: str
    user: str
    protocol_version: str
    dictionary_hash: str
    tick_rate_hz: float
    packets: dict[str, PacketSummary]

    @property
    def duration_s(self) -> float:
        return max(0.0, self.stop - self.created)

    @property
    def frames(self) -> int:
        return sum(p.frames for p in self.packets.values())

    @property
    def drops(self) -> int:
        return sum(p.drops for p in self.packets.values())

    def format(self) -> str:
        """A few lines for a terminal."""
        state = "closed cleanly" if self.clean_close else "NOT closed (crash or still recording)"
        lines = [f"{self.path}",
                 f"  test '{self.test_name}' run {self.run}, {self.created_utc} .. {self.stop_utc} "
                 f"({self.duration_s:.1f} s), {state}",
                 f"  protocol {self.protocol_version} (dictionary {self.dictionary_hash}), "
                 f"software {self.software_version} on {self.host}"]
        if self.notes:
            lines.append(f"  notes: {self.notes}")
        for p in self.packets.values():
            span = (f"device t {p.first_device_time:.4f}..{p.last_device_time:.4f} s"
                    if p.frames else "no frames")
            lines.append(f"  {p.name:<13} {p.frames:>9} frames  {p.rate_hz:8.2f}/s  "
                         f"drops {p.drops} in {p.gaps} gap(s)  {span}")
        return "\n".join(lines)


@dataclass(frozen=True)
class JournalRecord:
    time: float               # host time, s since the epoch
    kind: str
    data: dict[str, Any]
    blob: bytes


def _text(value: Any) -> str:
    if isinstance(value, bytes):
        return value.decode("utf-8", errors="replace")
    if isinstance(value, np.ndarray) and value.shape == ():
        return _text(value[()])
    return "" if value is None else str(value)


def _utc_seconds(text: str) -> float | None:
    try:
        return datetime.fromisoformat(text).timestamp()
    except (TypeError, ValueError):
        return None


def _convertible(conversion: dict | None) -> bool:
    return isinstance(conversion, dict) and (
        isinstance(conversion.get("polynomial"), list) or "scale" in conversion)


def _to_engineering(raw: np.ndarray, conversion: dict) -> np.ndarray:
    """Wire counts -> engineering units by the recorded conversion, with the same float64
    operations as dictionary.Item.to_engineering (so the values equal the live ones)."""
    if "polynomial" in conversion:
        return np.polynomial.polynomial.polyval(raw.astype(np.float64),
                                                [float(c) for c in conversion["polynomial"]])
    eng = raw.astype(np.float64)
    eng *= float(conversion["scale"])
    offset = float(conversion.get("offset", 0.0) or 0.0)
    if offset:
        eng += offset
    return eng


def _search(ds: h5py.Dataset, n: int, value: float, side: str) -> int:
    """First row i of the sorted rows [0, n) with ds[i] >= value ("left") or > value
    ("right"); n if there is none.  Bisects over chunk starts (one point read each),
    then searches inside the one chunk that holds the answer."""
    if n <= 0:
        return 0
    step = ds.chunks[0] if ds.chunks else 8192
    lo, hi = 0, (n - 1) // step + 1
    while lo < hi:
        mid = (lo + hi) // 2
        x = ds[mid * step]
        if (x < value) if side == "left" else (x <= value):
            lo = mid + 1
        else:
            hi = mid
    if lo == 0:                       # the first row already qualifies
        return 0
    c0 = (lo - 1) * step
    block = ds[c0:min(n, c0 + step)]
    return c0 + int(np.searchsorted(block, value, side=side))


def _open_h5(path: Path) -> h5py.File:
    """Open for SWMR reading without an HDF5 file lock: a reader holding the shared lock
    would make the recorder's final reopen (which marks the log clean_close) fail in the
    writing process.  If this process already has the file open with locking (a recorder
    in this process), HDF5 requires the same flag: then open it that way."""
    try:
        return h5py.File(path, "r", libver="latest", swmr=True, locking=False)
    except OSError as exc:
        if "locking" not in str(exc):
            raise
    return h5py.File(path, "r", libver="latest", swmr=True)


def open_log_file(path: Path, *, salvage: bool = False) -> tuple[h5py.File, tuple[int, int] | None]:
    """Open `path` for SWMR reading, or say precisely why it cannot be read: no such
    file, empty, not HDF5, HDF5 structures without a superblock, unopenable, truncated.
    Returns the file and (bytes on disk, bytes expected) when it is truncated - which
    raises LogDamagedError unless `salvage` (then the caller reads what it can)."""
    if not path.exists():
        raise LogError(f"{path}: no such file")
    if not path.is_file():
        raise LogFormatError(f"{path} is not a file")
    try:
        size = path.stat().st_size
        is_hdf5 = h5py.is_hdf5(str(path))
    except OSError as exc:
        raise LogError(f"{path}: cannot read ({exc})") from None
    if size == 0:
        raise LogDamagedError(path, "not an HDF5 file: it is empty (0 bytes)", salvageable=False)
    if not is_hdf5:
        if _looks_like_hdf5_body(path):
            raise LogDamagedError(
                path, "not an HDF5 file any more: the HDF5 superblock at its start is destroyed "
                      "(HDF5 structures follow it, but no HDF5 reader can find them)",
                salvageable=False)
        try:
            with open(path, "rb") as fh:
                head = fh.read(16)
        except OSError:
            head = b""
        raise LogFormatError(
            f"{path} is not an HDF5 file (it starts with {head!r}); a ground-station "
            f"log is the .h5 file `groundstation record` writes")
    try:
        f = _open_h5(path)
    except H5_READ_ERRORS as exc:
        expected = _superblock_eof(path)
        if expected is not None and expected > size:
            raise LogDamagedError(path, truncation_text(size, expected) + " and what is left "
                                  f"cannot be opened ({exc})", salvageable=False) from None
        raise LogDamagedError(path, f"the HDF5 file cannot be opened ({exc})",
                              salvageable=False) from None
    cut = file_truncation(f, path)
    if cut is not None and not salvage:
        f.close()
        # a recorder may be between writing the superblock and extending the file at a
        # flush: a file it is still writing is looked at once more before it is called cut
        f = _open_h5(path)
        cut = file_truncation(f, path)
        if cut is not None:
            f.close()
            raise LogDamagedError(path, truncation_text(*cut))
    return f, cut


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
        if self.truncated is not None:
            what = f"{what}; the file is {truncation_text(*self.truncated)}"
        return LogDamagedError(self.path, what, salvageable=salvageable)

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
            where = f"after frame {row}" if row else "from its first frame"
            raise self._damaged(f"dataset /{path} unreadable {where} (of {n}; {exc})") from None

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
        a = self._f.attrs
        if "schema" not in a:
            top = ", ".join(list(self._f.keys())[:10]) or "nothing"
            raise LogFormatError(f"{self.path} is an HDF5 file but not a ground-station log: no "
                                 f"'schema' attribute (top level holds: {top})")
        found = _text(a["schema"])
        if found != schema.SCHEMA:
            raise LogFormatError(f"{self.path}: schema '{found}', not a ground-station log "
                                 f"('{schema.SCHEMA}')")
        try:
            version = int(a["schema_version"])
        except (KeyError, TypeError, ValueError):
            raise LogFormatError(f"{self.path}: no valid 'schema_version' attribute "
                                 f"(found {a.get('schema_version')!r})") from None
        if version > schema.SCHEMA_VERSION:
            raise LogFormatError(
                f"{self.path}: log schema_version {version} is newer than this ground station "
                f"reads (up to {schema.SCHEMA_VERSION}); update the ground station to open it")
        if version < 1:
            raise LogFormatError(f"{self.path}: invalid schema_version {version}")
        missing = [g for g in ("telemetry", "frames", "journal", "protocol") if g not in self._f]
        if missing:
            raise LogFormatError(f"{self.path}: damaged log, group(s) {', '.join(missing)} missing")
        return version

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
        return float(self._f.attrs.get("tick_rate_hz", 1200.0))

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
        try:
            doc = tomllib.loads(self.protocol_files().get("telemetry.toml", ""))
            order = {}
            for p in doc.get("packet", []):
                items = p.get("items", [])
                names = [i["name"] for i in items]
                names += [flag for i in items for flag in i.get("bits", {})]
                order[p["name"]] = names
            return order
        except (tomllib.TOMLDecodeError, KeyError, TypeError, AttributeError):
            return {}

    @_guard
    def channels(self, packet: str) -> list[Channel]:
        """Every column of `packet`: header counters and times, items, flags, text items,
        then the raw counts (named raw/<item>)."""
        if packet in self._channels:
            return self._channels[packet]
        g = self._packet_group(packet)
        raw_group = g.get("raw")
        raw_names = set(raw_group.keys()) if isinstance(raw_group, h5py.Group) else set()
        order = {n: i for i, n in enumerate(self._item_order().get(packet, []))}
        names = sorted((n for n in g.keys() if n != "raw"),
                       key=lambda n: (0, HEADER_CHANNELS.index(n), "") if n in HEADER_CHANNELS
                       else (1, order.get(n, len(order)), n))
        out: list[Channel] = []
        for name in names:
            obj = g[name]
            a = obj.attrs
            if isinstance(obj, h5py.Group):
                encoding = _text(a.get("encoding", "binary"))
                out.append(Channel(name, "", _text(a.get("description", "")), np.dtype(object),
                                   "text", encoding=encoding))
                continue
            kind = ("header" if name in HEADER_CHANNELS
                    else "flag" if obj.dtype == np.bool_ else "eng")
            conversion = json.loads(_text(a["conversion"])) if "conversion" in a else None
            has_raw = name in raw_names
            from_raw = (kind == "eng" and has_raw and _convertible(conversion)
                        and obj.dtype.kind == "f" and obj.dtype.itemsize < 8)
            out.append(Channel(
                name, _text(a.get("units", "")), _text(a.get("description", "")),
                np.dtype(np.float64) if from_raw else obj.dtype, kind, conversion=conversion,
                states=json.loads(_text(a["states"])) if "states" in a else {},
                limits=json.loads(_text(a["limits"])) if "limits" in a else None,
                has_raw=has_raw, from_raw=from_raw))
        for ch in list(out):
            if ch.has_raw:
                ds = raw_group[ch.name]
                out.append(Channel(f"raw/{ch.name}", _text(ds.attrs.get("units", "counts")),
                                   _text(ds.attrs.get("description", "")), ds.dtype, "raw"))
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
        """(row index after each gap, frames missing there, duplicates and outliers) for
        `packet`, reading the sequence column in bounded pieces.  The rule is the live
        link's (codec/sequence.py): one wild sequence number is an outlier, not a gap."""
        n = self.n_frames(packet)
        tracker = SequenceTracker()
        idx, missing, odd = [], [], 0
        for a in range(0, n, _SCAN_ROWS):
            seq = self._read(f"telemetry/{packet}/sequence", slice(a, min(n, a + _SCAN_ROWS)))
            rep = tracker.feed(seq)
            idx.append(rep.gap_index)
            missing.append(rep.missing)
            odd += rep.duplicates + rep.outliers
        end = tracker.finish()
        idx.append(end.gap_index)
        missing.append(end.missing)
        odd += end.outliers
        return np.concatenate(idx), np.concatenate(missing), odd

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
        a = self.attrs
        packets: dict[str, PacketSummary] = {}
        for name in self.packets():
            g = self._f["telemetry"][name]
            n = self.n_frames(name)
            base = f"telemetry/{name}"
            if n:
                dev = self._dataset(f"{base}/device_time")
                host = self._dataset(f"{base}/host_time")
                ends = [0, n - 1] if n > 1 else [0]
                dev, host = self._read(f"{base}/device_time", ends), self._read(f"{base}/host_time", ends)
                fd, ld, fh, lh = float(dev[0]), float(dev[-1]), float(host[0]), float(host[-1])
            else:
                fd = ld = fh = lh = None
            idx, missing, dups = self._scan_sequence(name)
            span = (ld - fd) if n > 1 else 0.0
            packets[name] = PacketSummary(
                name=name, id=int(g.attrs.get("id", 0)), description=_text(g.attrs.get("description", "")),
                nominal_rate_hz=float(g.attrs.get("rate_hz", 0.0)), frames=n,
                first_device_time=fd, last_device_time=ld, first_host_time=fh, last_host_time=lh,
                drops=int(missing.sum()), gaps=len(idx), duplicates=dups,
                rate_hz=(n - 1) / span if span > 0 else 0.0)
        created_utc = _text(a.get("created_utc", ""))
        created = _utc_seconds(created_utc)
        clean = bool(a.get("clean_close", False))
        stop_utc = _text(a.get("stop_utc", "")) if clean else ""
        stop = _utc_seconds(stop_utc) if stop_utc else None
        if stop is None:      # not closed: the last frame (or journal record) says when it ended
            lasts = [p.last_host_time for p in packets.values() if p.last_host_time is not None]
            if not lasts:
                jt = self._dataset("journal/time")
                lasts = [float(jt[jt.shape[0] - 1])] if jt.shape[0] else []
            stop = max(lasts) if lasts else (created or 0.0)
            stop_utc = datetime.fromtimestamp(stop, timezone.utc).isoformat()
        if created is None:
            firsts = [p.first_host_time for p in packets.values() if p.first_host_time is not None]
            created = min(firsts) if firsts else stop
        return LogInfo(
            path=self.path, schema_version=self.schema_version, uuid=_text(a.get("uuid", "")),
            test_name=_text(a.get("test_name", "")), run=int(a.get("run", 0)),
            notes=_text(a.get("notes", "")), created_utc=created_utc, created=created,
            stop_utc=stop_utc, stop=stop, clean_close=clean,
            software_version=_text(a.get("software_version", "")), host=_text(a.get("host", "")),
            user=_text(a.get("user", "")), protocol_version=_text(a.get("protocol_version", "")),
            dictionary_hash=_text(a.get("dictionary_hash", "")),
            tick_rate_hz=float(a.get("tick_rate_hz", 1200.0)), packets=packets)

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
