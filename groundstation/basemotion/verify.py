"""Did the stage do what the profile asked?  Achieved vs target RMS, PSD and cumulative
spectral power (CSP) from a recorded base-angle series (e.g. the base encoder telemetry).

The achieved RMS is the standard deviation of the series (testbed reference §8: the base
has an arbitrary zero); record a whole number of waveform periods after the stage has
settled for it to compare exactly.  The PSD is Welch's estimate (Hann windows, 50 %
overlap); the CSP is its running integral over frequency, and its square root at the top
frequency is the RMS.  The target CSP is the PSD table scaled to the target RMS,
integrated exactly.  No plotting here: `csp_curves()` gives the arrays a GUI plots.

`select_window()` picks the part of a recording to check (the last whole waveform period
of settled motion, with the telemetry's missing frames counted), `band_rms()` splits the
comparison into octave bands, and `preview_spectrum()` gives the spectrum a profile
should produce, before anything is played.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from scipy import signal

from ..analysis.spectra import csp
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
    """Cumulative spectral power: the trapezoidal running integral, 0 at the first
    frequency - the ground station's one CSP (analysis/spectra.py), under this module's
    name."""
    return csp(frequency_hz, psd)


def check_base_motion(angle_rad, sample_rate_hz: float, target: PsdTable | BaseMotionProfile, *,
                      target_rms_rad: float | None = None,
                      segment_s: float | None = None, window: str = "hann") -> BaseMotionCheck:
    """Compare a recorded base-angle series with a profile (or a PSD table + target RMS).

    For a record of whole waveform periods, `segment_s` = its length and window="boxcar"
    give the exact line spectrum of the periodic motion (Parseval: the CSP ends at the
    variance); a Hann window there would mix neighbouring lines of random phase and
    leave the achieved CSP off the RMS by tens of percent."""
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
    f, pxx = signal.welch(x, fs=sample_rate_hz, window=window, nperseg=nperseg,
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


#: more missing telemetry frames than this (fraction of the window) make the Welch
#: estimate meaningless: the samples would be joined across the holes
MAX_MISSING_FRACTION = 0.02


@dataclass(frozen=True)
class RecordWindow:
    """The stretch of a recorded base angle that a check uses."""

    angle_rad: np.ndarray
    start_s: float                 # device time of the window's start
    end_s: float                   # device time of its end (exclusive)
    sample_rate_hz: float
    missing_frames: int            # frames the window should hold but the record lacks

    @property
    def seconds(self) -> float:
        return self.end_s - self.start_s


def select_window(device_time_s, angle_rad, duration_s: float, sample_rate_hz: float, *,
                  end_s: float | None = None, not_before_s: float | None = None,
                  periods: int = 1) -> RecordWindow:
    """The `periods` x `duration_s` seconds of a record that end at `end_s` (default: the
    newest sample): whole waveform periods, so that the RMS compares exactly.

    `not_before_s` is where the stage has settled (output on + its settling time); a
    window reaching back before it, or before the record, is refused with how many
    seconds more the record needs."""
    t = np.asarray(device_time_s, dtype=float)
    x = np.asarray(angle_rad, dtype=float)
    if t.shape != x.shape or t.ndim != 1:
        raise BaseMotionError("device times and angles must be two equally long 1-D arrays")
    if not (duration_s > 0 and math.isfinite(duration_s)) or periods < 1:
        raise BaseMotionError(f"the window must be one or more periods of a positive "
                              f"duration, not {periods} x {duration_s!r} s")
    if not len(t):
        raise BaseMotionError("no base-encoder samples are recorded")
    dt = 1.0 / sample_rate_hz
    length = periods * duration_s
    newest = float(t[-1]) + dt                  # the record ends one sample after its last
    end = newest if end_s is None else min(float(end_s), newest)
    start = end - length
    # the earliest usable time: the record's start, or the settled stage if later
    floor, why = float(t[0]), "the record starts"
    if not_before_s is not None and not_before_s > floor:
        floor, why = float(not_before_s), "the stage has settled"
    if start < floor - dt / 2:
        have = max(0.0, end - floor)
        raise BaseMotionError(
            f"the check needs {length:g} s of settled motion (whole waveform periods) but only "
            f"{have:.1f} s lie between where {why} ({floor:.2f} s) and the end of the window "
            f"({end:.2f} s): {length - have:.1f} s more are needed")
    # half a sample of margin at both ends: device times are whole ticks
    inside = (t >= start - dt / 2) & (t < end - dt / 2)
    expected = int(round(length * sample_rate_hz))
    got = int(np.count_nonzero(inside))
    missing = max(0, expected - got)
    if missing > MAX_MISSING_FRACTION * expected:
        raise BaseMotionError(
            f"{missing} of the {expected} base-encoder samples of the window {start:.2f}-"
            f"{end:.2f} s are missing (telemetry drops): the spectrum would be wrong; record again")
    return RecordWindow(x[inside].copy(), start, end, float(sample_rate_hz), missing)


def check_record(device_time_s, angle_rad, sample_rate_hz: float, profile: BaseMotionProfile, *,
                 end_s: float | None = None, not_before_s: float | None = None,
                 periods: int = 1) -> tuple[BaseMotionCheck, RecordWindow]:
    """`select_window` (whole periods of the profile, ending at `end_s`) then
    `check_base_motion` on it with the exact whole-period spectrum (one boxcar segment)."""
    w = select_window(device_time_s, angle_rad, profile.duration_s, sample_rate_hz,
                      end_s=end_s, not_before_s=not_before_s, periods=periods)
    check = check_base_motion(w.angle_rad, sample_rate_hz, profile, segment_s=w.seconds,
                              window="boxcar")
    return check, w


@dataclass(frozen=True)
class BandRms:
    low_hz: float
    high_hz: float
    target_rms_rad: float
    achieved_rms_rad: float

    @property
    def error(self) -> float:
        """(achieved - target) / target; inf where the target has no power."""
        if self.target_rms_rad == 0:
            return math.inf if self.achieved_rms_rad > 0 else 0.0
        return self.achieved_rms_rad / self.target_rms_rad - 1.0


def band_rms(check: BaseMotionCheck, edges_hz=None) -> list[BandRms]:
    """Target and achieved RMS per frequency band (default: octaves across the profile's
    band), from the two CSP curves - where in the spectrum a difference lies."""
    lo, hi = check.band_hz
    if edges_hz is None:
        start = lo if lo > 0 else max(hi / 64, float(check.frequency_hz[1]))
        edges = [start]
        while edges[-1] * 2 < hi * 0.999:
            edges.append(edges[-1] * 2)
        edges.append(hi)
        if lo == 0:
            edges.insert(0, 0.0)
    else:
        edges = sorted(float(e) for e in edges_hz)
    f = check.csp.frequency_hz
    ct = np.interp(edges, f, check.csp.target_csp_rad2)
    ca = np.interp(edges, f, check.csp.achieved_csp_rad2)
    return [BandRms(edges[i], edges[i + 1], math.sqrt(max(0.0, ct[i + 1] - ct[i])),
                    math.sqrt(max(0.0, ca[i + 1] - ca[i]))) for i in range(len(edges) - 1)]


@dataclass(frozen=True)
class PreviewSpectrum:
    """A profile's spectrum before it is played: the table it was made from (scaled to
    the target RMS) and that of the base angle the stage model gives (one waveform
    period, exact at the frequencies k/T it holds)."""

    frequency_hz: np.ndarray
    target_psd_rad2_per_hz: np.ndarray
    synthesised_psd_rad2_per_hz: np.ndarray


def preview_spectrum(profile: BaseMotionProfile) -> PreviewSpectrum:
    """Only the frequencies inside the PSD's band (where log axes can show them)."""
    n, period = profile.points, profile.duration_s
    line = np.fft.rfft(profile.expected_angle_rad) / n
    f = np.arange(len(line)) / period
    # a sinusoid of amplitude A in bin k has |line| = A/2 and variance A^2/2 = S df, df = 1/T
    synthesised = 2.0 * np.abs(line) ** 2 * period
    target = profile.psd.scaled_to_rms(profile.target_rms_rad).density(f)
    keep = (target > 0) & (f > 0)
    return PreviewSpectrum(f[keep], target[keep], synthesised[keep])
