"""analysis/friction_id.py: hysteresis loops of known friction models, identified back."""

from __future__ import annotations

import math

import numpy as np
import pytest

from groundstation.analysis.friction_id import (DEFAULT_X_GRID, FrictionIdError, identify_friction,
                                                split_branches, write_slope_table)
from groundstation.core.dictionary import default_control_rate_hz
from groundstation.core.errors import GroundStationError
from groundstation.plant.slope_table import (DEFAULT_SLOPE_TABLE, SlopeTableError,
                                             load_slope_table, validate_slope_table)
from groundstation.sim.friction import FrictionParams, simulate_friction

SIGMA, TC = 5730.0, 2.25        # in-oz/rad, in-oz: the rig's reference values


def triangle(amplitude_rad: float, step_rad: float, half_cycles: int) -> np.ndarray:
    """The friction test's position profile: from −A up to +A, then back and forth between
    ±A, sampled at a constant step (constant rate, constant sample rate); the turn points
    land on samples.  The lead-in from −A is a full swing, so the loop starts on its outer
    branch (from rest at T = 0 it reaches the running torque within e^-10 for A = 2 mrad)."""
    n = int(round(amplitude_rad / step_rad))
    legs = [np.linspace(-amplitude_rad, amplitude_rad, 2 * n + 1)]
    for k in range(half_cycles):
        a, b = (amplitude_rad, -amplitude_rad) if k % 2 == 0 else (-amplitude_rad, amplitude_rad)
        legs.append(np.linspace(a, b, 2 * n + 1)[1:])
    return np.concatenate(legs)


def dhm_alpha1_loop(angle: np.ndarray, sigma=SIGMA, t_c=TC) -> np.ndarray:
    """The Dahl hysteresis model with α = 1, integrated in closed form, independent of
    sim/friction.py: on a branch of direction s from (θ_k, T_k),
    dT/dθ = σ·(2 − s(T − T_k)/T_c)  ⇒  s(T − T_k) = T_c·(x0 … → 2) with
    2 − x = (2 − x0)·exp(−(σ/T_c)·ψ), ψ = s(θ − θ_k).
    The triangle's branches each run between two reversals (no minor loops), so T_k is
    simply the torque at the last reversal; the first leg starts at rest (T = 0) on the
    outer branch, whose T_k is the opposite Coulomb level (x0 = 1)."""
    k = sigma / t_c
    T = np.empty_like(angle)
    T[0] = 0.0
    d = np.diff(angle)
    s = 1.0
    th_k, t_k, x0 = angle[0], -t_c, 1.0
    for i in range(1, angle.size):
        si = 1.0 if d[i - 1] > 0 else -1.0
        if si != s:                                      # reversal at sample i-1
            s, th_k, t_k, x0 = si, angle[i - 1], T[i - 1], 0.0
        psi = s * (angle[i] - th_k)
        x = 2.0 - (2.0 - x0) * math.exp(-k * psi)
        T[i] = t_k + s * x * t_c
    return T


# ======================================================================================
@pytest.fixture(scope="module")
def dhm_record():
    angle = triangle(2e-3, 1e-7, 5)               # 5 branches of 4 mrad, 1e-7 rad per sample
    return angle, dhm_alpha1_loop(angle)


def test_the_test_loop_is_the_dahl_model_of_the_simulator(dhm_record):
    angle, torque = dhm_record
    ref = simulate_friction(angle, FrictionParams(model="DHM", sigma=SIGMA, T_c=TC, alpha=1.0))
    assert np.max(np.abs(ref - torque)) < 1e-4 * TC


def test_branches_split_at_the_triangle_turns(dhm_record):
    angle, torque = dhm_record
    loop = split_branches(angle, torque)
    n = 20_000                                        # samples per amplitude
    assert list(loop.reversal_indices) == [2 * n + 2 * n * k for k in range(5)]
    assert len(loop.branches) == 5
    assert [b.direction for b in loop.branches] == [-1, 1, -1, 1, -1]
    assert [b.complete for b in loop.branches] == [True] * 4 + [False]
    assert loop.lead_in == slice(0, 2 * n + 1)
    a, t = loop.branch_arrays(1)
    assert a[0] == pytest.approx(-2e-3) and a[-1] == pytest.approx(2e-3)
    for b in loop.branches:
        assert b.travel_rad == pytest.approx(4e-3)
        # the reference: right after any reversal the slope is 2^α·σ
        assert b.turnaround_slope_in_oz_per_rad == pytest.approx(2.0 * SIGMA, rel=0.002)
        # late in the branch the torque has reached T_k ± 2·T_c: slope σ·(2 − x) ≈ 0
        assert 0.0 <= b.late_slope_in_oz_per_rad < 0.01 * SIGMA
        assert b.torque_swing_in_oz == pytest.approx(2.0 * TC, rel=1e-3)


