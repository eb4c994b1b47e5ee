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
"""

from __future__ import annotations

import csv
import math
import zlib
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Callable

import numpy as np
from scipy import signal

from ..dictionary import Dictionary
from ..errors import GroundStationError
from ..tomlfile import read_toml
from . import waveforms as gen

RATE_HZ = gen.RATE_HZ
WAVEFORMS_DIR = Path(__file__).resolve().parent.parent.parent / "profiles" / "waveforms"

#: the rigs' gyro full scale (SPEC §11.2): the bound of a RATE_REFERENCE sample when no
#: testbed file says otherwise
DEFAULT_GYRO_RANGE = math.radians(1000.0)


class ProfileError(GroundStationError):
    """A profile cannot be used (the message says which file and field, and what to do)."""


class ProfileFileError(ProfileError):
    """A profile file cannot be read, is malformed, or describes no valid waveform."""


class ProfileRefused(ProfileError):
    """A readable profile that must not be sent (out of the target's range, too long, ...)."""


# ----------------------------------------------------------------------------- units
_ANGLE = {"rad": 1.0, "mrad": 1e-3, "urad": 1e-6, "deg": math.pi / 180, "arcsec": math.pi / 648000}
_RATE = {f"{u}_per_s": f for u, f in _ANGLE.items()}
_ACCEL = {f"{u}_per_s2": f for u, f in _ANGLE.items()}
_CURRENT = {"a": 1.0, "ma": 1e-3}
_CURRENT_SLOPE = {f"{u}_per_s": f for u, f in _CURRENT.items()}


@dataclass(frozen=True)
class TargetInfo:
    name: str
    units: str                         # the wire units of the samples
    quantity: str                      # "angle", "rate", "current"
    value_units: dict[str, float]      # key suffix -> factor to `units`
    slope_units: dict[str, float]      # key suffix -> factor to `units`/s
    modes: tuple[str, ...]             # modes that play it (SPEC §11.2)


TARGETS: dict[str, TargetInfo] = {
    "REFERENCE": TargetInfo("REFERENCE", "rad", "angle", _ANGLE, _RATE, ("RELATIVE", "INERTIAL")),
    "RATE_REFERENCE": TargetInfo("RATE_REFERENCE", "rad/s", "rate", _RATE, _ACCEL, ("INERTIAL",)),
    "CURRENT_COARSE": TargetInfo("CURRENT_COARSE", "A", "current", _CURRENT, _CURRENT_SLOPE, ("OPEN_LOOP",)),
    "CURRENT_FINE": TargetInfo("CURRENT_FINE", "A", "current", _CURRENT, _CURRENT_SLOPE, ("OPEN_LOOP",)),
}

#: the unit names a CSV column may be given in (value_units), by quantity
_CSV_UNITS = {"angle": _ANGLE, "rate": _RATE, "current": _CURRENT}


# ----------------------------------------------------------------------------- the profile
@dataclass
class Profile:
    """Samples for one target, played one per control period."""

    name: str
    target: str                        # a key of TARGETS
    units: str                         # the target's units
    samples: np.ndarray                # float32: exactly what is sent (before any origin offset)
    rate: float = RATE_HZ
    description: str = ""
    source: str = ""                   # the file it came from, or what made it
    #: "relative": REFERENCE samples are offsets from the position held when it is loaded
    #: (the loader adds it); "absolute": sent as they are
    origin: str = "absolute"
    generator: dict[str, Any] = field(default_factory=dict)   # the [generator] table, for the log

    def __post_init__(self) -> None:
        if self.target not in TARGETS:
            raise ProfileError(f"profile {self.name!r}: unknown target {self.target!r} "
                               f"(known: {', '.join(TARGETS)})")
        if self.origin not in ("absolute", "relative"):
            raise ProfileError(f"profile {self.name!r}: origin must be 'absolute' or 'relative'")
        self.samples = np.ascontiguousarray(self.samples, dtype=np.float32)
        if self.samples.ndim != 1:
            raise ProfileError(f"profile {self.name!r}: samples must be one-dimensional")

    @property
    def sample_count(self) -> int:
        return int(self.samples.size)

    @property
    def duration(self) -> float:
        """Playing time in seconds (sample_count / rate)."""
        return self.sample_count / self.rate

    @property
    def info(self) -> TargetInfo:
        return TARGETS[self.target]

    def wire_samples(self, offset: float = 0.0) -> np.ndarray:
        """The float32 samples as the device will play them: + offset for a relative profile
        (added in double precision, then rounded once to f32)."""
        if self.origin == "relative" and offset:
            return (self.samples.astype(np.float64) + offset).astype(np.float32)
        return self.samples

    def wire_bytes(self, offset: float = 0.0) -> bytes:
        """Big-endian f32 sample bytes, in index order (what PROFILE_WRITE carries)."""
        return self.wire_samples(offset).astype(">f4").tobytes()

    def crc(self, offset: float = 0.0) -> int:
        """CRC-32 of all sample bytes (PROFILE_COMMIT's profile_crc)."""
        return zlib.crc32(self.wire_bytes(offset))


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


def profile_from_dict(doc: dict, *, source: str = "", base_dir: Path | None = None,
                      rate: float = RATE_HZ) -> Profile:
    """A Profile from a parsed profile document ({'profile': …, 'generator': …}); errors
    are ProfileFileError naming `source` and the field."""
    src = source or "profile"
    ptable = doc.get("profile")
    gtable = doc.get("generator")
    if not isinstance(ptable, dict):
        raise _fail(src, "no [profile] table")
    if not isinstance(gtable, dict):
        raise _fail(src, "no [generator] table")
    for extra in doc:
        if extra not in ("profile", "generator"):
            raise _fail(src, f"unknown table [{extra}] (a profile file has [profile] and [generator])")
    where = f"{src} [profile]"
    unknown = [k for k in ptable if k not in _PROFILE_KEYS]
    if unknown:
        raise _fail(where, f"unknown key{'s' if len(unknown) > 1 else ''} {', '.join(unknown)} "
                           f"(known: {', '.join(sorted(_PROFILE_KEYS))})")
    for key in ("name", "target", "units"):
        if key not in ptable:
            raise _fail(where, f"{key} is missing")
        if not isinstance(ptable[key], str) or not ptable[key]:
            raise _fail(where, f"{key} must be a non-empty string")
    name = ptable["name"]
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
    if origin not in ("absolute", "relative"):
        raise _fail(where, f"origin must be 'absolute' or 'relative', not {origin!r}")
    if origin == "relative" and target != "REFERENCE":
        raise _fail(where, f"origin = 'relative' applies to REFERENCE profiles only: {target} "
                           f"starts from 0 after ARM")
    duration_s = _number(where, "duration_s", ptable["duration_s"]) if "duration_s" in ptable else None
    ramp_s = _number(where, "ramp_s", ptable["ramp_s"]) if "ramp_s" in ptable else None
    if ramp_s is not None and ramp_s < 0:
        raise _fail(where, f"ramp_s must be ≥ 0, not {ramp_s}")
    if duration_s is not None and duration_s <= 0:
        raise _fail(where, f"duration_s must be > 0, not {duration_s}")

    gwhere = f"{src} [generator]"
    gtype = gtable.get("type")
    if gtype not in _SPECS:
        raise _fail(gwhere, f"type = {gtype!r} is not one of {', '.join(_SPECS)}" if gtype is not None
                    else f"type is missing (one of {', '.join(_SPECS)})")
    kw = _generator_kwargs(gtable, gtype, info, ramp_s, gwhere)
    if gtype in _TAPERED:
        kw["ramp_s"] = ramp_s if ramp_s is not None else _TAPERED[gtype]
    if gtype not in _INTRINSIC:
        if duration_s is None:
            raise _fail(where, f"duration_s is missing (a {gtype} profile needs it)")
        kw["duration_s"] = duration_s
    elif gtype in ("ramp", "triangle", "constant_velocity") and duration_s is not None:
        kw["duration_s"] = duration_s
    try:
        if gtype == "csv":
            path = Path(kw["file"])
            if not path.is_absolute():
                path = (base_dir or Path.cwd()) / path
            values, times = _read_csv(path, kw["column"], kw["time_column"], gwhere)
            units = kw["value_units"]
            table = _CSV_UNITS[info.quantity]
            if units is None:
                factor = 1.0                      # in the profile's own units
            elif units.lower() in table:
                factor = table[units.lower()]
            else:
                raise _fail(gwhere, f"value_units = {units!r}: a {target} column may be in "
                                    f"{', '.join(table)}")
            x = gen.resample_series(values * factor * kw["scale"], times, ramp_s=kw["ramp_s"],
                                    rate=rate)
        else:
            fn: Callable[..., np.ndarray] = {
                "step": gen.step, "ramp": gen.ramp, "triangle": gen.triangle,
                "constant_velocity": gen.constant_velocity, "sine": gen.sine,
                "swept_sine": gen.swept_sine, "noise": gen.band_limited_noise,
                "prbs": gen.prbs, "multisine": gen.multisine}[gtype]
            x = fn(**kw, rate=rate)
    except gen.GeneratorError as exc:
        raise _fail(gwhere, str(exc)) from None
    if gtype in ("prbs", "multisine", "csv") and duration_s is not None:
        n = int(round(duration_s * rate))
        if n < len(x):
            raise _fail(where, f"duration_s = {duration_s:g} s is shorter than the {gtype} "
                               f"({len(x) / rate:g} s): leave it out or lengthen it")
        x = np.concatenate([x, np.full(n - len(x), x[-1])])
    return Profile(name=name, target=target, units=info.units, samples=x.astype(np.float32),
                   rate=rate, description=description, source=source, origin=origin,
                   generator=dict(gtable))


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


# ----------------------------------------------------------------------------- validation
@dataclass
class ProfileCheck:
    """What validation found: problems refuse the profile, warnings do not."""

    profile: Profile
    problems: list[str] = field(default_factory=list)
    warnings: list[str] = field(default_factory=list)

    @property
    def ok(self) -> bool:
        return not self.problems

    def raise_if_refused(self) -> None:
        if self.problems:
            where = self.profile.source or self.profile.name
            raise ProfileRefused(f"{where}: refused, nothing was sent: " + "; ".join(self.problems))


def sample_range(dictionary: Dictionary, target: str,
                 gyro_range: float = DEFAULT_GYRO_RANGE) -> tuple[float, float]:
    """The allowed sample range of a target (SPEC §11.2): that of the command argument the
    samples stand in for, or ± the gyro's full scale for a rate reference."""
    if target == "REFERENCE":
        item = dictionary.command("SET_REFERENCE").args[0]
    elif target in ("CURRENT_COARSE", "CURRENT_FINE"):
        args = {a.name: a for a in dictionary.command("SET_CURRENTS").args}
        item = args["current_coarse" if target == "CURRENT_COARSE" else "current_fine"]
    else:
        return -gyro_range, gyro_range
    assert item.value_range is not None
    return item.value_range


def _in_range(dictionary: Dictionary, target: str, x: np.ndarray, gyro_range: float) -> bool:
    if target == "REFERENCE":
        item = dictionary.command("SET_REFERENCE").args[0]
    elif target in ("CURRENT_COARSE", "CURRENT_FINE"):
        item = dictionary.command("SET_CURRENTS").args[0 if target == "CURRENT_COARSE" else 1]
    else:
        return bool(np.all(np.abs(x.astype(np.float64)) <= gyro_range))
    # as the device compares: f32 sample against the bounds rounded to f32 (Item.in_range)
    return item.in_range(float(x.min())) and item.in_range(float(x.max()))


def check_profile(profile: Profile, dictionary: Dictionary | None = None, *, offset: float = 0.0,
                  gyro_range: float = DEFAULT_GYRO_RANGE) -> ProfileCheck:
    """Everything the device would refuse, found here first; `offset` is the position a
    relative profile will be added to (0 before it is known)."""
    if dictionary is None:
        from ..dictionary import load_dictionary
        dictionary = load_dictionary()
    check = ProfileCheck(profile)
    p = check.problems
    x = profile.wire_samples(offset)
    count_item = next(a for a in dictionary.command("PROFILE_BEGIN").args if a.name == "sample_count")
    lo_n, hi_n = count_item.value_range or (1, 2**32 - 1)
    if not lo_n <= x.size <= hi_n:
        p.append(f"{x.size} samples ({x.size / profile.rate:g} s) is outside PROFILE_BEGIN's "
                 f"sample_count range {int(lo_n)} … {int(hi_n)} ({hi_n / profile.rate:g} s)")
    if profile.rate != dictionary.control_rate_hz:
        p.append(f"sampled at {profile.rate:g} Hz, but the device plays at "
                 f"{dictionary.control_rate_hz:g} Hz")
    if x.size == 0:
        return check
    finite = np.isfinite(x)
    if not finite.all():
        p.append(f"sample {int(np.flatnonzero(~finite)[0])} is not a finite number")
        return check
    lo, hi = sample_range(dictionary, profile.target, gyro_range)
    if not _in_range(dictionary, profile.target, x, gyro_range):
        at = "" if profile.origin == "absolute" or not offset else f" (offset {offset:.6g} {profile.units})"
        p.append(f"samples span {float(x.min()):.6g} … {float(x.max()):.6g} {profile.units}{at}, "
                 f"outside the {profile.target} range {lo:g} … {hi:g} {profile.units}")
    rest = np.float32(offset) if profile.origin == "relative" else np.float32(0.0)
    if x[0] != rest:
        p.append(f"the first sample is {float(x[0]):.6g} {profile.units}, not the rest value "
                 f"{float(rest):g}: the device would jump to it - add a ramp in (ramp_s) or start "
                 f"the data at rest")
    if profile.target == "REFERENCE":
        travel = next((q.default for q in dictionary.parameters if q.name == "travel_limit"), None)
        if travel is not None and float(np.abs(x).max()) > float(travel):
            check.warnings.append(f"the reference reaches {float(np.abs(x).max()):.4g} rad, beyond "
                                  f"the default travel_limit {float(travel):g} rad: the device "
                                  f"faults (OVER_TRAVEL) if the axis gets there")
        # samples are absolute float32 angles: away from zero they resolve less than the
        # per-sample steps of a slow motion (at 0.3 rad: 30 nrad, 20 encoder counts)
        step = np.abs(np.diff(profile.samples.astype(np.float64)))
        step = step[step > 0]
        if step.size:
            ulp = float(np.spacing(np.float32(np.abs(x.astype(np.float64)).max())))
            typical = float(np.median(step))
            if ulp > 0.5 * typical:
                check.warnings.append(
                    f"at {float(np.abs(x.astype(np.float64)).max()):.4g} rad a float32 sample "
                    f"resolves {ulp:.3g} rad, coarse against the profile's typical step of "
                    f"{typical:.3g} rad per sample: the reference moves in stairs (start nearer "
                    f"the encoder zero)")
    elif x[-1] != 0 and profile.target.startswith("CURRENT"):
        check.warnings.append(f"the profile ends at {float(x[-1]):.4g} A: the device holds it "
                              f"until disarmed")
    return check


# ----------------------------------------------------------------------------- preview
def preview(profile: Profile, nperseg: int = 16384) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """(t [s], samples [units], freqs [Hz], psd [units²/Hz]) for a plot: the time series
    as played and its one-sided power spectral density (Welch, Hann windows of up to
    `nperseg` samples, half overlap, no detrending, so a motion's low-frequency content
    shows).  Integrating psd over freqs gives the mean square of the samples."""
    x = profile.samples.astype(np.float64)
    t = np.arange(x.size) / profile.rate
    if x.size < 2:
        return t, x, np.zeros(1), np.zeros(1)
    freqs, psd = signal.welch(x, fs=profile.rate, window="hann", nperseg=min(nperseg, x.size),
                              detrend=False, scaling="density")
    return t, x, freqs, psd


@dataclass(frozen=True)
class ProfileSummary:
    name: str
    target: str
    units: str
    origin: str
    sample_count: int
    duration_s: float
    minimum: float
    maximum: float
    rms: float
    max_slope: float                 # units/s: largest |sample-to-sample change| x rate
    max_accel: float                 # units/s²
    peak_frequency_hz: float         # strongest PSD bin above DC
    crc: int

    def lines(self) -> list[str]:
        u = self.units
        return [
            f"profile:  {self.name}",
            f"target:   {self.target} ({u}, origin {self.origin})",
            f"duration: {self.duration_s:g} s = {self.sample_count} samples at 1200 Hz",
            f"range:    min {self.minimum:.6g} {u}, max {self.maximum:.6g} {u}, RMS {self.rms:.6g} {u}",
            f"rates:    max |slope| {self.max_slope:.6g} {u}/s, max |2nd derivative| "
            f"{self.max_accel:.6g} {u}/s²",
            f"spectrum: peak at {self.peak_frequency_hz:.4g} Hz",
            f"crc:      {self.crc:08x}",
        ]


def summarise(profile: Profile) -> ProfileSummary:
    x = profile.samples.astype(np.float64)
    d1 = np.diff(x) * profile.rate
    d2 = np.diff(d1) * profile.rate
    _, _, f, psd = preview(profile)
    peak = float(f[1:][np.argmax(psd[1:])]) if f.size > 1 else 0.0
    return ProfileSummary(
        name=profile.name, target=profile.target, units=profile.units, origin=profile.origin,
        sample_count=profile.sample_count, duration_s=profile.duration,
        minimum=float(x.min()), maximum=float(x.max()), rms=float(np.sqrt(np.mean(x ** 2))),
        max_slope=float(np.abs(d1).max()) if d1.size else 0.0,
        max_accel=float(np.abs(d2).max()) if d2.size else 0.0,
        peak_frequency_hz=peak, crc=profile.crc())


def write_csv(profile: Profile, path: str | Path) -> None:
    """time_s and the samples (named after the target and its units) as CSV."""
    column = f"{profile.target.lower()}_{profile.units.replace('/', '_per_').lower()}"
    x = profile.samples
    t = np.arange(x.size) / profile.rate
    with open(path, "w", encoding="utf-8", newline="") as f:
        f.write(f"# {profile.name}: {profile.target} in {profile.units}, origin {profile.origin}, "
                f"{profile.rate:g} Hz, from {profile.source or 'memory'}\n")
        f.write(f"time_s,{column}\n")
        for ti, xi in zip(t.tolist(), x.tolist()):
            f.write(f"{ti:.6f},{xi!r}\n")
