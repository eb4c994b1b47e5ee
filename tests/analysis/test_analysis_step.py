"""analysis/step.py: step-response figures of merit against analytic responses."""

from __future__ import annotations

import math

import numpy as np
import pytest
from scipy.optimize import brentq

from groundstation.analysis.step import StepMetrics, StepMetricsError, step_metrics
from groundstation.core.errors import GroundStationError

FS = 10_000.0           # Hz: fine sampling, so interpolation error is far below tolerance
DT = 1.0 / FS


def second_order(zeta: float, wn: float):
    """Unit step response of wn²/(s² + 2ζ wn s + wn²), underdamped."""
    wd = wn * math.sqrt(1.0 - zeta ** 2)

    def y(t):
        t = np.asarray(t, dtype=float)
        return 1.0 - np.exp(-zeta * wn * t) * (np.cos(wd * t)
                                                + zeta / math.sqrt(1 - zeta ** 2) * np.sin(wd * t))
    return y, wd


def settling_time_of(y, band, t_max):
    """The last time |y − 1| equals the band: bracketed on a dense grid, refined by brentq."""
    t = np.linspace(0.0, t_max, 2_000_001)
    out = np.abs(y(t) - 1.0) > band
    j = int(np.flatnonzero(out)[-1])
    return brentq(lambda s: abs(float(y(s)) - 1.0) - band, t[j], t[j + 1], xtol=1e-12)


@pytest.mark.parametrize("zeta", [0.2, 0.5, 0.7])
def test_second_order_step_matches_the_analytic_figures(zeta):
    wn = 2 * math.pi * 5.0                       # 5 Hz closed-loop bandwidth
    y, wd = second_order(zeta, wn)
    t0, size = 0.1, 2.5e-4                        # a 250 µrad step at t = 0.1 s
    t = np.arange(0.0, 3.0, DT)
    resp = 1e-3 + size * np.where(t >= t0, y(np.clip(t - t0, 0.0, None)), 0.0)
    kp = 40.0                                     # effort: a P-law on the error, peak at the step
    effort = np.where(t >= t0, kp * (1e-3 + size - resp) / size, 0.0)
    m = step_metrics(t, resp, size, t0, effort)
    assert isinstance(m, StepMetrics)
    # overshoot: exp(−ζπ/√(1−ζ²)), at the peak time π/wd
    assert m.overshoot_percent == pytest.approx(100 * math.exp(-zeta * math.pi / math.sqrt(1 - zeta ** 2)),
                                                abs=1e-3)
    assert m.peak_time_s == pytest.approx(math.pi / wd, abs=DT)
    assert m.peak_value == pytest.approx(1e-3 + size * (1 + m.overshoot_percent / 100), rel=1e-9)
    # rise time 10 → 90 %: both first crossings solved on the analytic response
    tp = math.pi / wd
    t10 = brentq(lambda s: float(y(s)) - 0.1, 0.0, tp)
    t90 = brentq(lambda s: float(y(s)) - 0.9, 0.0, tp)
    assert m.rise_time_s == pytest.approx(t90 - t10, abs=1e-6)
    # settling into ±2 % for good
    ts = settling_time_of(y, 0.02, 2.5)
    assert m.settling_time_s == pytest.approx(ts, abs=1e-6)
    assert m.settled and m.settling_band_fraction == 0.02
    # the envelope rule of thumb 4/(ζ wn) is the right size (it is only an approximation)
    assert 0.5 < m.settling_time_s / (4 / (zeta * wn)) < 1.5
    # settled long before the end: no steady-state error
    assert abs(m.steady_state_error) < 1e-6 * size
    assert m.initial_value == pytest.approx(1e-3) and m.target_value == pytest.approx(1e-3 + size)
    assert m.peak_effort == pytest.approx(kp) and m.peak_effort_time_s == pytest.approx(0.0)


