"""Design #2 against Design #1 under base motion, linear (groundstation/params/disturbance_ratios.py).

What is held: where the energy ratio passes 1 (Design #2 cheaper below, dearer above,
as §9 of the reference says), the outside review's figures for a coarse-axis torque
(issue 28: 0.014 at 2 Hz ... 6.8 at 10 Hz, two significant figures), the jitter ratio of
two output-equivalent designs (exactly 1), and the frequency-domain responses against a
time-domain simulation of the same loop built independently from the testbed's state
space (groundstation/plant/model.py) driven by a sine on the base stage.
"""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np
import pytest
from scipy import signal

from groundstation.basemotion.psd import PsdTable
from groundstation.params.design_file import load_design
from groundstation.params.disturbance_ratios import (disturbance_ratios, energy_ratio_crossings_hz,
                                                     predicted_figures, response)
from groundstation.plant import model

CONTROLLERS = Path(__file__).resolve().parents[2] / "profiles" / "controllers"
# issue 28, the outside review: D2/D1 control energy for a disturbance torque on the coarse axis
REVIEW_ENERGY_RATIOS = {2.0: 0.014, 4.0: 0.22, 5.0: 0.60, 7.0: 2.3, 10.0: 6.8}


@pytest.fixture(scope="module")
def designs():
    return tuple(load_design(CONTROLLERS / f"inertial_design{i}.toml") for i in (1, 2))


def test_design2_is_cheaper_below_the_crossing_and_dearer_above(designs):
    crossings = energy_ratio_crossings_hz(*designs, 0.1, 20.0)
    r = disturbance_ratios(*designs, [2.0, 10.0])
    note = f"energy ratio passes 1 at {crossings} Hz; at 2 / 10 Hz: {r.energy_ratio}"
    assert r.energy_ratio[0] < 1 < r.energy_ratio[1], note
    assert len(crossings) == 1 and 2.0 < crossings[0] < 10.0, note


def test_the_review_figures_for_a_coarse_axis_torque(designs):
    f = np.array(sorted(REVIEW_ENERGY_RATIOS))
    got = disturbance_ratios(*designs, f).energy_ratio
    stated = np.array([REVIEW_ENERGY_RATIOS[x] for x in f])
    # two significant figures: within 5 % (0.014 is 0.0137 rounded: 2.5 %)
    assert np.all(np.abs(got / stated - 1) < 0.05), dict(zip(f, got))


def test_output_equivalent_designs_have_the_same_jitter(designs):
    """Same loop gain, same LOS response to any coarse-axis torque: the jitter ratio is 1
    at every frequency, so the linear loop cannot order the designs in jitter."""
    r = disturbance_ratios(*designs, np.geomspace(0.1, 20, 50))
    assert np.allclose(r.jitter_ratio, 1.0, rtol=1e-6)


def test_the_energy_ratio_does_not_depend_on_the_gyro_delay(designs):
    """The rate error is the same in both designs (same loop), so the ratio is that of
    the controllers alone: the sensor path (delay, outer loop) cancels."""
    f = np.array([1.0, 5.0, 10.0])
    a = disturbance_ratios(*designs, f).energy_ratio
    b = disturbance_ratios(*designs, f, gyro_delay_s=0.0, crossover_hz=0.5).energy_ratio
    assert np.allclose(a, b, rtol=1e-9)


def _state_space(tf):
    """(A, B, C, D) of a transfer function as a series of 2nd-order sections (one
    companion form of c0 of Design #2, order 12, has entries of 1e25: useless); a
    constant has no states (tf2ss gives it a dummy one at s = 0)."""
    A, B, C = np.zeros((0, 0)), np.zeros((0, 1)), np.zeros((1, 0))
    if not len(tf.poles) and not len(tf.zeros):
        return A, B, C, np.array([[tf.gain]])
    D = np.array([[1.0]])                         # zpk2sos puts the gain in a section
    for sec in signal.zpk2sos(tf.zeros, tf.poles, tf.gain, analog=True):
        # analog sections pad first-order ones with leading zeros: tf2ss wants them gone
        a2, b2, c2, d2 = signal.tf2ss(np.trim_zeros(sec[:3], "f"), np.trim_zeros(sec[3:], "f"))
        n1, n2 = A.shape[0], a2.shape[0]
        A = np.block([[A, np.zeros((n1, n2))], [b2 @ C, a2]])
        B = np.vstack([B, b2 @ D])
        C = np.hstack([d2 @ C, c2])
        D = d2 @ D
    return A, B, C, D


