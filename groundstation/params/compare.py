"""Three tables side by side: the design (or edited) table, the last one uploaded from
here, and the one the device reports.  Used by `groundstation params show` and the GUI's
parameter panel; no Qt.

Values are compared as the wire carries them (after conversion to the entry's type), so
a design value that rounds to the same f32 as the device's is "same"."""

from __future__ import annotations

import zlib
from dataclasses import dataclass
from typing import Any, Mapping

import numpy as np

from ..core.dictionary import Dictionary, ParameterDef

SOURCES = ("design", "uploaded", "device")


@dataclass
class Row:
    name: str
    units: str
    value_range: tuple[float, float]
    description: str
    texts: dict[str, str]          # source -> value as text ("" where the source has no table)
    status: str                    # "same", "differs", or "partial" (fewer than two sources)
    differing: list[str]           # sources whose value differs from the device's (or the first)


def wire_value(p: ParameterDef, value: Any) -> np.ndarray:
    return np.asarray(value, dtype=p.dtype).reshape(p.shape)


def value_text(p: ParameterDef, value: Any) -> str:
    """Short text for one entry.  Arrays show a size and a short CRC of their wire bytes,
    so two arrays that differ anywhere read differently."""
    v = wire_value(p, value)
    if p.filter == "sos":
        used = sum(1 for r in np.asarray(v, dtype=float) if not np.array_equal(r, IDENTITY_ROW))
        return f"{used} section(s) #{_short_crc(v)}"
    if v.shape:
        return f"{v.size} values #{_short_crc(v)}"
    if np.issubdtype(v.dtype, np.integer):
        return str(int(v))
    return f"{float(v):.7g}"


IDENTITY_ROW = (1.0, 0.0, 0.0, 1.0, 0.0, 0.0)


def _short_crc(v: np.ndarray) -> str:
    return f"{zlib.crc32(v.tobytes()) & 0xFFFF:04x}"


def three_way(dictionary: Dictionary, tables: Mapping[str, Mapping[str, Any] | None]) -> list[Row]:
    """One row per parameter; `tables` maps a source name (SOURCES) to its values or None."""
    present = [s for s in SOURCES if tables.get(s) is not None]
    rows = []
    for p in dictionary.parameters:
        wire = {s: wire_value(p, tables[s][p.name]) for s in present if p.name in tables[s]}
        texts = {s: (value_text(p, tables[s][p.name]) if s in wire else "") for s in SOURCES}
        reference = "device" if "device" in wire else (next(iter(wire)) if wire else None)
        differing = [s for s in wire if s != reference
                     and wire[s].tobytes() != wire[reference].tobytes()]
        status = "partial" if len(wire) < 2 else ("differs" if differing else "same")
        rows.append(Row(p.name, p.units, p.value_range, p.description, texts, status, differing))
    return rows


def format_rows(rows: list[Row], only_differences: bool = False) -> str:
    """A plain-text table for a terminal."""
    shown = [r for r in rows if not only_differences or r.status == "differs"]
    head = ("parameter", "design", "uploaded", "device", "units", "")
    lines = [head] + [(r.name, r.texts["design"], r.texts["uploaded"], r.texts["device"], r.units,
                       "DIFFERS: " + ", ".join(r.differing) if r.differing else "") for r in shown]
    widths = [max(len(line[i]) for line in lines) for i in range(len(head))]
    return "\n".join("  ".join(cell.ljust(w) for cell, w in zip(line, widths)).rstrip()
                     for line in lines)
