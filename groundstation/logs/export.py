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
"""

from __future__ import annotations

import re
from pathlib import Path
from typing import Iterable

import numpy as np

from .reader import Channel, EmptyRangeError, LogError, LogQueryError, LogReader

_FLOAT_FMT = "%.17g"
MATLAB_NAME_MAX = 63


class ExportError(LogError):
    """An export could not be written (bad name, unwritable path, ...)."""


def _columns(reader: LogReader, packet: str, channels: str | Iterable[str] | None) -> list[Channel]:
    chans = reader.resolve_channels(packet, channels)
    return [c for c in chans if c.name not in ("device_time", "host_time")]


def _rows(reader: LogReader, packet: str, start, stop, timebase: str, relative: bool) -> tuple[int, int]:
    i0, i1 = reader.index_range(packet, start, stop, timebase, relative=relative)
    if i1 <= i0:
        raise EmptyRangeError(f"{reader.path}: no {packet} frames in "
                              f"{reader.describe_range(packet, start, stop, timebase, relative)}")
    return i0, i1


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
               raw: bool = False, chunk_rows: int = 65536) -> int:
    """Write `channels` of `packet` for [start, stop] (timebase seconds) to a CSV file;
    returns the number of rows.  raw=True writes wire counts for converted items."""
    chans = _columns(reader, packet, channels)
    i0, i1 = _rows(reader, packet, start, stop, timebase, relative)
    path = Path(path)
    header = ["device_time [s]", "host_time [s]"] + [
        _header_name(c.name, "counts" if raw and c.has_raw else c.units) for c in chans]
    names = [c.name for c in chans]
    written = 0
    try:
        with open(path, "w", encoding="utf-8", newline="") as fh:
            fh.write(",".join(header) + "\n")
            for a in range(i0, i1, chunk_rows):
                data = reader.read_rows(packet, names, a, min(i1, a + chunk_rows), raw=raw)
                cols = [data["device_time"], data["host_time"]] + [data[n] for n in names]
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
    except OSError as exc:
        raise ExportError(f"cannot write {path}: {exc.strerror or exc}") from None
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
               raw: bool = False) -> int:
    """Write `channels` of `packet` for [start, stop] to a MATLAB .mat file (one struct
    named after the packet); returns the number of rows."""
    import scipy.io

    chans = _columns(reader, packet, channels)
    i0, i1 = _rows(reader, packet, start, stop, timebase, relative)
    data = reader.read_rows(packet, [c.name for c in chans], i0, i1, raw=raw)
    fields: dict[str, str] = {}                  # matlab name -> channel name
    for name in ["device_time", "host_time"] + [c.name for c in chans]:
        m = matlab_name(name)
        if m in fields and fields[m] != name:
            raise ExportError(f"channels '{fields[m]}' and '{name}' both become the MATLAB "
                              f"name '{m}'; export them separately")
        fields[m] = name
    units = {"device_time": "s", "host_time": "s"}
    descr = {"device_time": "device tick / tick rate: device time since boot",
             "host_time": "host arrival time, seconds since the Unix epoch"}
    for c in chans:
        units[c.name] = "counts" if raw and c.has_raw else c.units
        descr[c.name] = c.description
    struct: dict[str, object] = {m: data[name] for m, name in fields.items()}
    struct["units"] = {m: units[name] for m, name in fields.items()}
    struct["description"] = {m: descr[name] for m, name in fields.items()}
    info = reader.info
    log_info = {"file": str(reader.path), "packet": packet, "test_name": info.test_name,
                "run": info.run, "created_utc": info.created_utc,
                "protocol_version": info.protocol_version,
                "dictionary_hash": info.dictionary_hash, "timebase": timebase,
                "start": np.nan if start is None else float(start),
                "stop": np.nan if stop is None else float(stop), "relative": int(relative),
                "raw_counts": int(raw)}
    try:
        scipy.io.savemat(str(path), {matlab_name(packet): struct, "log_info": log_info},
                         do_compression=True, oned_as="column", long_field_names=True)
    except OSError as exc:
        raise ExportError(f"cannot write {path}: {exc.strerror or exc}") from None
    return i1 - i0


__all__ = ["ExportError", "LogQueryError", "export_csv", "export_mat", "matlab_name"]
