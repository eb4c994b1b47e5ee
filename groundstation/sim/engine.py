"""The simulation engine: owns the state arrays of the compiled core (core.py), builds
them from a testbed file and the active parameter table, and runs batches of control
periods.  Deterministic for a seed, whatever the batch sizes: the noise is drawn per
period from one numpy Generator, in order, and nothing else is random.
"""

from __future__ import annotations

import math
from typing import Any

import numpy as np

from . import core
from . import friction as fr
from ..core.dictionary import default_control_rate_hz
from ..plant.model import discrete_model
from ..plant.testbed import Testbed

SOS_SECTIONS_DEFAULT = 12
CONTROLLER_KEYS = ("relative_c0", "relative_c1", "relative_c2",
                   "inertial_c0", "inertial_c1", "inertial_c2")
DEG = math.pi / 180.0


class Engine:
    """Plant + sensors + firmware control law of one simulated testbed."""

    def __init__(self, testbed: Testbed, params: dict[str, Any], *, seed: int = 0,
                 control_rate_hz: float | None = None):
        """control_rate_hz: the firmware's loop rate (None: the protocol dictionary's)."""
        if control_rate_hz is None:
            control_rate_hz = default_control_rate_hz()
        self.testbed = testbed
        self.rate = control_rate_hz
        self.model = discrete_model(testbed, control_rate_hz)
        self._rng = np.random.default_rng(seed)
        s, m = testbed.sensors, testbed.mechanics
        self.x = np.zeros(8)
        k = np.zeros(core.K_SIZE)
        k[core.K_ENC_LSB] = 2 * math.pi / 2 ** s["encoder_bits"]
        k[core.K_BASE_LSB] = 2 * math.pi / 2 ** s["base_encoder_bits"]
        k[core.K_GYRO_LSB] = s["gyro_resolution"]
        k[core.K_GYRO_RANGE] = s["gyro_range"]
        k[core.K_AC_LSB] = s["autocollimator_range"] * DEG / (2 ** (s["autocollimator_bits"] - 1) - 1)
        k[core.K_ENC_NOISE] = s["encoder_noise"]
        k[core.K_AC_NOISE] = s["autocollimator_noise"]
        # angle random walk N [rad/sqrt(s)] -> white rate noise of N*sqrt(fs) per sample
        arw = s["gyro_arw"] * DEG / 60.0
        k[core.K_GYRO_SIGMA] = arw * math.sqrt(control_rate_hz)
        # bias: a constant draw with the bias-stability figure as its standard deviation
        k[core.K_GYRO_BIAS] = s["gyro_bias_stability"] * DEG / 3600.0 * float(self._rng.standard_normal())
        k[core.K_DELAY] = s["gyro_delay"] / self.model.substep
        k[core.K_INERTIAL] = 1.0 if testbed.inertial else 0.0
        k[core.K_TWO_DOF] = 1.0 if testbed.is_2dof else 0.0
        mc, mf = testbed.motor_coarse, testbed.motor_fine
        k[core.K_KT1], k[core.K_KT2] = mc["torque_constant"], mf["torque_constant"]
        k[core.K_R1], k[core.K_R2] = mc["resistance"], mf["resistance"]
        k[core.K_KE1], k[core.K_KE2] = mc["back_emf"], mf["back_emf"]
        k[core.K_PEAK1], k[core.K_PEAK2] = mc["peak_torque"], mf["peak_torque"]
        k[core.K_DT] = 1.0 / control_rate_hz
        k[core.K_SUBSTEPS] = testbed.substeps
        k[core.K_LOS_IDX] = self.model.los_index
        k[core.K_FLEX_SAFE] = m.get("flexure_safe_deflection", math.inf)
        ripple = testbed.bearing_ripple
        k[core.K_RIPPLE_AMP] = ripple["amplitude"]
        k[core.K_RIPPLE_WAVENUMBER] = 2 * math.pi / ripple["period"]
        k[core.K_RIPPLE_PHASE] = ripple["phase"]
        self.k = k
        self.gbuf = np.zeros(int(math.ceil(k[core.K_DELAY])) + 4)
        self.gpos = np.zeros(1, dtype=np.int64)
        # plant friction
        f = testbed.friction
        model = f["model"]
        self.plant_friction = None
        if model == "viscous":
            self.fparams = np.array([-1.0, 1.0, 1.0, 1.0])
            self.flut_x, self.flut_y = np.array([0.0, 2.0]), np.array([1.0, 0.0])
            plant_fp = fr.FrictionParams("DHM", 1.0, 1.0, 1.0, self.flut_x, self.flut_y, 8)
        else:
            lut_x, lut_y = fr.load_slope_table(testbed.slope_table_path)
            plant_fp = fr.FrictionParams(model, f["sigma"], f["coulomb_torque"], f["alpha"],
                                         lut_x, lut_y, f["stack_capacity"])
            self.fparams = np.array([fr.FRICTION_MODELS[model], f["sigma"],
                                     f["coulomb_torque"], f["alpha"]], dtype=np.float64)
            self.flut_x, self.flut_y = plant_fp.lut_x, plant_fp.lut_y
        self.fstate, self.fstack = fr.new_state(plant_fp, 0)
        self.fw = np.zeros(core.FW_SIZE)
        self.sos = np.zeros((6, SOS_SECTIONS_DEFAULT, 6))
        self.zs = np.zeros((6, SOS_SECTIONS_DEFAULT, 2))
        self.zs_new = np.zeros_like(self.zs)
        self.profile = np.zeros(1)
        self.events = np.zeros((32, 2))
        self.apply_parameters(params)
        # compile (or load from numba's cache) now, not in the first control period:
        # a device must answer its first command within the protocol's timeouts
        self.run(0)

    # ------------------------------------------------------------------ configuration
    def apply_parameters(self, p: dict[str, Any]) -> None:
        """Activate a (validated) parameter table; called between two control periods."""
        sos = np.array([np.asarray(p[key], dtype=np.float64) for key in CONTROLLER_KEYS])
        if sos.shape != self.sos.shape or not np.array_equal(sos, self.sos):
            self.sos = np.ascontiguousarray(sos)
            self.zs = np.zeros((6, sos.shape[1], 2))     # new filters start from rest
            self.zs_new = np.zeros_like(self.zs)
        fw = self.fw
        fw[core.FW_KP] = p["outer_loop_gain"]
        fw[core.FW_SAT1] = p["saturation_coarse"]
        fw[core.FW_SAT2] = p["saturation_fine"]
        fw[core.FW_WD_TICKS] = p["watchdog_timeout"] * self.rate
        fw[core.FW_TRAVEL] = p["travel_limit"]
        fw[core.FW_ANTI_WINDUP] = p["anti_windup"]
        tau = 1.0 / (2 * math.pi * p["complementary_crossover"])
        self.k[core.K_COMP_ALPHA] = tau / (tau + 1.0 / self.rate)
        npts = int(p["friction_comp_table_points"])
        self.clut_x = np.asarray(p["friction_comp_table_x"], dtype=np.float64)[:npts].copy()
        self.clut_y = np.asarray(p["friction_comp_table_slope"], dtype=np.float64)[:npts].copy()
        self.cparams = np.array([p["friction_comp_model"], p["friction_comp_sigma"],
                                 p["friction_comp_coulomb"], p["friction_comp_alpha"]], dtype=np.float64)
        comp_fp = fr.FrictionParams(
            {v: k for k, v in fr.FRICTION_MODELS.items()}[int(self.cparams[0])],
            max(self.cparams[1], 1e-9), max(self.cparams[2], 1e-9), self.cparams[3],
            self.clut_x, self.clut_y, 64)
        self.cstate, self.cstack = fr.new_state(comp_fp, 0)

    def reset_controllers(self) -> None:
        """Filter states to rest (on arming: no memory of an earlier run)."""
        self.zs[:] = 0.0
        self.zs_new[:] = 0.0

    def load_profile(self, samples: np.ndarray, target: int) -> None:
        self.profile = np.ascontiguousarray(samples, dtype=np.float64)
        self.fw[core.FW_PROF_TARGET] = target

    # ------------------------------------------------------------------ running
    def run(self, n: int, v_fg: np.ndarray | None = None, out: np.ndarray | None = None,
            ) -> tuple[dict[str, np.ndarray] | None, np.ndarray, list[tuple[int, int]]]:
        """n control periods -> (HIGH_RATE columns, truth array (n, 6), events [(tick, code)]).
        `out`: an (n, N_OUT) array to write the outputs into (a slice of a caller's
        larger batch, who makes the columns of the whole with `columns`); then the
        columns returned are None."""
        noise = self._rng.standard_normal((n, core.N_NOISE))
        if v_fg is None:
            v_fg = np.zeros(n)
        given = out is not None
        if not given:
            out = np.empty((n, core.N_OUT))
        truth = np.empty((n, core.N_TRUTH))
        n_ev = core.run_ticks(n, self.x, self.model.Ad, self.model.Bd, self.k, self.fw,
                              self.fstate, self.fstack, self.flut_x, self.flut_y, self.fparams,
                              self.cstate, self.cstack, self.clut_x, self.clut_y, self.cparams,
                              self.sos, self.zs, self.zs_new, self.gbuf, self.gpos, self.profile,
                              noise, np.ascontiguousarray(v_fg, dtype=np.float64), out, truth,
                              self.events)
        events = [(int(t), int(c)) for t, c in self.events[:n_ev]]
        return (None if given else self.columns(out)), truth, events

    @staticmethod
    def columns(out: np.ndarray) -> dict[str, np.ndarray]:
        """(n, N_OUT) outputs -> HIGH_RATE columns by name (views; status flags as bool)."""
        cols = {name: out[:, i] for i, name in enumerate(core.OUT_COLUMNS)}
        for flag in ("armed", "coarse_saturated", "fine_saturated", "profile_active",
                     "friction_comp_on", "fault"):
            cols[flag] = cols[flag] > 0.5
        return cols

    @property
    def tick(self) -> int:
        return int(self.fw[core.FW_TICK])
