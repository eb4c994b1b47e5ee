"""The curves an identification is judged by, as arrays: each measured frequency response
beside the base model's and the identified model's on the same bins, and the residuals
of both.  The report's figures and the window's overlays draw these; neither computes a
model itself (the window does no numerics, and two plotters computing the same curve
twice would sooner or later disagree).

The models are the fit's own (analysis.plant_fit.sampled_model: the record's sampling
and the held current included); the identified one carries the bearing friction's
linearised stiffness the fit found beside the plant, the base one none, as the fit
compared them.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ..analysis.plant_fit import FRICTION_STIFFNESS, sampled_model
from .pipeline import Identification


@dataclass(frozen=True, eq=False)
class ResponseCurves:
    """One measured response (input current -> output) and both models on its bins."""

    source: str                 # the log's file name
    input_channel: str          # current_coarse / current_fine
    output_channel: str         # encoder_outer / encoder_inner / gyro_rate
    which: str                  # the model's path, e.g. 'T1->phi1'
    units: str                  # the response's units (output per ampere)
    freq_hz: np.ndarray
    measured: np.ndarray        # complex H1
    coherence: np.ndarray       # gamma^2
    base: np.ndarray            # complex, the base testbed's model
    identified: np.ndarray      # complex, the identified testbed's model
    fitted: np.ndarray          # bool: the bin was used by the fit (band and coherence)

    @property
    def label(self) -> str:
        return f"{self.input_channel} -> {self.output_channel}"

    @staticmethod
    def _db(h: np.ndarray) -> np.ndarray:
        with np.errstate(divide="ignore"):
            return 20.0 * np.log10(np.abs(h))

    @staticmethod
    def _deg(h: np.ndarray) -> np.ndarray:
        return np.degrees(np.angle(h))

    def magnitude_db(self, which: str) -> np.ndarray:
        """20 log10 |H| of 'measured', 'base' or 'identified'."""
        return self._db(getattr(self, which))

    def phase_deg(self, which: str) -> np.ndarray:
        """The phase of 'measured', 'base' or 'identified', wrapped to +-180 deg."""
        return self._deg(getattr(self, which))

    def residual_db(self, which: str) -> np.ndarray:
        """Magnitude of model / measured in dB ('base' or 'identified')."""
        with np.errstate(divide="ignore", invalid="ignore"):
            return self._db(getattr(self, which) / self.measured)

    def residual_deg(self, which: str) -> np.ndarray:
        """Phase of model / measured in degrees, wrapped to +-180 deg."""
        with np.errstate(divide="ignore", invalid="ignore"):
            return self._deg(getattr(self, which) / self.measured)


def _units(output_channel: str) -> str:
    return "rad/s per A" if output_channel == "gyro_rate" else "rad per A"


def response_curves(result: Identification) -> list[ResponseCurves]:
    """Every response the identification estimated, with both models on its bins."""
    fit = result.fit
    kf_estimate = fit.estimate(FRICTION_STIFFNESS.name)
    kf = kf_estimate.value if kf_estimate.status == "identified" else 0.0
    lo, hi = fit.band_hz
    out = []
    for lf in result.responses:
        m = lf.measured
        model = sampled_model(m.rate_hz)
        f = np.asarray(m.freq_hz, dtype=float)
        h = np.asarray(m.response, dtype=complex)
        g = np.asarray(m.coherence, dtype=float)
        fitted = (np.isfinite(h) & (np.abs(h) > 0) & np.isfinite(g) & (g >= fit.min_coherence)
                  & (f >= lo) & (f <= hi))
        out.append(ResponseCurves(
            source=lf.path.name, input_channel=lf.input_channel,
            output_channel=lf.output_channel, which=lf.model_path,
            units=_units(lf.output_channel), freq_hz=f, measured=h, coherence=g,
            base=model(result.base, lf.model_path, f, 0.0),
            identified=model(fit.testbed, lf.model_path, f, kf), fitted=fitted))
    return out


__all__ = ["ResponseCurves", "response_curves"]
