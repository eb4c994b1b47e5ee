"""Base-motion profiles from a PSD: the generator waveform and the base angle it should give.

1. Base angle: a sum of sinusoids at the frequencies k/T of one waveform period T (so the
   waveform loops seamlessly), amplitudes sqrt(2 S(f_k) df) matching the PSD, phases
   uniformly random from a seeded generator (same seed, same profile), summed exactly by
   an inverse FFT at the generator's arbitrary-waveform length, then scaled to the
   target RMS (exactly: the RMS of the samples is the target).
2. Volts: the angle divided, frequency by frequency, by the stage's modelled response
   (`BaseStageModel.held_response`, the staircase the generator plays included) -
   "pre-compensation", so the stage's resonance does not distort the spectrum; or, with
   precompensate=False, by its DC gain only.
3. Expected angle: the modelled stage's periodic steady-state response to those volts
   (equal to the target angle when pre-compensated).

The waveform is played by the generator at frequency 1/T.  Pre-compensation is bounded
because the PSD is band-limited: it is applied only where the PSD is not zero, and the
largest gain it needs is reported (`compensation_peak`).
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from ..instruments import spec4050
from .psd import BaseMotionError, PsdTable, load_psd
from .stage import BaseStageModel

DEFAULT_DURATION_S = 60.0                   # the rig ran BM1..BM3 for 60 s each
DEFAULT_POINTS = spec4050.ARB_POINTS_MAX
MAX_COMPENSATION = 1000.0                   # x the DC gain: beyond this the band is unreachable


@dataclass(frozen=True)
class BaseMotionProfile:
    """One period of a base-motion profile, sampled at the generator's waveform length."""

    name: str
    psd: PsdTable
    stage: BaseStageModel
    duration_s: float
    seed: int
    target_rms_rad: float
    precompensated: bool
    target_angle_rad: np.ndarray            # what the base should do
    volts: np.ndarray                       # the generator waveform (V at the amplifier input)
    expected_angle_rad: np.ndarray          # what the modelled stage does with `volts`
    compensation_peak: float                # largest |volts/angle| used, in units of 1/DC gain

    @property
    def points(self) -> int:
        return len(self.volts)

    @property
    def sample_interval_s(self) -> float:
        return self.duration_s / self.points

    @property
    def sample_rate_hz(self) -> float:
        return self.points / self.duration_s

    @property
    def frequency_hz(self) -> float:
        """The generator frequency that plays one waveform period in `duration_s`."""
        return 1.0 / self.duration_s

    @property
    def time_s(self) -> np.ndarray:
        return np.arange(self.points) * self.sample_interval_s

    @property
    def amplitude_vpp(self) -> float:
        """The generator amplitude setting it needs (symmetric span 2 max|v|, offset 0)."""
        return 2.0 * float(np.max(np.abs(self.volts)))

    @property
    def expected_rms_rad(self) -> float:
        return float(np.sqrt(np.mean(self.expected_angle_rad ** 2)))

    def summary(self) -> str:
        lo, hi = self.psd.band_hz
        return (f"{self.name}: {self.target_rms_rad * 1e3:.3f} mrad RMS target, band "
                f"{lo:g}-{hi:g} Hz, {self.points} points over {self.duration_s:g} s "
                f"(generator at {self.frequency_hz:.6g} Hz), seed {self.seed}; "
                f"{'pre-compensated' if self.precompensated else 'not pre-compensated'} "
                f"(peak gain {self.compensation_peak:.2f} x 1/DC gain); needs "
                f"{self.amplitude_vpp:.3f} Vpp; expected base RMS "
                f"{self.expected_rms_rad * 1e3:.3f} mrad")