def test_dhm_loop_identifies_two_minus_x_and_the_coulomb_torque(dhm_record):
    angle, torque = dhm_record
    ident = identify_friction(angle, torque, sigma_in_oz_per_rad=SIGMA)
    # T_c from the loop's running torque: half the swing of a full branch
    assert ident.coulomb_torque_estimated
    assert ident.coulomb_torque_in_oz == pytest.approx(TC, rel=0.002)
    x = ident.x
    assert np.array_equal(x, DEFAULT_X_GRID)
    mid = ident.identified & (x <= 1.5)
    assert mid.sum() >= 20
    # α = 1: f(x) = 2 − x, within a few %
    np.testing.assert_allclose(ident.f_raw[mid], 2.0 - x[mid], rtol=0.03)
    assert ident.f[0] == pytest.approx(2.0, rel=0.01)
    np.testing.assert_allclose(ident.f, 2.0 - x, atol=0.03 * 2.0)
    # the DHM is non-increasing by itself: the monotone fit had nothing to do
    assert ident.monotone_violation < 0.01
    assert ident.branches_per_point[0] == 5
    # a valid table for the simulator
    validate_slope_table(ident.x, ident.f, "identified")


def test_given_coulomb_torque_is_used_as_given(dhm_record):
    angle, torque = dhm_record
    ident = identify_friction(angle, torque, sigma_in_oz_per_rad=SIGMA, coulomb_torque_in_oz=TC)
    assert not ident.coulomb_torque_estimated and ident.coulomb_torque_in_oz == TC
    ok = ident.identified & (ident.x <= 1.5)
    np.testing.assert_allclose(ident.f_raw[ok], 2.0 - ident.x[ok], rtol=0.03)


def test_the_shipped_table_is_recovered_from_a_db_dhm_loop():
    """A loop shaped by the shipped slope table (DB-DHM, simulator's model), sampled as
    finely as the rig's 0.001 deg/s at 1200 Hz (1.45e-8 rad), identified back."""
    lx, ly = load_slope_table(DEFAULT_SLOPE_TABLE)
    params = FrictionParams(model="DB-DHM", sigma=SIGMA, T_c=TC, lut_x=lx, lut_y=ly)
    angle = triangle(2e-3, 2e-8, 3)
    torque = simulate_friction(angle, params)
    ident = identify_friction(angle, torque, sigma_in_oz_per_rad=SIGMA, x_grid=lx)
    # the branches end 0.15 % short of the running torque (the table's last segment is
    # approached exponentially): the extrapolation to the plateau recovers T_c
    assert ident.loop.branches[1].torque_swing_in_oz < 0.999 * 2 * TC
    assert ident.coulomb_torque_in_oz == pytest.approx(TC, rel=0.002)
    # turnaround slope σ·f(0) = 12σ: the table falls by a third over the first 2 %, so the
    # quadratic fit over the first 1 % of the swing is a little low
    turn = ident.turnaround_slopes_in_oz_per_rad
    np.testing.assert_allclose(turn, ly[0] * SIGMA, rtol=0.03)
    ok = ident.identified
    assert ok[:-1].all() and not ok[-1]        # up to x = 1.85; 2.0 is never reached
    # within 3 %: the windows (±0.01 in x) straddle the table's kinks at 0.02 … 0.1
    np.testing.assert_allclose(ident.f_raw[ok], ly[ok], rtol=0.03)
    np.testing.assert_allclose(ident.f, ly, rtol=0.03)
    assert ident.f[-1] == 0.0                  # the filled end of the branch
    validate_slope_table(ident.x, ident.f, "identified")


def test_write_slope_table_round_trips_through_the_plant_reader(tmp_path):
    x = np.array([0.0, 0.1, 1.0 / 3.0, 1.2, 2.0])
    f = np.array([2.0, 1.9, 5.0 / 3.0, 0.8, 0.0])
    path = write_slope_table(tmp_path / "lut.csv", x, f, comment="identified from run 7\nDHM")
    text = path.read_text(encoding="utf-8")
    assert text.startswith("# identified from run 7\n# DHM\n")
    assert "\nx,slope_ratio\n" in text
    lx, ly = load_slope_table(path)
    assert np.array_equal(lx, x) and np.array_equal(ly, f)     # bit for bit
    # and the simulator takes it
    FrictionParams.from_csv(path, model="DB-DHM")
    # the shipped table too, rewritten, reads back the same
    sx, sy = load_slope_table(DEFAULT_SLOPE_TABLE)
    wx, wy = load_slope_table(write_slope_table(tmp_path / "copy.csv", sx, sy))
    assert np.array_equal(wx, sx) and np.array_equal(wy, sy)


