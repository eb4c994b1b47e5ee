"""Spectra (groundstation.analysis.spectra): Welch PSD and cumulative spectral power,
their RMS against known signals, stretches that must not be joined, the chunked
accumulator against scipy's welch, and the base-motion check using the same CSP."""

from __future__ import annotations

import math

import numpy as np
import pytest
from scipy import signal

from groundstation.analysis import AnalysisError, WelchAccumulator, csp, psd
from groundstation.analysis.spectra import (MIN_SEGMENT, band_rms, psd_by_time, runs,
                                             segment_samples, time_breaks)
from groundstation.core.dictionary import default_control_rate_hz

RATE_HZ = default_control_rate_hz()


def test_white_noise_csp_ends_at_its_variance():
    rng = np.random.default_rng(5)
    sigma = 3e-6
    x = 1e-3 + sigma * rng.standard_normal(int(120 * RATE_HZ))
    s = psd(x, RATE_HZ, segment_s=2.0)
    assert s.rms == pytest.approx(sigma, rel=0.01)
    assert s.rms == pytest.approx(float(np.std(x)), rel=0.01)
    # flat at sigma^2 / (fs/2) rad^2/Hz, one-sided
    inner = s.density[5:-5]
    assert float(np.mean(inner)) == pytest.approx(sigma ** 2 / (RATE_HZ / 2), rel=0.02)
    assert s.density_units() == "rad^2/Hz" and s.resolution_hz == pytest.approx(0.5)


def test_a_sinusoid_csp_steps_to_its_mean_square_at_its_frequency():
    t = np.arange(int(60 * RATE_HZ)) / RATE_HZ
    x = 5e-4 + 2e-5 * np.sin(2 * np.pi * 13.0 * t + 0.4)
    s = psd(x, RATE_HZ)
    assert s.rms == pytest.approx(2e-5 / math.sqrt(2), rel=0.005)
    c = s.csp
    below, above = np.searchsorted(s.frequency_hz, [12.0, 14.0])
    assert c[below] < 1e-3 * c[-1] and c[above] > 0.999 * c[-1]     # the offset is detrended


def test_csp_is_the_trapezoidal_running_integral():
    f = np.array([0.0, 1.0, 3.0, 4.0])
    p = np.array([2.0, 4.0, 0.0, 1.0])
    assert csp(f, p).tolist() == [0.0, 3.0, 7.0, 7.5]
    assert csp(np.zeros(0), np.zeros(0)).shape == (0,)
    with pytest.raises(AnalysisError, match="equally long"):
        csp(f, p[:3])


def test_the_psd_is_scipys_welch():
    x = np.random.default_rng(6).standard_normal(50_000)
    s = psd(x, RATE_HZ, segment_s=5.0)
    f, p = signal.welch(x, fs=RATE_HZ, window="hann", nperseg=6000, detrend="constant")
    assert np.array_equal(s.frequency_hz, f)
    np.testing.assert_allclose(s.density, p, rtol=1e-12)
    assert s.segments == (50_000 - 3000) // 3000


def test_a_record_shorter_than_a_segment_gets_one_of_its_length():
    assert segment_samples(RATE_HZ, 10.0, 2400) == 2400
    s = psd(np.random.default_rng(1).standard_normal(2400), RATE_HZ)
    assert (s.segment_samples, s.segments) == (2400, 1)


def test_runs_split_at_exclusions_and_gaps():
    valid = np.array([1, 1, 0, 1, 1, 1, 1, 0, 0, 1], dtype=bool)
    gap = np.zeros(10, dtype=bool)
    gap[5] = True
    assert runs(10, valid, gap) == [(0, 2), (3, 5), (5, 7), (9, 10)]
    assert runs(4) == [(0, 4)]
    assert runs(3, np.zeros(3, dtype=bool)) == []


def test_segments_never_span_a_hole():
    rng = np.random.default_rng(8)
    a, b = rng.standard_normal(7000), 10 + rng.standard_normal(9000)
    x = np.concatenate([a, np.full(50, 1e3), b])
    valid = np.concatenate([np.ones(7000, bool), np.zeros(50, bool), np.ones(9000, bool)])
    s = psd(x, RATE_HZ, segment_s=2.0, valid=valid)
    fa, pa = signal.welch(a, fs=RATE_HZ, nperseg=2400)
    fb, pb = signal.welch(b, fs=RATE_HZ, nperseg=2400)
    ka, kb = (7000 - 1200) // 1200, (9000 - 1200) // 1200
    assert s.segments == ka + kb
    np.testing.assert_allclose(s.density, (pa * ka + pb * kb) / (ka + kb), rtol=1e-12)


@pytest.mark.parametrize("chunk", [1000, 2399, 2400, 5000, 65_536])
def test_the_accumulator_in_pieces_equals_the_whole(chunk):
    rng = np.random.default_rng(9)
    n = 40_000
    x = np.cumsum(rng.standard_normal(n)) * 1e-7
    valid = np.ones(n, dtype=bool)
    valid[10_000:10_100] = False
    valid[-5:] = False
    gap = np.zeros(n, dtype=bool)
    gap[25_000] = True
    whole = psd(x, RATE_HZ, segment_s=2.0, valid=valid, gap_before=gap)
    acc = WelchAccumulator(RATE_HZ, whole.segment_samples)
    for a in range(0, n, chunk):
        acc.feed(x[a:a + chunk], valid[a:a + chunk], gap[a:a + chunk])
    part = acc.result()
    assert part.segments == whole.segments
    assert np.array_equal(part.frequency_hz, whole.frequency_hz)
    np.testing.assert_allclose(part.density, whole.density, rtol=1e-9)


