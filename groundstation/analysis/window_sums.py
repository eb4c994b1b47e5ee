"""One window's running metric sums - missing and stalled frames, the scored sensor's
jitter and Welch sums, the control-energy sums - and the rules that decide which samples
of the sensor count.  The log adapter (log_metrics.analyze_log) feeds them a chunk at a
time, metrics_from_columns once.
"""

from __future__ import annotations

import numpy as np

from ..core.kinds import Setup
from . import AnalysisError
from .energy import EnergyAccumulator
from .frame_gaps import frame_steps, missing_before
from .jitter import JitterAccumulator, sensor_valid
from .spectra import WelchAccumulator, segment_samples
from .testbed_figures import DEG, TestbedFigures

#: the sensors only the inertial set-up carries (IMU and mirror with the autocollimator)
LOS_SENSORS = ("autocollimator", "los_estimate")


def exclusion_rule(sensor: str, figures: TestbedFigures, bits: int,
                   notes: list[str]) -> tuple[float | None, str]:
    """(calibrated range or None, the exclusion rule in words) of the scored sensor;
    `bits`: its raw count's width (0: unknown).  Notes an unknown autocollimator range."""
    # a count at either end of its wire type is a clipped value, not a measurement
    rail = ((f" or at the {bits}-bit A/D rail" if sensor == "autocollimator"
             else f" or at the limit of its {bits}-bit count") if bits else "")
    if sensor != "autocollimator":
        return None, rail.removeprefix(" or ") if rail else ""
    range_rad = figures.autocollimator_range_rad
    if range_rad is None:
        known = figures.source or figures.missing
        notes.append(f"the autocollimator's calibrated range is unknown ({known}; it is "
                     f"[sensors] autocollimator_range): only samples at the A/D rail are "
                     f"excluded; give --testbed FILE for the range")
        return None, "at the A/D rail" if bits else ""
    return range_rad, (f"|angle| >= {range_rad * 1e3:.4g} mrad (calibrated range "
                       f"{range_rad / DEG:g} deg, {figures.source}){rail}")


def check_resistances(figures: TestbedFigures, where: object) -> None:
    if figures.resistance_coarse_ohm is None or figures.resistance_fine_ohm is None:
        known = figures.source or figures.missing
        raise AnalysisError(f"{where}: the motor resistances ([motor_coarse] / [motor_fine] "
                            f"resistance) are unknown ({known}): give --testbed FILE")


class WindowSums:
    """One window's running figures: missing and stalled frames, the scored sensor's
    jitter and Welch sums, the energy sums.  analyze_log feeds it a chunk at a time,
    metrics_from_columns once."""

    def __init__(self, wanted: tuple[str, ...], rate: float, frames: int,
                 integration_period_s: float, psd_segment_s: float, figures: TestbedFigures,
                 range_rad: float | None):
        self.range_rad = range_rad
        self.jit = JitterAccumulator(rate, integration_period_s) if "jitter" in wanted else None
        self.welch = (WelchAccumulator(rate, segment_samples(rate, psd_segment_s, frames))
                      if "psd" in wanted else None)
        self.energy = (EnergyAccumulator(rate, figures.resistance_coarse_ohm, figures.resistance_fine_ohm)
                       if "energy" in wanted else None)
        self.frames = self.missing = self.stalled = 0
        self.excluded = 0                 # scored samples the sensor did not measure
        self.unscored = ""                # why the sensor gave no figure at all
        self.last_tick: int | None = None

    def feed(self, ticks, angle=None, counts=None, currents=None, saturation=None) -> None:
        """The next piece: its ticks, the scored angle (None: not scoring) and counts
        (None: unknown), the currents and saturation bits (None: none)."""
        gap, m, s = frame_steps(ticks, self.last_tick)
        holes = missing_before(ticks, self.last_tick) if m else None
        self.missing += m
        self.stalled += s
        self.last_tick = int(ticks[-1])
        self.frames += len(ticks)
        if angle is not None:
            ok = sensor_valid(angle, range_rad=self.range_rad, raw_counts=counts)
            self.excluded += len(ok) - int(np.count_nonzero(ok))
            if self.jit is not None:
                self.jit.feed(angle, ok, gap, holes)
            if self.welch is not None:
                self.welch.feed(angle, ok, gap)
        if self.energy is not None:
            self.energy.feed(*currents, *(saturation if saturation is not None else (None, None)))

    def finish(self, sensor: str, rule: str, setup: str, notes: list[str]):
        """(jitter, energy, spectrum); what the data do not allow (every sample excluded,
        no stretch long enough for a PSD segment) is left out, the reason in `notes`."""
        if self.stalled:
            notes.append(f"{self.stalled} frame(s) did not advance the device tick (repeated or "
                         f"out of order): the filters restart there")
        jit, welch = self.jit, self.welch
        jitter = spectrum = None
        if jit is not None and jit.n and jit.lowest == jit.highest:
            if setup == Setup.RELATIVE and sensor in LOS_SENSORS:
                # the relative set-up has no IMU or mirror: the channel is a placeholder, and
                # its constant is nothing measured - not a perfect line of sight
                notes.append(f"no jitter or PSD: the {sensor} reads one constant value "
                             f"({jit.lowest:.6g} rad) over all {jit.n} samples and the testbed is "
                             f"the relative set-up, which has no autocollimator or IMU: --sensor "
                             f"encoder_inner")
                self.unscored = f"the relative set-up has no {sensor}: nothing was measured"
                jit = welch = None
            else:
                notes.append(f"the {sensor} reads one constant value over all {jit.n} samples: "
                             f"any motion was below its resolution")
        if jit is not None:
            try:
                jitter = jit.result(sensor, missing_frames=self.missing, exclusion_rule=rule)
            except AnalysisError as exc:
                notes.append(f"no jitter: {exc}")
                self.unscored = f"no jitter: {exc}"
        if welch is not None:
            try:
                spectrum = welch.result()
            except AnalysisError as exc:
                notes.append(f"no PSD: {exc} (--psd-segment S, psd_segment_s=S)")
        energy = self.energy.result(self.missing) if self.energy is not None else None
        return jitter, energy, spectrum


__all__ = ["LOS_SENSORS", "WindowSums", "check_resistances", "exclusion_rule"]
