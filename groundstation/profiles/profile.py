"""Profiles: what a profile file says, the samples it makes, and whether the device may
play them.

A profile file is TOML with two tables (see profiles/waveforms/README.md):

    [profile]
    name = "friction_triangle_0p05deg"
    target = "REFERENCE"        # REFERENCE | RATE_REFERENCE | CURRENT_COARSE | CURRENT_FINE
    units = "rad"               # the target's units (rad, rad/s, A): what the samples are in
    description = "..."
    origin = "relative"         # REFERENCE only: offsets from the held position (default)
    duration_s = 410.0          # total length; motions may leave it out (held at the end)
    ramp_s = 1.0                # tapers in/out; default blend/rise time of motions

    [generator]
    type = "triangle"           # step ramp triangle constant_velocity sine swept_sine
                                # noise prbs multisine csv
    amplitude_deg = 0.05        # quantities carry their unit in the key
    velocity_deg_per_s = 0.001

Quantities of the target's kind take a unit suffix: angles rad, mrad, urad, deg, arcsec;
rates <angle>_per_s; currents a, ma; their slopes <unit>_per_s (<angle>_per_s2 for a rate
reference).  Times end in _s, frequencies in _hz.

The samples are float32 (what the device receives).  Errors name the file and the field.

This module reads profile files; the Profile itself and its targets are in samples.py, the
device's checks in checks.py, previews and summaries in summary.py.
"""

from __future__ import annotations

import csv
import math
from dataclasses import dataclass
from pathlib import Path
from typing import Any, Callable

import numpy as np

from ..core.kinds import ProfileOrigin
from ..core.dictionary import Dictionary
from ..core.tomlfile import read_toml
from . import waveforms as gen
from .checks import check_profile
from .samples import (_CSV_UNITS, DEFAULT_GYRO_RANGE, RATE_HZ, TARGETS, Profile, ProfileFileError,
                      TargetInfo)

__all__ = ["WAVEFORMS_DIR", "load_profile", "profile_from_dict"]

WAVEFORMS_DIR = Path(__file__).resolve().parent.parent.parent / "profiles" / "waveforms"


# ----------------------------------------------------------------------------- file format
_REQUIRED = object()

# generator type -> {parameter: (kind, default)}; kinds: value / slope (target quantity
# with a unit suffix), time / hz (the key is the name, unit in it), int, float, str, bool.
# A default of "ramp_s" means: the profile's ramp_s if the file gives one, else the number.
_SPECS: dict[str, dict[str, tuple[str, Any]]] = {
    "step": {"level": ("value", _REQUIRED), "t_step_s": ("time", 0.5),
             "rise_s": ("time", ("ramp_s", 0.05)), "shape": ("str", "raised_cosine"),
             "return_at_s": ("time", None)},
    "ramp": {"level": ("value", _REQUIRED), "ramp_time_s": ("time", _REQUIRED),
             "hold_s": ("time", 0.0), "t_start_s": ("time", 0.0), "back": ("bool", True),
             "blend_s": ("time", ("ramp_s", 0.1))},
    "triangle": {"amplitude": ("value", _REQUIRED), "velocity": ("slope", _REQUIRED),
                 "cycles": ("int", 1), "turnaround_s": ("time", ("ramp_s", 0.5))},
    "constant_velocity": {"velocity": ("slope", _REQUIRED), "stroke": ("value", _REQUIRED),
                          "accel_s": ("time", ("ramp_s", 0.2)), "dwell_s": ("time", 0.5),
                          "cycles": ("int", 1), "lead_s": ("time", 0.0)},
    "sine": {"amplitude": ("value", _REQUIRED), "frequency_hz": ("hz", _REQUIRED)},
    "swept_sine": {"amplitude": ("value", _REQUIRED), "f_start_hz": ("hz", _REQUIRED),
                   "f_stop_hz": ("hz", _REQUIRED), "method": ("str", "logarithmic")},
    "noise": {"rms": ("value", _REQUIRED), "f_low_hz": ("hz", _REQUIRED),
              "f_high_hz": ("hz", _REQUIRED), "seed": ("int", 0), "method": ("str", "fft"),
              "order": ("int", 4), "peak_limit": ("value", None)},
    "prbs": {"amplitude": ("value", _REQUIRED), "bits": ("int", _REQUIRED),
             "samples_per_bit": ("int", 1), "periods": ("int", 1), "seed": ("int", 0)},
    "multisine": {"rms": ("value", _REQUIRED), "f_low_hz": ("hz", _REQUIRED),
                  "f_high_hz": ("hz", _REQUIRED), "n_freqs": ("int", 20),
                  "period_s": ("time", 10.0), "periods": ("int", 1), "spacing": ("str", "log"),
                  "phases": ("str", "low_crest"), "seed": ("int", 0)},
    "csv": {"file": ("str", _REQUIRED), "column": ("column", None), "time_column": ("str", None),
            "value_units": ("str", None), "scale": ("float", 1.0)},
}
#: generators whose length follows from their parameters (duration_s optional: a longer
#: one holds the last value, a shorter one is an error)
_INTRINSIC = {"ramp", "triangle", "constant_velocity", "prbs", "multisine", "csv"}
#: generators tapered over ramp_s (default 1 s; csv: 0, the data as they are)
_TAPERED = {"sine": 1.0, "swept_sine": 1.0, "noise": 1.0, "prbs": 0.5, "multisine": 1.0, "csv": 0.0}
_PROFILE_KEYS = {"name", "target", "units", "description", "origin", "duration_s", "ramp_s"}


