"""Running friction against velocity from a recorded log: analysis.friction_velocity on
what a constant-velocity-ramp log holds (the steady_state_friction campaign's).

The bearing's angle is ``encoder_outer`` (phi1).  The torque across the bearing is made
from the channels as hysteresis_from_log makes it (log_hysteresis.py), with the
coarse torque command as the default drive:

    T_f = T1 - T2 + k·(phi2 - phi1)     2-DOF testbed, the fine drive and both encoders logged
    T_f = T1                            1-DOF, or those channels not logged (a note says so)

At constant velocity the flexure and the fine motor cancel (the inner axis moves with
the outer one: k·(phi2 - phi1) = T2), but a fine motor that saturates while the coarse
loop catches up (the 50 deg/s pass) leaves the flexure deflected, so they are taken as
measured.  The inertia torque is zero on a plateau, and the bearing's viscous torque
b_f·w is part of what is measured: running friction, as the reference's procedure
defines it.  With ``drive_channel = "current_coarse"`` T1 is K_t1·i1 (and T2 K_t2·i2).

The log is read in chunks of ``chunk_rows`` rows into friction_velocity's blocks, so the
memory stays bounded whatever the log's length; the window is narrowed to the frames
that play a profile, as the other adapters do (the rest before and after holds no
constant-velocity pass, and a servo's limit cycle at rest would only add noise).
Missing frames are counted, not bridged (a block's slope uses the frames' own times).
"""

from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from ..logs import LogReader
from ..plant.testbed import Testbed
from .friction_velocity import (DEFAULT_BLOCK_S, DEFAULT_MIN_SEGMENT_S, DEFAULT_MIN_SPEED_RAD_S,
                                DEFAULT_SETTLE_TOLERANCE, DEFAULT_SETTLED_FRACTION,
                                DEFAULT_TOLERANCE, BlockAccumulator, FrictionVelocity,
                                segments_from_blocks)
from .log_window import (PACKET, LogIdentificationError, NoExcitationError,
                         WindowTooShortError, coarse_torque_constant, require_channels,
                         testbed_info, window_rows)

#: the coarse drives accepted: channel -> (kind, the fine motor's twin)
DRIVES = {"torque_coarse_cmd": ("torque", "torque_fine_cmd"),
          "current_coarse": ("current", "current_fine")}
ANGLE_CHANNEL = "encoder_outer"
DEFAULT_CHUNK_ROWS = 1 << 16


@dataclass(frozen=True, eq=False)
class LogFrictionVelocity:
    """The constant-velocity segments of a log and where they came from."""

    path: Path
    window_from_s: float            # first frame used, s from the log's start
    window_to_s: float
    frames: int
    drive_channel: str
    torque_formula: str
    testbed_source: str
    result: FrictionVelocity        # segment times are s from the log's start
    notes: tuple[str, ...] = field(default_factory=tuple)

    def text(self) -> str:
        head = (f"{self.path.name}: {self.torque_formula} against d({ANGLE_CHANNEL})/dt, "
                f"{self.window_from_s:.3f}..{self.window_to_s:.3f} s, {self.frames} frames")
        return "\n".join([head, self.result.text()] + [f"  note: {n}" for n in self.notes])


def _profile_span(r: LogReader, i0: int, i1: int, chunk_rows: int) -> tuple[int, int] | None:
    """Rows [a, b) from the first to the last frame that plays a profile (chunked)."""
    first = last = None
    for c0 in range(i0, i1, chunk_rows):
        c1 = min(i1, c0 + chunk_rows)
        idx = r.read_rows(PACKET, ["profile_index"], c0, c1, with_time=False)["profile_index"]
        playing = np.flatnonzero(idx > 0)
        if playing.size:
            if first is None:
                first = c0 + int(playing[0])
            last = c0 + int(playing[-1])
    return None if first is None else (first, last + 1)


@dataclass(frozen=True)
class _TorqueModel:
    """How the bearing's torque is made from a chunk of channels (module docstring)."""

    drive_channel: str
    fine_channel: str
    formula: str
    kt1: float | None = None        # coarse torque constant, for a current drive
    kt2: float | None = None        # fine torque constant (1.0 for a torque command)
    k: float | None = None          # flexure stiffness; None: no coupling terms

    @property
    def coupled(self) -> bool:
        return self.k is not None

    def columns(self) -> list[str]:
        """The channels the torque and the angle are made from."""
        columns = [ANGLE_CHANNEL, self.drive_channel]
        if self.coupled:
            columns += [self.fine_channel, "encoder_inner"]
        return columns

    def torque(self, d: dict, angle: np.ndarray) -> np.ndarray:
        torque = (np.asarray(d[self.drive_channel], dtype=np.float64)
                  * (self.kt1 if self.kt1 is not None else 1.0))
        if self.coupled:
            torque = (torque - self.kt2 * np.asarray(d[self.fine_channel], dtype=np.float64)
                      + self.k * (np.asarray(d["encoder_inner"], dtype=np.float64) - angle))
        return torque


