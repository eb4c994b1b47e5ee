"""The testbed's linear dynamics as one state-space system, discretised exactly.

Equations of motion of reference §4, with the bearing's Dahl friction torque left as an
input (it is the only nonlinearity), plus the base stage and the gyro's second-order
dynamics, so one matrix product per substep advances everything:

    x = [theta1, omega1, theta2, omega2, theta_b, omega_b, gyro, gyro_rate]
    u = [T1 (coarse motor), T2 (fine motor), T_dahl (bearing), v_fg (generator volts)]

    J1 w1' = T1 - T2 - T_dahl - b_f (w1 - w_b) + b (w2 - w1) + k (theta2 - theta1)
    J2 w2' = T2 - b (w2 - w1) - k (theta2 - theta1)
    theta_b'' = -2 zeta_s w_s theta_b' - w_s^2 theta_b + w_s^2 K_amp K_act v_fg
    gyro''    = w_g^2 (w2 - gyro) - 2 zeta_g w_g gyro'

The 1-DOF rigid configuration has no flexure and no fine motor: theta2 = theta1 (the
core reads the LOS from theta1) and J = J1.  The discretisation is the exact zero-order
hold (matrix exponential) at the substep, so with friction linearised (k_f = 0) the
simulated response equals the ZOH discretisation of g1(s), g2(s): no integration error.
"""

from __future__ import annotations

import functools
import math
from dataclasses import dataclass

import numpy as np

from ..core.dictionary import default_control_rate_hz
from ..core.numerics_cache import cached_arrays, scipy_version
from .testbed import Testbed

N_STATE = 8
N_INPUT = 4
TH1, W1, TH2, W2, THB, WB, GY, GYD = range(N_STATE)


@dataclass(frozen=True)
class DiscreteModel:
    Ad: np.ndarray            # (8, 8)
    Bd: np.ndarray            # (8, 4)
    substep: float            # s
    los_index: int            # state index of the LOS inertial angle (theta2, or theta1 rigid)
    los_rate_index: int


def continuous_model(tb: Testbed) -> tuple[np.ndarray, np.ndarray]:
    A = np.zeros((N_STATE, N_STATE))
    B = np.zeros((N_STATE, N_INPUT))
    m = tb.mechanics
    bf = m["bearing_viscous"]
    A[TH1, W1] = 1.0
    if tb.is_2dof:
        J1, J2, k, b = m["J1"], m["J2"], m["flexure_stiffness"], m["flexure_damping"]
        A[W1, TH1], A[W1, TH2] = -k / J1, k / J1
        A[W1, W1], A[W1, W2], A[W1, WB] = -(b + bf) / J1, b / J1, bf / J1
        B[W1, 0], B[W1, 1], B[W1, 2] = 1.0 / J1, -1.0 / J1, -1.0 / J1
        A[TH2, W2] = 1.0
        A[W2, TH1], A[W2, TH2] = k / J2, -k / J2
        A[W2, W1], A[W2, W2] = b / J2, -b / J2
        B[W2, 1] = 1.0 / J2
        los_rate = W2
    else:
        J = m["J"]
        A[W1, W1], A[W1, WB] = -bf / J, bf / J
        B[W1, 0], B[W1, 2] = 1.0 / J, -1.0 / J
        los_rate = W1
    base = tb.base_stage
    A[THB, WB] = 1.0
    if base.get("enabled"):
        ws = 2 * math.pi * base["natural_frequency"]
        A[WB, THB], A[WB, WB] = -ws * ws, -2 * base["damping"] * ws
        B[WB, 3] = ws * ws * base["amplifier_gain"] * base["actuator_gain"]
    s = tb.sensors
    wg = 2 * math.pi * s["gyro_bandwidth"]
    A[GY, GYD] = 1.0
    A[GYD, GY], A[GYD, GYD], A[GYD, los_rate] = -wg * wg, -2 * s["gyro_damping"] * wg, wg * wg
    return A, B


def discretise(A: np.ndarray, B: np.ndarray, h: float) -> tuple[np.ndarray, np.ndarray]:
    """Exact zero-order-hold discretisation: expm([[A, B], [0, 0]] h).

    Remembered for the last few (A, B, h), and kept on disk (core/numerics_cache.py):
    the design workbench re-derives its sampled loop on every edit of a controller,
    while the plant stays the same, and the stiff gyro dynamics make each matrix
    exponential cost milliseconds.  Callers get copies."""
    A, B = np.asarray(A, dtype=float), np.asarray(B, dtype=float)
    Ad, Bd = _discretised(A.shape, A.tobytes(), B.shape, B.tobytes(), float(h))
    return Ad.copy(), Bd.copy()


@functools.lru_cache(maxsize=16)
def _discretised(a_shape, a_bytes, b_shape, b_bytes, h):
    A = np.frombuffer(a_bytes).reshape(a_shape)
    B = np.frombuffer(b_bytes).reshape(b_shape)
    n, m = B.shape

    def compute():
        # scipy.linalg only here, and only for a plant not sampled before: a campaign's
        # upload check would otherwise import it (0.1 s) for one exponential
        # (core/numerics_cache.py); the simulator's child imports it anyway, numba does
        from scipy.linalg import expm

        M = np.zeros((n + m, n + m))
        M[:n, :n], M[:n, n:] = A, B
        E = expm(M * h)
        return E[:n, :n].copy(), E[:n, n:].copy()

    def valid(arrays) -> bool:
        return len(arrays) == 2 and arrays[0].shape == (n, n) and arrays[1].shape == (n, m)

    return cached_arrays("zero_order_hold", scipy_version(), (A, B, float(h)), compute, valid)


def discrete_model(tb: Testbed, control_rate_hz: float | None = None) -> DiscreteModel:
    """The testbed's model discretised for tb.substeps steps per control period
    (control_rate_hz None: the protocol dictionary's rate)."""
    if control_rate_hz is None:
        control_rate_hz = default_control_rate_hz()
    h = 1.0 / (control_rate_hz * tb.substeps)
    Ad, Bd = discretise(*continuous_model(tb), h)
    if not np.all(np.isfinite(Ad)) or np.max(np.abs(np.linalg.eigvals(Ad))) > 1.0 + 1e-12:
        raise ValueError(f"{tb.path}: the discretised model is unstable at {tb.substeps} substeps")
    los = TH2 if tb.is_2dof else TH1
    return DiscreteModel(Ad, Bd, h, los, W2 if tb.is_2dof else W1)


def plant_transfer_functions(tb: Testbed) -> tuple[tuple[np.ndarray, np.ndarray], tuple[np.ndarray, np.ndarray]]:
    """g1(s), g2(s) of reference §4 (u1, u2 -> LOS angle) with k_f = 0, as (num, den)."""
    m = tb.mechanics
    J1, J2, k, b, bf = m["J1"], m["J2"], m["flexure_stiffness"], m["flexure_damping"], m["bearing_viscous"]
    Jeff = J1 * J2 / (J1 + J2)
    D = np.polyadd(np.polymul([1, 0, 0], [1, b / Jeff, k / Jeff]),
                   np.polymul([bf / J1, 0], [1, b / J2, k / J2]))
    g1 = (np.array([b / (J1 * J2), k / (J1 * J2)]), D)
    g2 = (np.polymul([1.0 / J2, 0], [1, bf / J1]), D)
    return g1, g2
