"""System identification from a recorded log: a frequency response with the testbed
model beside it, and the bearing's hysteresis loop.  No Qt and no plotting here; the
numerics are frf.py and friction_id.py, this module only reads the log and decides what
goes in.

Frequency response (`frf_from_log`)
-----------------------------------
One HIGH_RATE input channel against one output channel over a window of the log (seconds
from its start, inclusive; None: open end).  Two choices are made on the data before
H1 is estimated:

* the window is narrowed to the frames that play a command profile (``profile_index``
  > 0) when it holds any: the upload before and the rest after carry no excitation and
  would only add output noise to the spectra (``trim_to_profile=False`` keeps it whole);
* a window with missing frames (device-tick holes) is not spliced: the longest gap-free
  stretch is used and a note says how much was left out.

The model's response is put on the same frequency grid, for the testbed the log
recorded (or the one given): the zero-order-hold equivalent at the log's rate (the
firmware holds each current for one control period), on the path the channels name:

    current_coarse / torque_coarse_cmd   -> T1      (current: per ampere, x K_t)
    current_fine   / torque_fine_cmd     -> T2
    encoder_outer -> phi1, encoder_inner -> phi2, gyro_rate -> gyro_rate,
    autocollimator / los_estimate -> los_angle (for los_estimate the complementary
    filter is not in the model; a note says so)

The model is the friction-free plant (viscous b_f only): the bearing's Dahl friction is
the one nonlinearity the linear model leaves out, so measured and model part where the
friction torque is not small against the excitation (low frequencies, small currents)
and near the flexure's anti-resonance, where the output is small.

Hysteresis (`hysteresis_from_log`)
----------------------------------
The friction test moves the outer axis with a triangle at a very low constant rate
(reference: 0.001 deg/s), so the friction torque is read off the motors.  The outer
axis' equation of motion (plant/model.py) is

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

The step response of a log is in log_step.py, which shares this module's window and
channel helpers.

Errors are GroundStationError subclasses with the reason in the message:
MissingChannelError, WindowTooShortError, NoExcitationError (and the log's own LogError,
an AnalysisError for anything else).
"""

from __future__ import annotations

import math
import tomllib
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from ..logs import LogReader
from ..plant.testbed import Testbed, TestbedConfigError, load_testbed
from . import AnalysisError
from .frf import (MIN_SEGMENT_SAMPLES, MIN_SEGMENTS, FrequencyResponse, FrfComparison,
                  compare_frf, h1_estimate, model_response)
from .friction_id import (FrictionIdentification, FrictionIdError, HysteresisLoop,
                          identify_friction, split_branches)

PACKET = "HIGH_RATE"

#: input channels and the model input they drive; True: a current (per ampere)
FRF_INPUTS: dict[str, tuple[str, bool]] = {
    "current_coarse": ("T1", True), "torque_coarse_cmd": ("T1", False),
    "current_fine": ("T2", True), "torque_fine_cmd": ("T2", False),
}
#: output channels and the model output they measure
FRF_OUTPUTS: dict[str, str] = {
    "encoder_outer": "phi1", "encoder_inner": "phi2", "gyro_rate": "gyro_rate",
    "autocollimator": "los_angle", "los_estimate": "los_angle",
}
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
#: coherence at or above which a bin counts in the measured-vs-model comparison
DEFAULT_MIN_COHERENCE = 0.9


class LogIdentificationError(AnalysisError):
    """A frequency response or a hysteresis loop cannot be had from this log."""


class MissingChannelError(LogIdentificationError):
    """The log does not hold a channel the analysis needs (the message lists what it has)."""


class WindowTooShortError(LogIdentificationError):
    """The chosen window of the log holds too few frames for the analysis."""


class NoExcitationError(LogIdentificationError):
    """The input does not vary (or the axis does not move) in the window."""


