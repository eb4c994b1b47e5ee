"""The bearing's hysteresis loop from a recorded log, and its DB-DHM slope table.  No Qt
and no plotting here; the numerics are friction_id.py, this module only reads the log
(with log_window.py's helpers) and makes the friction torque from its channels.

`hysteresis_from_log`: the friction test moves the outer axis with a triangle at a very
low constant rate (reference: 0.001 deg/s), so the friction torque is read off the
motors.  The outer axis' equation of motion (plant/model.py) is

    J1 w1' = T1 - T2 - T_f - b_f w1 + b (w2 - w1) + k (phi2 - phi1)

(T_f: bearing friction; the base is fixed).  The flexure joins the two axes, not the
outer axis and the base, so k·phi1 is *not* a torque on the bearing; the inner axis
pushes on the outer one through the flexure and the fine motor's reaction.  Hence

    T_f = K_t1·i1 - K_t2·i2 + k·(phi2 - phi1)     (2-DOF testbed, both encoders logged)
    T_f = K_t1·i1                                  (1-DOF, or the channels not logged)

neglecting J1·w1', b_f·w1 and the flexure damping b·(w2 - w1): at 0.001 deg/s the
viscous term is ~3e-4 in-oz against T_c = 2.25 in-oz, the reference's own procedure.
Quasi-statically the two coupling terms cancel (together they are the inner axis'
inertia torque, J2·w2', plus flexure damping), so they are small; but a fine loop
working during the test makes them a few hundredths of an in-oz (a few % of T_c in the
simulated triangle test), which is why they are subtracted as measured rather than
assumed zero.  ``coupling=False`` uses K_t1·i1 alone.
The torque constants, the flexure stiffness and the rest stiffness σ come from the
testbed (the log's recorded file, what was true when it was recorded).

The window is narrowed to the frames playing a profile, as for the frequency response
(the rest before and the disarmed tail after would add a jump of the torque to zero at a
standing angle).  Missing frames are reported, not bridged: a hole only thins a branch.
The loop is split into branches (friction_id.split_branches); with at least two complete
branches the DB-DHM slope table is identified too (friction_id.identify_friction, T_c
estimated from the loop); if that is not possible the loop is still returned with a note
saying why.

Errors: log_window's MissingChannelError, WindowTooShortError, NoExcitationError (and
the log's own LogError).
"""

from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from ..logs import LogReader
from ..plant.testbed import Testbed
from .friction_id import (FrictionIdentification, FrictionIdError, HysteresisLoop,
                          identify_friction, split_branches)
from .log_window import (PACKET, LogIdentificationError, NoExcitationError, TestbedInfo,
                         WindowTooShortError, check_channel, coarse_torque_constant,
                         longest_run, profile_span, require_channels, testbed_info,
                         window_rows)

#: what hysteresis_from_log accepts as the coarse motor's drive: channel -> (kind, fine twin)
HYSTERESIS_DRIVES: dict[str, tuple[str, str]] = {
    "current_coarse": ("current", "current_fine"),
    "torque_coarse_cmd": ("torque", "torque_fine_cmd"),
}
HYSTERESIS_ANGLES = ("encoder_outer",)
#: the least peak-to-peak travel a hysteresis record must have (about 700 encoder counts,
#: a quarter of a percent of the rig bearing's presliding range T_c/σ = 0.39 mrad): less
#: is encoder noise, and the "reversals" found in it would be noise too
MIN_TRAVEL_RAD = 1e-6


@dataclass(frozen=True, eq=False)
class LogHysteresis:
    """The friction torque against the bearing's angle, split into branches."""

    path: Path
    angle_channel: str
    drive_channel: str
    window_from_s: float
    window_to_s: float
    frames: int
    loop: HysteresisLoop
    identification: FrictionIdentification | None    # None: see notes
    torque_formula: str               # how the friction torque was made from the channels
    torque_constant_in_oz_per_a: float | None   # K_t of the coarse motor (None: torque channel)
    testbed_source: str
    notes: tuple[str, ...] = field(default_factory=tuple)

    def text(self) -> str:
        lp = self.loop
        complete = sum(b.complete for b in lp.branches)
        lines = [f"{self.path.name}: {self.torque_formula} against {self.angle_channel}, "
                 f"{self.window_from_s:.3f}..{self.window_to_s:.3f} s, {self.frames} frames, "
                 f"{len(lp.branches)} branches ({complete} complete)"]
        ident = self.identification
        if ident is not None:
            lines.append(f"  T_c {ident.coulomb_torque_in_oz:.3f} in-oz"
                         f"{' (estimated)' if ident.coulomb_torque_estimated else ''}, "
                         f"f(0) {ident.f[0]:.3g}, sigma {ident.sigma_in_oz_per_rad:g} in-oz/rad")
        lines += [f"  note: {n}" for n in self.notes]
        return "\n".join(lines)


