"""Jitter, control energy and spectra of a recorded log, read in bounded chunks.

`analyze_log(path)` is the adapter between the numerics (jitter.py, energy.py,
spectra.py: arrays in, no I/O) and a log: it reads HIGH_RATE through
`groundstation.logs.LogReader`, `chunk_rows` rows at a time, and feeds the running
accumulators - sums for mean/RMS/std, the high-pass filter's state, the last
integration period of samples for the windowed smear, the unfinished Welch segment,
energy sums and saturation counts - so an hour-long log (4.32 M frames) is never in
memory at once and the result equals the in-memory functions on the same data.

`metrics_from_columns(columns, ...)` runs the same accumulators on columns already in
memory (the GUI's live window), as one chunk: the same frames give the same figures.

The window is `start_s`..`stop_s` seconds of device time from the log's start
(inclusive, None: open end).  The testbed constants (the autocollimator's calibrated
range, the motor resistances) come from the testbed file recorded in the log, or from
`testbed=` when given.

Missing frames.  Sequence numbers count frames the device sent; the tick counts control
periods.  Energy and filters run in control periods, so the holes are found in device
time (ticks): a step of k ticks between consecutive frames means k - 1 frames are
missing, whether the link lost them or the device never sent them.  They are never
bridged: the jitter filter, its windows and the Welch segments restart after a hole,
the energy integrates only the frames received, and the count is reported.

The pieces: testbed_figures.py (the testbed constants), frame_gaps.py (the holes in
device ticks), window_sums.py (the running sums of one window and which sensor samples
count); this module reads the log, feeds them and makes the LogMetrics.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Callable, Iterable, Mapping

import numpy as np

from ..core.kinds import Setup
from ..logs import LogReader
from ..logs.channels import convertible, to_engineering
from ..plant.testbed import Testbed
from . import AnalysisError
from .energy import ControlEnergy
from .jitter import DEFAULT_INTEGRATION_PERIOD_S, JitterResult
from .loop_mode import ModeCheck, mode_check
from .names import AUTO_SENSOR, DEFAULT_SENSOR, METRICS, SENSORS
from .spectra import DEFAULT_SEGMENT_S, Spectrum
from .testbed_figures import TestbedFigures, figures_from_testbed
from .validity import MAX_EXCLUDED_FRACTION, WindowValidity, window_validity
from .window_sums import WindowSums, check_resistances, exclusion_rule

PACKET = "HIGH_RATE"
SENSOR_BY_SETUP = {Setup.RELATIVE: "encoder_inner", Setup.INERTIAL: DEFAULT_SENSOR}
DEFAULT_CHUNK_ROWS = 1 << 18                # ~2 MB per float64 column read at once
CURRENTS = ("current_coarse", "current_fine")
SATURATION_BITS = ("coarse_saturated", "fine_saturated")


# ---------------------------------------------------------------------- the result
@dataclass(frozen=True)
class LogMetrics:
    """The metrics of one log over one window."""

    path: Path
    test_name: str
    window_from_s: float               # first frame of the window, s from the log's start
    window_to_s: float                 # last frame
    frames: int                        # HIGH_RATE frames in the window
    missing_frames: int                # frames lost inside it (device-time holes)
    stalled_frames: int                # frames whose tick did not advance (not bridged either)
    rate_hz: float
    sensor: str
    metrics: tuple[str, ...]
    testbed_source: str
    jitter: JitterResult | None = None
    energy: ControlEnergy | None = None
    spectrum: Spectrum | None = None
    notes: tuple[str, ...] = field(default_factory=tuple)
    #: what the figures were computed from when it is no log file (metrics_from_columns:
    #: e.g. "live window (last 30.0 s)"); '' for a log
    source: str = ""
    #: samples of the window the scored sensor did not measure (None: no sensor scored)
    sensor_excluded: int | None = None
    #: why the scored sensor gave no figure at all ('' : it did, or none was asked for)
    unscored: str = ""
    #: the share of the jitter in the loop's lightly damped mode (None: no check; the
    #: notes say why when one was asked for)
    mode: ModeCheck | None = None

    def validity(self, max_excluded_fraction: float = MAX_EXCLUDED_FRACTION) -> WindowValidity:
        """How much of the window was excluded, and whether that leaves a measurement
        (analysis/validity.py)."""
        return window_validity(self.frames, self.missing_frames, self.sensor_excluded,
                               sensor=self.sensor, max_excluded_fraction=max_excluded_fraction,
                               unscored=self.unscored)

    @property
    def label(self) -> str:
        """The name a table or a plot shows: the log file's name, or the source."""
        return self.source or self.path.name

    @property
    def missing_metrics(self) -> tuple[str, ...]:
        """Metrics asked for that the data did not allow (the notes say why)."""
        have = {"jitter": self.jitter, "energy": self.energy, "psd": self.spectrum}
        return tuple(m for m in self.metrics if have[m] is None)

    def text(self, max_excluded_fraction: float = MAX_EXCLUDED_FRACTION) -> str:
        v = self.validity(max_excluded_fraction)
        lines = [f"{self.label}: {self.window_from_s:.3f}..{self.window_to_s:.3f} s, "
                 f"{self.frames} frames" + (f", {self.missing_frames} missing" if self.missing_frames else "")
                 + ("" if v.valid else f" - NOT VALID: {v.reason}")]
        if self.jitter is not None:
            lines.append("  " + self.jitter.text())
        if self.energy is not None:
            lines.append("  " + self.energy.text())
        if self.spectrum is not None:
            s = self.spectrum
            lines.append(f"  PSD of {self.sensor}: {s.segments} segments of {s.segment_samples} samples "
                         f"({s.resolution_hz:.3g} Hz), sqrt(CSP) {s.rms * 1e6:.3f} urad")
        if self.mode is not None:
            lines.append(f"  mode check ({self.mode.source}): {self.mode.text()}")
        lines += [f"  note: {n}" for n in self.notes]
        return "\n".join(lines)

    def row(self, max_excluded_fraction: float = MAX_EXCLUDED_FRACTION) -> dict[str, Any]:
        """The figures as one flat record (urad, J, A, %); None where not computed.
        `valid` (bool) and `excluded_fraction` judge the window against
        `max_excluded_fraction` (analysis/validity.py)."""
        j, e, s = self.jitter, self.energy, self.spectrum
        v = self.validity(max_excluded_fraction)

        def ur(v: float | None) -> float | None:
            return None if v is None or not math.isfinite(v) else v * 1e6

        def pct(v: float | None) -> float | None:
            return None if v is None else v * 100.0

        return {
            "log": self.label, "test_name": self.test_name, "from_s": self.window_from_s,
            "to_s": self.window_to_s, "frames": self.frames, "missing_frames": self.missing_frames,
            "sensor": self.sensor,
            "samples_used": j.samples_used if j else None,
            "samples_excluded": j.samples_excluded if j else None,
            "segments": j.segments if j else None,
            "integration_period_s": j.integration_period_s if j else None,
            "mean_urad": ur(j.mean_rad) if j else None, "rms_urad": ur(j.rms_rad) if j else None,
            "std_urad": ur(j.std_rad) if j else None,
            "highpass_rms_urad": ur(j.highpass_rms_rad) if j else None,
            "smear_rms_urad": ur(j.smear_rms_rad) if j else None,
            "energy_coarse_j": e.energy_coarse_j if e else None,
            "energy_fine_j": e.energy_fine_j if e else None,
            "energy_total_j": e.energy_total_j if e else None,
            "rms_current_coarse_a": e.rms_current_coarse_a if e else None,
            "rms_current_fine_a": e.rms_current_fine_a if e else None,
            "saturated_coarse_pct": pct(e.saturated_coarse_fraction) if e else None,
            "saturated_fine_pct": pct(e.saturated_fine_fraction) if e else None,
            "psd_rms_urad": ur(s.rms) if s else None,
            "psd_resolution_hz": s.resolution_hz if s else None,
            "psd_segments": s.segments if s else None,
            "highpass_samples_used": j.highpass_samples_used if j else None,
            "highpass_samples_settling": j.highpass_samples_settling if j else None,
            "excluded_fraction": v.excluded_fraction, "valid": v.valid,
            "invalid_reason": v.reason, "max_excluded_fraction": v.max_excluded_fraction,
            **mode_figures(self.mode),
            "notes": "; ".join(self.notes), "error": "",
        }