# ======================================================================================
# results
# ======================================================================================
@dataclass(frozen=True, eq=False)
class LogFrf:
    """A measured frequency response from a log and the testbed model's on its grid."""

    path: Path
    input_channel: str
    output_channel: str
    window_from_s: float            # first frame used, s from the log's start
    window_to_s: float              # last frame used
    frames: int                     # frames used
    measured: FrequencyResponse
    model: np.ndarray | None        # complex, on measured.freq_hz; None: no model (see notes)
    model_path: str                 # e.g. "T1->phi1" ('' without a model)
    model_per_amp: bool             # the model was multiplied by K_t (input is a current)
    model_description: str          # the model path in words, for a legend or a report
    testbed_source: str
    comparison: FrfComparison | None
    notes: tuple[str, ...] = field(default_factory=tuple)

    def text(self) -> str:
        m = self.measured
        lines = [f"{self.path.name}: {self.input_channel} -> {self.output_channel}, "
                 f"{self.window_from_s:.3f}..{self.window_to_s:.3f} s, {self.frames} frames, "
                 f"{m.segments} segments of {m.nperseg} ({m.resolution_hz:.3g} Hz)"]
        if self.model is not None:
            lines.append(f"  model: {self.model_description} ({self.testbed_source})")
        c = self.comparison
        if c is not None and c.bins_used:
            lines.append(f"  measured/model over {c.bins_used} bins with coherence >= "
                         f"{c.min_coherence:g}: RMS {c.rms_magnitude_ratio_db:.2f} dB, max "
                         f"{c.max_abs_magnitude_ratio_db:.2f} dB, phase max "
                         f"{c.max_abs_phase_difference_deg:.1f} deg")
        lines += [f"  note: {n}" for n in self.notes]
        return "\n".join(lines)


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


# ======================================================================================
# the log's testbed
# ======================================================================================
@dataclass(frozen=True)
class _TestbedInfo:
    """What this module needs of the testbed, and where it came from."""

    model: Testbed | None           # the full record (for the model), None if not loadable
    doc: dict[str, Any]             # the TOML document (constants)
    source: str                     # '' when the log records none
    note: str = ""                  # why there is no model, if there is none

    def number(self, section: str, key: str) -> float | None:
        sec = self.doc.get(section)
        v = sec.get(key) if isinstance(sec, dict) else None
        if isinstance(v, bool) or not isinstance(v, (int, float)) or not math.isfinite(v):
            return None
        return float(v)

    @property
    def two_dof(self) -> bool:
        sec = self.doc.get("testbed")
        return isinstance(sec, dict) and sec.get("configuration") == "2dof"


def coarse_torque_constant(tbi: _TestbedInfo, name: str) -> float:
    """K_t1 in in-oz/A from the testbed, for torques from the coarse motor's current."""
    kt1 = tbi.number("motor_coarse", "torque_constant")
    if kt1 is None:
        raise LogIdentificationError(f"{name}: the coarse motor's torque constant "
                                     f"([motor_coarse] torque_constant) is unknown "
                                     f"({tbi.source or tbi.note}): choose a testbed file")
    return kt1


def _testbed_info(reader: LogReader, testbed: str | Path | Testbed | None) -> _TestbedInfo:
    """From `testbed` if given; else the file the log recorded, loaded in full when it is
    still where it was and unchanged, else its recorded text for the constants only (what
    was true when the log was made; the model needs the checked file)."""
    if testbed is not None:
        tb = testbed if isinstance(testbed, Testbed) else load_testbed(testbed)
        return _TestbedInfo(tb, tomllib.loads(tb.text), f"testbed file {tb.path}")
    name, where, text = reader.testbed()
    if not text:
        return _TestbedInfo(None, {}, "", "the log records no testbed file: choose one")
    label = f"the log's testbed '{name}'" if name else "the log's testbed"
    try:
        doc = tomllib.loads(text)
    except tomllib.TOMLDecodeError as exc:
        return _TestbedInfo(None, {}, "", f"the testbed file recorded in the log is not valid "
                                          f"TOML ({exc}): choose a testbed file")
    if where and Path(where).is_file():
        try:
            tb = load_testbed(where)
        except TestbedConfigError as exc:
            return _TestbedInfo(None, doc, f"{label} (as recorded in the log)",
                                f"no model: the recorded testbed file does not load now ({exc})")
        if tb.text == text:
            return _TestbedInfo(tb, doc, f"{label} ({where})")
        return _TestbedInfo(None, doc, f"{label} (as recorded in the log)",
                            f"no model: {where} has changed since the log was recorded; "
                            f"choose a testbed file")
    return _TestbedInfo(None, doc, f"{label} (as recorded in the log)",
                        f"no model: the recorded testbed file {where or '(no path)'} is not "
                        f"there any more; choose a testbed file")


# ======================================================================================
# reading
# ======================================================================================
def _require(reader: LogReader, names: list[str], what: str) -> None:
    have = {c.name for c in reader.channels(PACKET)}
    missing = [n for n in names if n not in have]
    if missing:
        known = [c for c in (*FRF_INPUTS, *FRF_OUTPUTS) if c in have]
        raise MissingChannelError(
            f"{reader.path.name}: the log has no {PACKET} channel "
            f"{', '.join(repr(m) for m in missing)} for {what}"
            + (f" (it has {', '.join(known)})" if known else ""))


