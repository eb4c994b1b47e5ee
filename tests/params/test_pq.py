"""The PQ method's numbers (groundstation.params.pq*): alignment, contours, T_I(0), responses."""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np
import pytest
from scipy.linalg import subspace_angles

from groundstation.params.tf_algebra import TransferFunction
from groundstation.params.design_file import load_design
from groundstation.params.pq import (alignment_deg, cos_alignment, input_sensitivity_matrix,
                                     loop_functions,
                                     magnitude_band_db, magnitude_contour_deg, phase_band_deg,
                                     phase_contour_deg, pq_alignment_deg)
from groundstation.params.pq_design import (Leading, analyze, dc_input_sensitivity, leading_sum,
                                            plant_row, ratio_alignment_deg)
from groundstation.params.pq_response import (DisturbanceError, friction_disturbance,
                                              linear_responses, parse_disturbance,
                                              predict_saturation)

CONTROLLERS = Path(__file__).resolve().parents[2] / "profiles" / "controllers"


def design(name: str):
    return load_design(CONTROLLERS / f"{name}.toml")


# --------------------------------------------------------------------------------------
# alignment (Eq. 4.9)
# --------------------------------------------------------------------------------------
def test_alignment_hand_computed():
    # G C = 2 + 3 = 5, ||G|| = sqrt(5), ||C|| = sqrt(10): cos phi = 5 / sqrt(50) -> 45 deg
    assert alignment_deg(np.array([2, 1]), np.array([1, 3])) == pytest.approx(45.0)
    # G C = 1 + j, ||G|| = ||C|| = sqrt(2): cos phi = sqrt(2) / 2 -> 45 deg
    assert alignment_deg(np.array([1, 1j]), np.array([1, 1])) == pytest.approx(45.0)
    # C = G^H: perfectly aligned, however complex G is
    G = np.array([0.3 - 2j, -1.1 + 0.4j])
    assert alignment_deg(G, np.conj(G)) == pytest.approx(0.0, abs=1e-6)
    # the two paths cancel: G C = 0
    assert alignment_deg(np.array([1, 1]), np.array([1, -1])) == pytest.approx(90.0)
    # a plant/controller case by hand: g1 = 1/(j w)^2 and g2 = 0.5 at w = 1 rad/s make
    # G = [-1, 0.5]; C = [1, 1] gives |G C| = 0.5, ||G|| = sqrt(1.25), ||C|| = sqrt(2)
    g = np.array([1 / (1j) ** 2, 0.5])
    expected = math.degrees(math.acos(0.5 / math.sqrt(1.25 * 2)))      # 71.57 deg
    assert alignment_deg(g, np.array([1, 1])) == pytest.approx(expected)
    assert expected == pytest.approx(71.565, abs=1e-3)


def test_alignment_ignores_scalar_factors_but_not_input_scaling():
    rng = np.random.default_rng(1)
    G = rng.normal(size=(50, 2)) + 1j * rng.normal(size=(50, 2))
    C = rng.normal(size=(50, 2)) + 1j * rng.normal(size=(50, 2))
    a = rng.normal(size=(50, 1)) + 1j * rng.normal(size=(50, 1))      # s, gyro, c0 ...
    np.testing.assert_allclose(alignment_deg(a * G, C / a), alignment_deg(G, C), atol=1e-9)
    np.testing.assert_allclose(np.cos(np.radians(alignment_deg(G, C))), cos_alignment(G, C),
                               atol=1e-12)
    w = np.array([10.0, 1.0])                                          # u1 in other units
    assert not np.allclose(alignment_deg(G * w, C / w), alignment_deg(G, C))


def test_input_functions_match_the_matrices_and_reach_their_bounds_when_aligned():
    rng = np.random.default_rng(2)
    G = rng.normal(size=(40, 2)) + 1j * rng.normal(size=(40, 2))
    K = rng.normal(size=(40, 2)) + 1j * rng.normal(size=(40, 2))
    lf = loop_functions(G, K)
    TI = input_sensitivity_matrix(G, K)
    np.testing.assert_allclose(lf.ti_norm, np.linalg.norm(TI, ord=2, axis=(1, 2)), rtol=1e-10)
    SIK = np.linalg.solve(np.eye(2) + K[:, :, None] * G[:, None, :], K[:, :, None])[..., 0]
    np.testing.assert_allclose(lf.sik_norm, np.linalg.norm(SIK, axis=1), rtol=1e-10)
    cos = np.cos(np.radians(lf.phi_deg))
    np.testing.assert_allclose(lf.ti_norm * cos, lf.ti_bound, rtol=1e-9)
    np.testing.assert_allclose(lf.sik_norm * cos, lf.sik_bound, rtol=1e-9)
    aligned = loop_functions(G, 3.0 * np.conj(G))                      # phi = 0
    np.testing.assert_allclose(aligned.ti_norm, aligned.ti_bound, rtol=1e-12)
    np.testing.assert_allclose(aligned.sik_norm, aligned.sik_bound, rtol=1e-12)


