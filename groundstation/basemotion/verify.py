"""Did the stage do what the profile asked?  Achieved vs target RMS, PSD and cumulative
spectral power (CSP) from a recorded base-angle series (e.g. the base encoder telemetry).

The achieved RMS is the standard deviation of the series (testbed reference §8: the base
has an arbitrary zero); record a whole number of waveform periods after the stage has
settled for it to compare exactly.  The PSD is Welch's estimate (Hann windows, 50 %
overlap); the CSP is its running integral over frequency, and its square root at the top
frequency is the RMS.  The target CSP is the PSD table scaled to the target RMS,
integrated exactly.  No plotting here: `csp_curves()` gives the arrays a GUI plots.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from scipy import signal

from .psd import BaseMotionError, PsdTable
from .synthesis import BaseMotionProfile


@dataclass(frozen=True)
class CspCurves:
    """Target and achieved cumulative spectral power on one frequency axis (for one plot)."""

    frequency_hz: np.ndarray
    target_csp_rad2: np.ndarray
    achieved_csp_rad2: np.ndarray

    @property
    def target_cumulative_rms_rad(self) -> np.ndarray:
        return np.sqrt(self.target_csp_rad2)

    @property
    def achieved_cumulative_rms_rad(self) -> np.ndarray:
        return np.sqrt(self.achieved_csp_rad2)


@dataclass(frozen=True)
class BaseMotionCheck:
    name: str
    target_rms_rad: float
    achieved_rms_rad: float
    seconds: float
    sample_rate_hz: float
    band_hz: tuple[float, float]
    frequency_hz: np.ndarray
    achieved_psd_rad2_per_hz: np.ndarray
    target_psd_rad2_per_hz: np.ndarray
    csp: CspCurves
    in_band_fraction: float                  # of the achieved power (Welch), within the band

    @property
    def rms_error(self) -> float:
        """(achieved - target) / target."""
        return self.achieved_rms_rad / self.target_rms_rad - 1.0

    def within(self, tolerance: float) -> bool:
        return abs(self.rms_error) <= tolerance

    @property
    def max_cumulative_rms_difference_rad(self) -> tuple[float, float]:
        """The largest |sqrt(CSP achieved) - sqrt(CSP target)| and the frequency where it is."""
        d = np.abs(self.csp.achieved_cumulative_rms_rad - self.csp.target_cumulative_rms_rad)
        i = int(np.argmax(d))
        return float(d[i]), float(self.csp.frequency_hz[i])

    def summary(self) -> str:
        lo, hi = self.band_hz
        dmax, fmax = self.max_cumulative_rms_difference_rad
        return (f"{self.name}: base RMS {self.achieved_rms_rad * 1e3:.3f} mrad achieved vs "
                f"{self.target_rms_rad * 1e3:.3f} mrad target ({self.rms_error * 100:+.1f} %) over "
                f"{self.seconds:g} s; {self.in_band_fraction * 100:.1f} % of the achieved power "
                f"in the {lo:g}-{hi:g} Hz band; largest cumulative-RMS difference "
                f"{dmax * 1e3:.3f} mrad (at {fmax:.3g} Hz)")


def csp_from_psd(frequency_hz, psd) -> np.ndarray:
    """Cumulative spectral power: the trapezoidal running integral, 0 at the first frequency."""
    f = np.asarray(frequency_hz, dtype=float)
    p = np.asarray(psd, dtype=float)
    steps = np.diff(f) * (p[1:] + p[:-1]) / 2
    return np.concatenate([[0.0], np.cumsum(steps)])


def check_base_motion(angle_rad, sample_rate_hz: float, target: PsdTable | BaseMotionProfile, *,
                      target_rms_rad: float | None = None,
                      segment_s: float | None = None) -> BaseMotionCheck:
    """Compare a recorded base-angle series with a profile (or a PSD table + target RMS)."""
    x = np.asarray(angle_rad, dtype=float)
    if x.ndim != 1 or len(x) < 16 or not np.all(np.isfinite(x)):
        raise BaseMotionError("the base-angle record must be at least 16 finite samples")
    if not (sample_rate_hz > 0 and math.isfinite(sample_rate_hz)):
        raise BaseMotionError(f"sample rate must be > 0, not {sample_rate_hz!r}")
    if isinstance(target, BaseMotionProfile):
        psd, name = target.psd, target.name
        rms_target = target.target_rms_rad if target_rms_rad is None else target_rms_rad
    else:
        psd, name = target, target.name
        rms_target = psd.rms_rad() if target_rms_rad is None else target_rms_rad
    target_psd = psd.scaled_to_rms(rms_target)
    seconds = len(x) / sample_rate_hz
    lo, hi = target_psd.band_hz
    if segment_s is None:
        # segments long enough to resolve the band's lower edge (4 bins below it, at least
        # 20 s), but at most half the record so that Welch has a few averages
        wanted = max(20.0, 4.0 / lo) if lo > 0 else 20.0
        segment_s = min(wanted, seconds / 2) if seconds >= 8 else seconds
    nperseg = max(16, min(len(x), int(round(segment_s * sample_rate_hz))))
    f, pxx = signal.welch(x, fs=sample_rate_hz, window="hann", nperseg=nperseg,
                          detrend="constant", scaling="density")
    achieved_rms = float(np.std(x))
    csp_a = csp_from_psd(f, pxx)
    csp_t = target_psd.cumulative(f)
    band = (f >= lo) & (f <= hi)
    total = csp_a[-1]
    in_band = float(np.trapezoid(pxx[band], f[band]) / total) if total > 0 and band.sum() > 1 else 0.0
    return BaseMotionCheck(name, float(rms_target), achieved_rms, seconds, float(sample_rate_hz),
                           (lo, hi), f, pxx, target_psd.density(f), CspCurves(f, csp_t, csp_a),
                           in_band)


def csp_curves(check: BaseMotionCheck) -> CspCurves:
    """The arrays for a CSP plot of target and achieved on one set of axes."""
    return check.csp