def _fail(where: str, text: str) -> ProfileFileError:
    return ProfileFileError(f"{where}: {text}")


def _number(where: str, key: str, value: Any, kind: str = "float") -> Any:
    if isinstance(value, bool) or not isinstance(value, (int, float)):
        raise _fail(where, f"{key} must be a number, not {value!r}")
    if kind == "int":
        if isinstance(value, float) and not value.is_integer():
            raise _fail(where, f"{key} must be a whole number, not {value!r}")
        return int(value)
    if not math.isfinite(value):
        raise _fail(where, f"{key} must be a finite number, not {value!r}")
    return float(value)


def _generator_kwargs(gtable: dict, gtype: str, info: TargetInfo, ramp_s: float | None,
                      where: str) -> dict[str, Any]:
    """The [generator] table -> keyword arguments in the target's units."""
    spec = _SPECS[gtype]
    used = {"type"}
    out: dict[str, Any] = {}
    for name, (kind, default) in spec.items():
        if kind in ("value", "slope"):
            units = info.value_units if kind == "value" else info.slope_units
            keys = [k for k in gtable if k.startswith(name + "_") and k[len(name) + 1:] in units]
            if len(keys) > 1:
                raise _fail(where, f"{' and '.join(keys)} both give {name}: keep one")
            if not keys:
                wrong = [k for k in gtable if k.startswith(name + "_")
                         and k[len(name) + 1:] not in units and k not in spec]
                if wrong:
                    raise _fail(where, f"{wrong[0]}: {wrong[0][len(name) + 1:]!r} is not a unit "
                                       f"of a {info.name} profile's {name} ({', '.join(units)})")
                if default is _REQUIRED:
                    example = f"{name}_{next(iter(units))}"
                    raise _fail(where, f"{name} is missing: give it with its unit, e.g. "
                                       f"{example} (units for a {info.name} profile: "
                                       f"{', '.join(units)})")
                out[name] = default
                continue
            key = keys[0]
            used.add(key)
            out[name] = _number(where, key, gtable[key]) * units[key[len(name) + 1:]]
            continue
        if name not in gtable:
            if default is _REQUIRED:
                raise _fail(where, f"{name} is missing")
            if isinstance(default, tuple):                  # ("ramp_s", fallback)
                default = ramp_s if ramp_s is not None else default[1]
            out[name] = default
            continue
        used.add(name)
        value = gtable[name]
        if kind in ("time", "hz", "float"):
            out[name] = _number(where, name, value)
        elif kind == "int":
            out[name] = _number(where, name, value, "int")
        elif kind == "bool":
            if not isinstance(value, bool):
                raise _fail(where, f"{name} must be true or false, not {value!r}")
            out[name] = value
        elif kind == "column":
            if isinstance(value, bool) or not isinstance(value, (str, int)):
                raise _fail(where, f"{name} must be a column name or a 0-based column number")
            out[name] = value
        else:
            if not isinstance(value, str):
                raise _fail(where, f"{name} must be a string, not {value!r}")
            out[name] = value
    unknown = [k for k in gtable if k not in used]
    if unknown:
        known = []
        for name, (kind, _) in spec.items():
            if kind == "value":
                known.append(f"{name}_<{'|'.join(info.value_units)}>")
            elif kind == "slope":
                known.append(f"{name}_<{'|'.join(info.slope_units)}>")
            else:
                known.append(name)
        raise _fail(where, f"unknown key{'s' if len(unknown) > 1 else ''} "
                           f"{', '.join(unknown)} for a {gtype} generator on {info.name} "
                           f"(known: {', '.join(known)})")
    return out


