"""analysis/frf.py: H1 and coherence against known answers, the model on the same grid."""

from __future__ import annotations

import numpy as np
import pytest
from scipy import signal

from groundstation.analysis.frf import (FrequencyResponse, FrfError, compare_frf, h1_estimate,
                                        model_response)
from groundstation.core.errors import GroundStationError
from groundstation.plant.model import (continuous_model, discretise, plant_transfer_functions)
from groundstation.plant.testbed import TESTBEDS_DIR, load_testbed

FS = 1000.0          # Hz: any rate will do, the filter is defined in discrete time
N = 2 ** 17
NPERSEG = 1024


def resonance(f0_hz=100.0, zeta=0.05, fs=FS):
    """A 2nd-order resonance (unity DC gain) as a digital filter: the bilinear transform of
    w0²/(s² + 2ζw0 s + w0²) (its peak lands slightly below f0; freqz is the truth here)."""
    w0 = 2 * np.pi * f0_hz
    return signal.bilinear([w0 ** 2], [1.0, 2 * zeta * w0, w0 ** 2], fs)


def white(n=N, seed=1, std=1.0):
    return np.random.default_rng(seed).normal(0.0, std, n)


def test_h1_of_white_noise_through_a_resonance_matches_freqz():
    b, a = resonance()
    x = white()
    y = signal.lfilter(b, a, x)
    # segments long against the resonance's decay time (1/(ζ·w0) ≈ 32 samples): each
    # segment's response to the previous segment's input, which H1 cannot explain, is then
    # a small part of it (with 1024-sample segments γ² at the peak is only ≈ 0.986)
    nperseg = 4096
    frf = h1_estimate(x, y, FS, nperseg, input_units="A", output_units="rad")
    assert isinstance(frf, FrequencyResponse)
    assert frf.units == "rad/A" and frf.nperseg == nperseg and frf.rate_hz == FS
    assert frf.segments == 1 + (N - nperseg) // (nperseg // 2)
    assert frf.freq_hz[0] == 0.0 and frf.freq_hz[-1] == pytest.approx(FS / 2)
    assert frf.resolution_hz == pytest.approx(FS / nperseg)
    _, h_true = signal.freqz(b, a, worN=frf.freq_hz, fs=FS)
    # noise-free: coherence is 1 up to leakage and the segments' start-up transients
    # (at Nyquist the bilinear filter has a zero, so S_yy = 0 there and γ² is undefined)
    assert np.isnan(frf.coherence[-1])
    assert np.nanmedian(frf.coherence) > 0.999
    good = frf.coherence > 0.99
    assert good.mean() > 0.98
    # the resonance itself (peak 1/(2ζ) = 20 dB) must be among the trusted bins
    peak = np.argmin(np.abs(frf.freq_hz - 100.0))
    assert good[peak]
    mag_err_db = 20 * np.log10(np.abs(frf.response[good]) / np.abs(h_true[good]))
    ph_err_deg = np.degrees(np.angle(frf.response[good] / h_true[good]))
    assert np.max(np.abs(mag_err_db)) < 0.5
    assert np.max(np.abs(ph_err_deg)) < 3.0
    assert frf.magnitude_db[peak] == pytest.approx(20 * np.log10(abs(h_true[peak])), abs=0.5)


def test_coherence_with_output_noise_follows_the_snr_per_bin():
    """y = h*x + n, x and n white and independent: γ² = SNR/(1 + SNR) with
    SNR(f) = |H(f)|²·σx²/σn² (both one-sided densities are 2σ²/fs, the ratio is what counts)."""
    b, a = resonance()
    sx, sn = 1.0, 0.5
    x = white(std=sx, seed=2)
    y = signal.lfilter(b, a, x) + white(std=sn, seed=3)
    frf = h1_estimate(x, y, FS, NPERSEG)
    _, h_true = signal.freqz(b, a, worN=frf.freq_hz, fs=FS)
    snr = np.abs(h_true) ** 2 * sx ** 2 / sn ** 2
    expected = snr / (1 + snr)
    interior = (frf.freq_hz > 2 * frf.resolution_hz) & (frf.freq_hz < FS / 2 - 2 * frf.resolution_hz)
    dev = frf.coherence[interior] - expected[interior]
    # ~255 averaged segments: the estimate scatters by a few hundredths around theory
    assert np.mean(np.abs(dev)) < 0.02
    assert np.max(np.abs(dev)) < 0.12
    # and it really spans the range: high at the resonance, low at high frequency
    assert frf.coherence[np.argmin(np.abs(frf.freq_hz - 100.0))] > 0.98
    assert np.mean(frf.coherence[frf.freq_hz > 400]) < 0.05
    # H1 stays unbiased under output noise where the bins are trustworthy
    sure = interior & (expected > 0.9)
    assert np.max(np.abs(20 * np.log10(np.abs(frf.response[sure] / h_true[sure])))) < 1.0


