"""A controller design and its testbed on a frequency grid: the PQ views' numbers.

`analyze(design)` evaluates, on one grid and with a handful of vectorised operations:

- the plant row G as the controller sees it: the testbed's g1, g2 (plant/model.py, the
  bearing friction linearised to b_f) of the LOS angle (relative mode) or of the LOS rate
  (inertial mode: s g1, s g2, times the gyro's second-order dynamics and its pure delay
  e^(-s T_d) when `sensor` is true - the delay is exact here, no Pade);
- the controller column K = c0 [c1', c2'] and its ratio Q = c1'/c2';
- P = g1/g2, PQ, the alignment phi and its PQ-plane value phi_PQ, and the loop and
  input-side functions of groundstation.params.pq.

These are the continuous design functions the reference's Ch. 4-5 work with.  The
margins of the loop the rig actually runs (sampled, ZOH, gyro delay, K_p) are the
validation's (loop.py); the time responses are the sampled loop's (pq_response.py).
In inertial mode the closed-loop functions here are the rate loop's (K_p = 0), the loop
the PQ design shapes.

`dc_input_sensitivity(design)` gives T_I(0) exactly: each transfer function's leading
term a s^n of its series at s = 0 is computed from its roots (integrators in c0, Q or the
plant counted as the powers n they are), and T_I(0) is the limit of the ratio of those
terms - no evaluation at a small s, no rounding.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from ..core.kinds import Setup
from .design_file import ControllerDesign
from .pq import LoopFunctions, alignment_deg, loop_functions, pq_alignment_deg
from .tf_algebra import CONTROL_RATE_HZ, INTEGRATOR_TOLERANCE, DesignError, TransferFunction

LOWEST_HZ = 0.1                     # the default grid: 0.1 Hz ...
GRID_POINTS = 800                   # ... to just below Nyquist, log-spaced


def frequency_grid(points: int = GRID_POINTS, lowest_hz: float = LOWEST_HZ,
                   highest_hz: float | None = None) -> np.ndarray:
    """Log-spaced frequencies in Hz, by default 0.1 Hz to just below the control Nyquist."""
    hi = highest_hz if highest_hz is not None else 0.999 * CONTROL_RATE_HZ / 2
    return np.logspace(math.log10(lowest_hz), math.log10(hi), points)


def _require_two_inputs(testbed) -> None:
    if not testbed.is_2dof:
        raise DesignError(f"PQ analysis needs a 2-DOF testbed (two inputs u1, u2); "
                          f"{testbed.path.name} is {testbed.configuration}")


def _plant_polynomials(testbed):
    from ..plant.model import plant_transfer_functions

    _require_two_inputs(testbed)
    return plant_transfer_functions(testbed)


def gyro_response(testbed, s: np.ndarray) -> np.ndarray:
    """The gyro's w_g^2 / (s^2 + 2 zeta_g w_g s + w_g^2) e^(-s T_d) at the points s."""
    sens = testbed.sensors
    wg = 2 * math.pi * sens["gyro_bandwidth"]
    return wg * wg / (s * s + 2 * sens["gyro_damping"] * wg * s + wg * wg) * np.exp(-s * sens["gyro_delay"])


def plant_row(testbed, s: np.ndarray, mode: str, sensor: bool = True) -> np.ndarray:
    """G at the points s, shape (len(s), 2): angle (relative) or rate (inertial, with the
    gyro if `sensor`), in rad or rad/s per in-oz."""
    (n1, den), (n2, _) = _plant_polynomials(testbed)
    s = np.asarray(s, complex)
    d = np.polyval(den, s)
    G = np.stack([np.polyval(n1, s) / d, np.polyval(n2, s) / d], axis=-1)
    if mode == Setup.INERTIAL:
        factor = s * (gyro_response(testbed, s) if sensor else 1.0)
        G = G * factor[:, None]
    return G


def controller_ratio(c1: TransferFunction, c2: TransferFunction, s: np.ndarray) -> np.ndarray:
    """[c1', c2'] at the points s, shape (len(s), 2)."""
    return np.stack([c1.response(s), c2.response(s)], axis=-1)


@dataclass(frozen=True, eq=False)
class PQAnalysis:
    """One design's PQ views on one grid (arrays indexed like freqs_hz)."""

    design: ControllerDesign
    freqs_hz: np.ndarray
    plant: np.ndarray               # (n, 2) G
    ratio: np.ndarray               # (n, 2) [c1', c2']
    controller: np.ndarray          # (n, 2) K = c0 [c1', c2']
    functions: LoopFunctions
    sensor: bool

    @property
    def p(self) -> np.ndarray:
        with np.errstate(divide="ignore", invalid="ignore"):
            return self.plant[:, 0] / self.plant[:, 1]

    @property
    def q(self) -> np.ndarray:
        """c1'/c2'; infinite where c2' = 0 (a design that uses the coarse motor only)."""
        with np.errstate(divide="ignore", invalid="ignore"):
            return self.ratio[:, 0] / self.ratio[:, 1]

    @property
    def pq(self) -> np.ndarray:
        with np.errstate(invalid="ignore"):
            return self.p * self.q

    @property
    def phi_deg(self) -> np.ndarray:
        """Eq. 4.9 with the inputs in their units (both in-oz)."""
        return alignment_deg(self.plant, self.ratio)

    @property
    def phi_pq_deg(self) -> np.ndarray:
        """phi_PQ: the same at the best input scaling (|P| = |Q|); <= phi_deg."""
        return pq_alignment_deg(self.pq)


