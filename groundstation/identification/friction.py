"""The bearing's friction identified from closed-loop position logs: the running friction
against velocity (T_c and the viscous b_f) and the data-based Dahl model's slope table
from hysteresis loops.

Which log serves what is read off the log, not its name: every log that plays a
position-reference profile is scanned for constant-velocity passes
(analysis.log_friction_velocity; only the settled ones count), and for a hysteresis
loop (analysis.log_hysteresis; at least a whole cycle).  A loop serves the slope table
only when it was driven quasi-statically — the viscous torque b_f·ω at its speed below
QUASI_STATIC_FRACTION of T_c — since the table is the slope of friction alone; a fast
ramp's "loop" carries b_f·ω and inertia too.

The friction torque is made from the channels with the *identified* linear plant (the
fine motor's K_t and the flexure stiffness k enter T_f = K_t1·i1 − K_t2·i2 + k·(φ2 − φ1)):
with the base file's k on a rig whose flexure is 12 % softer, the table's first points
came out 20 % high on the twin, with the identified one within 7 %.

What is written:
- friction.coulomb_torque: the zero-speed intercept of the running-friction fit
  T = T0 + T_c·sgn(ω) + b_f·ω across all settled passes (the loops' own T_c estimate,
  each branch extrapolated to its plateau, is reported beside it as a cross-check);
  held when the sweep has no pass.
- mechanics.bearing_viscous: the slope of the same fit, given passes at two speeds or
  more (the frequency-response fit sees only an effective damping: pipeline.py).
- the slope table: with a data-based model only σ·f(x) is measured, so σ is held at the
  base value and the table carries the product (f = measured slope / σ_base), normalised
  with the written T_c.  Grid points no branch reached keep friction_id's fill (the tail
  down to f(2) = 0).  An analytic model (DHM, SFM) has no table: σ is then the turnaround
  slope over 2^α.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from pathlib import Path
from typing import Sequence

import numpy as np
from scipy import signal, stats

from ..analysis.friction_id import FrictionIdError, combine_tables, identify_friction
from ..analysis.friction_velocity import CoulombViscousFit, coulomb_viscous_fit
from ..analysis.log_friction_velocity import LogFrictionVelocity, friction_velocity_from_log
from ..analysis.log_hysteresis import LogHysteresis, hysteresis_from_log
from ..analysis.log_window import LogIdentificationError
from ..analysis.plant_fit import ParameterEstimate
from ..core.errors import GroundStationError
from ..plant.slope_table import load_slope_table
from ..plant.testbed import Testbed
from ..sim.friction import FrictionParams, simulate_friction

#: a loop serves the slope table when b_f·ω stays below this fraction of T_c
QUASI_STATIC_FRACTION = 0.02

def _t95(dof: int) -> float:
    """The two-sided 95 % quantile of Student's t with `dof` degrees of freedom: a handful
    of branches or passes is not a normal sample."""
    return float(stats.t.ppf(0.975, max(int(dof), 1)))

COULOMB = ("friction", "coulomb_torque", "in-oz")
VISCOUS = ("mechanics", "bearing_viscous", "in-oz-s/rad")
SIGMA = ("friction", "sigma", "in-oz/rad")
TABLE_START = ("friction", "slope_table f(0)", "")


@dataclass(frozen=True, eq=False)
class LoopCurves:
    """A measured hysteresis loop with both friction models along its angle."""
    source: str
    angle_rad: np.ndarray
    measured_in_oz: np.ndarray
    base_in_oz: np.ndarray
    identified_in_oz: np.ndarray


@dataclass(frozen=True, eq=False)
class FrictionFit:
    loops: tuple[LogHysteresis, ...]          # the quasi-static loops the table came from
    sweeps: tuple[LogFrictionVelocity, ...]   # every log with a settled constant-velocity pass
    running: CoulombViscousFit | None          # T = T0 + T_c sgn(w) + b_f w over the passes
    estimates: tuple[ParameterEstimate, ...]
    slope_table: tuple[np.ndarray, np.ndarray, np.ndarray] | None   # x, f, identified points
    base_params: FrictionParams
    identified_params: FrictionParams
    notes: tuple[str, ...]

    @property
    def written(self) -> dict[str, float]:
        return {e.name: e.value for e in self.estimates
                if e.status == "identified" and e.name != ".".join(TABLE_START[:2])}

    def loop_curves(self) -> list[LoopCurves]:
        """Each loop's measured torque and both models' along its measured angle (each
        model starting from the measured torque, moving the way the record first moves).

        The models are driven by the angle low-passed without phase shift: the encoder's
        noise is a reversal every few samples, and each reversal restarts a Dahl branch at
        its steepest slope, which drags the model's torque behind by about a tenth of T_c
        (measured on the twin) - the noise is the encoder's, not the bearing's motion."""
        out = []
        for lh in self.loops:
            angle, torque = lh.loop.angle_rad, lh.loop.torque_in_oz
            motion = _smooth_angle(angle, lh.frames / max(lh.window_to_s - lh.window_from_s, 1e-9))
            # from the first reversal on: before it the bearing's friction state is unknown
            # (what the closed loop left it in), and a model started there would carry that
            # guess through its memory of the later branches
            k = int(lh.loop.reversal_indices[0])
            direction = lh.loop.branches[0].direction
            curves = []
            for p in (self.base_params, self.identified_params):
                model = np.full(angle.size, np.nan)
                t0 = float(np.clip(torque[k], -p.T_c, p.T_c))
                model[k:] = simulate_friction(motion[k:], p, initial_direction=direction, T0=t0)
                curves.append(model)
            out.append(LoopCurves(lh.path.name, angle, torque, *curves))
        return out


#: the model's angle is low-passed here (Hz): far above a friction test's triangle
#: (0.001-0.01 deg/s over +-0.01-0.05 deg: periods of tens of seconds), far below the
#: encoder noise's band
MOTION_CUTOFF_HZ = 2.0


def _smooth_angle(angle: np.ndarray, rate_hz: float) -> np.ndarray:
    if angle.size < 20 or not rate_hz > 4 * MOTION_CUTOFF_HZ:
        return angle
    sos = signal.butter(2, MOTION_CUTOFF_HZ, fs=rate_hz, output="sos")
    return signal.sosfiltfilt(sos, angle)


def friction_params(tb: Testbed, *, coulomb: float | None = None, sigma: float | None = None,
                    table: tuple[np.ndarray, np.ndarray] | None = None) -> FrictionParams:
    """The simulator's friction parameters of `tb`, with the values given replaced."""
    fr = tb.friction
    model = fr["model"] if fr["model"] != "viscous" else "DHM"
    lut = table if table is not None else (load_slope_table(tb.slope_table_path)
                                           if model.startswith("DB-") else (None, None))
    return FrictionParams(model=model, sigma=float(sigma or fr["sigma"]),
                          T_c=float(coulomb or fr["coulomb_torque"]), alpha=float(fr["alpha"]),
                          lut_x=lut[0], lut_y=lut[1], stack_capacity=int(fr["stack_capacity"]))


