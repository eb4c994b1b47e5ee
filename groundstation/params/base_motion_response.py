"""The linear response of the continuous inertial loop to base motion, per frequency.

Base motion theta_b reaches the rig only through the bearing of the outer axis
(testbed.md §4): T_f = k_f phi1 + b_f phi1', phi1 = theta1 - theta_b.  The reference's
design model takes k_f = 0, and so does this module: theta_b then acts as a torque
d = b_f s theta_b added to the coarse motor's u1 (the rest of T_f, -b_f s theta1, is
already in the plant's D(s)).  With the rate error e = -(K_p H_est + s G e^{-sT}) theta2
= -S theta2 and P = c0 (c1' g1 + c2' g2):

    theta2 / theta_b = b_f s g1 / (1 + P S)
    u_k / theta_b    = -c0 c_k' S theta2 / theta_b          (k = 1 coarse, 2 fine)

and the motor currents are i_k = u_k / K_t,k.  Because theta_b enters as a coarse-axis
torque, any ratio between two designs here equals the ratio for a disturbance torque on
the coarse axis.  Only the base motion is in these responses: the loop's own lightly
damped 22.8 Hz mode (a pole on the stability boundary) is not excited by them.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from .continuous_loop import ContinuousLoop


@dataclass(frozen=True)
class BaseMotionResponse:
    """Complex responses per radian of base angle at `frequency_hz` (arrays)."""

    frequency_hz: np.ndarray
    los_rad_per_rad: np.ndarray            # theta2 / theta_b
    coarse_in_oz_per_rad: np.ndarray       # u1 / theta_b
    fine_in_oz_per_rad: np.ndarray         # u2 / theta_b
    coarse_a_per_rad: np.ndarray           # i1 / theta_b
    fine_a_per_rad: np.ndarray             # i2 / theta_b
    coarse_resistance_ohm: float
    fine_resistance_ohm: float

    @property
    def power_w_per_rad2(self) -> np.ndarray:
        """|i1|^2 R1 + |i2|^2 R2 per rad^2 of base angle: times a PSD (rad^2/Hz) it is the
        power's spectral density; for a sine of amplitude A the mean power is this A^2/2."""
        return (np.abs(self.coarse_a_per_rad) ** 2 * self.coarse_resistance_ohm
                + np.abs(self.fine_a_per_rad) ** 2 * self.fine_resistance_ohm)


def base_motion_response(loop: ContinuousLoop, testbed, frequency_hz) -> BaseMotionResponse:
    """theta2, u1, u2, i1, i2 per theta_b of `loop` on `testbed` (its motors' K_t and R)."""
    f = np.atleast_1d(np.asarray(frequency_hz, dtype=float))
    s = 2j * np.pi * f
    g1 = np.polyval(loop.g1[0], s) / np.polyval(loop.g1[1], s)
    sensed = loop.sensed(s)
    los = loop.bearing_viscous_in_oz_s_per_rad * s * g1 / (1 + loop.plant_path(s) * sensed)
    error = -sensed * los                          # rate error per theta_b
    u1 = loop.c0.response(s) * loop.c1.response(s) * error
    u2 = loop.c0.response(s) * loop.c2.response(s) * error
    mc, mf = testbed.motor_coarse, testbed.motor_fine
    return BaseMotionResponse(f, los, u1, u2, u1 / mc["torque_constant"], u2 / mf["torque_constant"],
                              float(mc["resistance"]), float(mf["resistance"]))
