"""Design against design under base motion, linear: ratios per frequency and figures per PSD.

What bounds the base-motion profiles (testbed.md §9): the reference reports Design #2
below Design #1 in jitter and in control energy under every profile, and the two
designs' input sensitivities decide at which frequencies that can hold.  Everything here
is the continuous loop of continuous_loop.py (the reference's T_d = 2.6 ms unless
given) with the bearing linearised with k_f = 0 (base_motion_response.py):

* disturbance_ratios: per frequency, |theta2|_2 / |theta2|_1 and the motor power
  (i1^2 R1 + i2^2 R2)_2 / (same)_1 for the same base motion;
* energy_ratio_crossings_hz: where that power ratio passes 1;
* predicted_figures: one design under a PSD table, 60 s: jitter RMS (plain and the
  reference's 1 s high-pass metric, §8), control energy, motor torque RMS, and the fine
  motor's RMS against its limit with the time fraction a Gaussian signal of that RMS
  spends beyond it (the base motion is a sum of randomly phased sines, near Gaussian).

Linear means: no saturation, no Dahl friction beyond its b_f, and none of the loop's
own lightly damped 22.8 Hz mode (the base motion does not excite it here).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from scipy.optimize import brentq

from .base_motion_response import BaseMotionResponse, base_motion_response
from .continuous_loop import REFERENCE_GYRO_DELAY_S, continuous_loop

#: the reference's jitter metric (§8): H(s) = s / (s + 1/dT_i), corner 1/dT_i in rad/s
#: (as groundstation.analysis.jitter writes it), dT_i = 1 s
INTEGRATION_PERIOD_S = 1.0
DEFAULT_DURATION_S = 60.0          # each base-motion run (§7)
GRID_POINTS = 4000                 # per PSD band: |T|^2 is smooth below the 22.8 Hz mode


def response(design, frequency_hz, testbed=None, *, gyro_delay_s: float = REFERENCE_GYRO_DELAY_S,
             crossover_hz: float | None = None) -> BaseMotionResponse:
    """The base-motion response of one design's continuous loop on `testbed` (default: its own)."""
    tb = design.testbed if testbed is None else testbed
    loop = continuous_loop(design, tb, gyro_delay_s=gyro_delay_s, crossover_hz=crossover_hz)
    return base_motion_response(loop, tb, frequency_hz)


@dataclass(frozen=True)
class DisturbanceRatios:
    """Second design over first, per frequency, for the same base motion."""

    frequency_hz: np.ndarray
    jitter_ratio: np.ndarray           # |theta2|_2 / |theta2|_1
    energy_ratio: np.ndarray           # (i1^2 R1 + i2^2 R2)_2 / (same)_1
    fine_torque_ratio: np.ndarray      # |u2|_2 / |u2|_1


def disturbance_ratios(first, second, frequency_hz, testbed=None, **loop_options) -> DisturbanceRatios:
    """Ratios of `second` to `first` (designs) at `frequency_hz`; both on `testbed`
    (default: each design's own).  loop_options go to continuous_loop."""
    a = response(first, frequency_hz, testbed, **loop_options)
    b = response(second, frequency_hz, testbed, **loop_options)
    return DisturbanceRatios(a.frequency_hz, np.abs(b.los_rad_per_rad) / np.abs(a.los_rad_per_rad),
                             b.power_w_per_rad2 / a.power_w_per_rad2,
                             np.abs(b.fine_in_oz_per_rad) / np.abs(a.fine_in_oz_per_rad))


def energy_ratio_crossings_hz(first, second, lowest_hz: float = 0.1, highest_hz: float = 20.0,
                              testbed=None, points: int = 2000, **loop_options) -> list[float]:
    """Every frequency in [lowest_hz, highest_hz] where the energy ratio passes 1,
    bracketed on a log grid and refined by root finding."""
    def log_ratio(f):
        return np.log(disturbance_ratios(first, second, f, testbed, **loop_options).energy_ratio)

    f = np.geomspace(lowest_hz, highest_hz, points)
    v = log_ratio(f)
    out = []
    for i in np.nonzero(np.sign(v[:-1]) * np.sign(v[1:]) < 0)[0]:
        out.append(float(brentq(lambda x: float(log_ratio(x)[0]), f[i], f[i + 1], xtol=1e-9)))
    return out


def band_grid_hz(psd, points: int = GRID_POINTS) -> np.ndarray:
    """Integration points over the PSD's nonzero band: geometric (the skirts are straight
    on log axes) plus the table's own breakpoints."""
    lo, hi = psd.band_hz
    start = lo if lo > 0 else hi * 1e-5        # a table starting at 0 Hz: its first decade-fifths
    f = np.geomspace(start, hi, points)
    rows = psd.frequency_hz[(psd.frequency_hz > start) & (psd.frequency_hz < hi)]
    return np.unique(np.concatenate([f, rows]))


def predicted_figures(design, testbed, psd, *, duration_s: float = DEFAULT_DURATION_S,
                      **loop_options) -> dict:
    """One design under the PSD table `psd` (a basemotion.PsdTable) for duration_s:

    base_rms_rad, jitter_rms_rad (theta2), jitter_highpass_rms_rad (1 s high-pass,
    the reference's metric), energy_j, mean_power_w, coarse_rms_in_oz, fine_rms_in_oz,
    fine_limit_in_oz, fine_rms_over_limit, fine_saturated_fraction (Gaussian estimate).
    testbed None: the design's own."""
    tb = design.testbed if testbed is None else testbed
    f = band_grid_hz(psd)
    S = psd.density(f)
    r = response(design, f, tb, **loop_options)
    hp = 1j * 2 * np.pi * f / (1j * 2 * np.pi * f + 1.0 / INTEGRATION_PERIOD_S)

    def integral(gain2: np.ndarray) -> float:
        return float(np.trapezoid(gain2 * S, f))

    fine_rms = math.sqrt(integral(np.abs(r.fine_in_oz_per_rad) ** 2))
    limit = float(design.saturation_fine_in_oz)
    power = integral(r.power_w_per_rad2)
    return {
        "design": design.name,
        "psd": psd.name,
        "band_hz": psd.band_hz,
        "duration_s": duration_s,
        "base_rms_rad": math.sqrt(integral(np.ones_like(f))),
        "jitter_rms_rad": math.sqrt(integral(np.abs(r.los_rad_per_rad) ** 2)),
        "jitter_highpass_rms_rad": math.sqrt(integral(np.abs(r.los_rad_per_rad * hp) ** 2)),
        "mean_power_w": power,
        "energy_j": power * duration_s,
        "coarse_rms_in_oz": math.sqrt(integral(np.abs(r.coarse_in_oz_per_rad) ** 2)),
        "fine_rms_in_oz": fine_rms,
        "fine_limit_in_oz": limit,
        "fine_rms_over_limit": fine_rms / limit,
        "fine_saturated_fraction": math.erfc(limit / (fine_rms * math.sqrt(2))) if fine_rms > 0 else 0.0,
    }


def figure_ratios(first: dict, second: dict) -> dict:
    """second / first of the jitter (both metrics) and the energy of predicted_figures."""
    keys = ("jitter_rms_rad", "jitter_highpass_rms_rad", "energy_j")
    return {k: second[k] / first[k] for k in keys}
