"""Margins of the continuous inertial loop as a Bode plot shows them, every crossing named.

`loop_response.margins` gives a loop's worst margins (the smallest phase margin over all
gain crossovers), which is what a validation must judge.  The reference states its
margins the way a designer reads them off the Bode plot (§9a): the phase margin at *the*
crossover (the first frequency where |L| falls through 1), the gain margin where the
phase first reaches -180 deg.  The lightly damped 22.8 Hz flexure mode makes |L| cross 1
again (a second and third crossover), so both readings are kept: LoopFigures has the
designer's numbers and every crossing beside them.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from scipy.optimize import brentq

from .continuous_loop import REFERENCE_GYRO_DELAY_S, ContinuousLoop, continuous_loop
from .loop_response import margins

TOP_HZ = 600.0          # the search grid ends here: both loops are below -40 dB long before


@dataclass(frozen=True)
class GainCrossing:
    frequency_hz: float
    phase_margin_deg: float      # 180 deg + angle of L there
    falling: bool                # |L| falls through 1 with frequency


@dataclass(frozen=True)
class PhaseCrossing:
    frequency_hz: float
    gain_db: float               # 20 log10 |L| where the angle of L is -180 deg


@dataclass(frozen=True)
class LoopFigures:
    """One loop gain's Bode-plot figures."""

    crossover_hz: float | None               # the first falling gain crossing
    phase_margin_deg: float                  # at crossover_hz
    gain_margin_db: float                    # smallest -20 log|L| at a phase crossing with |L| < 1
    gain_margin_hz: float | None
    closed_loop_bandwidth_hz: float | None   # first frequency where |L / (1 + L)| < -3 dB
    gain_crossings: tuple[GainCrossing, ...]
    phase_crossings: tuple[PhaseCrossing, ...]

    @property
    def later_crossings(self) -> tuple[GainCrossing, ...]:
        """The gain crossings after the crossover (the flexure mode's)."""
        return tuple(c for c in self.gain_crossings
                     if self.crossover_hz is not None and c.frequency_hz > self.crossover_hz)

    def text(self) -> str:
        head = (f"crossover {self.crossover_hz:.2f} Hz, phase margin {self.phase_margin_deg:.1f} deg, "
                f"gain margin {self.gain_margin_db:.1f} dB at {self.gain_margin_hz:.2f} Hz, "
                f"closed-loop -3 dB {self.closed_loop_bandwidth_hz:.1f} Hz")
        later = "; ".join(f"{c.frequency_hz:.2f} Hz ({'falling' if c.falling else 'rising'}, "
                          f"PM {c.phase_margin_deg:.1f} deg)" for c in self.later_crossings)
        phases = ", ".join(f"{p.frequency_hz:.2f} Hz ({p.gain_db:+.2f} dB)" for p in self.phase_crossings)
        return (head + (f"; |L| = 1 again at {later}" if later else "")
                + (f"; -180 deg at {phases}" if phases else ""))


def loop_figures(loop_gain, top_hz: float = TOP_HZ) -> LoopFigures:
    """Figures of the loop gain `loop_gain(frequency_hz) -> complex array`."""
    m = margins(loop_gain, top_hz)
    gains = []
    for f in m.gain_crossovers_hz:
        L, later = loop_gain(np.array([f, f * (1 + 1e-6)]))
        gains.append(GainCrossing(f, _phase_margin_deg(L), bool(abs(later) < abs(L))))
    # margins() closes a sampled loop's phase at Nyquist; a continuous loop has no such point
    phases = [PhaseCrossing(f, 20 * math.log10(abs(loop_gain(np.array([f]))[0])))
              for f in m.phase_crossovers_hz if f < top_hz * (1 - 1e-6)]
    falling = [c for c in gains if c.falling]
    first = falling[0] if falling else None
    upward = [(-p.gain_db, p.frequency_hz) for p in phases if p.gain_db < 0]
    gm_db, gm_hz = min(upward) if upward else (math.inf, None)
    return LoopFigures(first.frequency_hz if first else None,
                       first.phase_margin_deg if first else math.nan, gm_db, gm_hz,
                       _bandwidth_hz(loop_gain, top_hz), tuple(gains), tuple(phases))


@dataclass(frozen=True)
class InertialMargins:
    inner: LoopFigures           # rate loop, broken at the rate error, outer loop open
    outer: LoopFigures           # position loop at K_p, broken at the angle error, rate loop closed
    least_damped_pole: complex   # rad/s, both loops closed (Pade delay)

    @property
    def least_damped_zeta(self) -> float:
        return -self.least_damped_pole.real / abs(self.least_damped_pole)


def inertial_margins(design, testbed=None, *, gyro_delay_s: float = REFERENCE_GYRO_DELAY_S,
                     crossover_hz: float | None = None) -> InertialMargins:
    loop: ContinuousLoop = continuous_loop(design, testbed, gyro_delay_s=gyro_delay_s,
                                           crossover_hz=crossover_hz)
    return InertialMargins(loop_figures(loop.inner_open_loop), loop_figures(loop.outer_open_loop),
                           loop.least_damped_pole())


def _phase_margin_deg(L: complex) -> float:
    return (math.degrees(np.angle(L)) + 360.0) % 360.0 - 180.0


def _bandwidth_hz(loop_gain, top_hz: float, lowest_hz: float = 1e-2, points: int = 4000) -> float | None:
    def excess_db(f):
        L = loop_gain(np.atleast_1d(f))
        return 20 * np.log10(np.abs(L / (1 + L))) + 10 * math.log10(2)

    f = np.geomspace(lowest_hz, top_hz, points)
    below = np.nonzero(excess_db(f) < 0)[0]
    if not len(below) or below[0] == 0:
        return None
    i = below[0]
    return float(brentq(lambda x: float(excess_db(x)[0]), f[i - 1], f[i], xtol=1e-9))
