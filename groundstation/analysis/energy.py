"""Control energy: the electrical energy the two motors turn into heat over a window.

P1 = i1^2 R1 (coarse, BLDC) and P2 = i2^2 R2 (fine, voice coils), R from the testbed
file ([motor_coarse] / [motor_fine] resistance, ohm); E = integral of (P1 + P2) dt, per
motor and in total, with the RMS current of each motor and the fraction of the time
each was saturated (the HIGH_RATE status bits coarse_saturated / fine_saturated).

Integration: the controller holds each current for one control period, so every
received frame contributes i^2 R / rate (the rectangle rule is the exact integral of
that staircase).  Frames missing from the telemetry are not integrated - their
currents are unknown, and joining the neighbours across the hole would invent them -
and are counted instead (`missing_frames`): the energy covers `seconds` =
frames received / rate, and `mean_power_w` is what to scale by to estimate the whole
window.  Saturation fractions are likewise of the frames received.

`control_energy` works on arrays; `EnergyAccumulator` on pieces of a series (a log read
in chunks) with the same result.  No I/O here.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from . import AnalysisError


@dataclass(frozen=True)
class ControlEnergy:
    energy_coarse_j: float
    energy_fine_j: float
    rms_current_coarse_a: float
    rms_current_fine_a: float
    saturated_coarse_fraction: float | None   # None: the log has no saturation bits
    saturated_fine_fraction: float | None
    samples: int                               # frames integrated
    missing_frames: int                        # frames lost in the window (not integrated)
    rate_hz: float
    resistance_coarse_ohm: float
    resistance_fine_ohm: float

    @property
    def energy_total_j(self) -> float:
        return self.energy_coarse_j + self.energy_fine_j

    @property
    def seconds(self) -> float:
        """Time the energy covers (frames received x control period)."""
        return self.samples / self.rate_hz

    @property
    def mean_power_w(self) -> float:
        return self.energy_total_j / self.seconds if self.samples else 0.0

    def text(self) -> str:
        def pct(v: float | None) -> str:
            return "n/a" if v is None else f"{v * 100:.2f} %"
        s = (f"energy {self.energy_total_j:.4g} J (coarse {self.energy_coarse_j:.4g} J, fine "
             f"{self.energy_fine_j:.4g} J) over {self.seconds:.4g} s, mean {self.mean_power_w:.4g} W; "
             f"RMS current coarse {self.rms_current_coarse_a:.4g} A, fine {self.rms_current_fine_a:.4g} A; "
             f"saturated coarse {pct(self.saturated_coarse_fraction)}, fine "
             f"{pct(self.saturated_fine_fraction)}")
        if self.missing_frames:
            s += f"; {self.missing_frames} frames missing (not integrated)"
        return s


def _check_constants(rate_hz: float, r_coarse: float, r_fine: float) -> None:
    if not (rate_hz > 0 and math.isfinite(rate_hz)):
        raise AnalysisError(f"sample rate must be > 0 Hz, not {rate_hz!r}")
    for name, r in (("coarse", r_coarse), ("fine", r_fine)):
        if not (r > 0 and math.isfinite(r)):
            raise AnalysisError(f"the {name} motor resistance must be > 0 ohm, not {r!r} "
                                f"(testbed file [motor_{name}] resistance)")


class EnergyAccumulator:
    """Running sums of i^2 and saturated frames; feed pieces in order, then result()."""

    def __init__(self, rate_hz: float, resistance_coarse_ohm: float, resistance_fine_ohm: float):
        _check_constants(rate_hz, resistance_coarse_ohm, resistance_fine_ohm)
        self.rate_hz = float(rate_hz)
        self.r_coarse = float(resistance_coarse_ohm)
        self.r_fine = float(resistance_fine_ohm)
        self.n = 0
        self._i2_coarse = 0.0
        self._i2_fine = 0.0
        self._sat_coarse: int | None = 0
        self._sat_fine: int | None = 0

    def feed(self, current_coarse_a, current_fine_a, coarse_saturated=None, fine_saturated=None) -> None:
        i1 = np.asarray(current_coarse_a, dtype=float)
        i2 = np.asarray(current_fine_a, dtype=float)
        if i1.shape != i2.shape or i1.ndim != 1:
            raise AnalysisError("the coarse and fine currents must be two equally long 1-D series")
        sq1, sq2 = float(np.dot(i1, i1)), float(np.dot(i2, i2))
        # a NaN or inf anywhere makes its sum of squares non-finite: one check, no extra pass
        if not (math.isfinite(sq1) and math.isfinite(sq2)):
            raise AnalysisError("a motor current is not finite: the log is damaged there")
        self.n += len(i1)
        self._i2_coarse += sq1
        self._i2_fine += sq2
        # a piece without the bits makes the whole fraction unknown, never a partial count
        for attr, bits in (("_sat_coarse", coarse_saturated), ("_sat_fine", fine_saturated)):
            count = getattr(self, attr)
            if bits is None or count is None:
                setattr(self, attr, None)
            else:
                b = np.asarray(bits, dtype=bool)
                if b.shape != i1.shape:
                    raise AnalysisError("saturation bits and currents must be equally long")
                setattr(self, attr, count + int(np.count_nonzero(b)))

    def result(self, missing_frames: int = 0) -> ControlEnergy:
        if not self.n:
            raise AnalysisError("no motor-current samples in the window")
        dt = 1.0 / self.rate_hz
        return ControlEnergy(
            energy_coarse_j=self._i2_coarse * self.r_coarse * dt,
            energy_fine_j=self._i2_fine * self.r_fine * dt,
            rms_current_coarse_a=math.sqrt(self._i2_coarse / self.n),
            rms_current_fine_a=math.sqrt(self._i2_fine / self.n),
            saturated_coarse_fraction=None if self._sat_coarse is None else self._sat_coarse / self.n,
            saturated_fine_fraction=None if self._sat_fine is None else self._sat_fine / self.n,
            samples=self.n, missing_frames=int(missing_frames), rate_hz=self.rate_hz,
            resistance_coarse_ohm=self.r_coarse, resistance_fine_ohm=self.r_fine)


def control_energy(current_coarse_a, current_fine_a, rate_hz: float, resistance_coarse_ohm: float,
                   resistance_fine_ohm: float, *, coarse_saturated=None, fine_saturated=None,
                   missing_frames: int = 0) -> ControlEnergy:
    """Energy, RMS currents and saturation of two current series sampled at `rate_hz`
    (one sample per control period; see the module docstring for missing frames)."""
    i1 = np.asarray(current_coarse_a, dtype=float)
    i2 = np.asarray(current_fine_a, dtype=float)
    _check_constants(rate_hz, resistance_coarse_ohm, resistance_fine_ohm)
    if i1.shape != i2.shape or i1.ndim != 1:
        raise AnalysisError("the coarse and fine currents must be two equally long 1-D series")
    if not len(i1):
        raise AnalysisError("no motor-current samples in the window")
    if not (np.all(np.isfinite(i1)) and np.all(np.isfinite(i2))):
        raise AnalysisError("a motor current is not finite: the log is damaged there")
    dt = 1.0 / rate_hz

    def frac(bits) -> float | None:
        if bits is None:
            return None
        b = np.asarray(bits, dtype=bool)
        if b.shape != i1.shape:
            raise AnalysisError("saturation bits and currents must be equally long")
        return float(np.mean(b))

    # one sample per control period: the rectangle rule integrates the held current exactly
    return ControlEnergy(
        energy_coarse_j=float(np.sum(i1 ** 2) * resistance_coarse_ohm * dt),
        energy_fine_j=float(np.sum(i2 ** 2) * resistance_fine_ohm * dt),
        rms_current_coarse_a=float(np.sqrt(np.mean(i1 ** 2))),
        rms_current_fine_a=float(np.sqrt(np.mean(i2 ** 2))),
        saturated_coarse_fraction=frac(coarse_saturated), saturated_fine_fraction=frac(fine_saturated),
        samples=int(len(i1)), missing_frames=int(missing_frames), rate_hz=float(rate_hz),
        resistance_coarse_ohm=float(resistance_coarse_ohm), resistance_fine_ohm=float(resistance_fine_ohm))


__all__ = ["ControlEnergy", "EnergyAccumulator", "control_energy"]