def _scan(path: Path, plant: Testbed, notes: list[str]):
    """(the log's settled constant-velocity passes or None, its loop or None)."""
    loop = None
    try:
        sweep = friction_velocity_from_log(path, drive_channel="current_coarse", testbed=plant)
    except LogIdentificationError:            # no constant-velocity pass: not a sweep log
        sweep = None
    if sweep is not None and not any(s.settled for s in sweep.result.segments):
        sweep = None                          # passes, but none settled: no running friction
    try:
        loop = hysteresis_from_log(path, testbed=plant)
    except LogIdentificationError as exc:
        notes.append(f"{path.name}: no hysteresis loop ({exc})")
    if loop is not None and sum(b.complete for b in loop.loop.branches) < 2:
        loop = None                           # a single pass, not a cycle
    return sweep, loop


def _loop_speed(lh: LogHysteresis) -> float:
    """The loop's mean speed (rad/s): its whole path over its duration."""
    duration = max(lh.window_to_s - lh.window_from_s, 1e-9)
    return float(np.sum(np.abs(np.diff(lh.loop.angle_rad)))) / duration


def _running_fit(sweeps: Sequence[LogFrictionVelocity]) -> CoulombViscousFit | None:
    v = [s.velocity_rad_s for lf in sweeps for s in lf.result.segments if s.settled]
    t = [s.torque_in_oz for lf in sweeps for s in lf.result.segments if s.settled]
    return coulomb_viscous_fit(v, t) if v else None