def _window_rows(reader: LogReader, start_s, stop_s) -> tuple[int, int]:
    if start_s is not None and stop_s is not None and float(start_s) >= float(stop_s):
        raise WindowTooShortError(f"window {start_s}..{stop_s} s: 'from' must be before 'to'")
    i0, i1 = reader.index_range(PACKET, start_s, stop_s, relative=True)
    if i1 <= i0:
        raise WindowTooShortError(f"{reader.path.name}: no {PACKET} frames in the window "
                                  f"{reader.describe_range(PACKET, start_s, stop_s, relative=True)}")
    return i0, i1


def _longest_run(device_time: np.ndarray, rate_hz: float) -> tuple[int, int, int]:
    """(a, b, missing) of the longest stretch [a, b) whose frames follow one tick apart,
    and the frames missing anywhere in the record."""
    if device_time.size < 2:
        return 0, device_time.size, 0
    ticks = np.rint(np.diff(device_time) * rate_hz)
    missing = int(np.maximum(ticks - 1, 0).sum())
    breaks = np.flatnonzero(ticks != 1) + 1
    if not breaks.size:
        return 0, device_time.size, 0
    edges = np.concatenate(([0], breaks, [device_time.size]))
    k = int(np.argmax(np.diff(edges)))
    return int(edges[k]), int(edges[k + 1]), missing


def _trim_to_profile(index: np.ndarray) -> tuple[int, int] | None:
    playing = np.flatnonzero(index > 0)
    if not playing.size:
        return None
    return int(playing[0]), int(playing[-1]) + 1


# ======================================================================================
# frequency response
# ======================================================================================
@dataclass(frozen=True)
class _FrfWindow:
    """What frf_from_log reads from the log: the window's rows and what describes them."""

    d: dict[str, np.ndarray]
    rate: float
    origin: float
    units: dict[str, str]
    mode_names: dict[int, str]
    have_index: bool
    tbi: _TestbedInfo


def _check_frf_channels(input_channel: str, output_channel: str) -> None:
    if input_channel not in FRF_INPUTS:
        raise LogIdentificationError(f"input channel {input_channel!r}: choose one of "
                                     f"{', '.join(FRF_INPUTS)}")
    if output_channel not in FRF_OUTPUTS:
        raise LogIdentificationError(f"output channel {output_channel!r}: choose one of "
                                     f"{', '.join(FRF_OUTPUTS)}")


def _read_frf_window(r: LogReader, input_channel: str, output_channel: str, start_s, stop_s,
                     testbed: str | Path | Testbed | None) -> _FrfWindow:
    _require(r, [input_channel, output_channel], "this frequency response")
    chans = {c.name: c for c in r.channels(PACKET)}
    have_index = "profile_index" in chans
    i0, i1 = _window_rows(r, start_s, stop_s)
    columns = [input_channel, output_channel] + (["profile_index"] if have_index else [])
    columns += ["mode"] if "mode" in chans else []
    d = r.read_rows(PACKET, columns, i0, i1)
    rate = r.tick_rate_hz
    origin = r.origin("device")
    units = {name: c.units for name, c in chans.items()}
    mode_names = {v: k for k, v in chans["mode"].states.items()} if "mode" in chans else {}
    return _FrfWindow(d, rate, origin, units, mode_names, have_index, _testbed_info(r, testbed))