def test_bad_input_is_refused_with_a_clear_message():
    x, y = white(4096), white(4096, seed=5)
    with pytest.raises(FrfError, match="same length"):
        h1_estimate(x, y[:-1], FS, 256)
    with pytest.raises(FrfError, match="no excitation"):
        h1_estimate(np.zeros(4096), y, FS, 256)
    with pytest.raises(FrfError, match="no excitation"):
        h1_estimate(np.full(4096, 0.3), y, FS, 256)
    with pytest.raises(FrfError, match="too short"):
        h1_estimate(x[:10], y[:10], FS)
    with pytest.raises(FrfError, match="too short for nperseg = 4096"):
        h1_estimate(x, y, FS, 4096)          # one segment: coherence would be 1 regardless
    bad = x.copy()
    bad[7] = np.nan
    with pytest.raises(FrfError, match="non-finite value at sample 7"):
        h1_estimate(bad, y, FS, 256)
    with pytest.raises(FrfError, match="rate_hz"):
        h1_estimate(x, y, 0.0, 256)
    with pytest.raises(FrfError, match="nperseg"):
        h1_estimate(x, y, FS, 4)
    with pytest.raises(FrfError, match="1-D"):
        h1_estimate(x.reshape(64, 64), y.reshape(64, 64), FS, 16)
    assert issubclass(FrfError, GroundStationError)


def test_default_segment_length_gives_at_least_eight_segments():
    b, a = resonance()
    x = white(10_000, seed=6)
    frf = h1_estimate(x, signal.lfilter(b, a, x), FS)
    assert frf.nperseg == 1024 and frf.segments >= 8


def test_band_limited_input_leaves_unexcited_bins_undefined_not_a_warning():
    # a multisine on the first 40 bins of a 512-sample boxcar segment: every other bin has
    # S_xx = 0 up to round-off, and must come out undefined rather than 0/0 noise
    t = np.arange(2 ** 14) / FS
    rng = np.random.default_rng(7)
    x = sum(np.sin(2 * np.pi * k * FS / 512 * t + rng.uniform(0, 2 * np.pi)) for k in range(1, 41))
    frf = h1_estimate(x, 2.0 * x, FS, 512, window="boxcar", noverlap=0)
    low = (frf.freq_hz > 0) & (frf.freq_hz < 40 * FS / 512 + 0.1)
    assert np.allclose(frf.response[low], 2.0)
    assert np.allclose(frf.coherence[low], 1.0)
    assert np.all(np.isnan(frf.response[~low]))


# --------------------------------------------------------------------------------------
# the testbed model
# --------------------------------------------------------------------------------------
@pytest.fixture(scope="module")
def tb2():
    return load_testbed(TESTBEDS_DIR / "relative_2dof.toml")


def test_model_g1_g2_equal_the_reference_transfer_functions(tb2):
    f = np.array([0.0, 0.3, 3.0, 31.0, 150.0, 550.0])
    (n1, d1), (n2, d2) = plant_transfer_functions(tb2)
    s = 2j * np.pi * f[1:]
    g1 = model_response(tb2, "g1", f)
    g2 = model_response(tb2, "T2->los_angle", f)
    assert np.isnan(g1[0]) and np.isnan(g2[0])          # free rotation at 0 Hz
    np.testing.assert_allclose(g1[1:], np.polyval(n1, s) / np.polyval(d1, s), rtol=1e-9)
    np.testing.assert_allclose(g2[1:], np.polyval(n2, s) / np.polyval(d2, s), rtol=1e-9)
    # relative set-up: the base is fixed, so the inner encoder reads the LOS angle
    np.testing.assert_allclose(model_response(tb2, "T1->phi2", f)[1:], g1[1:], rtol=1e-12)
    # per ampere: times the motor's torque constant
    kt = tb2.motor_fine["torque_constant"]
    np.testing.assert_allclose(model_response(tb2, "g2", f, per_amp=True)[1:], kt * g2[1:])


