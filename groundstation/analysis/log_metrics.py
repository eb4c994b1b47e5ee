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
"""

from __future__ import annotations

import math
import tomllib
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Callable, Iterable, Mapping

import numpy as np

from ..logs import LogReader
from ..logs.channels import convertible, to_engineering
from ..plant.testbed import Testbed, TestbedConfigError, load_testbed
from . import AnalysisError
from .energy import ControlEnergy, EnergyAccumulator
from .jitter import DEFAULT_INTEGRATION_PERIOD_S, JitterAccumulator, JitterResult, sensor_valid
from .spectra import DEFAULT_SEGMENT_S, Spectrum, WelchAccumulator, segment_samples
from .loop_mode import ModeCheck, mode_check
from .validity import MAX_EXCLUDED_FRACTION, WindowValidity, window_validity

PACKET = "HIGH_RATE"
SENSORS = ("autocollimator", "los_estimate", "encoder_inner")
DEFAULT_SENSOR = "autocollimator"           # the reference's scoring sensor
#: the sensors only the inertial set-up carries (IMU and mirror with the autocollimator)
LOS_SENSORS = ("autocollimator", "los_estimate")
METRICS = ("jitter", "energy", "psd")
DEFAULT_CHUNK_ROWS = 1 << 18                # ~2 MB per float64 column read at once
CURRENTS = ("current_coarse", "current_fine")
SATURATION_BITS = ("coarse_saturated", "fine_saturated")
DEG = math.pi / 180.0


# ---------------------------------------------------------------------- testbed constants
@dataclass(frozen=True)
class TestbedFigures:
    """The testbed constants the metrics need, and where they came from."""

    __test__ = False

    source: str                                  # '' when the log records no testbed
    autocollimator_range_rad: float | None
    resistance_coarse_ohm: float | None
    resistance_fine_ohm: float | None
    setup: str = ""                              # "relative" | "inertial" | '' unknown

    @classmethod
    def of(cls, tb: Testbed, source: str) -> "TestbedFigures":
        return cls(source, tb.sensors["autocollimator_range"] * DEG, tb.motor_coarse["resistance"],
                   tb.motor_fine["resistance"], tb.setup)


def _number(doc: dict, section: str, key: str) -> float | None:
    v = doc.get(section, {}).get(key) if isinstance(doc.get(section), dict) else None
    if isinstance(v, bool) or not isinstance(v, (int, float)) or not (v > 0 and math.isfinite(v)):
        return None
    return float(v)


def figures_from_testbed(reader: LogReader, testbed: str | Path | Testbed | None = None) -> TestbedFigures:
    """From `testbed` (a file or a loaded Testbed) if given, else from the log: the
    recorded file itself when it is still where it was and unchanged (then checked in
    full by load_testbed), else the recorded text - what was true when the log was made."""
    if testbed is not None:
        tb = testbed if isinstance(testbed, Testbed) else load_testbed(testbed)
        return TestbedFigures.of(tb, f"testbed file {tb.path}")
    name, where, text = reader.testbed()
    if not text:
        return TestbedFigures("", None, None, None)
    label = f"the log's testbed '{name}'" if name else "the log's testbed"
    if where and Path(where).is_file():
        try:
            tb = load_testbed(where)
        except TestbedConfigError:
            tb = None
        if tb is not None and tb.text == text:
            return TestbedFigures.of(tb, f"{label} ({where})")
    try:
        doc = tomllib.loads(text)
    except tomllib.TOMLDecodeError as exc:
        raise AnalysisError(f"{reader.path}: the testbed file recorded in the log is not valid "
                            f"TOML ({exc}): give --testbed FILE") from None
    rng = _number(doc, "sensors", "autocollimator_range")
    return TestbedFigures(f"{label} (as recorded in the log)", None if rng is None else rng * DEG,
                          _number(doc, "motor_coarse", "resistance"),
                          _number(doc, "motor_fine", "resistance"),
                          str(doc.get("testbed", {}).get("setup", "")) if isinstance(doc.get("testbed"), dict) else "")


# ---------------------------------------------------------------------- missing frames
TICK_MODULUS = 1 << 32                      # the header's tick is a u32 that wraps (41 days)


def frame_steps(tick, previous_tick: int | None = None) -> tuple[np.ndarray, int, int]:
    """(gap_before, missing frames, non-advancing frames) of consecutive frames' device
    ticks: gap_before[k] is True when frame k is not one tick after the frame before it
    (`previous_tick`: the frame before the first; None: none).  A step of k > 1 ticks
    means k - 1 frames missing; a step of 0 or backwards (a repeated or out-of-order
    frame) is counted apart and breaks the stretch too."""
    t = np.asarray(tick).astype(np.uint32, copy=False)
    if not len(t):
        return np.zeros(0, dtype=bool), 0, 0
    steps = np.empty(len(t), dtype=np.uint32)
    steps[0] = 1 if previous_tick is None else (int(t[0]) - int(previous_tick)) % TICK_MODULUS
    np.subtract(t[1:], t[:-1], out=steps[1:])          # uint32 arithmetic wraps with the tick
    gap = steps != 1
    if not gap.any():
        return gap, 0, 0
    odd = steps[gap].astype(np.int64)
    back = (odd == 0) | (odd >= TICK_MODULUS // 2)     # no advance, or a step backwards
    return gap, int((odd[~back] - 1).sum()), int(back.sum())


def missing_before(tick, previous_tick: int | None = None) -> np.ndarray:
    """Frames missing just before each frame, from the device ticks (as frame_steps
    counts them): k - 1 for a step of k > 1 ticks, -1 for a step of 0 or backwards (a
    repeated or out-of-order frame: a break of no known length), else 0.  The jitter's
    high-pass bridges a short hole with it (jitter.BRIDGE_MAX_PERIODS)."""
    t = np.asarray(tick).astype(np.uint32, copy=False)
    if not len(t):
        return np.zeros(0, dtype=np.int64)
    steps = np.empty(len(t), dtype=np.int64)
    steps[0] = 1 if previous_tick is None else (int(t[0]) - int(previous_tick)) % TICK_MODULUS
    steps[1:] = np.subtract(t[1:], t[:-1])             # uint32 arithmetic wraps with the tick
    back = (steps == 0) | (steps >= TICK_MODULUS // 2)
    return np.where(back, -1, steps - 1)


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


# ---------------------------------------------------------------------- one window's sums
def _exclusion_rule(sensor: str, figures: TestbedFigures, bits: int,
                    notes: list[str]) -> tuple[float | None, str]:
    """(calibrated range or None, the exclusion rule in words) of the scored sensor;
    `bits`: its raw count's width (0: unknown).  Notes an unknown autocollimator range."""
    # a count at either end of its wire type is a clipped value, not a measurement
    rail = ((f" or at the {bits}-bit A/D rail" if sensor == "autocollimator"
             else f" or at the limit of its {bits}-bit count") if bits else "")
    if sensor != "autocollimator":
        return None, rail.removeprefix(" or ") if rail else ""
    range_rad = figures.autocollimator_range_rad
    if range_rad is None:
        notes.append("the autocollimator's calibrated range is unknown (the log records no "
                     "testbed file with [sensors] autocollimator_range): only samples at "
                     "the A/D rail are excluded; give --testbed FILE for the range")
        return None, "at the A/D rail" if bits else ""
    return range_rad, (f"|angle| >= {range_rad * 1e3:.4g} mrad (calibrated range "
                       f"{range_rad / DEG:g} deg, {figures.source}){rail}")