def analyze(design: ControllerDesign, freqs_hz: np.ndarray | None = None,
            sensor: bool = True) -> PQAnalysis:
    """All of the design's frequency-domain PQ views on `freqs_hz` (default frequency_grid())."""
    f = frequency_grid() if freqs_hz is None else np.asarray(freqs_hz, float)
    s = 2j * np.pi * f
    G = plant_row(design.testbed, s, design.mode, sensor)
    C = controller_ratio(design.c1, design.c2, s)
    K = design.c0.response(s)[:, None] * C
    return PQAnalysis(design, f, G, C, K, loop_functions(G, K), sensor)


def ratio_alignment_deg(testbed, c1: TransferFunction, c2: TransferFunction,
                        freqs_hz: np.ndarray) -> np.ndarray:
    """phi of any controller ratio on a testbed, e.g. Q = 1 (c1' = c2' = 1) for reference."""
    s = 2j * np.pi * np.asarray(freqs_hz, float)
    return alignment_deg(plant_row(testbed, s, "relative"), controller_ratio(c1, c2, s))


# ======================================================================================
# T_I(0): leading terms at s = 0
# ======================================================================================
@dataclass(frozen=True)
class Leading:
    """The leading term coef * s^order of a transfer function's series at s = 0."""

    coef: float
    order: int

    def __mul__(self, other: "Leading") -> "Leading":
        return Leading(self.coef * other.coef, self.order + other.order)

    def __truediv__(self, other: "Leading") -> "Leading":
        return Leading(self.coef / other.coef, self.order - other.order)

    def value(self) -> float:
        """The limit at s = 0: coef (order 0), 0 (order > 0) or a signed infinity."""
        if self.order > 0:
            return 0.0
        if self.order < 0:
            return math.copysign(math.inf, self.coef)
        return self.coef


def leading_of_tf(tf: TransferFunction) -> Leading:
    at_zero_z = np.abs(tf.zeros) < INTEGRATOR_TOLERANCE
    at_zero_p = np.abs(tf.poles) < INTEGRATOR_TOLERANCE
    coef = tf.gain * np.prod(-tf.zeros[~at_zero_z]) / np.prod(-tf.poles[~at_zero_p])
    return Leading(float(np.real(coef)), int(at_zero_z.sum() - at_zero_p.sum()))


def leading_of_polynomials(num: np.ndarray, den: np.ndarray) -> Leading:
    """num/den with coefficients highest power first: the lowest nonzero coefficients,
    and the powers of s that divide each polynomial (its trailing zero coefficients)."""
    def low(p) -> tuple[float, int]:
        p = np.asarray(p, float)
        trimmed = np.trim_zeros(p, "b")
        return float(trimmed[-1]), len(p) - len(trimmed)
    (a, na), (b, nb) = low(num), low(den)
    return Leading(a / b, na - nb)


def leading_sum(terms: list[Leading]) -> Leading:
    """The leading term of a sum; ValueError if the lowest-order terms cancel exactly."""
    terms = [t for t in terms if t.coef != 0.0]
    if not terms:
        return Leading(0.0, 0)
    low = min(t.order for t in terms)
    coefs = [t.coef for t in terms if t.order == low]
    total = sum(coefs)
    if abs(total) <= 1e-12 * max(abs(c) for c in coefs):
        raise ValueError("the lowest-order terms at s = 0 cancel; T_I(0) needs more terms")
    return Leading(total, low)


@dataclass(frozen=True)
class DCMatrix:
    """T_I(0): rows u1, u2 (the torques), columns d1, d2 (the input disturbances)."""

    values: np.ndarray              # (2, 2) float, +-inf where the limit diverges
    loop_order: int                 # L ~ s^loop_order at s = 0 (-2: two integrators)

    def text(self, digits: int = 3) -> str:
        def num(x):
            return f"{x:.{digits}g}" if math.isfinite(x) else ("inf" if x > 0 else "-inf")
        rows = ["[" + ", ".join(num(x + 0.0) for x in row) + "]" for row in self.values]
        return "[" + ", ".join(rows) + "]"


def dc_input_sensitivity(design: ControllerDesign) -> DCMatrix:
    """T_I(0) = lim_{s->0} K G / (1 + G K) from the leading terms at s = 0.

    The gyro's dynamics and delay are 1 at s = 0 and do not enter; the inertial rate
    output adds one power of s to both g1 and g2."""
    (n1, den), (n2, _) = _plant_polynomials(design.testbed)
    extra = 1 if design.mode == Setup.INERTIAL else 0
    g = [leading_of_polynomials(n, den) for n in (n1, n2)]
    g = [Leading(t.coef, t.order + extra) for t in g]
    c0 = leading_of_tf(design.c0)
    k = [c0 * leading_of_tf(design.c1), c0 * leading_of_tf(design.c2)]
    loop = leading_sum([k[0] * g[0], k[1] * g[1]])
    if loop.order < 0:
        ret = loop
    elif loop.order > 0:
        ret = Leading(1.0, 0)
    else:
        ret = leading_sum([Leading(1.0, 0), loop])
    values = np.array([[(k[i] * g[j] / ret).value() for j in range(2)] for i in range(2)])
    return DCMatrix(values, loop.order)
