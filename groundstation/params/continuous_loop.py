"""The reference's continuous inertial loop: its closed-loop poles and its loop gains.

The loop as the reference designed it (testbed.md §4, §6), before any sampling:

* plant: g1, g2 of §4 (u1, u2 in in-oz -> LOS angle theta2 in rad) with b_f, k_f = 0;
* controller: c0 (c1' g1 + c2' g2) on the rate error e (rad/s);
* gyro: 2nd order (omega_g, zeta_g) and a pure delay T, G(s) e^{-sT};
* outer loop: rate command K_p (0 - theta_hat), theta_hat the complementary blend of
  the autocollimator (theta2 below the crossover w_c) and the integrated gyro (above):
  H_est = (w_c + s G e^{-sT}) / (s + w_c).

Frequency responses take the delay exactly (e^{-j w T}); only the pole computation, which
needs polynomials, replaces it with a Pade approximant.  Angular frequencies are rad/s,
names ending in _hz are Hz.
"""

from __future__ import annotations

import dataclasses
import math
import warnings
from dataclasses import dataclass

import numpy as np
from scipy.interpolate import pade

from ..plant.model import plant_transfer_functions
from .tf_algebra import TransferFunction

#: the reference's continuous gyro delay T_d (testbed.md §2).  The twin's testbed file
#: holds T_d - T/2 because the twin models the zero-order hold separately; the continuous
#: loop has no hold, so its delay is the reference's own.
REFERENCE_GYRO_DELAY_S = 2.6e-3
PADE_ORDER = 8            # a 2.6 ms delay to within 0.1 deg well past 100 Hz


def default_crossover_hz() -> float:
    """The complementary filter's crossover as the device's table defaults it (assumed:
    the reference gives none; protocol/parameters.toml `complementary_crossover`)."""
    from ..core.dictionary import load_dictionary
    from .table import default_values

    return float(default_values(load_dictionary())["complementary_crossover"])


@dataclass(frozen=True)
class ContinuousLoop:
    """One design closed on one testbed, continuous.  Build with `continuous_loop`."""

    c0: TransferFunction              # in-oz/(rad/s)
    c1: TransferFunction              # coarse path c1' (dimensionless)
    c2: TransferFunction              # fine path c2'
    g1: tuple[np.ndarray, np.ndarray]   # (num, den) u1 -> theta2, rad/in-oz
    g2: tuple[np.ndarray, np.ndarray]   # (num, den) u2 -> theta2
    bearing_viscous_in_oz_s_per_rad: float   # b_f: how base motion reaches the outer axis
    outer_gain_per_s: float           # K_p
    gyro_bandwidth_rad_s: float
    gyro_damping: float
    gyro_delay_s: float
    crossover_rad_s: float            # complementary filter

    # ------------------------------------------------------------------ frequency responses
    def plant_path(self, s: np.ndarray) -> np.ndarray:
        """c0 (c1' g1 + c2' g2): LOS angle per rate error."""
        return self.c0.response(s) * (self.c1.response(s) * _ratio(self.g1, s)
                                      + self.c2.response(s) * _ratio(self.g2, s))

    def gyro(self, s: np.ndarray) -> np.ndarray:
        """Measured rate per true rate, G(s) e^{-sT}, the delay exact."""
        wg = self.gyro_bandwidth_rad_s
        return wg * wg / (s * s + 2 * self.gyro_damping * wg * s + wg * wg) * np.exp(-s * self.gyro_delay_s)

    def estimate(self, s: np.ndarray) -> np.ndarray:
        """LOS angle estimate per true LOS angle (complementary filter)."""
        wc = self.crossover_rad_s
        return (wc + s * self.gyro(s)) / (s + wc)

    def sensed(self, s: np.ndarray) -> np.ndarray:
        """-(rate error) per LOS angle with both loops closed: K_p H_est + s G e^{-sT}."""
        return self.outer_gain_per_s * self.estimate(s) + s * self.gyro(s)

    def inner_open_loop(self, frequency_hz) -> np.ndarray:
        """Rate loop broken at the rate error, outer loop open: c0 (c1' g1 + c2' g2) s G e^{-sT}."""
        s = _s(frequency_hz)
        return self.plant_path(s) * s * self.gyro(s)

    def outer_open_loop(self, frequency_hz) -> np.ndarray:
        """Outer loop broken at the angle error, rate loop closed: K_p H_est P / (1 + P s G e^{-sT})."""
        s = _s(frequency_hz)
        p = self.plant_path(s)
        return self.outer_gain_per_s * self.estimate(s) * p / (1 + p * s * self.gyro(s))

    # ------------------------------------------------------------------ poles
    def least_damped_pole(self) -> complex:
        """Least-damped closed-loop pole (rad/s), the delay as an order-PADE_ORDER Pade.

        Closed loop: 1 + c0 (c1 g1 + c2 g2) (K_p H_est + s G e^{-sT}) = 0."""
        c0n, c0d = _poly(self.c0)
        c1n, c1d = _poly(self.c1)
        c2n, c2d = _poly(self.c2)
        (g1n, gd), (g2n, _) = self.g1, self.g2
        # c0 (c1 g1 + c2 g2) = c0n (c1n c2d g1n + c2n c1d g2n) / (c0d c1d c2d gd)
        Ln = _mul(c0n, np.polyadd(_mul(c1n, c2d, g1n), _mul(c2n, c1d, g2n)))
        Ld = _mul(c0d, c1d, c2d, gd)
        wg = self.gyro_bandwidth_rad_s
        Gn, Gd = np.array([wg ** 2]), np.array([1.0, 2 * self.gyro_damping * wg, wg ** 2])
        dn, dd = pade_delay(self.gyro_delay_s)
        kp, wc = self.outer_gain_per_s, self.crossover_rad_s
        # sensor path over the common denominator (s + wc) Gd dd
        Sn = np.polyadd(np.polyadd(kp * wc * _mul(Gd, dd), kp * _mul([1.0, 0.0], Gn, dn)),
                        _mul([1.0, 0.0], [1.0, wc], Gn, dn))
        Sd = _mul([1.0, wc], Gd, dd)
        roots = np.roots(np.polyadd(_mul(Ld, Sd), _mul(Ln, Sn)))
        roots = roots[np.abs(roots) > 1e-6]       # integrator cancellations at the origin
        return complex(roots[np.argmax(roots.real)])