def test_first_order_step_down_from_an_offset():
    tau, y0, size = 0.05, 0.3, -2.0               # a negative step from a non-zero baseline
    t = np.arange(0.0, 0.5, DT)
    t0 = 0.02
    resp = y0 + size * np.where(t >= t0, 1.0 - np.exp(-(t - t0) / tau), 0.0)
    m = step_metrics(t, resp, size, t0, settling_band=0.05, steady_state_fraction=0.2)
    assert m.overshoot_percent == 0.0
    assert m.rise_time_s == pytest.approx(tau * math.log(9.0), abs=1e-6)     # 2.197 τ
    assert m.settling_time_s == pytest.approx(tau * math.log(1 / 0.05), abs=1e-6)  # 3.0 τ
    # 0.48 s of response = 9.6 τ: the last 20 % still lacks a little of the step
    post = t[t >= t0] - t0
    k = math.ceil(0.2 * post.size)
    expected = size * np.mean(np.exp(-post[-k:] / tau))    # short of a negative step: < 0
    assert expected < 0.0
    assert m.steady_state_error == pytest.approx(expected, rel=1e-9)
    assert m.steady_state_error_percent == pytest.approx(100 * expected / size, rel=1e-9)
    assert m.steady_state_error_percent > 0.0
    assert m.steady_state_window_s == pytest.approx(post[-1] - post[-k])
    assert math.isnan(m.peak_effort)


def test_a_loop_that_stops_short_has_its_error_and_no_settling():
    t = np.arange(0.0, 1.0, DT)
    tau = 0.02
    resp = 0.95 * (1.0 - np.exp(-t / tau))        # type-0 loop: 5 % short of the command
    m = step_metrics(t, resp, 1.0, 0.0)
    assert m.steady_state_error == pytest.approx(0.05, rel=1e-6)
    assert not m.settled and math.isnan(m.settling_time_s)        # outside ±2 % of the command
    assert m.rise_time_s == pytest.approx(tau * math.log(0.85 / 0.05), abs=1e-6)
    # never reaching 90 %: no rise time
    slow = step_metrics(t, 0.5 * (1.0 - np.exp(-t / tau)), 1.0, 0.0)
    assert math.isnan(slow.rise_time_s)
    # in the band from the first sample after the step on: settled at once (1 % short is
    # inside ±2 %).  The step is commanded between two samples: a sample exactly at the
    # start still shows the value before it (the baseline), as a held command would.
    jump = step_metrics(t, np.where(t >= 0.5, 0.99, 0.0), 1.0, 0.5 - DT / 2)
    assert jump.settling_time_s == 0.0 and jump.initial_value == 0.0
    assert jump.steady_state_error == pytest.approx(0.01)


def test_start_between_samples_takes_the_baseline_before_it():
    t = np.arange(0.0, 1.0, 0.01)
    resp = np.where(t >= 0.105, 1.0 - np.exp(-(t - 0.105) / 0.05), 0.0) + 7.0
    m = step_metrics(t, resp, 1.0, 0.105)
    assert m.initial_value == 7.0 and m.target_value == 8.0
    assert m.rise_time_s == pytest.approx(0.05 * math.log(9.0), rel=0.02)


def test_bad_input_is_refused_with_a_clear_message():
    t = np.arange(0.0, 1.0, 0.01)
    y = np.ones_like(t)
    with pytest.raises(StepMetricsError, match="same length"):
        step_metrics(t, y[:-1], 1.0, 0.0)
    with pytest.raises(StepMetricsError, match="no step"):
        step_metrics(t, y, 0.0, 0.0)
    with pytest.raises(StepMetricsError, match="strictly increasing"):
        step_metrics(np.r_[t[:5], t[4], t[6:]], y, 1.0, 0.0)
    with pytest.raises(StepMetricsError, match="too short after the step"):
        step_metrics(t, y, 1.0, 0.95)
    with pytest.raises(StepMetricsError, match="effort must have the same length"):
        step_metrics(t, y, 1.0, 0.0, effort=y[:-3])
    with pytest.raises(StepMetricsError, match="non-finite value at sample 3"):
        step_metrics(t, np.r_[y[:3], np.nan, y[4:]], 1.0, 0.0)
    with pytest.raises(StepMetricsError, match="settling_band"):
        step_metrics(t, y, 1.0, 0.0, settling_band=2.0)
    assert issubclass(StepMetricsError, GroundStationError)
