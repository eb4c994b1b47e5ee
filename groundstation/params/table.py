"""The controller's parameter table as bytes (SPEC.md, "Parameter upload").

Entries of protocol/parameters.toml in id order, each packed big-endian with its type
and shape, no padding.  Both sides use this module: the host to build and verify a
table, the simulated device to validate and activate one.
"""

from __future__ import annotations

import zlib
from typing import Any, Mapping

import numpy as np

from ..core.dictionary import Dictionary, ParameterDef
from ..core.errors import GroundStationError


class ParameterError(GroundStationError):
    """A parameter value is missing, unknown, non-finite or out of range."""


def table_dtype(dictionary: Dictionary) -> np.dtype:
    return np.dtype([(p.name, p.dtype, p.shape) for p in dictionary.parameters])


def table_size(dictionary: Dictionary) -> int:
    return table_dtype(dictionary).itemsize


def default_values(dictionary: Dictionary) -> dict[str, Any]:
    return {p.name: p.default for p in dictionary.parameters}


def problems(dictionary: Dictionary, values: Mapping[str, Any]) -> list[str]:
    """Every reason the table would be refused (empty list: acceptable)."""
    out = []
    names = {p.name for p in dictionary.parameters}
    for extra in sorted(set(values) - names):
        out.append(f"unknown parameter '{extra}'")
    for p in dictionary.parameters:
        if p.name not in values:
            out.append(f"'{p.name}' has no value")
            continue
        v = np.asarray(values[p.name], dtype=np.float64)
        if v.shape != p.shape:
            out.append(f"'{p.name}' has shape {v.shape}, expected {p.shape}")
            continue
        lo, hi = p.value_range
        if p.dtype.kind == "f":
            # compare at the table's precision: 81.3 stored as f32 is 81.30000305, and
            # must still count as within a range that ends at 81.3
            native = p.dtype.newbyteorder("=")
            v, lo, hi = v.astype(native), native.type(lo), native.type(hi)
        if not np.all(np.isfinite(v)):
            out.append(f"'{p.name}' is not finite")
        elif np.any(v < lo) or np.any(v > hi):
            out.append(f"'{p.name}' = {values[p.name]!r} {p.units} outside "
                       f"[{p.value_range[0]}, {p.value_range[1]}]")
        else:
            if p.filter == "sos":
                out += [f"'{p.name}' {msg}" for msg in sos_problems(v)]
    out += _slope_table_problems(values)
    return out


POLE_TOLERANCE = 1e-9


def sos_problems(sos: np.ndarray) -> list[str]:
    """Why a cascade of second-order sections may not run on the device.

    Each row is b0 b1 b2 a0 a1 a2 with a0 = 1; every pole must lie inside the unit circle
    except a pole at z = 1 exactly (an integrator, which the anti-windup handles)."""
    out = []
    for i, row in enumerate(np.asarray(sos, dtype=np.float64)):
        if row[3] != 1.0:
            out.append(f"section {i}: a0 = {row[3]!r}, must be 1 (normalised)")
            continue
        for pole in np.roots(row[3:]) if np.any(row[4:]) else []:
            if abs(pole) > 1.0 + POLE_TOLERANCE or (
                    abs(pole) > 1.0 - POLE_TOLERANCE and abs(pole - 1.0) > 1e-6):
                out.append(f"section {i}: pole at z = {complex(pole):.6g} "
                           f"(|z| = {abs(pole):.9f}) is not inside the unit circle")
    return out


def _slope_table_problems(values: Mapping[str, Any]) -> list[str]:
    """The compensation slope table: x from 0 to 2 strictly increasing, slope non-increasing."""
    if not {"friction_comp_table_points", "friction_comp_table_x",
            "friction_comp_table_slope"} <= set(values):
        return []
    n = int(values["friction_comp_table_points"])
    x = np.asarray(values["friction_comp_table_x"], dtype=np.float64)[:n]
    y = np.asarray(values["friction_comp_table_slope"], dtype=np.float64)[:n]
    out = []
    if len(x) < 2 or x[0] != 0.0 or abs(x[-1] - 2.0) > 1e-6:
        out.append("friction_comp_table_x must run from 0 to 2 over the used points")
    if np.any(np.diff(x) <= 0):
        out.append("friction_comp_table_x must be strictly increasing")
    if np.any(np.diff(y) > 0):
        out.append("friction_comp_table_slope must not increase with x")
    if len(y) and not y[0] > 0:
        out.append("friction_comp_table_slope must be positive at x = 0")
    return out


def pack(dictionary: Dictionary, values: Mapping[str, Any]) -> bytes:
    bad = problems(dictionary, values)
    if bad:
        raise ParameterError("parameter table refused: " + "; ".join(bad))
    rec = np.zeros(1, table_dtype(dictionary))
    for p in dictionary.parameters:
        rec[p.name] = values[p.name]
    return rec.tobytes()


def unpack(dictionary: Dictionary, blob: bytes) -> dict[str, Any]:
    dt = table_dtype(dictionary)
    if len(blob) != dt.itemsize:
        raise ParameterError(f"parameter table of {len(blob)} bytes, this dictionary's table "
                             f"has {dt.itemsize}")
    rec = np.frombuffer(blob, dt)[0]
    return {p.name: _pyvalue(p, rec[p.name]) for p in dictionary.parameters}


def _pyvalue(p: ParameterDef, v):
    return v.tolist() if p.shape else v.item()


def table_crc(blob: bytes) -> int:
    return zlib.crc32(blob)
