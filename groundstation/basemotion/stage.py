"""The base stage as the profile generator models it: generator volts -> base angle.

From the testbed file's [base_stage] (all values assumed there): the audio amplifier
(amplifier_gain, V/V) drives the linear actuator (actuator_gain, rad of stage per volt of
amplifier output at DC) against the centring spring; stage + tungsten weights on the
spring make a lightly damped second-order system, so

    theta_b(s) / v_fg(s) = K * wn^2 / (s^2 + 2 zeta wn s + wn^2),
    K = amplifier_gain * actuator_gain  (rad/V, the DC gain), wn = 2 pi natural_frequency

- the same model the simulator integrates (`groundstation/plant/model.py`).  The generator
plays an arbitrary waveform as a staircase (each sample held for one sample interval), so
the exact response at the sample instants is that of the zero-order-hold discretisation;
`held_response` gives it, and pre-compensation divides by it.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from ..core.numerics_cache import cached_arrays, scipy_version
from .psd import BaseMotionError


@dataclass(frozen=True)
class BaseStageModel:
    dc_gain_rad_per_volt: float
    natural_frequency_hz: float
    damping: float
    source: str = ""

    def __post_init__(self):
        for name in ("dc_gain_rad_per_volt", "natural_frequency_hz"):
            v = getattr(self, name)
            if not (v > 0 and math.isfinite(v)):
                raise BaseMotionError(f"base stage {name} must be > 0, not {v!r}")
        if not (self.damping > 0 and math.isfinite(self.damping)):
            raise BaseMotionError(f"base stage damping must be > 0 (an undamped stage cannot "
                                  f"be pre-compensated), not {self.damping!r}")

    @classmethod
    def from_testbed(cls, testbed) -> "BaseStageModel":
        b = testbed.base_stage
        if not b.get("enabled"):
            raise BaseMotionError(f"{testbed.path}: base_stage.enabled is false (this set-up has no "
                                  f"base stage); use an inertial testbed such as "
                                  f"profiles/testbeds/inertial_2dof.toml")
        return cls(b["amplifier_gain"] * b["actuator_gain"], b["natural_frequency"],
                   b["damping"], f"{testbed.path} [base_stage]")

    def _continuous(self) -> tuple[list[float], list[float]]:
        wn = 2 * math.pi * self.natural_frequency_hz
        return [self.dc_gain_rad_per_volt * wn * wn], [1.0, 2 * self.damping * wn, wn * wn]

    def response(self, frequency_hz) -> np.ndarray:
        """Continuous frequency response (rad/V) at the given frequencies."""
        f = np.asarray(frequency_hz, dtype=float)
        r = f / self.natural_frequency_hz
        return self.dc_gain_rad_per_volt / (1 - r * r + 2j * self.damping * r)

    def settling_time_s(self, fraction: float = 0.01) -> float:
        """Time for a start-up transient to decay to `fraction` of its size: the
        envelope exp(-zeta wn t) of the lightly damped stage.  A recording of the
        steady-state motion starts at least this long after the output went on."""
        if not 0 < fraction < 1:
            raise BaseMotionError(f"fraction must be between 0 and 1, not {fraction!r}")
        return math.log(1.0 / fraction) / (self.damping * 2 * math.pi * self.natural_frequency_hz)

    def held_response(self, frequency_hz, sample_interval_s: float) -> np.ndarray:
        """Response (rad/V) from a staircase input (samples held for `sample_interval_s`)
        to the output at the sample instants: the zero-order-hold equivalent."""
        num, den = self._continuous()
        numd, dend = _held(num, den, float(sample_interval_s))
        z = np.exp(2j * np.pi * np.asarray(frequency_hz, dtype=float) * sample_interval_s)
        b = np.ravel(numd)
        return np.polyval(b, z) / np.polyval(dend, z)


def _held(num, den, sample_interval_s: float) -> tuple[np.ndarray, np.ndarray]:
    """scipy.signal.cont2discrete's zero-order hold of num/den, kept on disk by its inputs
    (core/numerics_cache.py): a campaign's check synthesises every base motion it plays,
    and would otherwise import scipy.signal (0.3 s) for this one conversion."""

    def compute():
        from scipy import signal

        numd, dend, _ = signal.cont2discrete((num, den), sample_interval_s, method="zoh")
        return np.asarray(numd, dtype=float), np.asarray(dend, dtype=float)

    def valid(arrays) -> bool:
        return len(arrays) == 2 and arrays[1].ndim == 1 and arrays[1].size == len(den)

    inputs = (np.asarray(num, dtype=float), np.asarray(den, dtype=float), sample_interval_s)
    numd, dend = cached_arrays("held_stage", scipy_version(), inputs, compute, valid)
    return numd, dend