def test_write_slope_table_refuses_an_invalid_table(tmp_path):
    with pytest.raises(SlopeTableError, match="non-increasing"):
        write_slope_table(tmp_path / "bad.csv", [0.0, 1.0, 2.0], [1.0, 1.2, 0.0])
    with pytest.raises(SlopeTableError, match="cover"):
        write_slope_table(tmp_path / "bad.csv", [0.0, 1.0], [1.0, 0.5])
    assert not (tmp_path / "bad.csv").exists()
    with pytest.raises(FrictionIdError, match="cannot write the slope table"):
        write_slope_table(tmp_path / "no" / "such" / "dir.csv", [0.0, 2.0], [1.0, 0.0])


def test_noisy_data_still_give_the_table(dhm_record):
    """The rig's noise: encoder noise of a few nrad, and the current's 0.1 mA resolution
    times K_t ≈ 3e-3 in-oz of torque quantisation (about 1e-3 in-oz RMS)."""
    angle, torque = dhm_record
    rng = np.random.default_rng(3)
    noisy_angle = angle + rng.normal(0.0, 2e-9, angle.size)
    noisy_torque = torque + rng.normal(0.0, 1e-3, angle.size)
    ident = identify_friction(noisy_angle, noisy_torque, sigma_in_oz_per_rad=SIGMA)
    assert ident.coulomb_torque_in_oz == pytest.approx(TC, rel=0.005)
    assert np.all(np.diff(ident.f) <= 0.0) and np.all(ident.f >= 0.0)
    validate_slope_table(ident.x, ident.f, "noisy")
    np.testing.assert_allclose(ident.f, 2.0 - ident.x, atol=0.05)
    # one branch's turnaround slope scatters by a few %, their mean much less
    np.testing.assert_allclose(ident.turnaround_slopes_in_oz_per_rad, 2 * SIGMA, rtol=0.08)
    assert np.mean(ident.turnaround_slopes_in_oz_per_rad) == pytest.approx(2 * SIGMA, rel=0.03)


def loop_from_table(x_tab, f_tab, amplitude_rad, step_rad, half_cycles, x_end=1.95):
    """A steady triangle loop whose every branch has the slope σ·f(x), f piecewise linear
    (any shape, also one the plant would refuse): ψ(x) = ∫ T_c/(σ·f) dx by the trapezoid
    rule on a fine x grid up to x_end, inverted by interpolation; each branch starts where
    the previous one ended (T_k = −s·x_end·T_c/2, a symmetric loop)."""
    xf = np.linspace(0.0, x_end, 200_001)
    inv = TC / (SIGMA * np.interp(xf, x_tab, f_tab))
    psi_of_x = np.concatenate(([0.0], np.cumsum(0.5 * (inv[1:] + inv[:-1]) * np.diff(xf))))
    angle = triangle(amplitude_rad, step_rad, half_cycles)
    torque = np.empty_like(angle)
    turns = np.flatnonzero(np.diff(np.sign(np.diff(angle)))) + 1
    starts = np.concatenate(([0], turns))
    stops = np.concatenate((turns, [angle.size - 1]))
    for a, b in zip(starts, stops):
        s = 1.0 if angle[b] > angle[a] else -1.0
        psi = s * (angle[a:b + 1] - angle[a])
        torque[a:b + 1] = -s * x_end * TC / 2 + s * TC * np.interp(psi, psi_of_x, xf)
    return angle, torque


def test_a_rising_stretch_in_the_data_is_reported_and_smoothed_by_the_monotone_fit(tmp_path):
    x_tab = np.array([0.0, 0.8, 0.9, 1.0, 2.0])
    f_tab = np.array([2.0, 1.2, 1.4, 1.0, 0.0])     # 2 − x with a bump: rises by 0.2 at 0.9
    angle, torque = loop_from_table(x_tab, f_tab, 2e-3, 1e-7, 4)
    grid = np.array([0.0, 0.2, 0.4, 0.6, 0.8, 0.9, 1.0, 1.2, 1.4, 1.6, 1.8, 2.0])
    raw = identify_friction(angle, torque, sigma_in_oz_per_rad=SIGMA, coulomb_torque_in_oz=TC,
                            x_grid=grid, monotone=False)
    ok = raw.identified
    assert not ok[-1] and ok[:-1].all()
    np.testing.assert_allclose(raw.f_raw[ok], np.interp(grid[ok], x_tab, f_tab), rtol=0.03)
    assert raw.monotone_violation == pytest.approx(0.2 / 2.0, rel=0.1)
    with pytest.raises(SlopeTableError, match="non-increasing"):
        write_slope_table(tmp_path / "raw.csv", raw.x, raw.f)
    mono = identify_friction(angle, torque, sigma_in_oz_per_rad=SIGMA, coulomb_torque_in_oz=TC,
                             x_grid=grid)
    assert mono.monotone and mono.monotone_violation == raw.monotone_violation
    # pool adjacent violators: 0.8 and 0.9 (1.2, 1.4) become their mean, the rest stays
    assert mono.f[4] == mono.f[5] == pytest.approx(1.3, rel=0.03)
    np.testing.assert_allclose(np.delete(mono.f, [4, 5]), np.delete(raw.f, [4, 5]))
    lx, ly = load_slope_table(write_slope_table(tmp_path / "mono.csv", mono.x, mono.f))
    assert np.array_equal(ly, mono.f)