def mode_figures(mode: ModeCheck | None) -> dict[str, Any]:
    """The mode check's keys of a row (None where there is no check)."""
    if mode is None:
        return dict.fromkeys(("mode_share", "mode_band_hz", "mode_frequency_hz", "mode_damping",
                              "mode_dominates", "mode_band_rule"))
    return {"mode_share": mode.share, "mode_band_hz": [mode.band_hz[0], mode.band_hz[1]],
            "mode_frequency_hz": mode.mode.frequency_hz, "mode_damping": mode.mode.damping,
            "mode_dominates": mode.dominates, "mode_band_rule": mode.mode.rule()}


# ---------------------------------------------------------------------- one window's sums# ---------------------------------------------------------------------- the adapter
def _metrics(metrics: Iterable[str]) -> tuple[str, ...]:
    wanted = tuple(dict.fromkeys(metrics))
    bad = [m for m in wanted if m not in METRICS]
    if bad or not wanted:
        raise AnalysisError(f"unknown metric(s) {', '.join(map(repr, bad))}; choose from "
                            f"{', '.join(METRICS)}" if bad else "no metric asked for")
    return wanted


def _check_sensor(sensor: str) -> None:
    if sensor not in SENSORS and sensor != AUTO_SENSOR:
        raise AnalysisError(f"unknown sensor {sensor!r}; choose from {', '.join(SENSORS)} "
                            f"or {AUTO_SENSOR}")