def _estimate(base: Testbed, what: tuple[str, str, str], value: float, sd: float | None,
              sources: Sequence[str], *, status: str = "identified", reason: str = "",
              dof: int = 1) -> ParameterEstimate:
    section, key, units = what
    b = float(getattr(base, section)[key])
    t = _t95(dof)
    ci = None if sd is None or status != "identified" else (value - t * sd, value + t * sd)
    return ParameterEstimate(f"{section}.{key}", units, b, value, ci, status, reason,
                             tuple(sources))


def _held(base: Testbed, what, reason: str) -> ParameterEstimate:
    section, key, _ = what
    return _estimate(base, what, float(getattr(base, section)[key]), None, (),
                     status="held (no data)", reason=reason)


def _coulomb_and_viscous(base: Testbed, running: CoulombViscousFit | None,
                         sweeps, loops, notes: list[str]) -> list[ParameterEstimate]:
    if running is None:
        return [_held(base, COULOMB, "no settled constant-velocity pass: record the "
                                     "steady_state_friction campaign"),
                _held(base, VISCOUS, "no settled constant-velocity pass")]
    names = [lf.path.name for lf in sweeps]
    out = [_estimate(base, COULOMB, running.coulomb_in_oz, running.coulomb_sd_in_oz, names,
                     dof=running.dof)]
    if running.viscous_in_oz_s_per_rad is None:
        out.append(_held(base, VISCOUS, "constant-velocity passes at one speed only: the "
                                        "slope needs two speeds or more"))
    else:
        out.append(_estimate(base, VISCOUS, running.viscous_in_oz_s_per_rad,
                             running.viscous_sd_in_oz_s_per_rad, names, dof=running.dof))
    loop_tc = [lh.identification.coulomb_torque_in_oz for lh in loops
               if lh.identification is not None and lh.identification.coulomb_torque_estimated]
    if loop_tc:
        notes.append(f"T_c cross-check: the loops' plateaus give {np.median(loop_tc):.4g} in-oz, "
                     f"the velocity sweep {running.coulomb_in_oz:.4g} in-oz (written)")
    return out


def _table(base: Testbed, loops: Sequence[LogHysteresis], coulomb: float,
           notes: list[str]) -> tuple[tuple | None, list[ParameterEstimate], float | None]:
    """(the slope table, its estimates, an analytic model's sigma or None)."""
    if not loops:
        return None, [], None
    sigma = float(base.friction["sigma"])
    idents = []
    for lh in loops:
        try:
            idents.append(identify_friction(lh.loop.angle_rad, lh.loop.torque_in_oz,
                                            sigma_in_oz_per_rad=sigma, coulomb_torque_in_oz=coulomb))
        except FrictionIdError as exc:
            notes.append(f"{lh.path.name}: no slope table ({exc})")
    if not idents:
        return None, [], None
    names = [lh.path.name for lh in loops]
    if not base.friction["model"].startswith("DB-"):
        turn = np.concatenate([i.turnaround_slopes_in_oz_per_rad for i in idents])
        turn = turn[np.isfinite(turn) & (turn > 0)]
        s = float(np.median(turn)) / 2.0 ** float(base.friction["alpha"])
        sd = float(np.std(turn, ddof=1) / math.sqrt(turn.size)) / 2.0 ** float(base.friction["alpha"])
        return None, [_estimate(base, SIGMA, s, sd, names, dof=turn.size - 1)], s
    x, f, identified = combine_tables(idents)
    base_f0 = float(load_slope_table(base.slope_table_path)[1][0])
    per_branch = np.concatenate([i.f_per_branch[:, 0] for i in idents])
    per_branch = per_branch[np.isfinite(per_branch)]
    sd0 = (float(np.std(per_branch, ddof=1) / math.sqrt(per_branch.size))
           if per_branch.size > 1 else None)
    t0 = _t95(per_branch.size - 1)
    held_sigma = _estimate(base, SIGMA, sigma, None, (), status="held (scale)",
                           reason="with a data-based table only sigma*f(x) is measured: the "
                                  "table carries the product")
    why_not = _table_not_determined(x, identified, f[0], None if sd0 is None else t0 * sd0)
    if why_not:
        notes.append(f"slope table not written: {why_not}; the base table stays")
        return None, [held_sigma, ParameterEstimate(
            ".".join(TABLE_START[:2]), "", base_f0, base_f0, None, "held (not determined)",
            why_not, tuple(names))], None
    start = ParameterEstimate(".".join(TABLE_START[:2]), "", base_f0, float(f[0]),
                              (f[0] - t0 * sd0, f[0] + t0 * sd0),
                              "identified", f"{int(identified.sum())} of {x.size} table points "
                              f"from data, the rest filled", tuple(names))
    return (x, f, identified), [held_sigma, start], None


