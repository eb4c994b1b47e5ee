"""The margins' root refinement: every bracket at once, as exact as a scalar brentq."""

from __future__ import annotations

import math

import numpy as np
from scipy.optimize import brentq

from groundstation.params.loop_response import margins, refine_roots


def _brackets(g, lo, hi, points=400):
    x = np.linspace(lo, hi, points)
    y = g(x)
    i = np.nonzero(np.sign(y[:-1]) * np.sign(y[1:]) < 0)[0]
    return x[i], x[i + 1], y[i], y[i + 1]


def test_refined_roots_equal_brentq_for_smooth_steep_and_flat_functions():
    simple_roots = 15            # steps allowed where every root is simple
    bisections = math.ceil(math.log2((8.9 / 399) / 1e-12))
    functions = [
        (lambda x: np.sin(x), simple_roots),                        # ordinary, two brackets
        (lambda x: np.tanh(200 * (x - 2.2)) + 0.3, simple_roots),   # a steep step, as beside a resonance
        (lambda x: np.exp(x - 1.5) - 1.0, simple_roots),            # convex
        (lambda x: (x - 4.0) ** 3, 4 * bisections + 4),             # flat: a triple root
    ]
    for g, most_steps in functions:
        a, b, ga, gb = _brackets(g, 0.1, 9.0)
        calls = []

        def g_at(x, which):
            calls.append(len(which))
            return g(x)

        roots = refine_roots(g_at, a, b, ga, gb)
        expected = [brentq(lambda s: float(g(np.array([s]))[0]), lo, hi, xtol=1e-12, rtol=1e-12)
                    for lo, hi in zip(a, b)]
        assert len(roots) == len(expected) >= 1
        np.testing.assert_allclose(roots, expected, rtol=0, atol=1e-11)
        # one evaluation per step serves every bracket
        assert len(calls) <= most_steps
        assert all(n <= len(a) for n in calls)


def test_margins_of_a_known_discrete_loop():
    """L(z) = k / (z (z - 1)) sampled at 1 kHz: the phase crosses -180 deg where the
    angle of z (z - 1) is 0, i.e. never below Nyquist except at it, where L = -k/2;
    |L| = 1 where |z - 1| = k."""
    rate, k = 1000.0, 0.5

    def loop(f):
        z = np.exp(2j * np.pi * np.asarray(f, float) / rate)
        return k / (z * (z - 1))

    m = margins(loop, rate / 2)
    # |z - 1| = 2 sin(w T / 2) = k  ->  f = asin(k / 2) rate / pi
    f_c = math.asin(k / 2) * rate / math.pi
    assert m.crossover_hz is not None and abs(m.crossover_hz - f_c) < 1e-9 * f_c
    w = 2 * math.pi * f_c / rate
    pm = 180.0 + math.degrees(np.angle(k / (np.exp(1j * w) * (np.exp(1j * w) - 1))))
    assert abs(m.phase_margin_deg - pm) < 1e-9
    # at Nyquist z = -1: L = k / 2 > 0 ... on the positive axis; the phase crossing is where
    # angle(z (z - 1)) = 180 deg: 3 w / 2 + 90 deg = 180 deg -> w = pi / 3
    f_p = rate / 6
    assert m.gain_margin_hz is not None and abs(m.gain_margin_hz - f_p) < 1e-9 * f_p
    assert abs(m.gain_margin_db - (-20 * math.log10(k / (2 * math.sin(math.pi / 6))))) < 1e-9
