"""Interim plant of the simulated device: the 1-DOF rigid configuration.

J*theta'' = K_t*i - b_f*theta' (reference §4 with linear viscous bearing friction only),
sensors quantised to their wire resolution.  The simulated-testbed work replaces this
with the 1-/2-DOF models, the four friction models and the full sensor models.
"""

from __future__ import annotations

import math

import numpy as np

LB_IN2_TO_IN_OZ_S2 = 0.04144          # reference: 1 lb-in^2 = 0.04144 in-oz-s^2


class RigidPlant:
    def __init__(self, seed: int = 0, inertia_lb_in2: float = 47.87, b_f: float = 20.0,
                 kt: tuple[float, float] = (32.5, 16.1), resistance: tuple[float, float] = (4.8, 6.8),
                 back_emf: float = 0.227, gyro_noise_rad_s: float = 2e-6):
        self.J = inertia_lb_in2 * LB_IN2_TO_IN_OZ_S2
        self.b_f = b_f
        self.kt = kt
        self.R = resistance
        self.ke = back_emf
        self.i_max = (81.3 / kt[0], 16.1 / kt[1])
        self.angle = 0.0
        self.rate = 0.0
        self._rng = np.random.default_rng(seed)
        self._gyro_noise = gyro_noise_rad_s

    def step(self, i1: float, i2: float, dt: float) -> dict[str, float]:
        i1 = max(-self.i_max[0], min(self.i_max[0], i1))
        i2 = max(-self.i_max[1], min(self.i_max[1], i2))
        torque = self.kt[0] * i1 + self.kt[1] * i2      # rigid: both act on the one body
        # semi-implicit Euler, stable for the viscous term at 1200 Hz (b_f*dt/J << 1)
        self.rate += dt * (torque - self.b_f * self.rate) / self.J
        self.angle += dt * self.rate
        ac_range = math.radians(0.33)
        return {
            "encoder_outer": self.angle, "encoder_inner": self.angle, "encoder_base": 0.0,
            "gyro_rate": self.rate + self._gyro_noise * float(self._rng.standard_normal()),
            "autocollimator": max(-ac_range, min(ac_range, self.angle)),
            "los_estimate": self.angle,
            "current_coarse": i1, "current_fine": i2,
            "voltage_coarse": self.R[0] * i1 + self.ke * self.rate,
            "voltage_fine": self.R[1] * i2,
        }