def analyze_log(path: str | Path, *, metrics: Iterable[str] = METRICS, start_s: float | None = None,
                stop_s: float | None = None, sensor: str = DEFAULT_SENSOR,
                integration_period_s: float = DEFAULT_INTEGRATION_PERIOD_S,
                testbed: str | Path | Testbed | None = None, psd_segment_s: float = DEFAULT_SEGMENT_S,
                chunk_rows: int = DEFAULT_CHUNK_ROWS,
                on_progress: Callable[[int, int], None] | None = None,
                design: str | Path | None = None) -> LogMetrics:
    """The metrics of the log at `path` over its window (see the module docstring).

    `design`: the mode check (loop_mode.py) of the run's loop - "auto" for the last
    design the log records uploading (checked only when the window's frames ran in that
    design's closed-loop mode), a design file (its recorded table if the log has one),
    None for no check.  It needs the PSD (in `metrics`).

    `on_progress(frames_read, frames_in_window)` is called after each chunk; whatever it
    raises ends the analysis there and reaches the caller (the log closed): a caller's
    cancel.

    Raises a GroundStationError naming what is wrong: the log cannot be read (LogError),
    a channel or testbed constant is missing, the window is empty, or every sample of
    the scored sensor is excluded (AnalysisError)."""
    wanted = _metrics(metrics)
    _check_sensor(sensor)
    if chunk_rows < 1:
        raise AnalysisError(f"chunk_rows must be >= 1, not {chunk_rows}")
    with LogReader(path) as r:
        return _analyze(r, wanted, start_s, stop_s, sensor, integration_period_s, testbed,
                        psd_segment_s, int(chunk_rows), on_progress, design)


@dataclass
class _Reading:
    """What _analyze reads from the log, column by column, and what it does with it."""

    columns: list[str]                     # holes are found in ticks: "tick" first
    scoring: bool                          # jitter or PSD asked for: the sensor is read
    angle_from_raw: bool = False           # the sensor's angle converted from its counts
    range_rad: float | None = None         # the sensor's calibrated range, if known
    rule: str = ""                         # the exclusion rule in words
    sat_bits: tuple[str, ...] = ()         # the saturation bits read (none: not reported)


