"""protocol/SPEC.md §10.1 checked against the simulated firmware: the section recursion of
the control law."""

from __future__ import annotations

import pytest

# --- §10.1 control law: the section recursion ----------------------------------------------

def spec_cascade(sos: list[list[float]], xs: list[float]) -> list[float]:
    """§10.1's direct form II transposed cascade, states committed every period."""
    state = [[0.0, 0.0] for _ in sos]
    out = []
    for x in xs:
        for k, (b0, b1, b2, _a0, a1, a2) in enumerate(sos):
            s1, s2 = state[k]
            y = b0 * x + s1
            state[k] = [b1 * x - a1 * y + s2, b2 * x - a2 * y]
            x = y
        out.append(x)
    return out


def test_spec_cascade_recursion_matches_core():
    """The SOS equations of §10.1 give the simulated firmware's filter outputs."""
    import numpy as np

    from groundstation.sim.core import sos_run

    sos = [[0.2, 0.1, -0.05, 1, -1.0, 0.0],            # integrator section
           [0.5, 0.3, 0.2, 1, 0.0, 0.0],               # FIR section
           [0.1, 0.2, 0.1, 1, -1.6, 0.81],             # complex poles
           [1, 0, 0, 1, 0, 0]]                         # identity
    xs = [1.0, 0.0, -0.5, 0.25, 2.0, 0.0, 0.0, -1.0, 0.125, 0.0]
    arr = np.array(sos, dtype=np.float64)
    z = np.zeros((len(sos), 2))
    z_new = np.zeros_like(z)
    got = []
    for x in xs:
        got.append(sos_run(arr, z, z_new, x))
        z[:] = z_new
    assert got == pytest.approx(spec_cascade(sos, xs), rel=1e-12, abs=1e-15)
