"""A profile: the float32 samples for one target, played one per control period, and the
targets (with their units and the modes that play them) a profile may drive.

Profile files (profile.py), the device's checks (checks.py) and summaries (summary.py)
build on this module.
"""

from __future__ import annotations

import math
import zlib
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from ..core.kinds import ProfileOrigin
from ..core.errors import GroundStationError
from . import waveforms as gen

RATE_HZ = gen.RATE_HZ

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
        if self.origin not in set(ProfileOrigin):
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
        if self.origin == ProfileOrigin.RELATIVE and offset:
            return (self.samples.astype(np.float64) + offset).astype(np.float32)
        return self.samples

    def wire_bytes(self, offset: float = 0.0) -> bytes:
        """Big-endian f32 sample bytes, in index order (what PROFILE_WRITE carries)."""
        return self.wire_samples(offset).astype(">f4").tobytes()

    def crc(self, offset: float = 0.0) -> int:
        """CRC-32 of all sample bytes (PROFILE_COMMIT's profile_crc)."""
        return zlib.crc32(self.wire_bytes(offset))
