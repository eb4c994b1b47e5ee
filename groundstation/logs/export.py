"""Export a range of channels of a log to CSV or to MATLAB .mat.

CSV: one wide file per packet, one row per frame, timestamp-aligned: device_time and
host_time first, then the channels, under a single header line that carries the units
(`encoder_outer [rad]`).  Floats are written with 17 significant digits, so every
value reads back bit-exact; integers and flags as integers.  The rows are written in
pieces (`chunk_rows`), so an hour of telemetry never sits in memory as text.

MAT: `scipy.io.savemat` (format 5, compressed) with one struct named after the packet:
one field per channel (column vectors), device_time, host_time, and structs `units` and
`description` with the same field names; plus a `log_info` struct saying where the data
came from.  Names are made MATLAB-valid (anything but letters, digits and _ becomes _).

With `relative=True` (--from/--to counted from the log's start) both also carry
`time_from_start` first: the chosen timebase's time minus the log's origin (the zero of
those bounds), so the exported times match the bounds asked for; device_time and
host_time stay absolute for tracing the rows back to the log.

Both are written to a temporary file beside the target and renamed when complete, so a
failure never leaves a partial file (`atomic.py`).  A damaged log raises LogDamagedError
(an error of the input, not of the output); with `salvage=True` the rows before the
first unreadable one are exported instead, and `export()` says where the damage begins.
"""

from __future__ import annotations

import re
from dataclasses import dataclass
from pathlib import Path
from typing import Iterable

import numpy as np

from .atomic import atomic_output
from .reader import LogReader
from .channels import Channel
from .opening import LogDamagedError, LogQueryError, truncation_text
from .opening import EmptyRangeError, LogError

_FLOAT_FMT = "%.17g"
MATLAB_NAME_MAX = 63


class ExportError(LogError):
    """An export could not be written (bad name, unwritable path, ...)."""


def _columns(reader: LogReader, packet: str, channels: str | Iterable[str] | None) -> list[Channel]:
    chans = reader.resolve_channels(packet, channels)
    return [c for c in chans if c.name not in ("device_time", "host_time")]


@dataclass(frozen=True)
class ExportResult:
    """What an export wrote: `rows` rows of `packet` to `path`.  After a salvage,
    `damage` says where the unreadable part begins ('' when the range read whole) and
    `wanted` is how many rows the range holds in the file, readable or not."""

    path: Path
    packet: str
    rows: int
    wanted: int
    damage: str = ""


def _rows(reader: LogReader, packet: str, start, stop, timebase: str, relative: bool,
          limit: int | None = None) -> tuple[int, int]:
    i0, i1 = reader.index_range(packet, start, stop, timebase, relative=relative, limit=limit)
    if i1 <= i0:
        raise EmptyRangeError(f"{reader.path}: no {packet} frames in "
                              f"{reader.describe_range(packet, start, stop, timebase, relative)}")
    return i0, i1


def _needed(packet: str, chans: list[Channel], raw: bool) -> tuple[list[str], list[str]]:
    """Datasets an export of `chans` reads: per-row ones, and byte streams (text items)."""
    base = f"telemetry/{packet}"
    rows = [f"{base}/device_time", f"{base}/host_time"]
    streams = []
    for c in chans:
        if c.kind == "text":
            streams.append(f"{base}/{c.name}")
        elif (raw and c.has_raw) or c.from_raw:
            rows.append(f"{base}/raw/{c.name}")
        else:
            rows.append(f"{base}/{c.name}")
    return rows, streams


def readable_limit(reader: LogReader, packet: str, chans: list[Channel], raw: bool = False) -> tuple[int, str]:
    """(k, what): the first k rows of `packet` read in every column `chans` need; `what`
    names the first unreadable dataset ('' when all rows read)."""
    limit = reader.n_frames(packet)
    what = ""
    rows, streams = _needed(packet, chans, raw)
    for path in rows + [f"{s}/{c}" for s in streams for c in ("offset", "length")]:
        k, err = reader.readable_rows(path, 0, limit)
        if k < limit:
            limit, what = k, f"dataset /{path} unreadable after frame {k} ({err})"
    for s in streams:           # records whose bytes lie in the readable part of the stream
        if not limit:
            break
        nbytes, err = reader.readable_rows(f"{s}/data")
        ends = (reader._read(f"{s}/offset", slice(0, limit)).astype(np.int64)
                + reader._read(f"{s}/length", slice(0, limit)).astype(np.int64))
        bad = np.flatnonzero(ends > nbytes)
        if len(bad) and bad[0] < limit:
            limit = int(bad[0])
            what = f"dataset /{s}/data unreadable after byte {nbytes} ({err}), frame {limit}"
    return limit, what