# --------------------------------------------------------------------------------------
# contours in the (|PQ|, angle PQ) plane, against brute force
# --------------------------------------------------------------------------------------
MAGS_DB = np.linspace(-40, 40, 81)
ANGLES_DEG = np.linspace(-180, 180, 73)


def _vectors(m, theta, split, phase_split, g2, c2):
    """G = g2 [P, 1], C = c2 [Q, 1] with |P| = m^split, |Q| = m^(1 - split), PQ = m e^(j theta)."""
    P = m ** split * np.exp(1j * phase_split)
    Q = m ** (1 - split) * np.exp(1j * (theta - phase_split))
    return g2 * np.stack([P, np.ones_like(P)], -1), c2 * np.stack([Q, np.ones_like(Q)], -1)


def test_contour_equation_is_the_alignment_when_p_and_q_are_balanced():
    rng = np.random.default_rng(3)
    m, th = np.meshgrid(10 ** (MAGS_DB / 20), np.radians(ANGLES_DEG), indexing="ij")
    shape = m.shape
    G, C = _vectors(m, th, 0.5, rng.uniform(-np.pi, np.pi, shape),
                    (rng.normal(size=shape) + 1j * rng.normal(size=shape))[..., None],
                    (rng.normal(size=shape) + 1j * rng.normal(size=shape))[..., None])
    contour = pq_alignment_deg(m * np.exp(1j * th))
    # brute force 1: Eq. 4.9 on the vectors themselves
    np.testing.assert_allclose(alignment_deg(G, C), contour, atol=1e-6)
    # brute force 2: an independent angle, scipy's between span{G^H} and span{C}
    some = [(i, j) for i in range(0, shape[0], 8) for j in range(0, shape[1], 6)]
    for i, j in some:
        angle = subspace_angles(np.conj(G[i, j])[:, None], C[i, j][:, None])[0]
        assert math.degrees(angle) == pytest.approx(contour[i, j], abs=1e-6)


def test_contour_equation_bounds_every_split_of_the_magnitude():
    m, th = np.meshgrid(10 ** (MAGS_DB / 20), np.radians(ANGLES_DEG), indexing="ij")
    contour = pq_alignment_deg(m * np.exp(1j * th))
    splits = np.linspace(-1.0, 2.0, 121)                               # includes 0.5
    phis = np.stack([alignment_deg(*_vectors(m, th, a, 0.3, 1.0, 1.0)) for a in splits])
    assert np.all(phis >= contour - 1e-9)
    np.testing.assert_allclose(phis.min(axis=0), contour, atol=1e-6)


def test_magnitude_and_phase_contours_are_the_worst_cases_over_the_grid():
    m, th = np.meshgrid(10 ** (MAGS_DB / 20), np.radians(np.linspace(-180, 180, 3601)), indexing="ij")
    contour = pq_alignment_deg(m * np.exp(1j * th))
    np.testing.assert_allclose(contour.max(axis=1), magnitude_contour_deg(10 ** (MAGS_DB / 20)),
                               atol=1e-6)
    m, th = np.meshgrid(np.logspace(-3, 3, 6001), np.radians(ANGLES_DEG), indexing="ij")
    contour = pq_alignment_deg(m * np.exp(1j * th))
    np.testing.assert_allclose(contour.max(axis=0), phase_contour_deg(ANGLES_DEG), atol=1e-6)
    assert np.all(contour <= phase_contour_deg(np.degrees(th)) + 1e-9)
    assert np.all(contour <= magnitude_contour_deg(m) + 1e-9)


@pytest.mark.parametrize("level", [15.0, 30.0, 45.0, 60.0, 75.0, 90.0])
def test_band_edges_are_on_their_contours(level):
    edge = magnitude_band_db(level)
    for db in (edge, -edge):
        assert magnitude_contour_deg(10 ** (db / 20)) == pytest.approx(level, abs=1e-9)
    assert phase_contour_deg(phase_band_deg(level)) == pytest.approx(min(level, 90.0))
    assert phase_contour_deg(370.0) == pytest.approx(5.0)              # wrapped to 10 deg
    assert magnitude_band_db(0.0) == math.inf


# --------------------------------------------------------------------------------------
# the designs
# --------------------------------------------------------------------------------------
REFERENCE_TI0 = {
    "relative_design1": [[1, 0], [13.9, 0]],
    "relative_design2": [[1, 0], [0, 0]],
    "inertial_design1": [[1, 0], [27.5, 0]],
    "inertial_design2": [[1, 0], [0, 0]],
}


