"""The PQ method's alignment and input-side closed-loop functions, on frequency grids.

A two-input, single-output (TISO) plant is a row G = [g1, g2] (u1 coarse torque, u2 fine
torque -> the measured output); a SITO controller is a column K = c0 [c1', c2']^T.  The
loop is the scalar L = G K = c0 (c1' g1 + c2' g2) (no conjugation: it is a product of
transfer functions).  Everything here works on arrays of complex values at the points of
a frequency grid, last axis = the two inputs, so a whole grid is a few numpy operations.

Alignment (the reference's Eq. 4.9)
-----------------------------------
    cos phi = |G C| / (||G|| ||C||),   ||.|| the Euclidean norm of the complex 2-vector,

with C = [c1', c2'] (or K: a scalar factor such as c0 changes nothing).  By Cauchy-Schwarz
|sum g_i c_i| <= ||G|| ||C||, with equality exactly when C is parallel to G^H (the
conjugate transpose of G), so cos phi is in [0, 1] and phi in [0, 90] deg:

- phi = 0: the controller drives the inputs in the one direction in which the plant is
  most effective.  The smallest input ||K|| = |L| / ||G|| then gives the loop: the TISO
  loop acts like a SISO loop on a plant of gain ||G|| - the best case.
- phi = 90 deg: G C = 0, the two paths cancel at the output (PQ = -1 below).

phi is unchanged by any scalar factor of G or of C: the rate output's s, the gyro's
dynamics and delay and c0 do not move it, so the angle and the rate loops align alike.
It does change with the units of the inputs (both are torques in in-oz here).

Input-side closed-loop functions (exact, because K G is a rank-one 2x2 matrix)
------------------------------------------------------------------------------
With the input disturbance d added to the torques, u = -T_I d with

    T_I = K G / (1 + L)              (2x2; T_I[i, j]: from d_j to u_i, rows u1, u2)
    ||T_I|| = ||K|| ||G|| / |1 + L| = |T_O| / cos phi          (largest singular value)
    S_I K = (I + K G)^-1 K = K / (1 + L),  ||S_I K|| = |T_O| / (||G|| cos phi)

(S_I K: from the reference or an output disturbance to u.)  T_O = L / (1 + L) and
S_O = 1 / (1 + L) are the output side.  So |T_O| and |T_O| / ||G|| are the perfect-
alignment bounds, reached only at phi = 0: misalignment costs 1 / cos phi in input size.

The contours in the (|PQ|, angle PQ) plane (our derivation)
------------------------------------------------------------
With P = g1/g2, Q = c1'/c2': G = g2 [P, 1], C = c2' [Q, 1] and

    cos phi = |1 + PQ| / ( sqrt(1 + |P|^2) sqrt(1 + |Q|^2) ),

which depends on |P| and |Q| separately, not only on PQ.  For a given m = |PQ|,
(1 + |P|^2)(1 + |Q|^2) = 1 + m^2 + |P|^2 + |Q|^2 >= (1 + m)^2, equality iff |P| = |Q|, so

    phi >= phi_PQ,   cos phi_PQ = |1 + PQ| / (1 + |PQ|)          (Eq. A)

with equality exactly when |P| = |Q|.  Rescaling the inputs' units (u1 -> w u1) maps
P -> w P and Q -> Q / w and changes neither PQ nor the loop; phi_PQ is the alignment at
the best such scaling w = sqrt(|Q / P|) (the smallest phi over diagonal input scalings).
That is the only sense in which the alignment is a function of (|PQ|, angle PQ): contour
plots in that plane hold under the assumption |P| = |Q| and bound phi from below
otherwise.  Eq. A's worst cases over one coordinate give contours that depend on the
other alone, which is what can be drawn on the two panels of a PQ Bode plot:

- magnitude contour (worst over the phase, at angle PQ = 180 deg):
      phi_mag(|PQ|) = arccos(|1 - |PQ|| / (1 + |PQ|));  phi_mag <= a  iff
      |PQ| <= tan^2(a/2) or |PQ| >= cot^2(a/2),  i.e.  | |PQ|_dB | >= 40 log10 cot(a/2);
- phase contour (worst over the magnitude, at |PQ| = 1):
      phi_phase(angle PQ) = |angle PQ| / 2  (angle wrapped to [-180, 180] deg);
      phi_phase <= a  iff  |angle PQ| <= 2a.

phi_PQ <= min(phi_mag, phi_phase) at every point.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

#: the alignment levels the contour plots fill between, deg
CONTOUR_LEVELS_DEG = (0.0, 15.0, 30.0, 45.0, 60.0, 75.0, 90.0)


def cos_alignment(G: np.ndarray, C: np.ndarray) -> np.ndarray:
    """Eq. 4.9 as written, |G C| / (||G|| ||C||) along the last axis (the inputs); 0 where
    either is zero.  alignment_deg gives the angle (more precisely than arccos of this)."""
    G, C = np.asarray(G, complex), np.asarray(C, complex)
    num = np.abs(np.sum(G * C, axis=-1))
    den = np.linalg.norm(G, axis=-1) * np.linalg.norm(C, axis=-1)
    with np.errstate(invalid="ignore", divide="ignore"):
        return np.where(den > 0, num / np.where(den > 0, den, 1.0), 0.0)


def alignment_deg(G: np.ndarray, C: np.ndarray) -> np.ndarray:
    """The alignment angle phi in deg, [0, 90], of plant rows G and controller columns C
    (arrays (..., 2)): Eq. 4.9, see the module's docstring.

    Computed as atan2(sin, cos) so that it stays exact near 0 deg, where arccos of a
    cosine rounded to 1 loses half the digits: for two-vectors (Lagrange's identity)
    ||G||^2 ||C||^2 - |G C|^2 = |conj(g1) c2 - conj(g2) c1|^2."""
    G, C = np.asarray(G, complex), np.asarray(C, complex)
    dot = np.abs(np.sum(G * C, axis=-1))
    cross = np.abs(np.conj(G[..., 0]) * C[..., 1] - np.conj(G[..., 1]) * C[..., 0])
    return np.degrees(np.arctan2(cross, dot))


def pq_alignment_deg(pq: np.ndarray) -> np.ndarray:
    """phi_PQ (Eq. A): the alignment for this PQ when |P| = |Q|, a lower bound otherwise.

    tan phi_PQ = 2 sqrt(|PQ|) |sin(angle PQ / 2)| / |1 + PQ| (the sine from Eq. A).  An
    infinite or undefined PQ (one path unused: c2' = 0) gives the limit |PQ| -> inf, 0."""
    pq = np.asarray(pq, complex)
    finite = np.isfinite(pq)
    pq = np.where(finite, pq, 0.0)
    m = np.abs(pq)
    phi = np.degrees(np.arctan2(2 * np.sqrt(m) * np.abs(np.sin(np.angle(pq) / 2)),
                                np.abs(1.0 + pq)))
    return np.where(finite, phi, 0.0)


def magnitude_contour_deg(pq_abs: np.ndarray) -> np.ndarray:
    """phi_mag: the worst phi_PQ over all phases at this |PQ| (at angle PQ = 180 deg)."""
    m = np.asarray(pq_abs, float)
    return np.degrees(np.arctan2(2 * np.sqrt(m), np.abs(1.0 - m)))


def phase_contour_deg(pq_angle_deg: np.ndarray) -> np.ndarray:
    """phi_phase: the worst phi_PQ over all magnitudes at this angle (at |PQ| = 1)."""
    wrapped = (np.asarray(pq_angle_deg, float) + 180.0) % 360.0 - 180.0
    return np.abs(wrapped) / 2.0


def magnitude_band_db(level_deg: float) -> float:
    """The |PQ| (dB, >= 0) outside +-which phi_PQ <= level whatever the phase:
    40 log10 cot(level/2); inf at level 0, 0 at level 90 deg."""
    half = np.radians(level_deg) / 2.0
    if half <= 0.0:
        return float("inf")
    return float(40.0 * np.log10(1.0 / np.tan(half)))


def phase_band_deg(level_deg: float) -> float:
    """The |angle PQ| within which phi_PQ <= level whatever the magnitude: 2 level."""
    return float(min(2.0 * level_deg, 180.0))


def input_sensitivity_matrix(G: np.ndarray, K: np.ndarray) -> np.ndarray:
    """T_I = K G / (1 + G K), shape (..., 2, 2); T_I[..., i, j] is from d_j to u_i."""
    G, K = np.asarray(G, complex), np.asarray(K, complex)
    L = np.sum(G * K, axis=-1)
    return K[..., :, None] * G[..., None, :] / (1.0 + L)[..., None, None]


@dataclass(frozen=True, eq=False)
class LoopFunctions:
    """The scalar loop and the input-side norms at each frequency (arrays of one shape)."""

    loop: np.ndarray                # L = G K, complex
    phi_deg: np.ndarray             # alignment of G and K
    plant_norm: np.ndarray          # ||G||
    controller_norm: np.ndarray     # ||K||

    @property
    def t_out(self) -> np.ndarray:
        """T_O = L / (1 + L)."""
        return self.loop / (1.0 + self.loop)

    @property
    def s_out(self) -> np.ndarray:
        """S_O = 1 / (1 + L)."""
        return 1.0 / (1.0 + self.loop)

    @property
    def ti_norm(self) -> np.ndarray:
        """||T_I|| = ||K|| ||G|| / |1 + L| (= |T_O| / cos phi)."""
        return self.controller_norm * self.plant_norm / np.abs(1.0 + self.loop)

    @property
    def sik_norm(self) -> np.ndarray:
        """||S_I K|| = ||K|| / |1 + L| (= |T_O| / (||G|| cos phi))."""
        return self.controller_norm / np.abs(1.0 + self.loop)

    @property
    def ti_bound(self) -> np.ndarray:
        """|T_O|: ||T_I|| at perfect alignment."""
        return np.abs(self.t_out)

    @property
    def sik_bound(self) -> np.ndarray:
        """|T_O| / ||G||: ||S_I K|| at perfect alignment."""
        return np.abs(self.t_out) / self.plant_norm

    @property
    def cos_phi(self) -> np.ndarray:
        return np.cos(np.radians(self.phi_deg))


def loop_functions(G: np.ndarray, K: np.ndarray) -> LoopFunctions:
    """L, phi, ||G||, ||K|| for plant rows G and controller columns K (arrays (..., 2))."""
    G, K = np.asarray(G, complex), np.asarray(K, complex)
    return LoopFunctions(np.sum(G * K, axis=-1), alignment_deg(G, K),
                         np.linalg.norm(G, axis=-1), np.linalg.norm(K, axis=-1))