def _plan(reader: LogReader, packet: str, channels, start, stop, timebase: str, relative: bool,
          raw: bool, salvage: bool) -> tuple[list[Channel], int, int, int, str]:
    """(channels, i0, i1, rows the range holds, damage) of an export."""
    chans = _columns(reader, packet, channels)
    if not salvage:
        i0, i1 = _rows(reader, packet, start, stop, timebase, relative)
        return chans, i0, i1, i1 - i0, ""
    limit, what = readable_limit(reader, packet, chans, raw)
    n = reader.n_frames(packet)
    if limit == n:
        i0, i1 = _rows(reader, packet, start, stop, timebase, relative)
        return chans, i0, i1, i1 - i0, ""
    if limit == 0:
        # other packets or the journal may still read: say where to look, not "nothing"
        cut = f"; the file is {truncation_text(*reader.truncated)}" if reader.truncated else ""
        raise LogDamagedError(
            reader.path, f"no {packet} frame is readable: {what}{cut}", salvageable=False,
            advice=(f"`groundstation log check {reader.path}` says which packets still have "
                    f"readable frames (export one of them with --packet NAME)"))
    last = float(reader.read_rows(packet, [], limit - 1, limit)["device_time"][0])
    damage = (f"the log is damaged after {packet} frame {limit} of {n} (device time "
              f"{last:.4f} s): {what}")
    # the range is searched among the readable rows only (a search must not touch the rest)
    i0, i1 = reader.index_range(packet, start, stop, timebase, relative=relative, limit=limit)
    if i1 <= i0:
        raise EmptyRangeError(f"{reader.path}: no readable {packet} frames in the range asked; "
                              f"{damage}")
    if i1 < limit:              # the range ends before the damage
        return chans, i0, i1, i1 - i0, ""
    return chans, i0, i1, -1, damage


def _header_name(name: str, units: str) -> str:
    return f"{name} [{units}]" if units else name


def _csv_text(values: np.ndarray) -> np.ndarray:
    """Text/bytes cells, quoted for CSV (bytes as hex)."""
    out = np.empty(len(values), dtype=object)
    out[:] = ['"' + (v.hex() if isinstance(v, bytes) else str(v)).replace('"', '""') + '"'
              for v in values]
    return out


def export_csv(reader: LogReader, path: str | Path, packet: str,
               channels: str | Iterable[str] | None = None, start: float | None = None,
               stop: float | None = None, timebase: str = "device", *, relative: bool = False,
               raw: bool = False, chunk_rows: int = 65536, salvage: bool = False) -> int:
    """Write `channels` of `packet` for [start, stop] (timebase seconds) to a CSV file;
    returns the number of rows.  raw=True writes wire counts for converted items;
    salvage=True writes the rows before the first unreadable one of a damaged log."""
    return export(reader, path, packet, "csv", channels, start, stop, timebase, relative=relative,
                  raw=raw, chunk_rows=chunk_rows, salvage=salvage).rows


def _write_csv(reader: LogReader, path: Path, packet: str, chans: list[Channel], i0: int, i1: int,
               raw: bool, chunk_rows: int, timebase: str = "device",
               zero: float | None = None) -> int:
    """`zero`: the log's origin in `timebase` when the range is relative - a first
    column time_from_start is then written."""
    header = (["time_from_start [s]"] if zero is not None else []) + [
        "device_time [s]", "host_time [s]"] + [
        _header_name(c.name, "counts" if raw and c.has_raw else c.units) for c in chans]
    names = [c.name for c in chans]
    written = 0
    with atomic_output(path, ExportError) as tmp:
        with open(tmp, "w", encoding="utf-8", newline="") as fh:
            fh.write(",".join(header) + "\n")
            for a in range(i0, i1, chunk_rows):
                data = reader.read_rows(packet, names, a, min(i1, a + chunk_rows), raw=raw)
                cols = [data["device_time"], data["host_time"]] + [data[n] for n in names]
                if zero is not None:
                    cols.insert(0, data[f"{timebase}_time"] - zero)
                m = len(cols[0])
                if not m:
                    break
                cols = [_csv_text(c) if c.dtype == object else c for c in cols]
                fmt = [_FLOAT_FMT if c.dtype.kind == "f" else "%s" if c.dtype == object else "%d"
                       for c in cols]
                table = np.empty(m, dtype=[(f"c{k}", c.dtype) for k, c in enumerate(cols)])
                for k, c in enumerate(cols):
                    table[f"c{k}"] = c
                np.savetxt(fh, table, fmt=fmt, delimiter=",")
                written += m
    return written


