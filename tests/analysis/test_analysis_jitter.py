"""LOS jitter (groundstation.analysis.jitter): the reference's integration-period
definitions against each other, exclusions and segments, and the chunked accumulator
against the in-memory function."""

from __future__ import annotations

import math

import numpy as np
import pytest

from groundstation.analysis import (AnalysisError, JitterAccumulator, highpass_jitter_rms,
                                    integration_period_factor, los_jitter, sensor_valid,
                                    sinusoid_smear_rms, windowed_smear_rms)
from groundstation.analysis.jitter import (BRIDGE_MAX_PERIODS, SETTLING_TIME_CONSTANTS, error_table,
                                           highpass, window_variance_sum)
from groundstation.core.dictionary import default_control_rate_hz

RATE_HZ = default_control_rate_hz()
#: high-pass outputs discarded after each (re)start of the filter, dT_i = 1 s
SETTLE = int(math.ceil(SETTLING_TIME_CONSTANTS * RATE_HZ))


def settled_hp2(x: np.ndarray) -> tuple[float, int]:
    """(sum of squares, count) of the high-pass of one stretch after its settling."""
    y = highpass(x, RATE_HZ)[SETTLE:]
    return float(np.dot(y, y)), len(y)


def sinusoid(f_hz: float, seconds: float, amplitude: float = 1.0, phase: float = 0.3,
             offset: float = 0.0) -> np.ndarray:
    t = np.arange(int(round(seconds * RATE_HZ))) / RATE_HZ
    return offset + amplitude * np.sin(2 * np.pi * f_hz * t + phase)


# ---------------------------------------------------------------------- the closed form
def test_the_closed_form_at_its_landmarks():
    assert integration_period_factor(0.0, 1.0) == 0.0
    # whole periods in the window: all of the mean square lies within it
    for f in (1.0, 2.0, 5.0):
        assert integration_period_factor(f, 1.0) == pytest.approx(1.0, abs=1e-12)
    # half a period: 1 - 4/pi^2
    assert integration_period_factor(0.5, 1.0) == pytest.approx(1 - 4 / math.pi ** 2, rel=1e-12)
    # the series branch joins the direct formula smoothly
    for x in (1e-6, 0.99e-2, 1.01e-2, 0.1):
        series = x ** 2 / 12 - x ** 4 / 360 + x ** 6 / 20160 - x ** 8 / 1814400
        assert integration_period_factor(x / (2 * math.pi), 1.0) == pytest.approx(series, rel=1e-10)
    # it depends on F_m * dT_i only
    assert integration_period_factor(0.3, 2.0) == pytest.approx(integration_period_factor(0.6, 1.0))


@pytest.mark.parametrize("f_m_hz", [0.1, 0.2, 0.35, 0.5, 0.75, 1.0, 1.5, 2.5, 5.0, 7.3, 20.0])
def test_the_closed_form_is_the_windowed_mean_square_share(f_m_hz):
    """(a) and (b) are the same quantity: the share of a sinusoid's mean square within
    one integration period, closed form vs measured over every window position."""
    x = sinusoid(f_m_hz, 120.0, amplitude=2e-5)
    measured = windowed_smear_rms(x, RATE_HZ, 1.0) ** 2 / (2e-5 ** 2 / 2)
    assert measured == pytest.approx(integration_period_factor(f_m_hz, 1.0), rel=0.01)
    assert windowed_smear_rms(x, RATE_HZ, 1.0) == pytest.approx(
        float(sinusoid_smear_rms(2e-5, f_m_hz, 1.0)), rel=0.005)


def test_back_to_back_windows_would_depend_on_the_phase():
    """Why every window position counts: at 0.5 Hz windows 1 s apart all see the same
    phase, and their mean variance is -44 % / +30 % (RMS) off the true share."""
    exact = float(sinusoid_smear_rms(1.0, 0.5, 1.0))
    n = int(RATE_HZ)
    for phase, ratio in ((0.0, 0.564), (math.pi / 2, 1.297)):
        x = sinusoid(0.5, 100.0, phase=phase)
        back_to_back = math.sqrt(float(x.reshape(-1, n).var(axis=1).mean()))
        assert back_to_back / exact == pytest.approx(ratio, abs=0.002)
        assert windowed_smear_rms(x, RATE_HZ, 1.0) / exact == pytest.approx(1.0, abs=0.005)