def _closed_loop_state_space(design, crossover_hz: float):
    """The loop in the time domain, from the testbed's own state space (plant with b_f,
    base stage, gyro without delay), the cascades as state space, the complementary
    filter theta_hat' = w_c (theta2 - theta_hat) + gyro and e = -K_p theta_hat - gyro.
    Input: generator volts.  Outputs: theta2, theta_b, u1, u2."""
    tb = design.testbed
    Ap, Bp = model.continuous_model(tb)
    n = Ap.shape[0]
    parts = [_state_space(tf) for tf in (design.c0, design.c1, design.c2)]
    sizes = [n, 1] + [p[0].shape[0] for p in parts]
    off = np.concatenate([[0], np.cumsum(sizes)])
    N = off[-1]
    A, B = np.zeros((N, N)), np.zeros((N, 1))

    def row(index: int) -> np.ndarray:
        r = np.zeros(N)
        r[index] = 1.0
        return r

    gyro, theta2, h = row(model.GY), row(model.TH2), row(off[1])
    wc = 2 * math.pi * crossover_hz
    A[off[1]] = -wc * h + wc * theta2 + gyro
    e = -design.outer_loop_gain_per_s * h - gyro
    (A0, B0, C0, D0), (A1, B1, C1, D1), (A2, B2, C2, D2) = parts
    s0, s1, s2 = (slice(off[i], off[i + 1]) for i in (2, 3, 4))
    A[s0] += B0 @ e[None, :]
    A[s0, s0] += A0
    u = np.zeros(N)
    u[s0] = C0[0]
    u += D0[0, 0] * e
    us = []
    for sl, (Ai, Bi, Ci, Di) in ((s1, parts[1]), (s2, parts[2])):
        A[sl] += Bi @ u[None, :]
        A[sl, sl] += Ai
        ui = Di[0, 0] * u
        ui[sl] += Ci[0]
        us.append(ui)
    A[:n] += np.outer(Bp[:, 0], us[0]) + np.outer(Bp[:, 1], us[1])
    A[:n, :n] += Ap
    B[:n, 0] = Bp[:, 3]
    C = np.vstack([theta2, row(model.THB), us[0], us[1]])
    return signal.StateSpace(A, B, C, np.zeros((4, 1)))


def _amplitude(t: np.ndarray, x: np.ndarray, f_hz: float) -> complex:
    """Complex amplitude of x at f_hz by least squares (x ~ Re(a e^{j w t}))."""
    w = 2 * math.pi * f_hz
    M = np.column_stack([np.cos(w * t), -np.sin(w * t)])
    c, *_ = np.linalg.lstsq(M, x, rcond=None)
    return complex(c[0], c[1])


@pytest.mark.parametrize("which", [0, 1])
def test_the_responses_match_a_time_domain_simulation_of_one_sine(designs, which):
    """theta2, u1, u2 per theta_b from the frequency responses against lsim of the loop,
    steady state of a 3 Hz sine on the base stage.  No gyro delay in both (a pure delay
    has no finite state space; it is the same factor in both computations)."""
    design, f0, crossover = designs[which], 3.0, 2.0
    sys_ = _closed_loop_state_space(design, crossover)
    assert np.max(np.linalg.eigvals(sys_.A).real) < 0         # the check needs a steady state
    t = np.arange(0, 8.0, 1e-4)
    y = signal.lsim(sys_, 0.1 * np.sin(2 * math.pi * f0 * t), t)[1]
    tail = t > 6.0
    amp = [_amplitude(t[tail], y[tail, k], f0) for k in range(4)]
    base = amp[1]
    r = response(design, [f0], gyro_delay_s=0.0, crossover_hz=crossover)
    for got, want in ((amp[0] / base, r.los_rad_per_rad[0]), (amp[2] / base, r.coarse_in_oz_per_rad[0]),
                      (amp[3] / base, r.fine_in_oz_per_rad[0])):
        assert abs(got / want - 1) < 2e-3, (got, want)
    # mean power of the simulated currents against power_w_per_rad2 * A^2 / 2
    mc, mf = design.testbed.motor_coarse, design.testbed.motor_fine
    p_sim = np.mean((y[tail, 2] / mc["torque_constant"]) ** 2 * mc["resistance"]
                    + (y[tail, 3] / mf["torque_constant"]) ** 2 * mf["resistance"])
    assert abs(p_sim / (r.power_w_per_rad2[0] * abs(base) ** 2 / 2) - 1) < 5e-3


def test_predicted_figures_of_a_narrow_band_are_those_of_its_sine(designs):
    """A PSD 1 % wide around 3 Hz with variance A^2/2 is a sine of amplitude A: the
    integrated figures must be the single-frequency ones."""
    amp, f0 = 1e-3, 3.0
    lo, hi = f0 * 0.995, f0 * 1.005
    psd = PsdTable(np.array([lo, hi]), np.full(2, amp ** 2 / 2 / (hi - lo)), name="sine")
    for d in designs:
        fig = predicted_figures(d, None, psd, gyro_delay_s=0.0, crossover_hz=2.0)
        r = response(d, [f0], gyro_delay_s=0.0, crossover_hz=2.0)
        assert math.isclose(fig["base_rms_rad"], amp / math.sqrt(2), rel_tol=1e-6)
        assert math.isclose(fig["jitter_rms_rad"], abs(r.los_rad_per_rad[0]) * amp / math.sqrt(2), rel_tol=2e-3)
        assert math.isclose(fig["fine_rms_in_oz"], abs(r.fine_in_oz_per_rad[0]) * amp / math.sqrt(2), rel_tol=2e-3)
        assert math.isclose(fig["energy_j"], 60 * r.power_w_per_rad2[0] * amp ** 2 / 2, rel_tol=4e-3)