def matlab_name(name: str) -> str:
    """A MATLAB-valid variable/field name: [A-Za-z][A-Za-z0-9_]*, at most 63 characters."""
    out = re.sub(r"[^A-Za-z0-9_]", "_", name)
    if not out or not out[0].isalpha():
        out = "x" + out
    return out[:MATLAB_NAME_MAX]


def export_mat(reader: LogReader, path: str | Path, packet: str,
               channels: str | Iterable[str] | None = None, start: float | None = None,
               stop: float | None = None, timebase: str = "device", *, relative: bool = False,
               raw: bool = False, salvage: bool = False) -> int:
    """Write `channels` of `packet` for [start, stop] to a MATLAB .mat file (one struct
    named after the packet); returns the number of rows.  salvage=True: as export_csv."""
    return export(reader, path, packet, "mat", channels, start, stop, timebase, relative=relative,
                  raw=raw, salvage=salvage).rows


def export(reader: LogReader, path: str | Path, packet: str, fmt: str = "csv",
           channels: str | Iterable[str] | None = None, start: float | None = None,
           stop: float | None = None, timebase: str = "device", *, relative: bool = False,
           raw: bool = False, chunk_rows: int = 65536, salvage: bool = False) -> ExportResult:
    """export_csv / export_mat (fmt 'csv' or 'mat') with a full account of what was
    written, including where a salvaged export stopped."""
    if fmt not in ("csv", "mat"):
        raise ExportError(f"export format must be 'csv' or 'mat', not {fmt!r}")
    path = Path(path)
    chans, i0, i1, wanted, damage = _plan(reader, packet, channels, start, stop, timebase,
                                          relative, raw, salvage)
    zero = reader.origin(timebase) if relative else None
    if fmt == "csv":
        rows = _write_csv(reader, path, packet, chans, i0, i1, raw, chunk_rows,
                          timebase, zero)
    else:
        rows = _write_mat(reader, path, packet, chans, i0, i1, raw, start, stop, timebase,
                          relative)
    return ExportResult(path, packet, rows, rows if wanted < 0 else wanted, damage)


def _log_info(reader: LogReader) -> dict[str, object]:
    """Where the data came from, from the root attributes (not the full summary, which
    would read every sequence column - and part of a damaged log cannot be read)."""
    a = reader.attrs
    return {k: a.get(k, "") for k in ("test_name", "run", "created_utc", "protocol_version",
                                       "dictionary_hash")}


def _write_mat(reader: LogReader, path: Path, packet: str, chans: list[Channel], i0: int, i1: int,
               raw: bool, start, stop, timebase: str, relative: bool) -> int:
    import scipy.io

    data = reader.read_rows(packet, [c.name for c in chans], i0, i1, raw=raw)
    fields: dict[str, str] = {}                  # matlab name -> channel name
    times = ["device_time", "host_time"]
    if relative:            # the times the --from/--to bounds were given in (see above)
        data["time_from_start"] = data[f"{timebase}_time"] - reader.origin(timebase)
        times.insert(0, "time_from_start")
    for name in times + [c.name for c in chans]:
        m = matlab_name(name)
        if m in fields and fields[m] != name:
            raise ExportError(f"channels '{fields[m]}' and '{name}' both become the MATLAB "
                              f"name '{m}'; export them separately")
        fields[m] = name
    units = {"device_time": "s", "host_time": "s", "time_from_start": "s"}
    descr = {"device_time": "device tick / tick rate: device time since boot",
             "host_time": "host arrival time, seconds since the Unix epoch",
             "time_from_start": f"{timebase} time from the log's start (the zero of a "
                                f"relative --from/--to)"}
    for c in chans:
        units[c.name] = "counts" if raw and c.has_raw else c.units
        descr[c.name] = c.description
    struct: dict[str, object] = {m: data[name] for m, name in fields.items()}
    struct["units"] = {m: units[name] for m, name in fields.items()}
    struct["description"] = {m: descr[name] for m, name in fields.items()}
    log_info = {"file": str(reader.path), "packet": packet, **_log_info(reader), "timebase": timebase,
                "start": np.nan if start is None else float(start),
                "stop": np.nan if stop is None else float(stop), "relative": int(relative),
                "raw_counts": int(raw)}
    with atomic_output(path, ExportError) as tmp, open(tmp, "wb") as fh:
        scipy.io.savemat(fh, {matlab_name(packet): struct, "log_info": log_info},
                         do_compression=True, oned_as="column", long_field_names=True)
    return len(data["device_time"])


__all__ = ["ExportError", "ExportResult", "export", "export_csv", "export_mat", "matlab_name",
           "readable_limit"]