def test_an_odd_segment_length_matches_welch_too():
    x = np.random.default_rng(2).standard_normal(20_001)
    acc = WelchAccumulator(RATE_HZ, 1001)
    acc.feed(x[:7777])
    acc.feed(x[7777:])
    f, p = signal.welch(x, fs=RATE_HZ, nperseg=1001)
    np.testing.assert_allclose(acc.result().density, p, rtol=1e-9)


def test_no_segment_that_fits_is_an_actionable_error():
    valid = np.tile([True] * 100 + [False], 50)
    with pytest.raises(AnalysisError, match="no contiguous stretch of 1200 usable samples"):
        psd(np.zeros(len(valid)), RATE_HZ, segment_s=1.0, valid=valid)
    acc = WelchAccumulator(RATE_HZ, 1200)
    acc.feed(np.zeros(500))
    with pytest.raises(AnalysisError, match="shorten the segment"):
        acc.result()
    with pytest.raises(AnalysisError, match="segment length must be > 0"):
        psd(np.zeros(10), RATE_HZ, segment_s=0.0)


def test_the_live_psd_drops_nan_and_short_stretches():
    t = np.arange(4096) / RATE_HZ
    y = np.sin(2 * np.pi * 100 * t)
    y[2000] = np.nan
    s = psd_by_time(t, y)
    assert s.rate_hz == pytest.approx(RATE_HZ) and np.isfinite(s.density).all()
    assert s.frequency_hz[np.argmax(s.density)] == pytest.approx(100, abs=3)
    assert psd_by_time(t[:10], y[:10]) is None                     # fewer than MIN_SEGMENT
    assert psd_by_time(np.zeros(100), np.zeros(100)) is None        # times that do not rise


def test_the_live_psd_of_one_stretch_is_scipys_welch():
    """Its segment: the largest power of two giving about four segments."""
    rng = np.random.default_rng(3)
    t = np.arange(5000) / RATE_HZ
    y = rng.standard_normal(5000)
    s = psd_by_time(t, y, units="rad")
    assert s.segment_samples == 1024 and s.units == "rad"
    f, p = signal.welch(y, fs=RATE_HZ, nperseg=1024)
    np.testing.assert_allclose(s.frequency_hz, f)
    np.testing.assert_allclose(s.density, p, rtol=1e-12)


def test_the_live_psd_splits_at_time_jumps_and_lost_frames():
    rng = np.random.default_rng(4)
    t = np.arange(6000) / RATE_HZ
    t[4000:] += 0.5                                  # the clock jumps: a new stretch
    gap_at = t[1000]                                 # frames lost before sample 1000
    assert np.flatnonzero(time_breaks(t, [gap_at])).tolist() == [1000, 4000]
    y = rng.standard_normal(6000)
    s = psd_by_time(t, y, [gap_at])
    assert s.segment_samples == 512                  # the longest stretch: 3000 samples
    # every segment counts once: the average of the three stretches' segments
    parts = [signal.welch(y[a:b], fs=RATE_HZ, nperseg=512) for a, b in ((0, 1000), (1000, 4000),
                                                                       (4000, 6000))]
    counts = [(b - a - 256) // 256 for a, b in ((0, 1000), (1000, 4000), (4000, 6000))]
    expected = sum(p * k for (_, p), k in zip(parts, counts)) / sum(counts)
    assert s.segments == sum(counts)
    np.testing.assert_allclose(s.density, expected, rtol=1e-12)
    short = t[:MIN_SEGMENT + 10].copy()
    short[MIN_SEGMENT // 2:] += 1.0                  # no stretch holds a segment
    assert psd_by_time(short, y[:len(short)]) is None


def test_the_base_motion_check_uses_this_csp():
    from groundstation.basemotion import csp_from_psd
    from groundstation.basemotion import verify

    f = np.linspace(0, 10, 11)
    p = np.exp(-f)
    np.testing.assert_array_equal(csp_from_psd(f, p), csp(f, p))
    assert verify.csp_from_psd(f, p)[-1] == pytest.approx(float(np.trapezoid(p, f)))


def test_band_rms_is_the_root_of_the_trapezoid_and_parseval_holds():
    """A flat 2 units²/Hz from 1 to 9 Hz holds 16 units²: RMS 4.  A sine's Welch PSD
    integrates back to its RMS (amplitude / sqrt 2)."""
    assert band_rms([1.0, 5.0, 9.0], [2.0, 2.0, 2.0]) == pytest.approx(4.0)
    assert np.isnan(band_rms([1.0], [2.0]))
    rate = 1200.0
    t = np.arange(int(20 * rate)) / rate
    spectrum = psd_by_time(t, 3e-3 * np.sin(2 * np.pi * 37.0 * t), np.empty(0))
    assert band_rms(spectrum.frequency_hz, spectrum.density) == pytest.approx(
        3e-3 / np.sqrt(2), rel=0.02)