def _read_csv(path: Path, column: str | int | None, time_column: str | None,
              where: str) -> tuple[np.ndarray, np.ndarray | None]:
    """(values, times or None) from a CSV file with an optional header row; '#' comments."""
    try:
        text = path.read_text(encoding="utf-8")
    except FileNotFoundError:
        raise _fail(where, f"CSV file {path} not found") from None
    except OSError as exc:
        raise _fail(where, f"cannot read CSV file {path} ({exc.strerror})") from None
    rows = [r for r in csv.reader(line for line in text.splitlines()
                                  if line.strip() and not line.lstrip().startswith("#"))]
    if not rows:
        raise _fail(where, f"CSV file {path} has no data")
    header: list[str] | None = None
    try:
        [float(c) for c in rows[0]]
    except ValueError:
        header = [c.strip() for c in rows[0]]
        rows = rows[1:]
    width = len(header) if header else len(rows[0]) if rows else 0

    def index(col: str | int, what: str) -> int:
        if isinstance(col, int):
            if not 0 <= col < width:
                raise _fail(where, f"{what} {col} is not a column of {path.name} ({width} columns)")
            return col
        if header is None or col not in header:
            raise _fail(where, f"{what} {col!r} is not in {path.name}'s header "
                               f"({', '.join(header) if header else 'no header row'})")
        return header.index(col)

    t_idx = index(time_column, "time_column") if time_column is not None else None
    if column is None:
        v_idx = width - 1
        if t_idx == v_idx:
            raise _fail(where, "give column: the last column is the time column")
    else:
        v_idx = index(column, "column")
    data = np.empty((len(rows), 2))
    for i, row in enumerate(rows):
        if len(row) != width:
            raise _fail(where, f"{path.name} line {i + 1 + (header is not None)}: {len(row)} "
                               f"fields, expected {width}")
        try:
            data[i, 0] = float(row[v_idx])
            data[i, 1] = float(row[t_idx]) if t_idx is not None else 0.0
        except ValueError:
            raise _fail(where, f"{path.name} line {i + 1 + (header is not None)}: not a "
                               f"number in {row!r}") from None
    if not len(rows):
        raise _fail(where, f"CSV file {path} has a header but no data")
    return data[:, 0], (data[:, 1] if t_idx is not None else None)


@dataclass(frozen=True)
class _ProfileHeader:
    """The [profile] table of a profile document, checked."""

    name: str
    target: str
    info: TargetInfo
    description: str
    origin: str
    duration_s: float | None
    ramp_s: float | None


def _tables(doc: dict, src: str) -> tuple[dict, dict]:
    """The document's [profile] and [generator] tables; nothing else may be there."""
    ptable = doc.get("profile")
    gtable = doc.get("generator")
    if not isinstance(ptable, dict):
        raise _fail(src, "no [profile] table")
    if not isinstance(gtable, dict):
        raise _fail(src, "no [generator] table")
    for extra in doc:
        if extra not in ("profile", "generator"):
            raise _fail(src, f"unknown table [{extra}] (a profile file has [profile] and [generator])")
    return ptable, gtable


def _profile_header(ptable: dict, where: str) -> _ProfileHeader:
    unknown = [k for k in ptable if k not in _PROFILE_KEYS]
    if unknown:
        raise _fail(where, f"unknown key{'s' if len(unknown) > 1 else ''} {', '.join(unknown)} "
                           f"(known: {', '.join(sorted(_PROFILE_KEYS))})")
    for key in ("name", "target", "units"):
        if key not in ptable:
            raise _fail(where, f"{key} is missing")
        if not isinstance(ptable[key], str) or not ptable[key]:
            raise _fail(where, f"{key} must be a non-empty string")
    target = ptable["target"]
    if target not in TARGETS:
        raise _fail(where, f"target {target!r} is not one of {', '.join(TARGETS)}")
    info = TARGETS[target]
    if ptable["units"] != info.units:
        raise _fail(where, f"units = {ptable['units']!r}, but {target} samples are in "
                           f"{info.units!r} (put other units in the generator's keys, e.g. "
                           f"amplitude_{next(iter(info.value_units))})")
    description = ptable.get("description", "")
    if not isinstance(description, str):
        raise _fail(where, "description must be a string")
    origin = ptable.get("origin", "relative" if target == "REFERENCE" else "absolute")
    if origin not in (ProfileOrigin.ABSOLUTE, ProfileOrigin.RELATIVE):
        raise _fail(where, f"origin must be 'absolute' or 'relative', not {origin!r}")
    if origin == ProfileOrigin.RELATIVE and target != "REFERENCE":
        raise _fail(where, f"origin = 'relative' applies to REFERENCE profiles only: {target} "
                           f"starts from 0 after ARM")
    duration_s = _number(where, "duration_s", ptable["duration_s"]) if "duration_s" in ptable else None
    ramp_s = _number(where, "ramp_s", ptable["ramp_s"]) if "ramp_s" in ptable else None
    if ramp_s is not None and ramp_s < 0:
        raise _fail(where, f"ramp_s must be ≥ 0, not {ramp_s}")
    if duration_s is not None and duration_s <= 0:
        raise _fail(where, f"duration_s must be > 0, not {duration_s}")
    return _ProfileHeader(ptable["name"], target, info, description, origin, duration_s, ramp_s)


