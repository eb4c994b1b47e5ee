"""A frequency response from a recorded log, with the testbed model's beside it.  No Qt
and no plotting here; the numerics are frf.py, this module only reads the log (with
log_window.py's helpers) and decides what goes in.

`frf_from_log`: one HIGH_RATE input channel against one output channel over a window of
the log (seconds from its start, inclusive; None: open end).  Two choices are made on
the data before H1 is estimated:

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

Errors: log_window's MissingChannelError, WindowTooShortError, NoExcitationError (and
the log's own LogError).
"""

from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from ..logs import LogReader
from ..plant.testbed import Testbed
from . import AnalysisError
from .frf import (MIN_SEGMENT_SAMPLES, MIN_SEGMENTS, FrequencyResponse, FrfComparison,
                  compare_frf, h1_estimate, model_response)
from .log_window import (PACKET, LogIdentificationError, NoExcitationError, TestbedInfo,
                         WindowTooShortError, check_channel, longest_run, profile_span,
                         require_channels, testbed_info, window_rows)

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
#: coherence at or above which a bin counts in the measured-vs-model comparison
DEFAULT_MIN_COHERENCE = 0.9


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


@dataclass(frozen=True)
class _FrfWindow:
    """What frf_from_log reads from the log: the window's rows and what describes them."""

    d: dict[str, np.ndarray]
    rate: float
    origin: float
    units: dict[str, str]
    mode_names: dict[int, str]
    have_index: bool
    tbi: TestbedInfo


def _check_frf_channels(input_channel: str, output_channel: str) -> None:
    check_channel("input", input_channel, FRF_INPUTS, f"choose one of {', '.join(FRF_INPUTS)}")
    check_channel("output", output_channel, FRF_OUTPUTS,
                  f"choose one of {', '.join(FRF_OUTPUTS)}")


def _read_frf_window(r: LogReader, input_channel: str, output_channel: str, start_s, stop_s,
                     testbed: str | Path | Testbed | None) -> _FrfWindow:
    require_channels(r, [input_channel, output_channel], "this frequency response")
    chans = {c.name: c for c in r.channels(PACKET)}
    have_index = "profile_index" in chans
    i0, i1 = window_rows(r, start_s, stop_s)
    columns = [input_channel, output_channel] + (["profile_index"] if have_index else [])
    columns += ["mode"] if "mode" in chans else []
    d = r.read_rows(PACKET, columns, i0, i1)
    rate = r.tick_rate_hz
    origin = r.origin("device")
    units = {name: c.units for name, c in chans.items()}
    mode_names = {v: k for k, v in chans["mode"].states.items()} if "mode" in chans else {}
    return _FrfWindow(d, rate, origin, units, mode_names, have_index, testbed_info(r, testbed))


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
        span = profile_span(d["profile_index"])
        if span is not None and (span[0] > 0 or span[1] < t.size):
            notes.append(f"window narrowed to the profile playing in it "
                         f"({t[span[0]] - origin:.3f}..{t[span[1] - 1] - origin:.3f} s)")
            t, x, y = t[span[0]:span[1]], x[span[0]:span[1]], y[span[0]:span[1]]
            mode = mode[span[0]:span[1]] if mode is not None else None
    a, b, missing = longest_run(t, w.rate)
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


def _frf_model(tbi: TestbedInfo, measured: FrequencyResponse, input_channel: str,
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


__all__ = ["DEFAULT_MIN_COHERENCE", "FRF_INPUTS", "FRF_OUTPUTS", "LogFrf", "frf_from_log"]