def test_model_zoh_equivalent_tends_to_the_continuous_model_at_low_frequency(tb2):
    f = np.array([0.5, 2.0, 5.0])
    hc = model_response(tb2, "T1->phi1", f)
    hd = model_response(tb2, "T1->phi1", f, sample_rate_hz=20_000.0)
    # ZOH adds about half a sample of delay; at 20 kHz that is < 0.05° here
    np.testing.assert_allclose(hd, hc, rtol=2e-3)


def test_friction_stiffness_turns_the_free_rotation_into_a_spring(tb2):
    kf = 5730.0 * 12.0
    h = model_response(tb2, "T1->phi1", np.array([0.01]), friction_stiffness_in_oz_per_rad=kf)
    # quasi-static: the outer axis sits on the friction spring (and the flexure carries J2)
    assert abs(h[0]) == pytest.approx(1.0 / kf, rel=2e-3)


def test_measured_frf_of_the_simulated_linear_plant_matches_the_zoh_model(tb2):
    """End to end: random coarse torque held per sample through the exact ZOH model of the
    2-DOF testbed (friction linearised as a spring so the axis does not wander), the
    outer encoder recorded: H1 and the model's ZOH response agree where coherent."""
    fs, kf, n = 500.0, 5000.0, 2 ** 15
    A, B = continuous_model(tb2)
    rel = np.zeros(A.shape[0])
    rel[0] = 1.0
    A = A + kf * np.outer(B[:, 2], rel)             # same construction as the module's
    Ad, Bd = discretise(A, B, 1.0 / fs)
    u = white(n, seed=11, std=0.5)
    xs = np.zeros(A.shape[0])
    phi1 = np.empty(n)
    for k in range(n):
        phi1[k] = xs[0]
        xs = Ad @ xs + Bd[:, 0] * u[k]
    meas = h1_estimate(u, phi1, fs, 1024, input_units="in-oz", output_units="rad")
    model = model_response(tb2, "T1->phi1", meas.freq_hz, sample_rate_hz=fs,
                           friction_stiffness_in_oz_per_rad=kf)
    cmp_ = compare_frf(meas, model, min_coherence=0.99)
    assert cmp_.bins_used > 0.8 * meas.freq_hz.size
    assert cmp_.max_abs_magnitude_ratio_db < 0.5
    assert cmp_.max_abs_phase_difference_deg < 3.0
    assert np.all(np.isnan(cmp_.magnitude_ratio_db[~cmp_.used]))


def test_compare_frf_only_uses_coherent_bins_and_reports_ratio_and_phase():
    f = np.linspace(0.0, 50.0, 6)
    meas = FrequencyResponse(freq_hz=f, response=np.full(6, 2.0 * np.exp(1j * np.radians(10))),
                             coherence=np.array([np.nan, 0.95, 0.5, 0.99, 0.92, 1.0]),
                             segments=10, units="rad/A", rate_hz=100.0, nperseg=10)
    c = compare_frf(meas, np.ones(6), min_coherence=0.9, band_hz=(0.0, 45.0))
    assert list(c.used) == [False, True, False, True, True, False]
    assert np.allclose(c.magnitude_ratio_db[c.used], 20 * np.log10(2.0))
    assert np.allclose(c.phase_difference_deg[c.used], 10.0)
    assert c.rms_magnitude_ratio_db == pytest.approx(6.0206, abs=1e-3)
    with pytest.raises(FrfError, match="evaluate the model on measured.freq_hz"):
        compare_frf(meas, np.ones(5))


def test_model_refuses_what_the_testbed_does_not_have(tb2):
    tb1 = load_testbed(TESTBEDS_DIR / "rigid_1dof.toml")
    f = np.array([1.0, 10.0])
    with pytest.raises(FrfError, match="no fine motor"):
        model_response(tb1, "g2", f)
    with pytest.raises(FrfError, match="unknown output"):
        model_response(tb2, "T1->theta9", f)
    with pytest.raises(FrfError, match="INPUT->OUTPUT"):
        model_response(tb2, "g7", f)
    with pytest.raises(FrfError, match="freq_hz"):
        model_response(tb2, "g1", np.array([-1.0]))
    # the rigid axis: 1/(J s² + b_f s)
    m = tb1.mechanics
    s = 2j * np.pi * f
    np.testing.assert_allclose(model_response(tb1, "g1", f), 1.0 / (m["J"] * s ** 2 + m["bearing_viscous"] * s),
                               rtol=1e-9)