def _plan_sensor(r: LogReader, chans: dict, sensor: str, figures: TestbedFigures,
                 plan: _Reading, notes: list[str]) -> None:
    """The scored sensor's column (its A/D counts when they can be converted) and the
    rule that excludes its samples; AnalysisError if the log cannot give the angle."""
    ch = chans.get(sensor)
    if ch is None:
        present = [s for s in SENSORS if s in chans]
        raise AnalysisError(f"{r.path}: the log has no {PACKET} channel '{sensor}'"
                            + (f"; score another sensor (--sensor {' | '.join(present)})"
                               if present else "; it holds none of the LOS sensors "
                                               f"({', '.join(SENSORS)})"))
    if ch.units != "rad":
        raise AnalysisError(f"{r.path}: channel '{sensor}' is in {ch.units or 'no units'!r}, "
                            f"not rad: the log's dictionary differs from this version's")
    # the A/D count tells a rail sample from a large angle; read it once, convert it
    # exactly as the reader would
    plan.angle_from_raw = ch.has_raw and convertible(ch.conversion) and f"raw/{sensor}" in chans
    plan.columns.append(f"raw/{sensor}" if plan.angle_from_raw else sensor)
    bits = np.dtype(chans[f"raw/{sensor}"].dtype).itemsize * 8 if plan.angle_from_raw else 0
    plan.range_rad, plan.rule = exclusion_rule(sensor, figures, bits, notes)


def _plan_energy(r: LogReader, chans: dict, figures: TestbedFigures, plan: _Reading,
                 notes: list[str]) -> None:
    """The currents and, when the log has them, the saturation bits; AnalysisError
    without the currents or the motor resistances."""
    lacking = [c for c in CURRENTS if c not in chans]
    if lacking:
        raise AnalysisError(f"{r.path}: the log has no {PACKET} channel(s) {', '.join(lacking)}: "
                            f"no control energy (use --metrics without energy)")
    check_resistances(figures, r.path)
    plan.columns += list(CURRENTS)
    if all(b in chans for b in SATURATION_BITS):
        plan.sat_bits = SATURATION_BITS
        plan.columns += list(plan.sat_bits)
    else:
        notes.append("the log has no saturation status bits: saturation not reported")


def _plan_mode_check(r: LogReader, chans: dict, wanted, design, plan: _Reading,
                     notes: list[str]):
    """The loop whose mode the PSD is checked against (log_mode.DesignSource), or None
    with a note why not; a design found automatically also reads the loop's mode."""
    if design is None:
        return None
    if "psd" not in wanted:
        notes.append("no mode check: it needs the PSD (--metrics with psd)")
        return None
    from .log_mode import AUTO, find_design
    loop = find_design(r, design)
    if loop.mode is None:
        if loop.reason:
            notes.append(f"no mode check: {loop.reason}")
        return None
    if str(design) == AUTO and "mode" in chans:
        plan.columns.append("mode")          # the check wants the loop closed in the window
    return loop


def _feed_window(r: LogReader, i0: int, i1: int, chunk_rows: int, plan: _Reading, sensor: str,
                 chans: dict, sums: WindowSums, energy: bool,
                 on_progress: Callable[[int, int], None] | None) -> dict[int, int]:
    """Rows [i0, i1) fed to `sums` a chunk at a time; the frames counted per loop mode
    (empty when the mode is not read)."""
    mode_counts: dict[int, int] = {}
    a = i0
    while a < i1:
        d = r.read_rows(PACKET, plan.columns, a, min(i1, a + chunk_rows), with_time=False)
        ticks = d["tick"]
        if not len(ticks):           # a live log shorter than its index said: stop there
            break
        angle = counts = None
        if plan.scoring:
            if plan.angle_from_raw:
                counts = d[f"raw/{sensor}"]
                angle = to_engineering(counts, chans[sensor].conversion)
            else:
                angle = d[sensor]
        sat_bits = plan.sat_bits
        sums.feed(ticks, angle, counts,
                  (d[CURRENTS[0]], d[CURRENTS[1]]) if energy else None,
                  (d[sat_bits[0]], d[sat_bits[1]]) if sat_bits else None)
        if "mode" in d:
            values, n = np.unique(d["mode"], return_counts=True)
            for v, k in zip(values.tolist(), n.tolist()):
                mode_counts[v] = mode_counts.get(v, 0) + k
        a += len(ticks)
        if on_progress is not None:
            on_progress(sums.frames, i1 - i0)
    return mode_counts