def test_the_integration_period_scales_the_frequency():
    x = sinusoid(0.25, 200.0)
    assert windowed_smear_rms(x, RATE_HZ, 2.0) ** 2 * 2 == pytest.approx(
        integration_period_factor(0.5, 1.0), rel=0.01)


# ---------------------------------------------------------------------- the high-pass estimate
@pytest.mark.parametrize("f_m_hz", [5.0, 5.5, 10.0, 50.0])
def test_the_highpass_matches_the_closed_form_well_above_the_corner(f_m_hz):
    x = sinusoid(f_m_hz, 60.0)
    exact = math.sqrt(integration_period_factor(f_m_hz, 1.0) / 2)
    assert highpass_jitter_rms(x, RATE_HZ, 1.0) == pytest.approx(exact, rel=0.01)


#: the high-pass estimate's error against the exact share, as docs/analysis.md tabulates it
DOCUMENTED_ERROR = {0.2: 1.210, 0.5: 0.235, 1.0: -0.013, 1.5: 0.018}


def test_the_highpass_error_near_the_corner_is_the_documented_one():
    rows = {r["f_m_hz"]: r for r in error_table(list(DOCUMENTED_ERROR), RATE_HZ, seconds=300.0)}
    for f, err in DOCUMENTED_ERROR.items():
        assert rows[f]["highpass_error"] == pytest.approx(err, abs=0.005), f
        # the filter behaves as its analogue prototype: |H(j 2 pi f)| with a 1 rad/s corner
        assert rows[f]["highpass_fraction"] == pytest.approx(rows[f]["highpass_gain"], rel=0.005)
        assert rows[f]["windowed_fraction"] == pytest.approx(rows[f]["exact_fraction"], rel=0.005)


def test_a_constant_offset_gives_no_start_transient():
    y = highpass(np.full(5000, 3.1e-3), RATE_HZ, 1.0)
    assert np.max(np.abs(y)) < 1e-15
    x = sinusoid(10.0, 20.0, amplitude=1e-6, offset=3e-3)
    assert highpass_jitter_rms(x, RATE_HZ, 1.0) == pytest.approx(1e-6 / math.sqrt(2), rel=0.01)


# ---------------------------------------------------------------------- the windowed variance
def test_the_windowed_variance_equals_the_brute_force_one_far_from_zero():
    """A 3 mrad offset and a slow drift under 1 nrad of noise: the block-shifted sums keep
    the small within-window variance that one running sum of squares would lose."""
    rng = np.random.default_rng(4)
    n = 3000
    x = 3e-3 + 1e-5 * np.linspace(0, 1, n) + 1e-9 * rng.standard_normal(n)
    for w in (2, 17, 600, 1000, 2999, 3000):
        total, count = window_variance_sum(x, w)
        brute = np.lib.stride_tricks.sliding_window_view(x - x.mean(), w).var(axis=1)
        assert count == len(brute)
        assert total == pytest.approx(float(brute.sum()), rel=1e-7), w
    assert window_variance_sum(x, 3001) == (0.0, 0)


# ---------------------------------------------------------------------- los_jitter
def test_mean_rms_and_standard_deviation():
    x = sinusoid(3.0, 10.0, amplitude=4e-6, offset=5e-6)
    j = los_jitter(x, RATE_HZ, sensor="autocollimator")
    assert j.mean_rad == pytest.approx(5e-6, abs=1e-12)
    assert j.std_rad == pytest.approx(4e-6 / math.sqrt(2), rel=1e-6)
    assert j.rms_rad == pytest.approx(math.sqrt(25e-12 + 8e-12), rel=1e-6)
    assert (j.samples_used, j.samples_excluded, j.segments) == (len(x), 0, 1)
    assert j.smear_rms_rad == pytest.approx(windowed_smear_rms(x, RATE_HZ, 1.0))
    # the filter's first SETTLING_TIME_CONSTANTS x dT_i are its start, not motion
    hp2, used = settled_hp2(x)
    assert (j.highpass_samples_used, j.highpass_samples_settling) == (used, SETTLE)
    assert j.highpass_rms_rad == pytest.approx(math.sqrt(hp2 / used), rel=1e-12)
    assert j.highpass_rms_rad == pytest.approx(highpass_jitter_rms(x, RATE_HZ, 1.0), rel=0.01)
    assert "urad" in j.text() and "autocollimator" in j.text()


