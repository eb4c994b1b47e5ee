"""Whether a window's figures are a measurement: the fraction of the window the scored
sensor did not measure (samples out of its range, at its A/D rail, not finite) or the
telemetry did not bring (missing frames), against a stated limit.

A jitter computed from the 48 % of a run the autocollimator could see is the jitter of
the calm part of the run, not of the run; an energy integrated over the frames received
misses what the lost ones carried.  Comparisons must not rank such runs (issue 28: the
open-loop runs clipped the autocollimator 6 / 52 / 51 % of the time and were ranked).
The window counts in control periods: frames received plus frames missing.  Plain
Python, no numpy: the campaign's reading imports the limit.
"""

from __future__ import annotations

from dataclasses import dataclass

#: a window with more than this fraction excluded (out of range, at the rail, missing
#: frames) is not valid: 1 % is 0.6 s of a 60 s window - enough to lose a real excursion,
#: and more than a healthy closed-loop run ever loses (it never leaves the range; the
#: simulator and a good link lose no frames).  A campaign's [analysis] table may set it
#: (max_excluded_fraction), `groundstation analyze --max-excluded-fraction` too.
MAX_EXCLUDED_FRACTION = 0.01


def pct_text(fraction: float) -> str:
    """0.523 -> '52 %', 0.0042 -> '0.42 %': two significant figures, never '0 %' for > 0."""
    p = 100.0 * fraction
    return f"{p:.2g} %" if p < 10 else f"{p:.0f} %"


@dataclass(frozen=True)
class WindowValidity:
    """The excluded share of a window and the verdict."""

    excluded_fraction: float           # of the window's control periods (frames + missing)
    unmeasured_fraction: float         # scored sensor: out of range / rail / not finite
    missing_fraction: float            # frames missing in the telemetry
    max_excluded_fraction: float       # the limit the verdict used
    valid: bool
    reason: str = ""                   # why not valid ('' when valid)


def check_fraction(value: float) -> float:
    """The limit, checked: a finite number in [0, 1]."""
    if isinstance(value, bool) or not isinstance(value, (int, float)) or not 0.0 <= value <= 1.0:
        raise ValueError(f"the largest excluded fraction must be a number from 0 to 1, not {value!r}")
    return float(value)


def window_validity(frames: int, missing_frames: int, samples_excluded: int | None, *,
                    sensor: str = "", max_excluded_fraction: float = MAX_EXCLUDED_FRACTION,
                    unscored: str = "") -> WindowValidity:
    """The verdict on a window of `frames` received and `missing_frames` lost, of which
    the scored `sensor` did not measure `samples_excluded` (None: not scored).
    `unscored`: why the sensor's figures could not be had at all (the window is then not
    valid whatever the fractions say; '' : they were had, or not asked for)."""
    limit = check_fraction(max_excluded_fraction)
    periods = max(0, int(frames)) + max(0, int(missing_frames))
    if periods == 0:
        return WindowValidity(1.0, 0.0, 0.0, limit, False, "the window holds no frame")
    unmeasured = (samples_excluded or 0) / periods
    missing = max(0, int(missing_frames)) / periods
    excluded = unmeasured + missing
    if unscored:
        return WindowValidity(excluded, unmeasured, missing, limit, False, unscored)
    if excluded <= limit:
        return WindowValidity(excluded, unmeasured, missing, limit, True)
    parts = []
    if unmeasured:
        where = ("off the autocollimator's range or at its A/D rail" if sensor == "autocollimator"
                 else f"not measured by the {sensor or 'scored sensor'} (at its limit or not finite)")
        parts.append(f"{pct_text(unmeasured)} of the window {where}")
    if missing:
        parts.append(f"{pct_text(missing)} of its frames missing")
    reason = (" and ".join(parts) + f" (limit {pct_text(limit)} excluded)")
    return WindowValidity(excluded, unmeasured, missing, limit, False, reason)


__all__ = ["MAX_EXCLUDED_FRACTION", "WindowValidity", "check_fraction", "pct_text", "window_validity"]