def _check_resistances(figures: TestbedFigures, where: object) -> None:
    if figures.resistance_coarse_ohm is None or figures.resistance_fine_ohm is None:
        known = figures.source or "the log records no testbed file"
        raise AnalysisError(f"{where}: the motor resistances ([motor_coarse] / [motor_fine] "
                            f"resistance) are unknown ({known}): give --testbed FILE")


class _WindowSums:
    """One window's running figures: missing and stalled frames, the scored sensor's
    jitter and Welch sums, the energy sums.  analyze_log feeds it a chunk at a time,
    metrics_from_columns once."""

    def __init__(self, wanted: tuple[str, ...], rate: float, frames: int,
                 integration_period_s: float, psd_segment_s: float, figures: TestbedFigures,
                 range_rad: float | None):
        self.range_rad = range_rad
        self.jit = JitterAccumulator(rate, integration_period_s) if "jitter" in wanted else None
        self.welch = (WelchAccumulator(rate, segment_samples(rate, psd_segment_s, frames))
                      if "psd" in wanted else None)
        self.energy = (EnergyAccumulator(rate, figures.resistance_coarse_ohm, figures.resistance_fine_ohm)
                       if "energy" in wanted else None)
        self.frames = self.missing = self.stalled = 0
        self.excluded = 0                 # scored samples the sensor did not measure
        self.unscored = ""                # why the sensor gave no figure at all
        self.last_tick: int | None = None

    def feed(self, ticks, angle=None, counts=None, currents=None, saturation=None) -> None:
        """The next piece: its ticks, the scored angle (None: not scoring) and counts
        (None: unknown), the currents and saturation bits (None: none)."""
        gap, m, s = frame_steps(ticks, self.last_tick)
        holes = missing_before(ticks, self.last_tick) if m else None
        self.missing += m
        self.stalled += s
        self.last_tick = int(ticks[-1])
        self.frames += len(ticks)
        if angle is not None:
            ok = sensor_valid(angle, range_rad=self.range_rad, raw_counts=counts)
            self.excluded += len(ok) - int(np.count_nonzero(ok))
            if self.jit is not None:
                self.jit.feed(angle, ok, gap, holes)
            if self.welch is not None:
                self.welch.feed(angle, ok, gap)
        if self.energy is not None:
            self.energy.feed(*currents, *(saturation if saturation is not None else (None, None)))

    def finish(self, sensor: str, rule: str, setup: str, notes: list[str]):
        """(jitter, energy, spectrum); what the data do not allow (every sample excluded,
        no stretch long enough for a PSD segment) is left out, the reason in `notes`."""
        if self.stalled:
            notes.append(f"{self.stalled} frame(s) did not advance the device tick (repeated or "
                         f"out of order): the filters restart there")
        jit, welch = self.jit, self.welch
        jitter = spectrum = None
        if jit is not None and jit.n and jit.lowest == jit.highest:
            if setup == "relative" and sensor in LOS_SENSORS:
                # the relative set-up has no IMU or mirror: the channel is a placeholder, and
                # its constant is nothing measured - not a perfect line of sight
                notes.append(f"no jitter or PSD: the {sensor} reads one constant value "
                             f"({jit.lowest:.6g} rad) over all {jit.n} samples and the testbed is "
                             f"the relative set-up, which has no autocollimator or IMU: --sensor "
                             f"encoder_inner")
                self.unscored = f"the relative set-up has no {sensor}: nothing was measured"
                jit = welch = None
            else:
                notes.append(f"the {sensor} reads one constant value over all {jit.n} samples: "
                             f"any motion was below its resolution")
        if jit is not None:
            try:
                jitter = jit.result(sensor, missing_frames=self.missing, exclusion_rule=rule)
            except AnalysisError as exc:
                notes.append(f"no jitter: {exc}")
                self.unscored = f"no jitter: {exc}"
        if welch is not None:
            try:
                spectrum = welch.result()
            except AnalysisError as exc:
                notes.append(f"no PSD: {exc} (--psd-segment S, psd_segment_s=S)")
        energy = self.energy.result(self.missing) if self.energy is not None else None
        return jitter, energy, spectrum


