"""The bearing's torque ripple (reference §9a, issue 28) in the simulated plant, and the
testbed variant with the appendix's inertias.

The ripple is a torque on the bearing, T_r = A sin(2 pi phi1 / P + psi), added to the
friction torque: it pushes the outer axis exactly as a coarse-motor torque of -T_r would.
The tests hold it to that through the compiled engine itself, on a plant whose friction
is switched off so nothing else acts across the bearing."""

from __future__ import annotations

import math
import tomllib
from pathlib import Path

import numpy as np
import pytest

from groundstation.core.dictionary import load_dictionary
from groundstation.params.table import default_values
from groundstation.plant.model import TH1, TH2
from groundstation.plant.testbed import TESTBEDS_DIR, load_testbed
from groundstation.sim import core
from groundstation.sim.engine import Engine

RATE = 1200.0
LB_IN2 = 0.04144                    # in-oz-s^2 per lb-in^2 (reference, units)


def frictionless_with_ripple(tmp_path: Path, amplitude: float, period: float, phase: float) -> Path:
    """The relative 2-DOF testbed with no bearing friction (no Dahl, no b_f) and a ripple."""
    text = (TESTBEDS_DIR / "relative_2dof.toml").read_text()
    text = text.replace('"../friction_slope_lut.csv"', f'"{TESTBEDS_DIR.parent / "friction_slope_lut.csv"}"')
    lines = []
    section = ""
    for line in text.splitlines():
        if line.startswith("["):
            section = line.split("]")[0].strip("[")
        key = line.split("=")[0].strip()
        if section == "friction" and key == "model":
            line = 'model = "viscous"'
        elif section == "mechanics" and key == "bearing_viscous":
            line = "bearing_viscous = 0.0"
        elif section == "bearing_ripple" and key in ("amplitude", "period", "phase"):
            line = f"{key} = {dict(amplitude=amplitude, period=period, phase=phase)[key]!r}"
        lines.append(line)
    path = tmp_path / "ripple.toml"
    path.write_text("\n".join(lines) + "\n")
    return path


def open_loop_engine(testbed_path: Path, phi0: float, current_coarse: float = 0.0) -> Engine:
    d = load_dictionary()
    eng = Engine(load_testbed(testbed_path), dict(default_values(d)), seed=0, control_rate_hz=RATE)
    eng.x[TH1] = eng.x[TH2] = phi0          # base at 0: the bearing angle phi1 = phi0, flexure relaxed
    eng.fw[core.FW_MODE] = core.MODE_OPEN_LOOP
    eng.fw[core.FW_ARMED] = 1.0
    eng.fw[core.FW_I1] = current_coarse
    return eng


@pytest.mark.parametrize("phase_of_period", [0.125, 0.375, 0.625])
def test_the_ripple_pushes_the_outer_axis_as_a_motor_torque_of_minus_the_ripple(tmp_path, phase_of_period):
    amplitude, period, phase = 2.0, 0.008, 0.3
    phi0 = phase_of_period * period
    ripple_torque = amplitude * math.sin(2 * math.pi * phi0 / period + phase)
    with_ripple = open_loop_engine(frictionless_with_ripple(tmp_path, amplitude, period, phase), phi0)
    kt1 = with_ripple.testbed.motor_coarse["torque_constant"]
    by_motor = open_loop_engine(frictionless_with_ripple(tmp_path, 0.0, period, phase), phi0,
                                current_coarse=-ripple_torque / kt1)
    with_ripple.run(3)
    by_motor.run(3)
    moved = with_ripple.x[TH1] - phi0
    # over 2.5 ms the bearing moves ~1e-5 rad, 0.8 % of a period: the ripple is nearly constant
    assert abs(moved) > 1e-6
    assert np.sign(moved) == -np.sign(ripple_torque)
    assert moved == pytest.approx(by_motor.x[TH1] - phi0, rel=0.02)
    assert with_ripple.x[TH2] - phi0 == pytest.approx(by_motor.x[TH2] - phi0, rel=0.02)


def test_no_ripple_section_means_no_ripple(tmp_path):
    """Zero amplitude (and a file without the section): the plant is as it was."""
    still = open_loop_engine(frictionless_with_ripple(tmp_path, 0.0, 0.008, 0.0), 0.001)
    still.run(12)
    assert still.x[TH1] == pytest.approx(0.001, abs=1e-15)
    text = (TESTBEDS_DIR / "relative_2dof.toml").read_text().replace(
        '"../friction_slope_lut.csv"', f'"{TESTBEDS_DIR.parent / "friction_slope_lut.csv"}"')
    path = tmp_path / "no_section.toml"
    path.write_text(text.split("[bearing_ripple]")[0] + "[simulation]" + text.split("[simulation]")[1])
    assert "bearing_ripple" not in tomllib.loads(path.read_text())
    tb = load_testbed(path)
    assert tb.bearing_ripple["amplitude"] == 0.0


def test_the_shipped_testbeds_ripple_only_on_the_inertial_rig_and_say_it_is_assumed():
    for name in ("relative_2dof", "rigid_1dof"):
        assert load_testbed(TESTBEDS_DIR / f"{name}.toml").bearing_ripple["amplitude"] == 0.0
    for name in ("inertial_2dof", "inertial_2dof_appendix_inertia"):
        tb = load_testbed(TESTBEDS_DIR / f"{name}.toml")
        assert tb.bearing_ripple["amplitude"] > 0.0
        assert {"bearing_ripple.amplitude", "bearing_ripple.period", "bearing_ripple.phase"} <= set(tb.assumed)


def test_the_appendix_variant_differs_from_the_inertial_testbed_only_in_its_inertias():
    base = tomllib.loads((TESTBEDS_DIR / "inertial_2dof.toml").read_text())
    variant = tomllib.loads((TESTBEDS_DIR / "inertial_2dof_appendix_inertia.toml").read_text())
    assert variant["mechanics"]["J1"] == pytest.approx(65.65 * LB_IN2, abs=1e-4)
    assert variant["mechanics"]["J2"] == pytest.approx(43.14 * LB_IN2, abs=1e-4)
    for doc in (base, variant):
        for key in ("J1", "J2"):
            doc["mechanics"].pop(key)
        doc["testbed"].pop("name")
    assert variant == base


def test_a_malformed_ripple_is_refused_with_its_field(tmp_path):
    path = frictionless_with_ripple(tmp_path, 2.0, 0.0, 0.0)
    with pytest.raises(Exception, match=r"bearing_ripple\.period"):
        load_testbed(path)