def continuous_loop(design, testbed=None, *, gyro_delay_s: float = REFERENCE_GYRO_DELAY_S,
                    crossover_hz: float | None = None,
                    c0: TransferFunction | None = None) -> ContinuousLoop:
    """The continuous loop of an inertial design on a testbed (default: the design's own).

    gyro_delay_s: the reference's T_d unless given (pass the testbed's value to see the
    twin's delay without its hold); crossover_hz: the device table's default unless given;
    c0: replaces the design's c0 (to move one of its numbers)."""
    tb = design.testbed if testbed is None else testbed
    if design.outer_loop_gain_per_s is None:
        raise ValueError(f"{design.path}: not an inertial design (no outer_loop_gain_per_s)")
    g1, g2 = plant_transfer_functions(tb)
    s = tb.sensors
    cas = design.cascades
    return ContinuousLoop(
        c0=cas["c0"] if c0 is None else c0, c1=cas["c1"], c2=cas["c2"], g1=g1, g2=g2,
        bearing_viscous_in_oz_s_per_rad=float(tb.mechanics["bearing_viscous"]),
        outer_gain_per_s=float(design.outer_loop_gain_per_s),
        gyro_bandwidth_rad_s=2 * math.pi * s["gyro_bandwidth"], gyro_damping=float(s["gyro_damping"]),
        gyro_delay_s=float(gyro_delay_s),
        crossover_rad_s=2 * math.pi * (default_crossover_hz() if crossover_hz is None else crossover_hz))


def with_scaled_notch(c0: TransferFunction, scale: float) -> TransferFunction:
    """c0 with its lightly damped zero pair moved in frequency by sqrt(scale) (its s^0
    coefficient times scale): to see what the rounding of a printed coefficient does."""
    z = np.array(c0.zeros, dtype=complex)
    light = np.abs(z.real) < 0.2 * np.abs(z)
    z[light] *= math.sqrt(scale)
    return dataclasses.replace(c0, zeros=z)


def pade_delay(seconds: float) -> tuple[np.ndarray, np.ndarray]:
    """(num, den) of the order-PADE_ORDER Pade approximant of e^{-s seconds}."""
    if seconds <= 0:
        return np.array([1.0]), np.array([1.0])
    taylor = [(-seconds) ** i / math.factorial(i) for i in range(2 * PADE_ORDER + 1)]
    with warnings.catch_warnings():          # the Taylor system is ill-conditioned, the result is fine
        warnings.simplefilter("ignore")
        num, den = pade(taylor, PADE_ORDER)
    return np.asarray(num.coeffs), np.asarray(den.coeffs)


def _s(frequency_hz) -> np.ndarray:
    return 2j * np.pi * np.asarray(frequency_hz, dtype=float)


def _ratio(numden: tuple[np.ndarray, np.ndarray], s: np.ndarray) -> np.ndarray:
    return np.polyval(numden[0], s) / np.polyval(numden[1], s)


def _poly(tf: TransferFunction) -> tuple[np.ndarray, np.ndarray]:
    return (tf.gain * np.real(np.poly(tf.zeros)) if len(tf.zeros) else np.array([tf.gain]),
            np.real(np.poly(tf.poles)) if len(tf.poles) else np.array([1.0]))


def _mul(*ps) -> np.ndarray:
    out = np.array([1.0])
    for p in ps:
        out = np.polymul(out, p)
    return out
