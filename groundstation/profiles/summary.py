"""Looking at a profile: its time series and spectrum for a plot, a text summary, and the
samples as CSV."""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

import numpy as np

from .samples import RATE_HZ, Profile


def preview(profile: Profile, nperseg: int = 16384) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """(t [s], samples [units], freqs [Hz], psd [units²/Hz]) for a plot: the time series
    as played and its one-sided power spectral density (Welch, Hann windows of up to
    `nperseg` samples, half overlap, no detrending, so a motion's low-frequency content
    shows).  Integrating psd over freqs gives the mean square of the samples."""
    x = profile.samples.astype(np.float64)
    t = np.arange(x.size) / profile.rate
    if x.size < 2:
        return t, x, np.zeros(1), np.zeros(1)
    from scipy import signal      # here, not at the top: 0.3 s a campaign's check need not pay
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
    rate_hz: float = RATE_HZ         # samples per second as played

    def lines(self) -> list[str]:
        u = self.units
        return [
            f"profile:  {self.name}",
            f"target:   {self.target} ({u}, origin {self.origin})",
            f"duration: {self.duration_s:g} s = {self.sample_count} samples at {self.rate_hz:g} Hz",
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
        peak_frequency_hz=peak, crc=profile.crc(), rate_hz=profile.rate)


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
