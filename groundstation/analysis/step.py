"""Closed-loop step-response figures of merit: rise time, overshoot, settling time,
steady-state error, peak control effort.

Definitions (all times from the step's start, ``start_time_s``):

- baseline y0: the response at the last sample at or before the start (the loop is at
  rest there; if the record starts after the step, its first sample).
- target: y0 + reference_step_size.  Rise time, overshoot and settling are measured
  against the *commanded* step, not against the final value the loop happened to reach:
  the question is how well the loop follows its command, and a loop that settles short
  of it should not have that hidden.  How far short it settles is the steady-state error.
  Everything works in the normalised response n = (y − y0) / step, so a negative step
  behaves like a positive one.
- rise time: 10 % → 90 % of the step, each crossing the first one, linearly interpolated
  between samples (nan if the response never reaches 90 %).
- overshoot: max(0, max n − 1) in percent of the step.
- settling time: the time after which |n − 1| stays within ``settling_band`` (2 % by
  default), i.e. the interpolated moment the response last enters the band; nan if it
  is outside the band at the end of the record (not settled).  0 if it never leaves it.
- steady-state error: target minus the mean response over the last
  ``steady_state_fraction`` (10 %) of the post-step record, in response units (and in %
  of the step); the mean, not the last sample, so encoder noise and a limit cycle from
  friction average out.  It has the step's sign when the loop stopped short of the
  command (the percentage is then positive) and the opposite sign when it went past.
- peak control effort: max |effort| over the samples from the start on (e.g. motor
  torque or current), with its time.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from . import AnalysisError

__all__ = ["StepMetricsError", "StepMetrics", "step_metrics"]


class StepMetricsError(AnalysisError, ValueError):
    """A step record cannot be evaluated (the message says which argument and why)."""


MIN_POST_STEP_SAMPLES = 10


@dataclass(frozen=True)
class StepMetrics:
    rise_time_s: float                   # 10 → 90 % of the commanded step (nan: never reached 90 %)
    overshoot_percent: float             # beyond the target, % of the step (0 if none)
    settling_time_s: float               # into the band for good (nan: not settled by the end)
    settling_band_fraction: float        # the band used, e.g. 0.02 = ±2 % of the step
    steady_state_error: float            # target − mean of the last part, response units
    steady_state_error_percent: float    # the same in % of the step
    steady_state_window_s: float         # length of that last part
    peak_effort: float                   # max |effort| after the start (nan: no effort given)
    peak_effort_time_s: float            # when, from the start
    initial_value: float                 # y0
    target_value: float                  # y0 + step
    peak_value: float                    # the response's extreme in the step's direction
    peak_time_s: float

    @property
    def settled(self) -> bool:
        return not math.isnan(self.settling_time_s)


def _as_1d(name: str, values) -> np.ndarray:
    try:
        a = np.asarray(values, dtype=np.float64)
    except (TypeError, ValueError):
        raise StepMetricsError(f"{name} must be a 1-D array of numbers") from None
    if a.ndim != 1:
        raise StepMetricsError(f"{name} must be 1-D, got shape {a.shape}")
    if not np.all(np.isfinite(a)):
        i = int(np.argmax(~np.isfinite(a)))
        raise StepMetricsError(f"{name} contains a non-finite value at sample {i} ({a[i]})")
    return a


def _first_crossing(t: np.ndarray, n: np.ndarray, level: float) -> float:
    """Time of the first sample pair where n reaches ``level`` from below (interpolated)."""
    above = n >= level
    if not np.any(above):
        return math.nan
    i = int(np.argmax(above))
    if i == 0:
        return float(t[0])
    t0, t1, n0, n1 = t[i - 1], t[i], n[i - 1], n[i]
    return float(t0 + (level - n0) / (n1 - n0) * (t1 - t0))


def _checked_arguments(t: np.ndarray, y: np.ndarray, reference_step_size, start_time_s,
                       settling_band, steady_state_fraction) -> tuple[float, float, float, float]:
    """(step, start time, settling band, steady-state fraction), checked with the samples."""
    if t.size != y.size:
        raise StepMetricsError(f"time_s and response must have the same length: "
                               f"{t.size} vs {y.size}")
    if t.size >= 2 and np.any(np.diff(t) <= 0.0):
        i = int(np.argmax(np.diff(t) <= 0.0))
        raise StepMetricsError(f"time_s must be strictly increasing (sample {i + 1}: "
                               f"{t[i + 1]!r} after {t[i]!r})")
    step = float(reference_step_size)
    if not math.isfinite(step) or step == 0.0:
        raise StepMetricsError(f"reference_step_size = {reference_step_size!r}: must be a "
                               f"finite, non-zero step (there is no step to evaluate)")
    t_start = float(start_time_s)
    if not math.isfinite(t_start):
        raise StepMetricsError(f"start_time_s = {start_time_s!r}: must be finite")
    band = float(settling_band)
    if not 0.0 < band < 1.0:
        raise StepMetricsError(f"settling_band = {settling_band!r}: must be a fraction in (0, 1)")
    frac = float(steady_state_fraction)
    if not 0.0 < frac <= 1.0:
        raise StepMetricsError(f"steady_state_fraction = {steady_state_fraction!r}: must be "
                               f"in (0, 1]")
    return step, t_start, band, frac


def _first_after_start(t: np.ndarray, t_start: float) -> int:
    """Index of the first sample at or after the step; raises if too few follow it."""
    post = t >= t_start
    n_post = int(np.count_nonzero(post))
    if n_post < MIN_POST_STEP_SAMPLES:
        raise StepMetricsError(f"record too short after the step: {n_post} samples from "
                               f"start_time_s = {t_start:g} s (need at least "
                               f"{MIN_POST_STEP_SAMPLES}; the record spans "
                               f"{t[0]:g} … {t[-1]:g} s)" if t.size else
                               "record is empty")
    return int(np.argmax(post))


def _settling_time(t_after: np.ndarray, n_after: np.ndarray, band: float) -> float:
    """When the normalised response enters the band for good (NaN: it ends outside)."""
    outside = np.abs(n_after - 1.0) > band
    if outside[-1]:
        return math.nan
    if not np.any(outside):
        return 0.0
    j = int(np.flatnonzero(outside)[-1])     # last sample outside; j + 1 is inside
    # interpolate where |n − 1| crosses the band between samples j and j + 1
    e0, e1 = abs(n_after[j] - 1.0), abs(n_after[j + 1] - 1.0)
    fr = (e0 - band) / (e0 - e1) if e0 != e1 else 1.0
    return float(t_after[j] + fr * (t_after[j + 1] - t_after[j]))


def _peak_effort(effort, t: np.ndarray, first: int, t_start: float) -> tuple[float, float]:
    """(largest |effort| from the step on, its time after the step); NaNs without effort."""
    if effort is None:
        return math.nan, math.nan
    u = _as_1d("effort", effort)
    if u.size != t.size:
        raise StepMetricsError(f"effort must have the same length as time_s: "
                               f"{u.size} vs {t.size}")
    ua = np.abs(u[first:])
    iu = int(np.argmax(ua))
    return float(ua[iu]), float(t[first + iu] - t_start)


def step_metrics(time_s, response, reference_step_size: float, start_time_s: float,
                 effort=None, *, settling_band: float = 0.02,
                 steady_state_fraction: float = 0.1) -> StepMetrics:
    """Figures of merit of a step response (definitions in the module docstring).

    time_s               sample times, strictly increasing [s]
    response             the controlled output (same length), e.g. the LOS angle [rad]
    reference_step_size  the commanded step in response units (sign = direction; ≠ 0)
    start_time_s         when the step was commanded
    effort               optional control effort samples (same length), e.g. torque
    Raises StepMetricsError for mismatched lengths, non-finite samples, a time axis that
    does not increase, a zero step, or fewer than 10 samples after the start.
    """
    t = _as_1d("time_s", time_s)
    y = _as_1d("response", response)
    step, t_start, band, frac = _checked_arguments(t, y, reference_step_size, start_time_s,
                                                   settling_band, steady_state_fraction)
    first = _first_after_start(t, t_start)
    y0 = float(y[first - 1]) if first > 0 and t[first] > t_start else float(y[first])
    target = y0 + step
    # from the step on; a baseline sample just before the start anchors the interpolation
    lo = first - 1 if first > 0 else first
    tp = t[lo:] - t_start
    n = (y[lo:] - y0) / step

    t10 = _first_crossing(tp, n, 0.1)
    t90 = _first_crossing(tp, n, 0.9)
    rise = t90 - t10 if not (math.isnan(t10) or math.isnan(t90)) else math.nan

    n_after = n[1:] if lo < first else n
    t_after = tp[1:] if lo < first else tp
    ipk = int(np.argmax(n_after))
    overshoot = max(0.0, float(n_after[ipk]) - 1.0) * 100.0
    settling = _settling_time(t_after, n_after, band)

    k = max(int(math.ceil(frac * n_after.size)), 1)
    y_tail = y[-k:]
    sse = target - float(np.mean(y_tail))
    window = float(t[-1] - t[-k]) if k > 1 else 0.0
    peak_effort, peak_effort_t = _peak_effort(effort, t, first, t_start)

    return StepMetrics(
        rise_time_s=float(rise), overshoot_percent=overshoot, settling_time_s=settling,
        settling_band_fraction=band, steady_state_error=sse,
        steady_state_error_percent=100.0 * sse / step, steady_state_window_s=window,
        peak_effort=peak_effort, peak_effort_time_s=peak_effort_t, initial_value=y0,
        target_value=target, peak_value=float(y0 + step * n_after[ipk]),
        peak_time_s=float(t_after[ipk]))