@pytest.mark.parametrize("name", sorted(REFERENCE_TI0))
@pytest.mark.parametrize("variant", ["", "_friction_comp"])
def test_dc_input_sensitivity_reproduces_the_reference(name, variant):
    d = design(name + variant)
    dc = dc_input_sensitivity(d)
    np.testing.assert_allclose(dc.values, REFERENCE_TI0[name], atol=0.05)
    assert dc.text() == str(REFERENCE_TI0[name])
    # the exact limit against the matrix itself at a tiny frequency
    s = np.array([1e-7j])
    K = d.c0.response(s)[:, None] * np.stack([d.c1.response(s), d.c2.response(s)], -1)
    TI = input_sensitivity_matrix(plant_row(d.testbed, s, d.mode), K)[0]
    np.testing.assert_allclose(TI.real, dc.values, atol=1e-4)


def test_design1_dc_gain_is_one_over_q_at_dc():
    for name in ("relative_design1", "inertial_design1"):
        d = design(name)
        q0 = d.q.response(np.array([0j]))[0].real
        assert dc_input_sensitivity(d).values[1, 0] == pytest.approx(1 / q0, rel=1e-12)


def test_leading_terms_that_cancel_are_refused():
    with pytest.raises(ValueError, match="cancel"):
        leading_sum([Leading(2.0, -1), Leading(-2.0, -1), Leading(5.0, 0)])
    assert leading_sum([Leading(2.0, -1), Leading(5.0, 0)]) == Leading(2.0, -1)
    assert Leading(3.0, -1).value() == math.inf and Leading(3.0, 1).value() == 0.0


def test_q_equal_one_is_poorly_aligned_near_14_hz_on_the_inertial_rig():
    d = design("inertial_design1")
    one = TransferFunction.constant(1.0)
    f = np.linspace(10, 20, 101)
    phi = ratio_alignment_deg(d.testbed, one, one, f)
    assert phi.max() > 85.0 and 13.0 < f[np.argmax(phi)] < 15.5


def test_analysis_views_are_consistent():
    a = analyze(design("inertial_design2"))
    np.testing.assert_allclose(a.pq, a.plant[:, 0] * a.ratio[:, 0] / (a.plant[:, 1] * a.ratio[:, 1]))
    assert np.all(a.phi_pq_deg <= a.phi_deg + 1e-9)
    assert np.all((a.phi_deg >= 0) & (a.phi_deg <= 90))
    # output-equivalent designs share the loop, hence T_O and its bounds
    b = analyze(design("inertial_design1"), a.freqs_hz)
    np.testing.assert_allclose(a.functions.loop, b.functions.loop, rtol=1e-6)


# --------------------------------------------------------------------------------------
# linear responses and the predicted saturation
# --------------------------------------------------------------------------------------
@pytest.mark.parametrize("name", ["relative_design1", "relative_design2"])
def test_the_disturbance_response_settles_on_the_dc_input_sensitivity(name):
    d = design(name)
    dist = friction_disturbance(d.testbed)
    assert (dist.kind, dist.input, dist.amplitude_in_oz) == ("step", 0, 2.25)
    r = linear_responses(d, dist, duration_s=1.0)
    expected = -dc_input_sensitivity(d).values[:, 0] * dist.amplitude_in_oz
    np.testing.assert_allclose(r.disturbance.u[-1], expected, atol=1e-3 * 2.25)
    assert r.step.y[-1] == pytest.approx(0.5e-3, rel=1e-4)
    assert r.max_pole_radius < 1


def test_predicted_saturation_design1_saturates_the_fine_motor_design2_does_not():
    for name, fine in (("relative_design1", True), ("relative_design2", False),
                       ("inertial_design1", True), ("inertial_design2", False)):
        d = design(name)
        p = predict_saturation(d, linear_responses(d).disturbance)
        assert p.saturates == (False, fine), (name, p.peaks_in_oz)
        assert (p.first_over_s[1] is not None) == fine


def test_disturbance_text():
    assert parse_disturbance("step:u2:1.5").text() == "a 1.5 in-oz step into u2"
    s = parse_disturbance("sine:u1:2:14")
    assert (s.kind, s.input, s.frequency_hz) == ("sine", 0, 14.0)
    for bad in ("ramp:u1:1", "step:u3:1", "step:u1", "sine:u1:1:0", "step:u1:x"):
        with pytest.raises(DisturbanceError):
            parse_disturbance(bad)


def test_an_unused_fine_path_is_the_limit_of_infinite_q():
    d = design("relative_design2")
    f = np.array([1.0, 14.0])
    G = plant_row(d.testbed, 2j * np.pi * f, d.mode)
    phi = alignment_deg(G, np.array([[1.0, 0.0], [1.0, 0.0]]))
    np.testing.assert_allclose(np.cos(np.radians(phi)), np.abs(G[:, 0]) / np.linalg.norm(G, axis=1))
    assert pq_alignment_deg(np.array([np.inf, complex(np.inf, np.nan)])).tolist() == [0.0, 0.0]