def test_out_of_range_samples_are_excluded_counted_and_split_the_filter():
    range_rad = 0.33 * math.pi / 180
    a = sinusoid(7.0, 4.0, amplitude=1e-5, offset=1e-4)
    b = sinusoid(9.0, 5.0, amplitude=2e-5, offset=-2e-4)
    rail = np.full(100, range_rad)               # the sensor pinned at its range
    x = np.concatenate([a, rail, b])
    counts = np.concatenate([np.zeros(len(a), np.int16), np.full(100, 32767, np.int16),
                             np.zeros(len(b), np.int16)])
    ok = sensor_valid(x, range_rad=range_rad, raw_counts=counts)
    assert int((~ok).sum()) == 100
    j = los_jitter(x, RATE_HZ, valid=ok)
    assert (j.samples_used, j.samples_excluded, j.segments) == (len(a) + len(b), 100, 2)
    both = np.concatenate([a, b])
    assert j.mean_rad == pytest.approx(both.mean(), rel=1e-12)
    assert j.std_rad == pytest.approx(both.std(), rel=1e-12)
    # the hole is longer than the bridge: the filter restarts from steady state on each
    # stretch (the step between them is not jitter) and settles again
    (sa2, na), (sb2, nb) = settled_hp2(a), settled_hp2(b)
    assert j.highpass_restarts == 2 and j.highpass_samples_used == na + nb
    assert j.highpass_rms_rad == pytest.approx(math.sqrt((sa2 + sb2) / (na + nb)), rel=1e-12)
    joined = los_jitter(both, RATE_HZ)
    assert joined.highpass_rms_rad > 2 * j.highpass_rms_rad
    # windows never straddle the hole
    sa, ca = window_variance_sum(a, 1200)
    sb, cb = window_variance_sum(b, 1200)
    assert j.smear_rms_rad == pytest.approx(math.sqrt((sa + sb) / (ca + cb)), rel=1e-12)


def test_the_rail_alone_and_non_finite_samples_are_excluded():
    x = np.array([0.0, 1e-6, -2e-6, 3e-6, np.nan])
    counts = np.array([0, 1, -32768, 32767, 0], dtype=np.int16)
    assert sensor_valid(x, raw_counts=counts).tolist() == [True, True, False, False, False]
    assert sensor_valid(x, range_rad=2.5e-6).tolist() == [True, True, True, False, False]


def test_a_gap_splits_the_segments():
    x = sinusoid(4.0, 10.0, amplitude=1e-6)
    gap = np.zeros(len(x), dtype=bool)
    gap[5000] = True
    j = los_jitter(x, RATE_HZ, gap_before=gap, missing_frames=3)
    assert j.segments == 2 and j.missing_frames == 3 and "3 frames missing" in j.text()
    # a gap of unknown length (no missing_before) restarts the filter
    (s1, n1), (s2, n2) = settled_hp2(x[:5000]), settled_hp2(x[5000:])
    assert j.highpass_restarts == 2
    assert j.highpass_rms_rad == pytest.approx(math.sqrt((s1 + s2) / (n1 + n2)), rel=1e-12)


def test_a_stretch_shorter_than_the_integration_period_has_no_windowed_figure():
    j = los_jitter(sinusoid(20.0, 0.5), RATE_HZ)
    assert math.isnan(j.smear_rms_rad) and "n/a" in j.text()


