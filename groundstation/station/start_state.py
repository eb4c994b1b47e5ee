"""Is the rig ready for a run's clock to start?  At rest, in range and unfaulted.

A campaign's runs are only comparable if each starts from the same state: a run that
starts while the base stage still rings from the last profile, or with the outer axis
far off centre, or the line of sight off the autocollimator after a fault, measures the
previous run as much as its own.  `StartStateMonitor` watches HIGH_RATE (a telemetry
subscriber, like the state tracker) and keeps the last `hold_s` seconds of the channels
that say so; `problems()` lists, in the operator's words and with the measured values,
every criterion the window fails.  The Station's `settle` verb waits (device time) until
the list is empty.

The criteria and their defaults (each can be changed by the caller):

* unfaulted: no latched fault in the window;
* at rest: over the window, each encoder (outer, inner, base) moves less than
  `max_motion_rad` peak to peak, and on the inertial set-up the gyro's mean |rate| is
  below `max_rate_rad_s` (the base stage rings for seconds after its generator stops);
* in range: |outer encoder| within `travel_fraction` of the device's travel limit, the
  flexure deflection within `deflection_fraction` of its safe deflection, and on the
  inertial set-up the autocollimator inside `autocollimator_fraction` of its range (a
  reading at the rail is no reading).

Qt-free and I/O-free; the receiver thread feeds it, the session thread asks it.
"""

from __future__ import annotations

import math
import threading
from dataclasses import dataclass

import numpy as np

DEG = math.pi / 180.0
CHANNELS = ("encoder_outer", "encoder_inner", "encoder_base", "gyro_rate", "autocollimator", "fault")


@dataclass(frozen=True)
class Problem:
    """One unmet criterion: kind "waiting", "fault", "motion" or "range", and the words."""

    kind: str
    text: str

    def __str__(self) -> str:
        return self.text


@dataclass(frozen=True)
class StartCriteria:
    """Limits of a ready start state (see the module docstring)."""

    hold_s: float = 1.0
    max_motion_rad: float = 50e-6
    max_rate_rad_s: float = 1e-3
    travel_fraction: float = 0.5
    deflection_fraction: float = 0.5
    autocollimator_fraction: float = 0.9

    def __post_init__(self):
        for name in ("hold_s", "max_motion_rad", "max_rate_rad_s"):
            v = getattr(self, name)
            if not (isinstance(v, (int, float)) and math.isfinite(v) and v > 0):
                raise ValueError(f"start state: {name} must be a positive number, not {v!r}")
        for name in ("travel_fraction", "deflection_fraction", "autocollimator_fraction"):
            v = getattr(self, name)
            if not (isinstance(v, (int, float)) and 0 < v <= 1):
                raise ValueError(f"start state: {name} must be in (0, 1], not {v!r}")


@dataclass(frozen=True)
class RigLimits:
    """What the rig's testbed file says the ranges are."""

    travel_rad: float
    safe_deflection_rad: float | None      # None: 1-DOF (no flexure)
    autocollimator_range_rad: float | None  # None: no autocollimator (relative set-up)

    @classmethod
    def from_testbed(cls, testbed, travel_limit_rad: float | None = None) -> "RigLimits":
        m = testbed.mechanics
        travel = m["travel"] if travel_limit_rad is None else min(m["travel"], travel_limit_rad)
        ac = testbed.sensors.get("autocollimator_range") if testbed.inertial else None
        return cls(float(travel), float(m["flexure_safe_deflection"]) if testbed.is_2dof else None,
                   float(ac) * DEG if ac is not None else None)