def _check_hysteresis_channels(angle_channel: str, current_channel: str) -> None:
    check_channel("angle", angle_channel, HYSTERESIS_ANGLES,
                  f"the bearing's angle is {' or '.join(HYSTERESIS_ANGLES)}")
    check_channel("drive", current_channel, HYSTERESIS_DRIVES,
                  f"the coarse motor's is {' or '.join(HYSTERESIS_DRIVES)}")


@dataclass(frozen=True)
class _HysteresisWindow:
    """What hysteresis_from_log reads from the log."""

    d: dict[str, np.ndarray]
    origin: float
    rate: float
    tbi: TestbedInfo
    use_coupling: bool              # the coupling terms wanted and their channels logged


def _read_hysteresis_window(r: LogReader, angle_channel: str, current_channel: str,
                            start_s, stop_s, *, coupling: bool, trim_to_profile: bool,
                            testbed: str | Path | Testbed | None,
                            notes: list[str]) -> _HysteresisWindow:
    fine_channel = HYSTERESIS_DRIVES[current_channel][1]
    require_channels(r, [angle_channel, current_channel], "a hysteresis loop")
    have = {c.name for c in r.channels(PACKET)}
    i0, i1 = window_rows(r, start_s, stop_s)
    tbi = testbed_info(r, testbed)
    use_coupling = coupling and tbi.two_dof
    if use_coupling and not {fine_channel, "encoder_inner"} <= have:
        notes.append(f"the flexure and fine-motor torques are neglected: the log has no "
                     f"{' / '.join(sorted({fine_channel, 'encoder_inner'} - have))}")
        use_coupling = False
    columns = [angle_channel, current_channel]
    if use_coupling:
        columns += [fine_channel, "encoder_inner"]
    if trim_to_profile and "profile_index" in have:
        columns.append("profile_index")
    d = r.read_rows(PACKET, columns, i0, i1)
    return _HysteresisWindow(d, r.origin("device"), r.tick_rate_hz, tbi, use_coupling)


def _bearing_torque(d: dict[str, np.ndarray], angle: np.ndarray, drive: np.ndarray,
                    current_channel: str, w: _HysteresisWindow, name: str,
                    notes: list[str]) -> tuple[np.ndarray, str, float | None]:
    """(torque, its formula, K_t1 if the drive is a current): the friction torque across
    the bearing as the module docstring makes it."""
    kind, fine_channel = HYSTERESIS_DRIVES[current_channel]
    kt1 = None
    if kind == "current":
        kt1 = coarse_torque_constant(w.tbi, name)
        torque = kt1 * drive
        formula = "K_t1*i1"
    else:
        torque = drive.copy()
        formula = "T1"
    if w.use_coupling:
        k = w.tbi.number("mechanics", "flexure_stiffness")
        kt2 = w.tbi.number("motor_fine", "torque_constant") if kind == "current" else 1.0
        if k is None or kt2 is None:
            notes.append("the flexure and fine-motor torques are neglected: the testbed does "
                         "not give flexure_stiffness / the fine motor's torque constant")
        else:
            fine = np.asarray(d[fine_channel], dtype=np.float64)
            torque = torque - kt2 * fine + k * (np.asarray(d["encoder_inner"]) - angle)
            formula += " - K_t2*i2" if kind == "current" else " - T2"
            formula += " + k*(phi2 - phi1)"
    return torque, formula, kt1


