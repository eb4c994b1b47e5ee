"""Writing what the Analysis dock shows to files: a table's rows as CSV or JSON, a
rendered image's bytes.  No Qt here - the dock hands over plain rows (or PNG bytes) and
a path; what cannot be written is an ExportError that says which file and why.

A row is a dict keyed by the table's column keys, the values as the analysis gave them
(numbers at full precision, None where there is none).  CSV writes None as an empty
cell; JSON writes it as null and a non-finite float as null too (JSON has no NaN).
"""

from __future__ import annotations

import csv
import io
import json
import math
from pathlib import Path
from typing import Any, Iterable, Sequence

from ...core.errors import GroundStationError

FORMATS = ("csv", "json")


class ExportError(GroundStationError):
    """A file of the Analysis dock cannot be written (the message names it and why)."""


def _json_value(v: Any) -> Any:
    if isinstance(v, float) and not math.isfinite(v):
        return None
    if isinstance(v, Path):
        return str(v)
    return v


def rows_csv(keys: Sequence[str], rows: Iterable[dict[str, Any]]) -> str:
    """The rows as CSV text, a header of `keys` first."""
    out = io.StringIO()
    w = csv.DictWriter(out, fieldnames=list(keys), lineterminator="\n", extrasaction="ignore")
    w.writeheader()
    for row in rows:
        w.writerow({k: "" if row.get(k) is None else row.get(k) for k in keys})
    return out.getvalue()


def rows_json(keys: Sequence[str], rows: Iterable[dict[str, Any]]) -> str:
    """The rows as a JSON list of records (keys in the table's order)."""
    records = [{k: _json_value(row.get(k)) for k in keys} for row in rows]
    return json.dumps(records, indent=2, allow_nan=False) + "\n"


def format_of(path: str | Path) -> str:
    """'csv' or 'json' from the file's suffix; ExportError for another."""
    suffix = Path(path).suffix.lower().lstrip(".")
    if suffix not in FORMATS:
        raise ExportError(f"{Path(path).name}: a table is written as .csv or .json, not "
                          f"{('.' + suffix) if suffix else 'a file without a suffix'}")
    return suffix


def write_rows(path: str | Path, keys: Sequence[str], rows: Iterable[dict[str, Any]],
               fmt: str | None = None) -> Path:
    """The rows to `path` as CSV or JSON (`fmt`; None: from the suffix)."""
    fmt = fmt or format_of(path)
    if fmt not in FORMATS:
        raise ExportError(f"unknown table format {fmt!r}: {' or '.join(FORMATS)}")
    text = rows_csv(keys, rows) if fmt == "csv" else rows_json(keys, rows)
    return write_bytes(path, text.encode("utf-8"))


def write_bytes(path: str | Path, data: bytes) -> Path:
    """`data` to `path` (replacing it); ExportError with the system's reason on failure."""
    path = Path(path)
    try:
        path.write_bytes(data)
    except OSError as exc:
        reason = exc.strerror or type(exc).__name__
        raise ExportError(f"cannot write {path}: {reason}") from None
    return path


__all__ = ["ExportError", "FORMATS", "format_of", "rows_csv", "rows_json", "write_bytes",
           "write_rows"]