# ---------------------------------------------------------------------- the adapter
def _metrics(metrics: Iterable[str]) -> tuple[str, ...]:
    wanted = tuple(dict.fromkeys(metrics))
    bad = [m for m in wanted if m not in METRICS]
    if bad or not wanted:
        raise AnalysisError(f"unknown metric(s) {', '.join(map(repr, bad))}; choose from "
                            f"{', '.join(METRICS)}" if bad else "no metric asked for")
    return wanted


def _check_sensor(sensor: str) -> None:
    if sensor not in SENSORS:
        raise AnalysisError(f"unknown sensor {sensor!r}; choose from {', '.join(SENSORS)}")


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


def _analyze(r: LogReader, wanted, start_s, stop_s, sensor, integration_period_s, testbed,
             psd_segment_s, chunk_rows, on_progress=None, design=None) -> LogMetrics:
    chans = {c.name: c for c in r.channels(PACKET)}
    rate = r.tick_rate_hz
    figures = figures_from_testbed(r, testbed)
    notes: list[str] = []
    columns = ["tick"]               # holes are found in ticks (see the module docstring)
    angle_from_raw = False
    range_rad = None
    rule = ""
    scoring = "jitter" in wanted or "psd" in wanted
    if scoring:
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
        angle_from_raw = ch.has_raw and convertible(ch.conversion) and f"raw/{sensor}" in chans
        columns.append(f"raw/{sensor}" if angle_from_raw else sensor)
        bits = np.dtype(chans[f"raw/{sensor}"].dtype).itemsize * 8 if angle_from_raw else 0
        range_rad, rule = _exclusion_rule(sensor, figures, bits, notes)
    sat_bits: tuple[str, ...] = ()
    if "energy" in wanted:
        lacking = [c for c in CURRENTS if c not in chans]
        if lacking:
            raise AnalysisError(f"{r.path}: the log has no {PACKET} channel(s) {', '.join(lacking)}: "
                                f"no control energy (use --metrics without energy)")
        _check_resistances(figures, r.path)
        columns += list(CURRENTS)
        if all(b in chans for b in SATURATION_BITS):
            sat_bits = SATURATION_BITS
            columns += list(sat_bits)
        else:
            notes.append("the log has no saturation status bits: saturation not reported")

    loop = None
    if design is not None and "psd" in wanted:
        from .log_mode import AUTO, find_design
        loop = find_design(r, design)
        if loop.mode is None:
            if loop.reason:
                notes.append(f"no mode check: {loop.reason}")
            loop = None
        elif str(design) == AUTO and "mode" in chans:
            columns.append("mode")           # the check wants the loop closed in the window
    elif design is not None:
        notes.append("no mode check: it needs the PSD (--metrics with psd)")
    mode_counts: dict[int, int] = {}

    i0, i1 = r.index_range(PACKET, start_s, stop_s, relative=True)
    if i1 <= i0:
        raise AnalysisError(f"{r.path}: no {PACKET} frames in the window "
                            f"{r.describe_range(PACKET, start_s, stop_s, relative=True)}")
    sums = _WindowSums(wanted, rate, i1 - i0, integration_period_s, psd_segment_s, figures,
                       range_rad)
    origin = r.origin("device")
    a = i0
    while a < i1:
        d = r.read_rows(PACKET, columns, a, min(i1, a + chunk_rows), with_time=False)
        ticks = d["tick"]
        if not len(ticks):           # a live log shorter than its index said: stop there
            break
        angle = counts = None
        if scoring:
            if angle_from_raw:
                counts = d[f"raw/{sensor}"]
                angle = to_engineering(counts, chans[sensor].conversion)
            else:
                angle = d[sensor]
        sums.feed(ticks, angle, counts,
                  (d[CURRENTS[0]], d[CURRENTS[1]]) if "energy" in wanted else None,
                  (d[sat_bits[0]], d[sat_bits[1]]) if sat_bits else None)
        if "mode" in d:
            values, n = np.unique(d["mode"], return_counts=True)
            for v, k in zip(values.tolist(), n.tolist()):
                mode_counts[v] = mode_counts.get(v, 0) + k
        a += len(ticks)
        if on_progress is not None:
            on_progress(sums.frames, i1 - i0)
    # the window's ends in device time: two values, not a column
    ends = r.read_rows(PACKET, ["device_time"], i0, i0 + 1, with_time=False)["device_time"]
    first_t = float(ends[0])
    last_t = float(r.read_rows(PACKET, ["device_time"], i0 + sums.frames - 1, i0 + sums.frames,
                               with_time=False)["device_time"][0])
    jitter, energy, spectrum = sums.finish(sensor, rule, figures.setup, notes)
    mode = _mode_check(loop, spectrum, mode_counts, chans.get("mode"), sums.frames, notes)
    return LogMetrics(
        path=r.path, test_name=str(r.attrs.get("test_name", "")),
        window_from_s=first_t - origin, window_to_s=last_t - origin, frames=sums.frames,
        missing_frames=sums.missing, stalled_frames=sums.stalled, rate_hz=rate,
        sensor=sensor if scoring else "", metrics=wanted, testbed_source=figures.source,
        jitter=jitter, energy=energy, spectrum=spectrum, notes=tuple(notes),
        sensor_excluded=sums.excluded if scoring else None, unscored=sums.unscored, mode=mode)


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
        range_rad, rule = _exclusion_rule(sensor, figures,
                                          counts.dtype.itemsize * 8 if counts is not None else 0,
                                          notes)
    currents = saturation = None
    if "energy" in wanted:
        lacking = [c for c in CURRENTS if c not in columns]
        if lacking:
            raise AnalysisError(f"{source}: no {PACKET} channel(s) {', '.join(lacking)}: no "
                                f"control energy")
        _check_resistances(figures, source)
        currents = (columns[CURRENTS[0]], columns[CURRENTS[1]])
        if all(b in columns for b in SATURATION_BITS):
            saturation = (columns[SATURATION_BITS[0]], columns[SATURATION_BITS[1]])
        else:
            notes.append(f"{source} has no saturation status bits: saturation not reported")
    sums = _WindowSums(wanted, float(rate_hz), n, integration_period_s, psd_segment_s, figures,
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


__all__ = ["CURRENTS", "DEFAULT_CHUNK_ROWS", "DEFAULT_SENSOR", "LogMetrics", "METRICS", "PACKET",
           "SATURATION_BITS", "SENSORS", "TICK_MODULUS", "TestbedFigures", "analyze_log", "frame_steps",
           "missing_before",
           "figures_from_testbed", "metrics_from_columns"]