class StartStateMonitor:
    """A HIGH_RATE subscriber holding the last `hold_s` seconds of the start-state channels."""

    def __init__(self, limits: RigLimits, rate_hz: float, criteria: StartCriteria = StartCriteria()):
        """rate_hz: the control rate (the dictionary's), which sets how many frames the
        hold window is."""
        self.limits = limits
        self.criteria = criteria
        self.rate_hz = float(rate_hz)
        self.frames = max(2, int(round(criteria.hold_s * rate_hz)))
        self._lock = threading.Lock()
        self._ring = {c: np.zeros(self.frames) for c in CHANNELS}
        self._filled = 0
        self._pos = 0
        self.tick = -1

    def __call__(self, block) -> None:
        if block.name != "HIGH_RATE" or not len(block):
            return
        cols = {c: np.asarray(block[c], dtype=float)[-self.frames:] for c in CHANNELS}
        m = len(cols["fault"])
        with self._lock:
            for c, v in cols.items():
                ring = self._ring[c]
                first = min(m, self.frames - self._pos)
                ring[self._pos:self._pos + first] = v[:first]
                ring[:m - first] = v[first:]
            self._pos = (self._pos + m) % self.frames
            self._filled = min(self.frames, self._filled + m)
            self.tick = int(block["tick"][-1])

    def reset(self) -> None:
        """Forget the window (after a command that changes the state, e.g. DISARM)."""
        with self._lock:
            self._filled = 0
            self._pos = 0

    def window(self) -> dict[str, np.ndarray] | None:
        """The full window, oldest first; None until `hold_s` of frames has arrived."""
        with self._lock:
            if self._filled < self.frames:
                return None
            return {c: np.roll(r, -self._pos).copy() for c, r in self._ring.items()}

    def problems(self) -> list[Problem]:
        """Every criterion the last window fails ([] : ready)."""
        w = self.window()
        c, lim = self.criteria, self.limits
        if w is None:
            return [Problem("waiting", f"waiting for {c.hold_s:g} s of telemetry")]
        out: list[Problem] = []
        if np.any(w["fault"] > 0.5):
            out.append(Problem("fault", "a fault is latched (DISARM acknowledges it once the cause is gone)"))
        for name in ("encoder_outer", "encoder_inner", "encoder_base"):
            span = float(np.ptp(w[name]))
            if span > c.max_motion_rad:
                out.append(Problem("motion", f"not at rest: {name} moved {span * 1e6:.1f} urad in "
                                   f"{c.hold_s:g} s (limit {c.max_motion_rad * 1e6:g} urad)"))
        if lim.autocollimator_range_rad is not None:
            rate = float(np.mean(np.abs(w["gyro_rate"])))
            if rate > c.max_rate_rad_s:
                out.append(Problem("motion", f"not at rest: the LOS turns at {rate * 1e3:.2f} mrad/s "
                                   f"on the gyro (limit {c.max_rate_rad_s * 1e3:g} mrad/s)"))
        outer = float(np.max(np.abs(w["encoder_outer"])))
        if outer > c.travel_fraction * lim.travel_rad:
            out.append(Problem("range", f"out of range: the outer axis is {outer * 1e3:.2f} mrad off "
                               f"centre (limit {c.travel_fraction * lim.travel_rad * 1e3:.1f} mrad, "
                               f"{c.travel_fraction:.0%} of the travel): bring it back before the run"))
        if lim.safe_deflection_rad is not None:
            defl = float(np.max(np.abs(w["encoder_inner"] - w["encoder_outer"])))
            if defl > c.deflection_fraction * lim.safe_deflection_rad:
                out.append(Problem("range", f"out of range: the flexure is deflected {defl * 1e3:.2f} "
                                   f"mrad (limit {c.deflection_fraction * lim.safe_deflection_rad * 1e3:.1f} mrad)"))
        if lim.autocollimator_range_rad is not None:
            ac = float(np.max(np.abs(w["autocollimator"])))
            edge = c.autocollimator_fraction * lim.autocollimator_range_rad
            if ac > edge:
                out.append(Problem("range", f"out of range: the autocollimator reads {ac * 1e3:.3f} mrad, "
                                   f"beyond {edge * 1e3:.2f} mrad ({c.autocollimator_fraction:.0%} of "
                                   f"its range): the LOS is off the mirror's calibrated range"))
        return out

    def summary(self) -> dict[str, float]:
        """The measured start state (for the log and the report); {} before a full window."""
        w = self.window()
        if w is None:
            return {}
        s = {"outer_rad": float(np.mean(w["encoder_outer"])),
             "deflection_rad": float(np.mean(w["encoder_inner"] - w["encoder_outer"])),
             "base_rad": float(np.mean(w["encoder_base"])),
             "outer_motion_rad": float(np.ptp(w["encoder_outer"]))}
        if self.limits.autocollimator_range_rad is not None:
            s["autocollimator_rad"] = float(np.mean(w["autocollimator"]))
            s["gyro_mean_abs_rad_s"] = float(np.mean(np.abs(w["gyro_rate"])))
        return s