def _frf_samples(w: _FrfWindow, input_channel: str, output_channel: str,
                 trim_to_profile: bool, notes: list[str]
                 ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(t, x, y) of the window narrowed to the profile playing in it and then to its
    longest stretch without a hole; each narrowing, and a closed loop, noted."""
    d, origin = w.d, w.origin
    t = d["device_time"]
    x = np.asarray(d[input_channel], dtype=np.float64)
    y = np.asarray(d[output_channel], dtype=np.float64)
    mode = d.get("mode")
    if trim_to_profile and w.have_index:
        span = _trim_to_profile(d["profile_index"])
        if span is not None and (span[0] > 0 or span[1] < t.size):
            notes.append(f"window narrowed to the profile playing in it "
                         f"({t[span[0]] - origin:.3f}..{t[span[1] - 1] - origin:.3f} s)")
            t, x, y = t[span[0]:span[1]], x[span[0]:span[1]], y[span[0]:span[1]]
            mode = mode[span[0]:span[1]] if mode is not None else None
    a, b, missing = _longest_run(t, w.rate)
    if missing:
        notes.append(f"{missing} frame(s) missing in the window: the longest stretch without "
                     f"a hole is used ({b - a} of {t.size} frames)")
        t, x, y = t[a:b], x[a:b], y[a:b]
        mode = mode[a:b] if mode is not None else None
    if mode is not None and mode.size:
        closed = sorted({w.mode_names.get(int(m), str(int(m))) for m in np.unique(mode)}
                        - {"OPEN_LOOP"})
        if closed:
            notes.append(f"not open loop (mode {', '.join(closed)} in the window): the controller "
                         f"feeds the output back into the input, so this is not the plant's "
                         f"response alone")
    return t, x, y


def _check_frf_samples(name: str, x: np.ndarray, y: np.ndarray, rate: float,
                       nperseg: int | None, input_channel: str, output_channel: str) -> int | None:
    """Raise if the samples cannot give a frequency response; the segment length as an int."""
    finite = np.isfinite(x) & np.isfinite(y)
    if not np.all(finite):
        raise LogIdentificationError(f"{name}: {int(np.count_nonzero(~finite))} "
                                     f"non-finite sample(s) of {input_channel}/{output_channel} "
                                     f"in the window: choose a window without them")
    n = x.size
    least = MIN_SEGMENTS * MIN_SEGMENT_SAMPLES
    if nperseg is not None:
        nperseg = int(nperseg)
        least = max(least, nperseg + (MIN_SEGMENTS - 1) * (nperseg - nperseg // 2))
    if n < least:
        raise WindowTooShortError(
            f"{name}: {n} frames ({n / rate:.3g} s) in the window are too few for a "
            f"frequency response: at least {least}"
            + (f" with segments of {nperseg}" if nperseg is not None else "")
            + "; widen the window" + (" or shorten the segments" if nperseg is not None else ""))
    if not np.ptp(x) > 0.0:
        raise NoExcitationError(f"{name}: {input_channel} is constant ({x[0]:g}) "
                                f"over the window: no excitation to measure a response with "
                                f"(play an open-loop random current, e.g. a sysid profile)")
    return nperseg


@dataclass(frozen=True)
class _FrfModel:
    """The testbed model's response beside a measured one (None where there is none)."""

    which: str                      # the model's path, e.g. 'T1->phi1'
    per_amp: bool
    model: FrequencyResponse | None = None
    comparison: FrfComparison | None = None
    description: str = ""


def _frf_model(tbi: _TestbedInfo, measured: FrequencyResponse, input_channel: str,
               output_channel: str, rate: float, min_coherence: float,
               notes: list[str]) -> _FrfModel:
    """The model's response on the measured grid, and the comparison; why there is none
    (or what it leaves out) goes to `notes`."""
    model_in, per_amp = FRF_INPUTS[input_channel]
    which = f"{model_in}->{FRF_OUTPUTS[output_channel]}"
    if tbi.model is None:
        notes.append(tbi.note)
        return _FrfModel(which, per_amp)
    try:
        model = model_response(tbi.model, which, measured.freq_hz, sample_rate_hz=rate,
                               per_amp=per_amp)
    except AnalysisError as exc:
        notes.append(f"no model: {exc}")
        return _FrfModel(which, per_amp)
    motor = tbi.model.motor_coarse if model_in == "T1" else tbi.model.motor_fine
    description = (f"{which}, ZOH at {rate:g} Hz, friction-free plant"
                   + (f", x K_t {motor['torque_constant']:g} in-oz/A" if per_amp else ""))
    comparison = compare_frf(measured, model, min_coherence=min_coherence)
    if output_channel == "los_estimate":
        notes.append("the model's LOS angle leaves out the firmware's complementary "
                     "filter that makes los_estimate")
    return _FrfModel(which, per_amp, model, comparison, description)


def frf_from_log(path: str | Path, input_channel: str = "current_coarse",
                 output_channel: str = "encoder_outer", start_s: float | None = None,
                 stop_s: float | None = None, nperseg: int | None = None, *,
                 trim_to_profile: bool = True, testbed: str | Path | Testbed | None = None,
                 min_coherence: float = DEFAULT_MIN_COHERENCE) -> LogFrf:
    """H1 frequency response from `input_channel` to `output_channel` of the log at
    `path`, and the testbed model's response on the same grid (see the module docstring).

    nperseg  Welch segment length in samples (None: frf's default, at least 8 segments).
    Raises MissingChannelError, WindowTooShortError, NoExcitationError, LogError."""
    _check_frf_channels(input_channel, output_channel)
    with LogReader(path) as r:
        w = _read_frf_window(r, input_channel, output_channel, start_s, stop_s, testbed)
    notes: list[str] = []
    t, x, y = _frf_samples(w, input_channel, output_channel, trim_to_profile, notes)
    nperseg = _check_frf_samples(Path(path).name, x, y, w.rate, nperseg, input_channel,
                                 output_channel)
    measured = h1_estimate(x, y, w.rate, nperseg, input_units=w.units.get(input_channel, ""),
                           output_units=w.units.get(output_channel, ""))
    m = _frf_model(w.tbi, measured, input_channel, output_channel, w.rate, min_coherence, notes)
    return LogFrf(path=Path(path), input_channel=input_channel, output_channel=output_channel,
                  window_from_s=float(t[0] - w.origin), window_to_s=float(t[-1] - w.origin),
                  frames=int(x.size), measured=measured, model=m.model,
                  model_path=m.which if m.model is not None else "", model_per_amp=m.per_amp,
                  model_description=m.description, testbed_source=w.tbi.source,
                  comparison=m.comparison, notes=tuple(notes))


# ======================================================================================
# hysteresis
# ======================================================================================
def _check_hysteresis_channels(angle_channel: str, current_channel: str) -> None:
    if angle_channel not in HYSTERESIS_ANGLES:
        raise LogIdentificationError(f"angle channel {angle_channel!r}: the bearing's angle is "
                                     f"{' or '.join(HYSTERESIS_ANGLES)}")
    if current_channel not in HYSTERESIS_DRIVES:
        raise LogIdentificationError(f"drive channel {current_channel!r}: the coarse motor's is "
                                     f"{' or '.join(HYSTERESIS_DRIVES)}")


@dataclass(frozen=True)
class _HysteresisWindow:
    """What hysteresis_from_log reads from the log."""

    d: dict[str, np.ndarray]
    origin: float
    rate: float
    tbi: _TestbedInfo
    use_coupling: bool              # the coupling terms wanted and their channels logged


def _read_hysteresis_window(r: LogReader, angle_channel: str, current_channel: str,
                            start_s, stop_s, *, coupling: bool, trim_to_profile: bool,
                            testbed: str | Path | Testbed | None,
                            notes: list[str]) -> _HysteresisWindow:
    fine_channel = HYSTERESIS_DRIVES[current_channel][1]
    _require(r, [angle_channel, current_channel], "a hysteresis loop")
    have = {c.name for c in r.channels(PACKET)}
    i0, i1 = _window_rows(r, start_s, stop_s)
    tbi = _testbed_info(r, testbed)
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
                 tbi: _TestbedInfo, notes: list[str]) -> FrictionIdentification | None:
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
        span = _trim_to_profile(d["profile_index"])
        if span is not None and (span[0] > 0 or span[1] < t.size):
            notes.append(f"window narrowed to the profile playing in it "
                         f"({t[span[0]] - origin:.3f}..{t[span[1] - 1] - origin:.3f} s)")
            d = {key: v[span[0]:span[1]] for key, v in d.items()}
            t = d["device_time"]
    angle = np.asarray(d[angle_channel], dtype=np.float64)
    drive = np.asarray(d[current_channel], dtype=np.float64)
    torque, formula, kt1 = _bearing_torque(d, angle, drive, current_channel, w, name, notes)
    _, _, missing = _longest_run(t, w.rate)
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


# ======================================================================================
# logs of a folder
# ======================================================================================
def find_logs(folder: str | Path) -> list[Path]:
    """The logs (*.h5) in `folder` and below, sorted by path (a campaign's folder holds
    one per recorded step).  AnalysisError if the folder cannot be listed."""
    root = Path(folder)
    if not root.is_dir():
        raise AnalysisError(f"{root}: not a folder")
    try:
        return sorted(p for p in root.rglob("*.h5") if p.is_file())
    except OSError as exc:
        raise AnalysisError(f"{root}: cannot list the logs ({exc.strerror or exc})") from None


__all__ = ["DEFAULT_MIN_COHERENCE", "FRF_INPUTS", "FRF_OUTPUTS", "HYSTERESIS_ANGLES",
           "HYSTERESIS_DRIVES", "LogFrf", "LogHysteresis", "LogIdentificationError",
           "MIN_TRAVEL_RAD", "MissingChannelError", "NoExcitationError", "WindowTooShortError",
           "find_logs", "frf_from_log", "hysteresis_from_log"]
