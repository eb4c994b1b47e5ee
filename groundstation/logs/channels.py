"""The columns of a recorded packet, described from the file itself.

Units, descriptions, conversions, states and limits are read from the datasets'
attributes (what the recorder wrote), never from the protocol files installed today, so
an old log explains itself even after the dictionary has changed.
"""

from __future__ import annotations

import json
from dataclasses import dataclass, field

import h5py
import numpy as np

from .opening import attr_text

HEADER_CHANNELS = ("sequence", "tick", "device_time", "host_time")


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


def convertible(conversion: dict | None) -> bool:
    return isinstance(conversion, dict) and (
        isinstance(conversion.get("polynomial"), list) or "scale" in conversion)


def to_engineering(raw: np.ndarray, conversion: dict) -> np.ndarray:
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


def packet_channels(g: h5py.Group, item_order: list[str]) -> list[Channel]:
    """Every column of the packet group `g`: header counters and times, items and flags
    in `item_order` (the recorded telemetry.toml's; unknown names after, by name), text
    items, then the raw counts (named raw/<item>)."""
    raw_group = g.get("raw")
    raw_names = set(raw_group.keys()) if isinstance(raw_group, h5py.Group) else set()
    order = {n: i for i, n in enumerate(item_order)}
    names = sorted((n for n in g.keys() if n != "raw"),
                   key=lambda n: (0, HEADER_CHANNELS.index(n), "") if n in HEADER_CHANNELS
                   else (1, order.get(n, len(order)), n))
    out: list[Channel] = []
    for name in names:
        obj = g[name]
        a = obj.attrs
        if isinstance(obj, h5py.Group):
            encoding = attr_text(a.get("encoding", "binary"))
            out.append(Channel(name, "", attr_text(a.get("description", "")), np.dtype(object),
                               "text", encoding=encoding))
            continue
        kind = ("header" if name in HEADER_CHANNELS
                else "flag" if obj.dtype == np.bool_ else "eng")
        conversion = json.loads(attr_text(a["conversion"])) if "conversion" in a else None
        has_raw = name in raw_names
        from_raw = (kind == "eng" and has_raw and convertible(conversion)
                    and obj.dtype.kind == "f" and obj.dtype.itemsize < 8)
        out.append(Channel(
            name, attr_text(a.get("units", "")), attr_text(a.get("description", "")),
            np.dtype(np.float64) if from_raw else obj.dtype, kind, conversion=conversion,
            states=json.loads(attr_text(a["states"])) if "states" in a else {},
            limits=json.loads(attr_text(a["limits"])) if "limits" in a else None,
            has_raw=has_raw, from_raw=from_raw))
    for ch in list(out):
        if ch.has_raw:
            ds = raw_group[ch.name]
            out.append(Channel(f"raw/{ch.name}", attr_text(ds.attrs.get("units", "counts")),
                               attr_text(ds.attrs.get("description", "")), ds.dtype, "raw"))
    return out


__all__ = ["Channel", "HEADER_CHANNELS", "convertible", "packet_channels", "to_engineering"]
