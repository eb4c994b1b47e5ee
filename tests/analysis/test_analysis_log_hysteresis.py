"""analysis/log_hysteresis.py: the bearing's hysteresis loop and its slope table from a
closed-loop triangle the fast simulator records, checked against the testbed."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from groundstation import Testbed
from groundstation.analysis.log_hysteresis import hysteresis_from_log
from groundstation.plant.testbed import load_testbed
from groundstation.profiles.profile import profile_from_dict

ROOT = Path(__file__).resolve().parents[2]
DESIGN = ROOT / "profiles/controllers/relative_design2.toml"


@pytest.fixture(scope="module")
def triangle(tmp_path_factory):
    """A closed-loop position triangle, +-0.05 deg at 0.01 deg/s, two cycles: the bearing
    runs through full hysteresis loops (40 s of device time)."""
    folder = tmp_path_factory.mktemp("triangle")
    profile = profile_from_dict({
        "profile": {"name": "friction_triangle_test", "target": "REFERENCE", "units": "rad",
                    "origin": "relative"},
        "generator": {"type": "triangle", "amplitude_deg": 0.05, "velocity_deg_per_s": 0.01,
                      "cycles": 2, "turnaround_s": 0.5}})
    with Testbed("sim", testbed=ROOT / "profiles/testbeds/relative_2dof.toml", fast=True,
                 generator=None, log_folder=folder, history=folder / "h") as tb:
        tb.upload_design(DESIGN)
        path = tb.start_recording("triangle")
        tb.play(profile)
        tb.stop_recording()
    return path


def test_hysteresis_loop_and_slope_table_from_a_triangle(triangle):
    res = hysteresis_from_log(triangle)
    tb = load_testbed(ROOT / "profiles/testbeds/relative_2dof.toml")
    assert res.torque_formula == "K_t1*i1 - K_t2*i2 + k*(phi2 - phi1)"
    assert res.torque_constant_in_oz_per_a == tb.motor_coarse["torque_constant"]
    assert sum(b.complete for b in res.loop.branches) >= 3
    ident = res.identification
    assert ident is not None and ident.coulomb_torque_estimated
    # T_c read off the loop: the testbed's within 10 % (at 10x the reference's speed)
    assert ident.coulomb_torque_in_oz == pytest.approx(tb.friction["coulomb_torque"], rel=0.1)
    # the shipped slope table starts at f(0) = 12; the estimate is within 20 %
    assert ident.f[0] == pytest.approx(12.0, rel=0.2)
    # the fine loop holds the inner axis on the flexure: what it passes to the outer axis
    # (fine-motor reaction and flexure torque, together J2 * w2') is a few hundredths of
    # an in-oz here, a few % of T_c at most - small, not nothing
    plain = hysteresis_from_log(triangle, coupling=False)
    assert plain.torque_formula == "K_t1*i1"
    difference = np.abs(plain.loop.torque_in_oz - res.loop.torque_in_oz)
    assert 0.0 < np.max(difference) < 0.05 * tb.friction["coulomb_torque"]