def _torque_model(tbi, name: str, drive_channel: str, coupling: bool, have: set[str],
                  notes: list[str]) -> _TorqueModel:
    """The torque formula the testbed and the logged channels allow; why a coupling
    term is left out goes to `notes`."""
    kind, fine_channel = DRIVES[drive_channel]
    kt1 = None
    formula = "T1"
    if kind == "current":
        kt1 = coarse_torque_constant(tbi, name)
        formula = "K_t1*i1"
    use_coupling = coupling and tbi.two_dof
    if use_coupling and not {fine_channel, "encoder_inner"} <= have:
        notes.append(f"the flexure and fine-motor torques are neglected: the log has no "
                     f"{' / '.join(sorted({fine_channel, 'encoder_inner'} - have))}")
        use_coupling = False
    if use_coupling:
        k = tbi.number("mechanics", "flexure_stiffness")
        kt2 = tbi.number("motor_fine", "torque_constant") if kind == "current" else 1.0
        if k is None or kt2 is None:
            notes.append("the flexure and fine-motor torques are neglected: the testbed does "
                         "not give flexure_stiffness / the fine motor's torque constant")
        else:
            formula += (" - K_t2*i2" if kind == "current" else " - T2") + " + k*(phi2 - phi1)"
            return _TorqueModel(drive_channel, fine_channel, formula, kt1, kt2, k)
    return _TorqueModel(drive_channel, fine_channel, formula, kt1)


def _narrow_to_profile(r: LogReader, i0: int, i1: int, chunk_rows: int, origin: float,
                       notes: list[str]) -> tuple[int, int]:
    """Rows [i0, i1) narrowed to the frames that play a profile (unchanged if none does);
    a narrowing is noted."""
    span = _profile_span(r, i0, i1, chunk_rows)
    if span is not None and (span[0] > i0 or span[1] < i1):
        t_a = r.read_rows(PACKET, [], span[0], span[0] + 1)["device_time"][0] - origin
        t_b = r.read_rows(PACKET, [], span[1] - 1, span[1])["device_time"][0] - origin
        notes.append(f"window narrowed to the profile playing in it ({t_a:.3f}..{t_b:.3f} s)")
        return span
    return i0, i1


class _BlockScan:
    """Rows of the log fed chunk by chunk into friction_velocity's blocks, with the
    frames counted and the missing ones (holes in device time) tallied."""

    def __init__(self, name: str, model: _TorqueModel, flags: list[str], block_s: float,
                 origin: float, rate: float) -> None:
        self.name, self.model, self.flags = name, model, flags
        self.origin, self.rate = origin, rate
        self.acc = BlockAccumulator(block_s, origin_s=None)
        self.frames = self.missing = 0
        self.first_t: float | None = None
        self.last_t: float | None = None

    def read(self, r: LogReader, i0: int, i1: int, chunk_rows: int) -> None:
        columns = self.model.columns() + self.flags
        for c0 in range(i0, i1, chunk_rows):
            self.add(r.read_rows(PACKET, columns, c0, min(i1, c0 + chunk_rows)))

    def add(self, d: dict) -> None:
        t = np.asarray(d["device_time"], dtype=np.float64) - self.origin
        if not t.size:
            return
        angle = np.asarray(d[ANGLE_CHANNEL], dtype=np.float64)
        torque = self.model.torque(d, angle)
        if not (np.all(np.isfinite(angle)) and np.all(np.isfinite(torque))):
            raise LogIdentificationError(f"{self.name}: non-finite samples in the window: "
                                         f"choose a window without them")
        saturated = None
        if self.flags:
            saturated = np.zeros(t.size, dtype=bool)
            for f in self.flags:
                saturated |= np.asarray(d[f], dtype=bool)
        # holes: device time advances by more than one tick (counted across chunks)
        joined = t if self.last_t is None else np.concatenate(([self.last_t], t))
        steps = np.rint(np.diff(joined) * self.rate)
        self.missing += int(np.maximum(steps - 1, 0).sum())
        self.acc.add(t, angle, torque, saturated)
        self.frames += t.size
        self.first_t = t[0] if self.first_t is None else self.first_t
        self.last_t = float(t[-1])