def synthesise_angle(psd: PsdTable, *, duration_s: float = DEFAULT_DURATION_S,
                     points: int = DEFAULT_POINTS, seed: int = 0,
                     target_rms_rad: float | None = None) -> np.ndarray:
    """One period (`points` samples over `duration_s`) of a random-phase multisine with
    the PSD's shape and exactly `target_rms_rad` RMS (default: the PSD's own RMS)."""
    if not (duration_s > 0 and math.isfinite(duration_s)):
        raise BaseMotionError(f"duration must be a positive number of seconds, not {duration_s!r}")
    if not spec4050.ARB_POINTS_MIN <= points or points % 2:
        raise BaseMotionError(f"points must be an even number >= {spec4050.ARB_POINTS_MIN}, "
                              f"not {points}")
    if isinstance(seed, bool) or not isinstance(seed, (int, np.integer)) or seed < 0:
        raise BaseMotionError(f"the seed must be a non-negative integer, not {seed!r}")
    f_nyquist = points / (2 * duration_s)
    lo, hi = psd.band_hz
    if hi >= f_nyquist:
        raise BaseMotionError(
            f"{psd.name} reaches {hi:g} Hz but {points} points over {duration_s:g} s resolve only "
            f"below {f_nyquist:g} Hz: shorten the duration to under {points / (2 * hi):g} s")
    freqs = np.arange(points // 2 + 1) / duration_s
    s = psd.density(freqs)
    s[0] = 0.0                       # no DC: the base moves about its centre
    s[-1] = 0.0                      # the Nyquist bin cannot carry a random phase
    if np.count_nonzero(s) < 2:
        raise BaseMotionError(f"{psd.name}: fewer than 2 of the frequencies k/{duration_s:g} s fall "
                              f"in the band {lo:g}-{hi:g} Hz: lengthen the duration")
    rng = np.random.default_rng(seed)
    # one phase per bin whatever the band, so a seed means the same phases for every PSD
    phases = rng.uniform(0.0, 2 * np.pi, size=len(freqs))
    amplitudes = np.sqrt(2.0 * s / duration_s)
    spectrum = amplitudes * np.exp(1j * phases) * (points / 2)
    angle = np.fft.irfft(spectrum, points)
    rms = float(np.sqrt(np.mean(angle ** 2)))
    target = psd.rms_rad() if target_rms_rad is None else float(target_rms_rad)
    if not (target > 0 and math.isfinite(target)):
        raise BaseMotionError(f"target RMS must be a positive number of rad, not {target_rms_rad!r}")
    return angle * (target / rms)


def make_profile(psd: PsdTable, stage: BaseStageModel, *, duration_s: float = DEFAULT_DURATION_S,
                 points: int = DEFAULT_POINTS, seed: int = 0, target_rms_rad: float | None = None,
                 precompensate: bool = True, name: str | None = None) -> BaseMotionProfile:
    """A base-motion profile: target angle, generator volts and expected angle."""
    if points > spec4050.ARB_POINTS_MAX:
        raise BaseMotionError(f"the generator holds at most {spec4050.ARB_POINTS_MAX} points, "
                              f"not {points}")
    angle = synthesise_angle(psd, duration_s=duration_s, points=points, seed=seed,
                             target_rms_rad=target_rms_rad)
    dt = duration_s / points
    freqs = np.arange(points // 2 + 1) / duration_s
    spectrum = np.fft.rfft(angle)
    held = stage.held_response(freqs, dt)
    used = np.abs(spectrum) > 1e-12 * np.max(np.abs(spectrum))
    gain = np.zeros(len(freqs), dtype=complex)
    if precompensate:
        gain[used] = 1.0 / held[used]
    else:
        gain[used] = 1.0 / stage.dc_gain_rad_per_volt
    peak = float(np.max(np.abs(gain[used])) * stage.dc_gain_rad_per_volt)
    if peak > MAX_COMPENSATION:
        raise BaseMotionError(f"{psd.name}: reproducing the band through the stage needs "
                              f"{peak:.0f} x its DC drive somewhere: keep the PSD where the "
                              f"stage responds (its natural frequency is "
                              f"{stage.natural_frequency_hz:g} Hz)")
    volts_spectrum = spectrum * gain
    volts = np.fft.irfft(volts_spectrum, points)
    expected = np.fft.irfft(volts_spectrum * held, points)
    target_rms = float(np.sqrt(np.mean(angle ** 2)))
    return BaseMotionProfile(name or psd.name, psd, stage, float(duration_s), int(seed), target_rms,
                             bool(precompensate), angle, volts, expected, peak)


def load_profile(path: str | Path, testbed, **kwargs) -> BaseMotionProfile:
    """`make_profile` from a PSD file and a testbed (its base stage model)."""
    return make_profile(load_psd(path), BaseStageModel.from_testbed(testbed), **kwargs)