def _analyze(r: LogReader, wanted, start_s, stop_s, sensor, integration_period_s, testbed,
             psd_segment_s, chunk_rows, on_progress=None, design=None) -> LogMetrics:
    chans = {c.name: c for c in r.channels(PACKET)}
    rate = r.tick_rate_hz
    figures = figures_from_testbed(r, testbed)
    notes: list[str] = []
    if sensor == AUTO_SENSOR:
        sensor = SENSOR_BY_SETUP.get(figures.setup, DEFAULT_SENSOR)
    plan = _Reading(columns=["tick"], scoring="jitter" in wanted or "psd" in wanted)
    if plan.scoring:
        _plan_sensor(r, chans, sensor, figures, plan, notes)
    if "energy" in wanted:
        _plan_energy(r, chans, figures, plan, notes)
    loop = _plan_mode_check(r, chans, wanted, design, plan, notes)

    i0, i1 = r.index_range(PACKET, start_s, stop_s, relative=True)
    if i1 <= i0:
        raise AnalysisError(f"{r.path}: no {PACKET} frames in the window "
                            f"{r.describe_range(PACKET, start_s, stop_s, relative=True)}")
    sums = WindowSums(wanted, rate, i1 - i0, integration_period_s, psd_segment_s, figures,
                      plan.range_rad)
    origin = r.origin("device")
    mode_counts = _feed_window(r, i0, i1, chunk_rows, plan, sensor, chans, sums,
                               "energy" in wanted, on_progress)
    # the window's ends in device time: two values, not a column
    ends = r.read_rows(PACKET, ["device_time"], i0, i0 + 1, with_time=False)["device_time"]
    first_t = float(ends[0])
    last_t = float(r.read_rows(PACKET, ["device_time"], i0 + sums.frames - 1, i0 + sums.frames,
                               with_time=False)["device_time"][0])
    jitter, energy, spectrum = sums.finish(sensor, plan.rule, figures.setup, notes)
    mode = _mode_check(loop, spectrum, mode_counts, chans.get("mode"), sums.frames, notes)
    return LogMetrics(
        path=r.path, test_name=str(r.attrs.get("test_name", "")),
        window_from_s=first_t - origin, window_to_s=last_t - origin, frames=sums.frames,
        missing_frames=sums.missing, stalled_frames=sums.stalled, rate_hz=rate,
        sensor=sensor if plan.scoring else "", metrics=wanted, testbed_source=figures.source,
        jitter=jitter, energy=energy, spectrum=spectrum, notes=tuple(notes),
        sensor_excluded=sums.excluded if plan.scoring else None, unscored=sums.unscored,
        mode=mode)


def _mode_check(loop, spectrum: Spectrum | None, mode_counts: dict[int, int], channel,
                frames: int, notes: list[str]) -> ModeCheck | None:
    """The mode check of the window's PSD against `loop` (log_mode.DesignSource; None:
    none).  With mode counts (the design was found automatically) the loop must have
    been closed, in the design's mode, over most of the window."""
    if loop is None:
        return None
    if spectrum is None:
        notes.append("no mode check: no PSD of the window")
        return None
    if mode_counts:
        from .log_mode import CLOSED_LOOP_STATES
        state = channel.states.get(CLOSED_LOOP_STATES.get(loop.design_mode, ""))
        closed = mode_counts.get(state, 0) if state is not None else 0
        if closed * 2 <= frames:
            notes.append(f"no mode check: the loop of {loop.source} was not closed over most of "
                         f"the window ({closed} of {frames} frames in {loop.design_mode} mode)")
            return None
    try:
        return mode_check(loop.mode, spectrum.frequency_hz, spectrum.density, spectrum.resolution_hz,
                          loop.source)
    except AnalysisError as exc:
        notes.append(f"no mode check: {exc}")
        return None


