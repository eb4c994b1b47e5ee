"""The batch's rows as a tidy table (one row per log, one column per key), written to
Parquet (pyarrow) and CSV with pandas.

    write_table(rows, "results/ibm")           # results/ibm.parquet and results/ibm.csv
    write_table(rows, "results/ibm.csv")        # CSV only (the suffix says which)

Column types are decided from the values' Python types, not left to pandas' guess: a
column of ints with a missing value would otherwise turn into floats (a seed of 3
written as 3.0), and a column's type would depend on which logs failed.  Nullable
pandas types (Int64, Float64, boolean, string) keep a missing value missing in both
files (null in Parquet, an empty cell in CSV).
"""

from __future__ import annotations

import numbers
from pathlib import Path
from typing import Any, Iterable

import numpy as np

from ..core.errors import GroundStationError

SUFFIXES = (".parquet", ".csv")
#: columns whose values are text even when every row left them empty
TEXT_KEYS = {"path", "log", "campaign", "test_name", "design", "base_motion", "profiles",
             "created_utc", "sensor", "step_effort_channel", "frf_input", "frf_output",
             "hyst_slope_table_file", "fv_torque_formula", "notes", "error", "invalid_reason",
             "mode_band_rule"}

#: whole numbers and flags, so typed even in a column no log filled (a batch of failures)
INTEGER_KEYS = {"bytes", "campaign_run", "run", "seed", "frames", "missing_frames",
                "samples_used", "samples_excluded", "segments", "psd_segments",
                "frf_coherent_bins", "hyst_branches", "hyst_complete_branches", "fv_segments",
                "fv_settled_segments", "highpass_samples_used", "highpass_samples_settling"}
FLAG_KEYS = {"clean_close", "hyst_slope_table", "valid", "mode_dominates"}


def table_paths(out: str | Path) -> list[Path]:
    """OUT.parquet and OUT.csv for OUT; only the one named by a .parquet or .csv suffix."""
    out = Path(out)
    if out.suffix.lower() in SUFFIXES:
        return [out]
    return [out.with_name(out.name + s) for s in SUFFIXES]


def _dtype(key: str, values: list[Any]) -> str:
    present = [v for v in values if v is not None]
    if not present:
        return ("string" if key in TEXT_KEYS else "Int64" if key in INTEGER_KEYS
                else "boolean" if key in FLAG_KEYS else "Float64")
    if all(isinstance(v, (bool, np.bool_)) for v in present):
        return "boolean"
    if all(isinstance(v, numbers.Integral) and not isinstance(v, bool) for v in present):
        return "Int64"
    if all(isinstance(v, numbers.Real) and not isinstance(v, bool) for v in present):
        return "Float64"
    return "string"


def rows_frame(rows: list[dict[str, Any]], columns: Iterable[str]):
    """The rows as a pandas DataFrame with `columns` in that order, typed as above."""
    import pandas as pd

    data = {}
    for key in columns:
        values = [row.get(key) for row in rows]
        dtype = _dtype(key, values)
        if dtype == "string":
            values = [None if v is None else str(v) for v in values]
        data[key] = pd.array(values, dtype=dtype)
    return pd.DataFrame(data)


def write_table(rows: list[dict[str, Any]], out: str | Path,
                columns: Iterable[str] | None = None) -> list[Path]:
    """Write the rows to the file(s) of table_paths(out), with `columns` (default: the
    batch's TABLE_KEYS); returns them.  Raises a GroundStationError when a file cannot
    be written (the message names it)."""
    from .batch import TABLE_KEYS

    frame = rows_frame(rows, list(TABLE_KEYS if columns is None else columns))
    written = []
    for path in table_paths(out):
        try:
            path.parent.mkdir(parents=True, exist_ok=True)
            if path.suffix.lower() == ".parquet":
                frame.to_parquet(path, engine="pyarrow", index=False)
            else:
                frame.to_csv(path, index=False)
        except OSError as exc:
            raise GroundStationError(f"cannot write the table {path}: {exc.strerror or exc}; "
                                     f"choose another --table path") from None
        written.append(path)
    return written


def read_table(path: str | Path):
    """A table written by write_table, back as a DataFrame (Parquet or CSV by suffix)."""
    import pandas as pd

    path = Path(path)
    if path.suffix.lower() == ".parquet":
        return pd.read_parquet(path, engine="pyarrow")
    return pd.read_csv(path, keep_default_na=False, na_values=[""])


__all__ = ["SUFFIXES", "read_table", "rows_frame", "table_paths", "write_table"]
