"""Whether the device may play a profile: everything it would refuse (sample count, rate,
range, first sample), found here first, and warnings for what it would play badly."""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from ..core.kinds import ProfileOrigin
from ..core.dictionary import Dictionary
from .samples import DEFAULT_GYRO_RANGE, Profile, ProfileRefused


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
        from ..core.dictionary import load_dictionary
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
        at = "" if profile.origin == ProfileOrigin.ABSOLUTE or not offset else f" (offset {offset:.6g} {profile.units})"
        p.append(f"samples span {float(x.min()):.6g} … {float(x.max()):.6g} {profile.units}{at}, "
                 f"outside the {profile.target} range {lo:g} … {hi:g} {profile.units}")
    rest = np.float32(offset) if profile.origin == ProfileOrigin.RELATIVE else np.float32(0.0)
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