def friction_velocity_from_log(path: str | Path, start_s: float | None = None,
                               stop_s: float | None = None, *,
                               drive_channel: str = "torque_coarse_cmd", coupling: bool = True,
                               trim_to_profile: bool = True,
                               testbed: str | Path | Testbed | None = None,
                               block_s: float = DEFAULT_BLOCK_S,
                               tolerance: float = DEFAULT_TOLERANCE,
                               min_speed_rad_s: float = DEFAULT_MIN_SPEED_RAD_S,
                               settled_fraction: float = DEFAULT_SETTLED_FRACTION,
                               settle_tolerance: float = DEFAULT_SETTLE_TOLERANCE,
                               min_segment_s: float = DEFAULT_MIN_SEGMENT_S,
                               chunk_rows: int = DEFAULT_CHUNK_ROWS) -> LogFrictionVelocity:
    """Running friction against velocity of the log at `path` over [start_s, stop_s]
    (s from the log's start; None: open end).  See the module docstring.
    Raises MissingChannelError, WindowTooShortError, NoExcitationError (no
    constant-velocity segment), LogIdentificationError, LogError."""
    if drive_channel not in DRIVES:
        raise LogIdentificationError(f"drive channel {drive_channel!r}: the coarse motor's is "
                                     f"{' or '.join(DRIVES)}")
    if int(chunk_rows) < 1:
        raise LogIdentificationError(f"chunk_rows must be >= 1, not {chunk_rows}")
    chunk_rows = int(chunk_rows)
    name = Path(path).name
    notes: list[str] = []
    with LogReader(path) as r:
        require_channels(r, [ANGLE_CHANNEL, drive_channel], "friction against velocity")
        have = {c.name for c in r.channels(PACKET)}
        i0, i1 = window_rows(r, start_s, stop_s)
        origin = r.origin("device")
        tbi = testbed_info(r, testbed)
        if trim_to_profile and "profile_index" in have:
            i0, i1 = _narrow_to_profile(r, i0, i1, chunk_rows, origin, notes)
        model = _torque_model(tbi, name, drive_channel, coupling, have, notes)
        flags = [c for c in ("coarse_saturated", "fine_saturated") if c in have]
        scan = _BlockScan(name, model, flags, block_s, origin, r.tick_rate_hz)
        scan.read(r, i0, i1, chunk_rows)
    result = _segments(scan, name, notes, tolerance=tolerance, min_speed_rad_s=min_speed_rad_s,
                       settled_fraction=settled_fraction, settle_tolerance=settle_tolerance,
                       min_segment_s=min_segment_s)
    return LogFrictionVelocity(path=Path(path), window_from_s=float(scan.first_t),
                               window_to_s=float(scan.last_t), frames=int(scan.frames),
                               drive_channel=drive_channel, torque_formula=model.formula,
                               testbed_source=tbi.source, result=result, notes=tuple(notes))


def _segments(scan: _BlockScan, name: str, notes: list[str], *, tolerance: float,
              min_speed_rad_s: float, settled_fraction: float, settle_tolerance: float,
              min_segment_s: float) -> FrictionVelocity:
    """The constant-velocity segments of the scanned blocks; what qualifies them goes to
    `notes`.  Raises WindowTooShortError, NoExcitationError."""
    if scan.frames < 2:
        raise WindowTooShortError(f"{name}: {scan.frames} frame(s) in the window: friction "
                                  f"against velocity needs a constant-velocity pass")
    if scan.missing:
        notes.append(f"{scan.missing} frame(s) missing in the window (not bridged)")
    result = segments_from_blocks(scan.acc.result(), tolerance=tolerance,
                                  min_speed_rad_s=min_speed_rad_s,
                                  settled_fraction=settled_fraction,
                                  settle_tolerance=settle_tolerance, min_segment_s=min_segment_s)
    if not result.segments:
        raise NoExcitationError(
            f"{name}: no constant-velocity pass in the window {scan.first_t:.3f}..{scan.last_t:.3f} s "
            f"(none moving faster than {min_speed_rad_s:g} rad/s within {tolerance * 100:g} % "
            f"of one speed for {min_segment_s:g} s): play a velocity ramp profile in closed loop"
            + (f"; {'; '.join(result.notes)}" if result.notes else ""))
    sat = [s.saturated_fraction for s in result.segments if s.saturated_fraction]
    if sat:
        notes.append(f"a motor was saturated in {max(sat) * 100:.0f} % of the frames of some "
                     f"segment's settled part (the torque is the command after saturation)")
    return result


__all__ = ["ANGLE_CHANNEL", "DRIVES", "LogFrictionVelocity", "friction_velocity_from_log"]
