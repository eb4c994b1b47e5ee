"""Control energy (groundstation.analysis.energy): i^2 R integrated per motor, RMS
currents, saturation fractions, missing frames counted, and the chunked accumulator."""

from __future__ import annotations

import math

import numpy as np
import pytest

from groundstation.analysis import AnalysisError, EnergyAccumulator, control_energy
from groundstation.core.dictionary import default_control_rate_hz

RATE_HZ = default_control_rate_hz()
R_COARSE, R_FINE = 4.8, 6.8          # ohm, profiles/testbeds/inertial_2dof.toml


def test_constant_currents_give_i2_r_t():
    n = int(round(2.5 * RATE_HZ))
    e = control_energy(np.full(n, 0.05), np.full(n, -0.01), RATE_HZ, R_COARSE, R_FINE)
    assert e.energy_coarse_j == pytest.approx(0.05 ** 2 * R_COARSE * 2.5, rel=1e-12)
    assert e.energy_fine_j == pytest.approx(0.01 ** 2 * R_FINE * 2.5, rel=1e-12)
    assert e.energy_total_j == pytest.approx(e.energy_coarse_j + e.energy_fine_j)
    assert (e.rms_current_coarse_a, e.rms_current_fine_a) == (pytest.approx(0.05), pytest.approx(0.01))
    assert e.seconds == pytest.approx(2.5) and e.samples == n
    assert e.mean_power_w == pytest.approx(0.05 ** 2 * R_COARSE + 0.01 ** 2 * R_FINE)
    assert e.saturated_coarse_fraction is None and "n/a" in e.text()


def test_a_sinusoidal_current_dissipates_r_times_its_mean_square():
    t = np.arange(int(10 * RATE_HZ)) / RATE_HZ
    i = 0.3 * np.sin(2 * np.pi * 4.0 * t)
    e = control_energy(i, np.zeros_like(i), RATE_HZ, R_COARSE, R_FINE)
    assert e.energy_coarse_j == pytest.approx(R_COARSE * 0.3 ** 2 / 2 * 10.0, rel=1e-9)
    assert e.rms_current_coarse_a == pytest.approx(0.3 / math.sqrt(2), rel=1e-9)
    assert e.energy_fine_j == 0.0


def test_saturation_fractions_and_missing_frames():
    n = 1000
    sat_c = np.zeros(n, dtype=bool)
    sat_c[:250] = True
    sat_f = np.zeros(n, dtype=bool)
    sat_f[::10] = True
    e = control_energy(np.full(n, 1.0), np.full(n, 1.0), RATE_HZ, 2.0, 3.0,
                       coarse_saturated=sat_c, fine_saturated=sat_f, missing_frames=12)
    assert e.saturated_coarse_fraction == pytest.approx(0.25)
    assert e.saturated_fine_fraction == pytest.approx(0.10)
    # the energy covers the frames received only; the missing ones are reported
    assert e.missing_frames == 12 and e.seconds == pytest.approx(n / RATE_HZ)
    assert e.energy_total_j == pytest.approx(5.0 * n / RATE_HZ)
    assert "25.00 %" in e.text() and "12 frames missing" in e.text()


@pytest.mark.parametrize("chunk", [1, 333, 4096])
def test_the_accumulator_in_pieces_equals_the_whole(chunk):
    rng = np.random.default_rng(3)
    n = 5000
    i1, i2 = rng.normal(0, 0.2, n), rng.normal(0.01, 0.05, n)
    s1, s2 = rng.random(n) < 0.1, rng.random(n) < 0.02
    whole = control_energy(i1, i2, RATE_HZ, R_COARSE, R_FINE, coarse_saturated=s1,
                           fine_saturated=s2, missing_frames=4)
    acc = EnergyAccumulator(RATE_HZ, R_COARSE, R_FINE)
    for a in range(0, n, chunk):
        acc.feed(i1[a:a + chunk], i2[a:a + chunk], s1[a:a + chunk], s2[a:a + chunk])
    part = acc.result(missing_frames=4)
    for name in ("energy_coarse_j", "energy_fine_j", "rms_current_coarse_a", "rms_current_fine_a",
                 "saturated_coarse_fraction", "saturated_fine_fraction"):
        assert getattr(part, name) == pytest.approx(getattr(whole, name), rel=1e-12), name
    assert (part.samples, part.missing_frames) == (whole.samples, whole.missing_frames)


def test_a_piece_without_saturation_bits_makes_the_fraction_unknown():
    acc = EnergyAccumulator(RATE_HZ, R_COARSE, R_FINE)
    acc.feed(np.ones(3), np.ones(3), np.ones(3, bool), np.ones(3, bool))
    acc.feed(np.ones(3), np.ones(3))
    e = acc.result()
    assert e.saturated_coarse_fraction is None and e.saturated_fine_fraction is None


def test_bad_input_says_what_is_wrong():
    with pytest.raises(AnalysisError, match=r"coarse motor resistance must be > 0 ohm.*\[motor_coarse\]"):
        control_energy(np.ones(3), np.ones(3), RATE_HZ, 0.0, 1.0)
    with pytest.raises(AnalysisError, match="equally long"):
        control_energy(np.ones(3), np.ones(4), RATE_HZ, 1.0, 1.0)
    with pytest.raises(AnalysisError, match="no motor-current samples"):
        control_energy(np.zeros(0), np.zeros(0), RATE_HZ, 1.0, 1.0)
    with pytest.raises(AnalysisError, match="not finite"):
        control_energy(np.array([0.0, np.nan]), np.ones(2), RATE_HZ, 1.0, 1.0)
    acc = EnergyAccumulator(RATE_HZ, 1.0, 1.0)
    with pytest.raises(AnalysisError, match="not finite"):
        acc.feed(np.array([np.inf]), np.ones(1))
    with pytest.raises(AnalysisError, match="no motor-current samples"):
        acc.result()