# ---------------------------------------------------------------------- columns in memory
def metrics_from_columns(columns: Mapping[str, Any], rate_hz: float, figures: TestbedFigures, *,
                         source: str, window_s: tuple[float, float],
                         metrics: Iterable[str] = METRICS, sensor: str = DEFAULT_SENSOR,
                         integration_period_s: float = DEFAULT_INTEGRATION_PERIOD_S,
                         psd_segment_s: float = DEFAULT_SEGMENT_S,
                         test_name: str = "") -> LogMetrics:
    """The metrics of HIGH_RATE columns held in memory, computed as analyze_log computes
    one chunk: "tick" (its holes are the missing frames), the scored `sensor` in rad and,
    if known, "raw/<sensor>" (integer counts: either end of the type is the rail), for
    energy the currents and, if known, the saturation bits.  `source` names the window
    (the result's label; its `path` is empty: no file), `window_s` its first and last
    frames' times.  Raises AnalysisError as analyze_log does."""
    wanted = _metrics(metrics)
    _check_sensor(sensor)
    ticks = np.asarray(columns["tick"]) if "tick" in columns else np.zeros(0)
    n = len(ticks)
    if not n:
        raise AnalysisError(f"{source}: no {PACKET} frames in it")
    if any(len(v) != n for v in columns.values()):
        raise AnalysisError(f"{source}: the columns are not all as long as 'tick' ({n})")
    notes: list[str] = []
    scoring = "jitter" in wanted or "psd" in wanted
    angle = counts = None
    range_rad, rule = None, ""
    if scoring:
        if sensor not in columns:
            present = [s for s in SENSORS if s in columns]
            raise AnalysisError(f"{source}: no {PACKET} channel '{sensor}'"
                                + (f"; score another sensor ({' | '.join(present)})"
                                   if present else ""))
        angle = np.asarray(columns[sensor], dtype=float)
        raw = columns.get(f"raw/{sensor}")
        if raw is not None and np.asarray(raw).dtype.kind in "iu":
            counts = np.asarray(raw)
        range_rad, rule = exclusion_rule(sensor, figures,
                                         counts.dtype.itemsize * 8 if counts is not None else 0,
                                         notes)
    currents = saturation = None
    if "energy" in wanted:
        lacking = [c for c in CURRENTS if c not in columns]
        if lacking:
            raise AnalysisError(f"{source}: no {PACKET} channel(s) {', '.join(lacking)}: no "
                                f"control energy")
        check_resistances(figures, source)
        currents = (columns[CURRENTS[0]], columns[CURRENTS[1]])
        if all(b in columns for b in SATURATION_BITS):
            saturation = (columns[SATURATION_BITS[0]], columns[SATURATION_BITS[1]])
        else:
            notes.append(f"{source} has no saturation status bits: saturation not reported")
    sums = WindowSums(wanted, float(rate_hz), n, integration_period_s, psd_segment_s, figures,
                      range_rad)
    sums.feed(ticks, angle, counts, currents, saturation)
    jitter, energy, spectrum = sums.finish(sensor, rule, figures.setup, notes)
    return LogMetrics(
        path=Path(), test_name=test_name, window_from_s=float(window_s[0]),
        window_to_s=float(window_s[1]), frames=sums.frames, missing_frames=sums.missing,
        stalled_frames=sums.stalled, rate_hz=float(rate_hz), sensor=sensor if scoring else "",
        metrics=wanted, testbed_source=figures.source, jitter=jitter, energy=energy,
        spectrum=spectrum, notes=tuple(notes), source=source,
        sensor_excluded=sums.excluded if scoring else None, unscored=sums.unscored)


__all__ = ["CURRENTS", "DEFAULT_CHUNK_ROWS", "LogMetrics", "PACKET", "SATURATION_BITS",
           "analyze_log", "metrics_from_columns"]