def _check_loop_samples(name: str, angle: np.ndarray, torque: np.ndarray, drive: np.ndarray,
                        angle_channel: str, current_channel: str) -> None:
    """Raise if the samples cannot make a hysteresis loop."""
    n = angle.size
    if n < 3 * 5:          # friction_id's least: three fits of five samples
        raise WindowTooShortError(f"{name}: {n} frames in the window are too few for a "
                                  f"hysteresis loop: widen the window")
    if not (np.all(np.isfinite(angle)) and np.all(np.isfinite(torque))):
        raise LogIdentificationError(f"{name}: non-finite samples in the window: choose a "
                                     f"window without them")
    if not np.ptp(drive) > 0.0:
        raise NoExcitationError(f"{name}: {current_channel} is constant ({drive[0]:g}) over the "
                                f"window: no torque, no loop (play the friction triangle profile "
                                f"in closed loop)")
    travel = float(np.ptp(angle))
    if travel < MIN_TRAVEL_RAD:
        raise NoExcitationError(f"{name}: {angle_channel} moves only {travel * 1e6:.3g} urad over "
                                f"the window (encoder noise; a loop needs at least "
                                f"{MIN_TRAVEL_RAD * 1e6:g} urad): play the friction triangle "
                                f"profile in closed loop")


def _slope_table(angle: np.ndarray, torque: np.ndarray, loop: HysteresisLoop,
                 tbi: TestbedInfo, notes: list[str]) -> FrictionIdentification | None:
    """The DB-DHM slope table of the loop, or None with a note saying why not."""
    complete = sum(b.complete for b in loop.branches)
    sigma = tbi.number("friction", "sigma")
    if complete < 2:
        notes.append(f"{complete} complete branch(es): the slope table needs at least two "
                     f"(a whole cycle of the triangle)")
    elif sigma is None or not sigma > 0.0:
        notes.append("no slope table: the rest stiffness sigma ([friction] sigma) is unknown "
                     "(choose a testbed file)")
    else:
        try:
            return identify_friction(angle, torque, sigma_in_oz_per_rad=sigma)
        except FrictionIdError as exc:
            notes.append(f"no slope table: {exc}")
    return None


def hysteresis_from_log(path: str | Path, start_s: float | None = None,
                        stop_s: float | None = None, angle_channel: str = "encoder_outer",
                        current_channel: str = "current_coarse", *, coupling: bool = True,
                        trim_to_profile: bool = True,
                        testbed: str | Path | Testbed | None = None) -> LogHysteresis:
    """The bearing's hysteresis loop (friction torque against the outer axis' angle) from
    a triangle-profile record, and its DB-DHM slope table when the loop allows (see the
    module docstring).  `current_channel`: current_coarse (x K_t) or torque_coarse_cmd.
    Raises MissingChannelError, WindowTooShortError, NoExcitationError, LogError."""
    _check_hysteresis_channels(angle_channel, current_channel)
    notes: list[str] = []
    with LogReader(path) as r:
        w = _read_hysteresis_window(r, angle_channel, current_channel, start_s, stop_s,
                                    coupling=coupling, trim_to_profile=trim_to_profile,
                                    testbed=testbed, notes=notes)
    name = Path(path).name
    d, origin = w.d, w.origin
    t = d["device_time"]
    if "profile_index" in d:
        span = profile_span(d["profile_index"])
        if span is not None and (span[0] > 0 or span[1] < t.size):
            notes.append(f"window narrowed to the profile playing in it "
                         f"({t[span[0]] - origin:.3f}..{t[span[1] - 1] - origin:.3f} s)")
            d = {key: v[span[0]:span[1]] for key, v in d.items()}
            t = d["device_time"]
    angle = np.asarray(d[angle_channel], dtype=np.float64)
    drive = np.asarray(d[current_channel], dtype=np.float64)
    torque, formula, kt1 = _bearing_torque(d, angle, drive, current_channel, w, name, notes)
    _, _, missing = longest_run(t, w.rate)
    if missing:
        notes.append(f"{missing} frame(s) missing in the window (the loop has holes there)")
    _check_loop_samples(name, angle, torque, drive, angle_channel, current_channel)
    try:
        loop = split_branches(angle, torque)
    except FrictionIdError as exc:
        raise NoExcitationError(f"{name}: {exc}") from None
    identification = _slope_table(angle, torque, loop, w.tbi, notes)
    return LogHysteresis(path=Path(path), angle_channel=angle_channel, drive_channel=current_channel,
                         window_from_s=float(t[0] - origin), window_to_s=float(t[-1] - origin),
                         frames=int(angle.size), loop=loop, identification=identification,
                         torque_formula=formula, torque_constant_in_oz_per_a=kt1,
                         testbed_source=w.tbi.source, notes=tuple(notes))


__all__ = ["HYSTERESIS_ANGLES", "HYSTERESIS_DRIVES", "LogHysteresis", "MIN_TRAVEL_RAD",
           "hysteresis_from_log"]