def test_bad_records_are_refused_with_a_clear_message(dhm_record):
    angle, torque = dhm_record
    with pytest.raises(FrictionIdError, match="same length"):
        split_branches(angle, torque[:-1])
    with pytest.raises(FrictionIdError, match="does not move"):
        split_branches(np.zeros(1000), torque[:1000])
    with pytest.raises(FrictionIdError, match="no velocity reversal"):
        split_branches(np.linspace(0.0, 1e-3, 1000), torque[:1000])
    with pytest.raises(FrictionIdError, match="too short"):
        split_branches(angle[:5], torque[:5])
    with pytest.raises(FrictionIdError, match="non-finite value at sample 2"):
        split_branches([0.0, 1.0, np.inf] + [0.0] * 20, [0.0] * 23)
    with pytest.raises(FrictionIdError, match="sigma"):
        identify_friction(angle, torque, sigma_in_oz_per_rad=0.0)
    with pytest.raises(FrictionIdError, match="x_grid"):
        identify_friction(angle, torque, sigma_in_oz_per_rad=SIGMA, x_grid=[0.0, 1.0])
    # a small triangle never reaches the running torque: T_c must then be given
    small = triangle(5e-5, 1e-7, 3)
    with pytest.raises(FrictionIdError, match="give coulomb_torque_in_oz"):
        identify_friction(small, dhm_alpha1_loop(small), sigma_in_oz_per_rad=SIGMA)
    assert issubclass(FrictionIdError, GroundStationError)


def test_small_loops_identify_the_start_of_the_table_and_fill_the_rest():
    small = triangle(1e-4, 1e-8, 3)            # the branch reaches x ≈ 0.8 of 2
    ident = identify_friction(small, dhm_alpha1_loop(small), sigma_in_oz_per_rad=SIGMA,
                              coulomb_torque_in_oz=TC)
    reached = ident.x <= 0.7
    assert ident.identified[reached].all() and not ident.identified[ident.x >= 1.0].any()
    np.testing.assert_allclose(ident.f_raw[reached], 2.0 - ident.x[reached], rtol=0.03)
    # the unreached tail is filled linearly down to f(2) = 0, and the table stays valid
    assert ident.f[-1] == 0.0
    validate_slope_table(ident.x, ident.f, "small loop")


def test_a_record_at_the_rigs_rate_with_its_noise_and_quantisation():
    """The procedure as run: 0.001 deg/s sampled at the control rate (1.45e-8 rad per
    sample), 5 nrad of encoder noise, torque from a current with 0.1 mA resolution times
    K_t = 32.1 in-oz/A plus 1e-3 in-oz of noise, the shipped table in the simulator."""
    lx, ly = load_slope_table(DEFAULT_SLOPE_TABLE)
    params = FrictionParams(model="DB-DHM", sigma=SIGMA, T_c=TC, lut_x=lx, lut_y=ly)
    rng = np.random.default_rng(21)
    angle = triangle(3e-3, math.radians(0.001) / default_control_rate_hz(), 4)
    angle = angle + rng.normal(0.0, 5e-9, angle.size)
    kt, lsb = 32.1, 1e-4
    current = (simulate_friction(angle, params) + rng.normal(0.0, 1e-3, angle.size)) / kt
    torque = np.round(current / lsb) * lsb * kt
    ident = identify_friction(angle, torque, sigma_in_oz_per_rad=SIGMA, x_grid=lx)
    assert ident.coulomb_torque_in_oz == pytest.approx(TC, rel=0.002)
    assert np.mean(ident.turnaround_slopes_in_oz_per_rad) == pytest.approx(ly[0] * SIGMA, rel=0.08)
    ok = ident.identified
    assert ok[:-1].all()
    # the steep start is the hardest part (x = 0.01 of the swing is ~20 samples here)
    np.testing.assert_allclose(ident.f_raw[ok][:3], ly[ok][:3], rtol=0.08)
    np.testing.assert_allclose(ident.f_raw[ok][3:], ly[ok][3:], rtol=0.03)
    validate_slope_table(ident.x, ident.f, "rig-like")