# ---------------------------------------------------------------------- the accumulator
@pytest.mark.parametrize("chunk", [1, 7, 500, 1199, 1200, 4096, 100_000])
def test_the_accumulator_in_pieces_equals_the_whole(chunk):
    rng = np.random.default_rng(11)
    n = 9000
    x = 2e-3 + np.cumsum(rng.standard_normal(n)) * 1e-8 + sinusoid(3.3, n / RATE_HZ, 1e-6)
    ok = np.ones(n, dtype=bool)
    ok[1500:1530] = False                        # an excluded stretch
    ok[4000] = False                             # a single excluded sample
    ok[-3:] = False                              # excluded at the end
    gap = np.zeros(n, dtype=bool)
    gap[2600] = True
    gap[1530] = True                             # a gap where a stretch starts anyway
    x[~ok] = 1.0                                 # wild values there must not matter
    whole = los_jitter(x, RATE_HZ, valid=ok, gap_before=gap, sensor="s", missing_frames=5)
    acc = JitterAccumulator(RATE_HZ, 1.0)
    for a in range(0, n, chunk):
        acc.feed(x[a:a + chunk], ok[a:a + chunk], gap[a:a + chunk])
    part = acc.result("s", missing_frames=5)
    assert (part.samples_used, part.samples_excluded, part.segments) == \
        (whole.samples_used, whole.samples_excluded, whole.segments) == (n - 34, 34, 4)
    for name in ("mean_rad", "rms_rad", "std_rad", "highpass_rms_rad", "smear_rms_rad"):
        assert getattr(part, name) == pytest.approx(getattr(whole, name), rel=1e-9), name


@pytest.mark.parametrize("chunk", [1, 5, 1199, 4096, 100_000])
def test_the_accumulator_in_pieces_bridges_as_the_whole(chunk):
    """Short holes bridged across piece boundaries, long ones restarting, settling
    carried: the pieces give the whole's high-pass sums."""
    rng = np.random.default_rng(12)
    n = 14_000
    x = 1e-3 + np.cumsum(rng.standard_normal(n)) * 1e-8 + sinusoid(2.1, n / RATE_HZ, 3e-6)
    ok = np.ones(n, dtype=bool)
    ok[2000:2004] = False                        # short: bridged
    ok[6000:6100] = False                        # long: a restart
    ok[9000] = False
    missing = np.zeros(n, dtype=np.int64)
    missing[[3000, 9001, 12_000]] = [2, 3, 11]   # short gaps, 9001 right after an exclusion
    missing[7000] = -1                           # a stalled frame: always a restart
    gap = missing != 0
    x[~ok] = 1.0
    whole = los_jitter(x, RATE_HZ, valid=ok, gap_before=gap, missing_before=missing)
    assert whole.highpass_restarts == 3          # the start, after 6000:6100, at 7000
    acc = JitterAccumulator(RATE_HZ, 1.0)
    for a in range(0, n, chunk):
        acc.feed(x[a:a + chunk], ok[a:a + chunk], gap[a:a + chunk], missing[a:a + chunk])
    part = acc.result()
    for name in ("highpass_samples_used", "highpass_samples_settling", "highpass_restarts",
                 "segments", "samples_used"):
        assert getattr(part, name) == getattr(whole, name), name
    assert part.highpass_rms_rad == pytest.approx(whole.highpass_rms_rad, rel=1e-9)


def _gapped_sinusoid(amplitude: float, f_hz: float):
    """A sinusoid of 120 s with two long excluded stretches (the sensor off its range,
    20 s and 15 s, reading its rail) and 1-4 frames missing every 0.7 s: the kept
    samples, whether each is usable, and the frames missing before each."""
    n = int(120 * RATE_HZ)
    x = sinusoid(f_hz, 120.0, amplitude)
    ok = np.ones(n, dtype=bool)
    for a, b in [(30, 50), (80, 95)]:
        ok[int(a * RATE_HZ):int(b * RATE_HZ)] = False
    x[~ok] = 5.76e-3                             # at the rail: nothing to do with the sinusoid
    keep = np.ones(n, dtype=bool)
    lost = np.random.default_rng(1).integers(1, 5, n)
    for i in range(int(0.35 * RATE_HZ), n, int(0.7 * RATE_HZ)):
        keep[i:i + lost[i]] = False
    idx = np.flatnonzero(keep)
    missing = idx - np.concatenate([[-1], idx[:-1]]) - 1
    return x[keep], ok[keep], missing


