"""The mode check: how much of a closed-loop run's jitter lies in a band around its
loop's least-damped closed-loop mode, the band taken from the design itself.

Why.  The inertial designs close their loop with a lightly damped pole pair (the
flexure mode; |L| crosses 1 three times, the last two close together; docs/fidelity.md
H4).  A run whose jitter is mostly that one line measures a limit cycle of the loop,
not the rejection of base motion, and comparing two such runs compares two limit
cycles (issue 28: a 22.8 Hz line carried ~700 of Design #1's 860 urad under BM2).  The
check says so beside the figures.

The band.  The sampled closed loop of the design with the table the run used
(params/loop_response.py: `loop_model`, the device's loop structure and the testbed's
discretised plant) gives its poles; the mode is the complex pole pair of least damping
ratio (z -> s = ln(z) f_s).  The band is that pole's damped frequency
+-MODE_BAND_HALF_WIDTH (5 %), at least +-MODE_BAND_MIN_BINS PSD bins:

* 5 %: the linear model's mode moves with the plant's uncertain numbers (the inertias
  differ by 0.35 % between two tables of the reference, the stiffness and the bearing
  damping are linearised) and a limit cycle of the nonlinear loop sits near, not at,
  the linear pole; 5 % of 22.8 Hz (21.7-23.9 Hz) holds the loop's second and third
  gain crossovers (21.9, 22.8 Hz) and stays far from the first (14.6 Hz) and from the
  base-motion bands (< 10 Hz);
* 3 bins: a line's Hann-window leakage spans +-2 bins, so a narrow band at a coarse
  PSD resolution still holds the whole line.

A design with no pole pair of damping below LIGHTLY_DAMPED_MAX has no such mode: no
check.  The share is the band's part of the Welch PSD's integral (the variance of the
scored angle with each segment's mean removed); above DOMINANT_SHARE the run is
flagged.  No I/O here (log_mode.py finds a log's design).
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any, Mapping

import numpy as np

from . import AnalysisError

#: half-width of the band around the mode, as a fraction of its frequency
MODE_BAND_HALF_WIDTH = 0.05
#: ... and at least this many PSD bins either side (a Hann line spans +-2 bins)
MODE_BAND_MIN_BINS = 3
#: a pole pair damped less than this is a lightly damped mode (the inertial designs'
#: flexure mode: -0.0005; the next, 13 Hz: 0.28)
LIGHTLY_DAMPED_MAX = 0.2
#: more than this share of the jitter's variance in the band: the mode dominates
DOMINANT_SHARE = 0.5


@dataclass(frozen=True)
class LoopMode:
    """The least-damped closed-loop pole pair of a design's sampled loop."""

    design: str                       # the design's name
    frequency_hz: float               # damped frequency of the pole pair
    damping: float                    # damping ratio (negative: growing)
    gain_crossovers_hz: tuple[float, ...] = ()   # of the loop broken at the error, for the reader

    def band_hz(self, resolution_hz: float = 0.0) -> tuple[float, float]:
        """The band around the mode (module docstring), for a PSD of `resolution_hz`."""
        half = max(MODE_BAND_HALF_WIDTH * self.frequency_hz, MODE_BAND_MIN_BINS * resolution_hz)
        return max(0.0, self.frequency_hz - half), self.frequency_hz + half

    def rule(self) -> str:
        cross = (", |L| = 1 at " + ", ".join(f"{f:.3g}" for f in self.gain_crossovers_hz) + " Hz"
                 if self.gain_crossovers_hz else "")
        return (f"{self.design}'s least-damped closed-loop pole pair, {self.frequency_hz:.4g} Hz "
                f"(damping {self.damping:+.2g}{cross}), +-{MODE_BAND_HALF_WIDTH * 100:g} % "
                f"(at least +-{MODE_BAND_MIN_BINS} PSD bins)")


def least_damped_mode(poles_z: np.ndarray, rate_hz: float, design: str = "",
                      gain_crossovers_hz: tuple[float, ...] = ()) -> LoopMode | None:
    """The complex pole pair of least damping among discrete poles `poles_z` sampled at
    `rate_hz` (None when there is none, or its damping is above LIGHTLY_DAMPED_MAX)."""
    p = np.asarray(poles_z, dtype=complex)
    p = p[(np.abs(p) > 0) & np.isfinite(p)]
    s = np.log(p) * rate_hz
    nyquist_rad = math.pi * rate_hz
    # one of each pair (positive frequency), neither real nor at the Nyquist frequency
    osc = s[(s.imag > 1e-9 * nyquist_rad) & (s.imag < (1 - 1e-6) * nyquist_rad)]
    if not len(osc):
        return None
    zeta = -osc.real / np.abs(osc)
    i = int(np.argmin(zeta))
    if zeta[i] > LIGHTLY_DAMPED_MAX:
        return None
    return LoopMode(design, float(osc[i].imag / (2 * math.pi)), float(zeta[i]),
                    tuple(float(f) for f in gain_crossovers_hz))


def design_mode(design, values: Mapping[str, Any] | None = None) -> LoopMode | None:
    """The lightly damped mode of `design` (a params ControllerDesign) in its sampled loop
    with the table `values` (None: the design's own table)."""
    from ..params.loop_response import loop_model, margins

    lm = loop_model(design, values)
    rate = lm.loop.rate_hz
    cross = margins(lambda f: lm.response(f, "error"), rate / 2).gain_crossovers_hz
    return least_damped_mode(lm.closed_loop_poles(), rate, design.name, cross)


def band_share(frequency_hz, density, band_hz: tuple[float, float]) -> float:
    """The share of a one-sided PSD's variance (bins above 0 Hz) inside `band_hz`
    (edges included), by the bins' sum: the bins are equally wide."""
    f = np.asarray(frequency_hz, dtype=float)
    p = np.asarray(density, dtype=float)
    if f.shape != p.shape or f.ndim != 1:
        raise AnalysisError("frequency and PSD must be two equally long 1-D arrays")
    above = f > 0                     # the segments' means are removed: DC is no jitter
    total = float(p[above].sum())
    if not total > 0:
        raise AnalysisError("the PSD holds no variance: no share to take")
    inside = above & (f >= band_hz[0]) & (f <= band_hz[1])
    return float(p[inside].sum()) / total


@dataclass(frozen=True)
class ModeCheck:
    """The share of a run's jitter in its loop's mode band."""

    mode: LoopMode
    band_hz: tuple[float, float]
    share: float                      # of the scored angle's variance (PSD, 0..1)
    source: str = ""                  # where the design and its table came from

    @property
    def dominates(self) -> bool:
        return self.share > DOMINANT_SHARE

    def text(self) -> str:
        lo, hi = self.band_hz
        s = (f"{self.share * 100:.0f} % of the jitter's variance in {lo:.3g}-{hi:.3g} Hz, the band of the "
             f"loop's lightly damped mode at {self.mode.frequency_hz:.4g} Hz")
        return s + (" - the mode dominates: a limit cycle of the loop, not base-motion rejection"
                    if self.dominates else "")


def mode_check(mode: LoopMode, frequency_hz, density, resolution_hz: float, source: str = "") -> ModeCheck:
    """The mode check of one PSD."""
    band = mode.band_hz(resolution_hz)
    return ModeCheck(mode, band, band_share(frequency_hz, density, band), source)


__all__ = ["DOMINANT_SHARE", "LIGHTLY_DAMPED_MAX", "LoopMode", "MODE_BAND_HALF_WIDTH",
           "MODE_BAND_MIN_BINS", "ModeCheck", "band_share", "design_mode", "least_damped_mode",
           "mode_check"]