def _generator_arguments(gtable: dict, head: _ProfileHeader, where: str,
                         gwhere: str) -> tuple[str, dict[str, Any]]:
    """(generator type, its keyword arguments) with the header's ramp and duration in."""
    gtype = gtable.get("type")
    if gtype not in _SPECS:
        raise _fail(gwhere, f"type = {gtype!r} is not one of {', '.join(_SPECS)}" if gtype is not None
                    else f"type is missing (one of {', '.join(_SPECS)})")
    ramp_s, duration_s = head.ramp_s, head.duration_s
    kw = _generator_kwargs(gtable, gtype, head.info, ramp_s, gwhere)
    if gtype in _TAPERED:
        kw["ramp_s"] = ramp_s if ramp_s is not None else _TAPERED[gtype]
    if gtype not in _INTRINSIC:
        if duration_s is None:
            raise _fail(where, f"duration_s is missing (a {gtype} profile needs it)")
        kw["duration_s"] = duration_s
    elif gtype in ("ramp", "triangle", "constant_velocity") and duration_s is not None:
        kw["duration_s"] = duration_s
    return gtype, kw


def _csv_samples(kw: dict[str, Any], head: _ProfileHeader, base_dir: Path | None, rate: float,
                 gwhere: str) -> np.ndarray:
    """A csv generator's column, converted to the target's units and resampled."""
    path = Path(kw["file"])
    if not path.is_absolute():
        path = (base_dir or Path.cwd()) / path
    values, times = _read_csv(path, kw["column"], kw["time_column"], gwhere)
    units = kw["value_units"]
    table = _CSV_UNITS[head.info.quantity]
    if units is None:
        factor = 1.0                      # in the profile's own units
    elif units.lower() in table:
        factor = table[units.lower()]
    else:
        raise _fail(gwhere, f"value_units = {units!r}: a {head.target} column may be in "
                            f"{', '.join(table)}")
    return gen.resample_series(values * factor * kw["scale"], times, ramp_s=kw["ramp_s"],
                               rate=rate)


def _generated(gtype: str, kw: dict[str, Any], head: _ProfileHeader, base_dir: Path | None,
               rate: float, gwhere: str) -> np.ndarray:
    """The generator's samples; its errors name the [generator] table."""
    try:
        if gtype == "csv":
            return _csv_samples(kw, head, base_dir, rate, gwhere)
        fn: Callable[..., np.ndarray] = {
            "step": gen.step, "ramp": gen.ramp, "triangle": gen.triangle,
            "constant_velocity": gen.constant_velocity, "sine": gen.sine,
            "swept_sine": gen.swept_sine, "noise": gen.band_limited_noise,
            "prbs": gen.prbs, "multisine": gen.multisine}[gtype]
        return fn(**kw, rate=rate)
    except gen.GeneratorError as exc:
        raise _fail(gwhere, str(exc)) from None


def profile_from_dict(doc: dict, *, source: str = "", base_dir: Path | None = None,
                      rate: float = RATE_HZ) -> Profile:
    """A Profile from a parsed profile document ({'profile': …, 'generator': …}); errors
    are ProfileFileError naming `source` and the field."""
    src = source or "profile"
    ptable, gtable = _tables(doc, src)
    where = f"{src} [profile]"
    head = _profile_header(ptable, where)
    gwhere = f"{src} [generator]"
    gtype, kw = _generator_arguments(gtable, head, where, gwhere)
    x = _generated(gtype, kw, head, base_dir, rate, gwhere)
    duration_s = head.duration_s
    if gtype in ("prbs", "multisine", "csv") and duration_s is not None:
        # these make their own length: a longer duration holds the last value
        n = int(round(duration_s * rate))
        if n < len(x):
            raise _fail(where, f"duration_s = {duration_s:g} s is shorter than the {gtype} "
                               f"({len(x) / rate:g} s): leave it out or lengthen it")
        x = np.concatenate([x, np.full(n - len(x), x[-1])])
    return Profile(name=head.name, target=head.target, units=head.info.units,
                   samples=x.astype(np.float32), rate=rate, description=head.description,
                   source=source, origin=head.origin, generator=dict(gtable))


def load_profile(path: str | Path, dictionary: Dictionary | None = None, *,
                 validate: bool = True, gyro_range: float = DEFAULT_GYRO_RANGE) -> Profile:
    """Read and build a profile file; with validate (default), refuse (ProfileRefused) one
    the device must not be sent.  Malformed files raise ProfileFileError."""
    path = Path(path)
    doc, _ = read_toml(path, ProfileFileError, "profile file not found")
    profile = profile_from_dict(doc, source=str(path), base_dir=path.parent)
    if validate:
        check_profile(profile, dictionary, gyro_range=gyro_range).raise_if_refused()
    return profile
