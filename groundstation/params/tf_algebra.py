"""Continuous transfer-function algebra for the controller designs.

Zero-pole-gain transfer functions built from the reference's factors ([a] is (s + a),
[b, c] is (s^2 + b s + c)), their factored text, the output-equivalent c0 computed from
a partner design and the testbed's plant, and pole/zero cancellation.  All angular
frequencies are rad/s, all frequencies named `_hz` are Hz.

One of the three modules of the design path (tf_algebra, design_file, discretise).
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import TYPE_CHECKING

import numpy as np

from ..core.dictionary import default_control_rate_hz
from ..core.errors import GroundStationError

if TYPE_CHECKING:
    from .design_file import ControllerDesign

CONTROL_RATE_HZ = default_control_rate_hz()   # the controller's loop rate (reference §2)
CANCEL_TOLERANCE = 1e-6           # relative distance at which a pole and a zero cancel
INTEGRATOR_TOLERANCE = 1e-9       # rad/s: a pole closer to s = 0 than this is an integrator


class DesignError(GroundStationError):
    """A controller design file is missing, malformed or inconsistent (names file and field)."""


# ======================================================================================
# continuous transfer functions
# ======================================================================================
@dataclass(frozen=True, eq=False)
class TransferFunction:
    """A continuous transfer function gain * prod(s - zeros) / prod(s - poles), rad/s."""

    zeros: np.ndarray             # complex, conjugate pairs complete
    poles: np.ndarray
    gain: float

    @staticmethod
    def from_factors(gain: float, numerator=(), denominator=()) -> "TransferFunction":
        return TransferFunction(_roots_of_factors(numerator), _roots_of_factors(denominator),
                                float(gain))

    @staticmethod
    def constant(gain: float) -> "TransferFunction":
        return TransferFunction(np.zeros(0, complex), np.zeros(0, complex), float(gain))

    @property
    def order(self) -> int:
        return max(len(self.zeros), len(self.poles))

    @property
    def integrators(self) -> int:
        """Number of poles at s = 0 (they map to z = 1 and are allowed on the device)."""
        return int(np.sum(self.poles == 0))

    def response(self, s: np.ndarray) -> np.ndarray:
        """Complex value at the points s (rad/s), evaluated factor by factor."""
        s = np.asarray(s, dtype=complex)
        out = np.full(s.shape, self.gain, dtype=complex)
        for z in self.zeros:
            out = out * (s - z)
        for p in self.poles:
            out = out / (s - p)
        return out

    def frequency_response(self, freqs_hz: np.ndarray) -> np.ndarray:
        return self.response(2j * np.pi * np.asarray(freqs_hz, dtype=float))

    def text(self) -> str:
        """Factored form as the reference writes it: 30801(s+36.28)(s^2+25.92s+8.61e+04) / [...]"""
        num, den = _factor_text(self.zeros), _factor_text(self.poles)
        out = f"{self.gain:.6g}{num}"
        if den:
            out += f" / [{den}]" if den.count("(") + den.count("s") > 1 else f" / {den}"
        return out


def _roots_of_factors(factors) -> np.ndarray:
    roots: list[complex] = []
    for f in factors:
        if len(f) == 1:
            roots.append(complex(-f[0]))
        else:
            b, c = f
            disc = b * b - 4.0 * c
            if disc >= 0:            # two real roots; the stable form avoids cancellation
                q = -0.5 * (b + math.copysign(math.sqrt(disc), b if b else 1.0))
                roots += [complex(q), complex(c / q) if q else 0j]
            else:
                re, im = -0.5 * b, 0.5 * math.sqrt(-disc)
                roots += [complex(re, im), complex(re, -im)]
    return np.array(roots, dtype=complex)


def _factor_text(roots: np.ndarray) -> str:
    """(s+a) and (s^2+bs+c) factors in the order of the roots, repeats as powers."""
    factors: list[str] = []
    done = np.zeros(len(roots), bool)
    for i, r in enumerate(roots):
        if done[i]:
            continue
        done[i] = True
        partner = None
        if r.imag != 0:
            partner = next((j for j in range(len(roots)) if not done[j] and roots[j] == np.conj(r)), None)
        if partner is not None:
            done[partner] = True
            factors.append(f"(s^2{_signed(-2 * r.real)}s{_signed(abs(r) ** 2)})")
        else:
            factors.append("s" if r == 0 else f"(s{_signed(-r.real)})")
    out, i = "", 0
    while i < len(factors):
        n = 1
        while i + n < len(factors) and factors[i + n] == factors[i]:
            n += 1
        out += factors[i] + (f"^{n}" if n > 1 else "")
        i += n
    return out


def _signed(x: float) -> str:
    return f"{'+' if x >= 0 else '-'}{abs(x):.6g}"


def _snap_integrators(tf: TransferFunction) -> TransferFunction:
    """Poles within INTEGRATOR_TOLERANCE of s = 0 become exactly 0 (so they map to z = 1)."""
    poles = np.where(np.abs(tf.poles) < INTEGRATOR_TOLERANCE, 0j, tf.poles)
    zeros = np.where(np.abs(tf.zeros) < INTEGRATOR_TOLERANCE, 0j, tf.zeros)
    return TransferFunction(zeros, poles, tf.gain)


# ======================================================================================
# output-equivalent c0
# ======================================================================================
def output_equivalent_c0(partner: ControllerDesign, c1: TransferFunction, c2: TransferFunction,
                         testbed, rtol: float = CANCEL_TOLERANCE,
                         where: str = "") -> tuple[TransferFunction, int]:
    """c0_b = c0_a (c1_a g1 + c2_a g2) / (c1_b g1 + c2_b g2): the same loop gain as the partner.

    With c2' = 1 this is the reference's c0_a (Q_a g1 + g2) / (Q_b g1 + g2).  g1, g2 are the
    testbed's angle outputs; for the inertial (rate) loop both carry the same factor s and
    gyro model, which cancel in the ratio.  Returns the new c0 and the number of pole/zero
    pairs cancelled.  The polynomials here are of low degree (<= 8); the roots are checked
    by comparing the two loop gains along the frequency axis."""
    from ..plant.model import plant_transfer_functions

    if not testbed.is_2dof:
        raise DesignError(f"{where}: c0.equivalent_to needs a 2-DOF testbed (two inputs g1, g2); "
                          f"{testbed.path.name} is {testbed.configuration}")
    (n1, d), (n2, _) = plant_transfer_functions(testbed)
    num_a, den_a = _path_sum(partner.c1, partner.c2, n1, n2)
    num_b, den_b = _path_sum(c1, c2, n1, n2)
    if not np.any(num_b):
        raise DesignError(f"{where}: c1' g1 + c2' g2 is identically zero; no c0 can match "
                          f"{partner.path.name}")
    zeros = np.concatenate([partner.c0.zeros, _roots(num_a), den_b])
    poles = np.concatenate([partner.c0.poles, den_a, _roots(num_b)])
    gain = partner.c0.gain * _lead(num_a) / _lead(num_b)
    zeros, poles, cancelled = cancel_common_roots(zeros, poles, rtol)
    c0 = _snap_integrators(TransferFunction(zeros, poles, gain))
    _check_same_loop(partner, c0, c1, c2, n1, n2, d, where)
    return c0, cancelled


def _path_sum(c1: TransferFunction, c2: TransferFunction, n1, n2) -> tuple[np.ndarray, np.ndarray]:
    """(numerator polynomial, denominator roots) of (c1' g1 + c2' g2) D."""
    num = np.polyadd(np.polymul(_poly(c1.zeros, c1.gain), np.polymul(_poly(c2.poles), n1)),
                     np.polymul(_poly(c2.zeros, c2.gain), np.polymul(_poly(c1.poles), n2)))
    return np.trim_zeros(num, "f"), np.concatenate([c1.poles, c2.poles])


def _poly(roots: np.ndarray, gain: float = 1.0) -> np.ndarray:
    return gain * np.real(np.poly(roots)) if len(roots) else np.array([gain])


def _roots(poly: np.ndarray) -> np.ndarray:
    return np.roots(poly).astype(complex)


def _lead(poly: np.ndarray) -> float:
    return float(np.trim_zeros(poly, "f")[0])


def cancel_common_roots(zeros: np.ndarray, poles: np.ndarray,
                        rtol: float = CANCEL_TOLERANCE) -> tuple[np.ndarray, np.ndarray, int]:
    """Drop pole/zero pairs closer than rtol*|root| (both within INTEGRATOR_TOLERANCE of 0
    also cancel).  Conjugate partners go together because they are equally close."""
    zeros, poles = list(zeros), list(poles)
    kept_zeros, cancelled = [], 0
    for z in zeros:
        best = None
        for i, p in enumerate(poles):
            gap = abs(z - p)
            if gap <= rtol * max(abs(z), abs(p)) or max(abs(z), abs(p)) < INTEGRATOR_TOLERANCE:
                if best is None or gap < abs(z - poles[best]):
                    best = i
        if best is None:
            kept_zeros.append(z)
        else:
            poles.pop(best)
            cancelled += 1
    return np.array(kept_zeros, complex), np.array(poles, complex), cancelled


def _check_same_loop(partner, c0, c1, c2, n1, n2, d, where) -> None:
    w = 2j * np.pi * np.logspace(-2, math.log10(CONTROL_RATE_HZ / 2), 200)
    g1, g2 = np.polyval(n1, w) / np.polyval(d, w), np.polyval(n2, w) / np.polyval(d, w)
    la = partner.c0.response(w) * (partner.c1.response(w) * g1 + partner.c2.response(w) * g2)
    lb = c0.response(w) * (c1.response(w) * g1 + c2.response(w) * g2)
    err = float(np.max(np.abs(lb / la - 1)))
    if not err < 1e-6:
        raise DesignError(f"{where}: c0.equivalent_to: the computed c0 reproduces "
                          f"{partner.path.name}'s loop gain only to {err:.2g} (relative); the "
                          f"polynomials are too ill-conditioned, write c0 out instead")