#: a table is written only when its turnaround slope f(0) is known to this fraction (95 %)
#: and the data reach this far along the branch: a loop cut short (a triangle stopped
#: before its turnarounds, or one inside the presliding range) leaves a table that is
#: mostly fill, and its f(0) from two or three branches is noise
MAX_TABLE_START_SPREAD = 0.2
MIN_TABLE_REACH_X = 1.0


def _table_not_determined(x: np.ndarray, identified: np.ndarray, f0: float,
                          half_width: float | None) -> str:
    """Why the identified table is not good enough to write ('' if it is)."""
    if half_width is None:
        return "f(0) from a single branch: record whole cycles of the triangle"
    if not half_width <= MAX_TABLE_START_SPREAD * abs(f0):
        return (f"f(0) = {f0:.3g} is known only to +-{half_width:.2g} (95 %), more than "
                f"{MAX_TABLE_START_SPREAD:.0%}: record more or longer triangle cycles")
    reach = float(np.max(x[identified])) if np.any(identified) else 0.0
    if reach < MIN_TABLE_REACH_X:
        return (f"the loops' branches reach x = {reach:.2g} of the table's 0..2 (at least "
                f"{MIN_TABLE_REACH_X:g} is needed): use a triangle amplitude beyond the "
                f"presliding range (T_c/sigma)")
    return ""


def identify_friction_logs(paths: Sequence[Path], base: Testbed, plant: Testbed) -> FrictionFit | None:
    """The friction of the rig from the logs among `paths` that serve it (None: none
    does).  `plant`: the base file with the identified linear plant."""
    notes: list[str] = []
    sweeps, loops = [], []
    viscous, coulomb = float(base.mechanics["bearing_viscous"]), float(base.friction["coulomb_torque"])
    for path in paths:
        try:
            sweep, loop = _scan(Path(path), plant, notes)
        except GroundStationError as exc:
            notes.append(f"{Path(path).name}: not used for friction ({exc})")
            continue
        if sweep is not None:
            sweeps.append(sweep)
        if loop is not None:
            if viscous * _loop_speed(loop) <= QUASI_STATIC_FRACTION * coulomb:
                loops.append(loop)
            else:
                notes.append(f"{loop.path.name}: its loop is not quasi-static (b_f*w = "
                             f"{viscous * _loop_speed(loop):.3g} in-oz): not used for the slope table")
    if not sweeps and not loops:
        return None
    running = _running_fit(sweeps)
    estimates = _coulomb_and_viscous(base, running, sweeps, loops, notes)
    tc = next(e.value for e in estimates if e.name == "friction.coulomb_torque")
    table, table_estimates, sigma = _table(base, loops, tc, notes)
    estimates += table_estimates
    identified = friction_params(base, coulomb=tc, sigma=sigma,
                                 table=None if table is None else (table[0], table[1]))
    return FrictionFit(tuple(loops), tuple(sweeps), running, tuple(estimates), table,
                       friction_params(base), identified, tuple(notes))


__all__ = ["FrictionFit", "LoopCurves", "QUASI_STATIC_FRACTION", "friction_params",
           "identify_friction_logs"]