@pytest.mark.parametrize("f_hz", [0.5, 2.0, 7.0])
def test_the_highpass_of_a_gapped_sinusoid_is_its_gain_times_its_rms(f_hz):
    """The known answer: |H(j w)| A / sqrt 2, through long exclusions and short frame
    gaps (the restart at each short gap cost 8 % at 0.5 Hz before the bridge)."""
    amplitude = 1e-4
    x, ok, missing = _gapped_sinusoid(amplitude, f_hz)
    j = los_jitter(x, RATE_HZ, valid=ok, gap_before=missing > 0, missing_before=missing)
    w = 2 * math.pi * f_hz
    expected = w / math.hypot(w, 1.0) * amplitude / math.sqrt(2)
    assert j.highpass_rms_rad == pytest.approx(expected, rel=2e-3)
    assert j.highpass_rms_rad <= j.std_rad
    # three starts (the window's, after each exclusion), each settling for 3 dT_i of
    # device time (the frames missing in it are not samples)
    assert j.highpass_restarts == 3
    assert 0.99 * 3 * SETTLE < j.highpass_samples_settling <= 3 * SETTLE
    assert j.highpass_samples_used + j.highpass_samples_settling == j.samples_used


def test_stretches_shorter_than_the_settling_give_no_highpass_figure():
    """An open-loop log: the base motion drags the LOS across the sensor's range, no
    stretch outlasts the settling, so no high-pass figure - where restarting on the rail
    gave one above the standard deviation (2.3 against 1.8 mrad here)."""
    t = np.arange(int(120 * RATE_HZ)) / RATE_HZ
    x = 4e-3 * np.sin(2 * np.pi * 0.3 * t) + 2e-3 * np.sin(2 * np.pi * 0.11 * t + 1)
    ok = sensor_valid(x, range_rad=3e-3)
    x = np.where(ok, x, np.sign(x) * 3e-3)
    j = los_jitter(x, RATE_HZ, valid=ok)
    assert j.highpass_samples_used == 0 and math.isnan(j.highpass_rms_rad)
    assert j.highpass_samples_settling == j.samples_used
    assert "high-pass 1 s n/a" in j.text()


def test_the_bridge_is_short_against_the_integration_period():
    assert BRIDGE_MAX_PERIODS * RATE_HZ >= 4        # a few frames at dT_i = 1 s
    assert BRIDGE_MAX_PERIODS <= 0.01               # the hold errs by <= 1 % of the change


# ---------------------------------------------------------------------- bad input
def test_bad_input_says_what_to_do():
    x = np.zeros(100)
    with pytest.raises(AnalysisError, match="all 100 autocollimator samples .* excluded"):
        los_jitter(x, RATE_HZ, valid=np.zeros(100, dtype=bool), sensor="autocollimator")
    with pytest.raises(AnalysisError, match="no autocollimator samples"):
        los_jitter(np.zeros(0), RATE_HZ, sensor="autocollimator")
    with pytest.raises(AnalysisError, match="integration period must be > 0"):
        los_jitter(x, RATE_HZ, integration_period_s=0.0)
    with pytest.raises(AnalysisError, match="at least one integration period"):
        windowed_smear_rms(x, RATE_HZ, 1.0)
    with pytest.raises(AnalysisError, match="non-finite"):
        highpass_jitter_rms(np.array([0.0, np.nan]), RATE_HZ)
    with pytest.raises(AnalysisError, match="sample rate"):
        highpass_jitter_rms(x, 0.0)
    acc = JitterAccumulator(RATE_HZ)
    acc.feed(x, np.zeros(100, dtype=bool))
    with pytest.raises(AnalysisError, match="all 100 .* excluded"):
        acc.result()
