"""analysis/plant_fit.py: the plant's parameters fitted to frequency responses.

Synthetic measurements are the model's own responses for a "hidden" testbed, with the
scatter an H1 estimate of that coherence and averaging has (seeded), so the truth is
known exactly; the simulated rig's logs are the round trip of tests/cli (identify)."""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np
import pytest

from groundstation.analysis.frf import model_response
from groundstation.analysis.plant_fit import (FRICTION_STIFFNESS, MeasuredResponse,
                                              PlantFitError, fit_plant, with_values)
from groundstation.plant.testbed import load_testbed

ROOT = Path(__file__).resolve().parents[2]
RELATIVE = load_testbed(ROOT / "profiles/testbeds/relative_2dof.toml")
INERTIAL = load_testbed(ROOT / "profiles/testbeds/inertial_2dof.toml")
RATE_HZ = 1200.0
FREQ_HZ = np.arange(5, 513) * RATE_HZ / 2048           # 2.9 .. 300 Hz, 0.59 Hz bins


def hidden_rig(base, **factors):
    """`base` with some values multiplied ('section.key' spelt section__key)."""
    values = {}
    for name, factor in factors.items():
        section, key = name.split("__")
        values[f"{section}.{key}"] = float(getattr(base, section)[key]) * factor
    return with_values(base, values)


def measured(truth, paths, coherence=0.98, segments=30, seed=1):
    """The truth's responses per ampere with an H1 estimate's random error."""
    rng = np.random.default_rng(seed)
    out = []
    sd = math.sqrt((1 - coherence) / (2 * segments * coherence))
    for which in paths:
        h = model_response(truth, which, FREQ_HZ, sample_rate_hz=RATE_HZ, per_amp=True)
        noise = sd * (rng.standard_normal(h.size) + 1j * rng.standard_normal(h.size))
        out.append(MeasuredResponse(which, FREQ_HZ, h * np.exp(noise),
                                    np.full(FREQ_HZ.shape, coherence), segments, "synthetic"))
    return out


ENCODERS = ("T1->phi1", "T1->phi2", "T2->phi1", "T2->phi2")


def test_every_identifiable_parameter_is_recovered_within_its_interval():
    truth = hidden_rig(RELATIVE, mechanics__J1=1.08, mechanics__flexure_stiffness=0.88,
                       mechanics__flexure_damping=2.0, mechanics__bearing_viscous=1.5,
                       motor_fine__torque_constant=0.95)
    fit = fit_plant(RELATIVE, measured(truth, ENCODERS), sample_rate_hz=RATE_HZ)
    for p in fit.parameters:
        if p.status != "identified" or p.name == FRICTION_STIFFNESS.name:
            continue
        section, key = p.name.split(".")
        true = float(getattr(truth, section)[key])
        lo, hi = p.ci95
        assert lo <= true <= hi, (p.name, true, p.ci95)
        assert p.value == pytest.approx(true, rel=0.01), p.name
    assert fit.reduced_chi_square == pytest.approx(1.0, abs=0.2)
    assert fit.rms_magnitude_db < 0.3 < fit.base_rms_magnitude_db
    assert fit.testbed.mechanics["J1"] == fit.estimate("mechanics.J1").value


def test_the_torque_scale_is_held_at_the_coarse_motor_and_unexcited_parts_are_not_invented():
    """Every torque-side parameter scales with K_t: the coarse motor's is held; the gyro
    has no measured response on the relative rig, so its parameters are held too."""
    truth = hidden_rig(RELATIVE, mechanics__J2=1.05)
    fit = fit_plant(RELATIVE, measured(truth, ENCODERS), sample_rate_hz=RATE_HZ)
    kt = fit.estimate("motor_coarse.torque_constant")
    assert kt.status == "held (scale)" and kt.value == kt.base and kt.ci95 is None
    for name in ("sensors.gyro_bandwidth", "sensors.gyro_damping", "sensors.gyro_delay"):
        p = fit.estimate(name)
        assert p.status == "held (no data)" and p.value == p.base, name


def test_with_only_the_fine_motor_excited_its_constant_sets_the_scale():
    truth = hidden_rig(RELATIVE, mechanics__J2=1.05)
    fit = fit_plant(RELATIVE, measured(truth, ("T2->phi1", "T2->phi2")), sample_rate_hz=RATE_HZ)
    assert fit.estimate("motor_fine.torque_constant").status == "held (scale)"
    assert fit.estimate("motor_coarse.torque_constant").status == "held (no data)"
    assert fit.estimate("mechanics.J2").value == pytest.approx(truth.mechanics["J2"], rel=0.01)


def test_the_gyro_is_identified_from_a_gyro_response():
    truth = hidden_rig(INERTIAL, sensors__gyro_bandwidth=0.9, sensors__gyro_delay=1.1,
                       mechanics__J1=1.05)
    fit = fit_plant(INERTIAL, measured(truth, ("T1->phi1", "T1->gyro_rate", "T2->phi2")),
                    sample_rate_hz=RATE_HZ)
    for name in ("sensors.gyro_bandwidth", "sensors.gyro_delay", "mechanics.J1"):
        p = fit.estimate(name)
        section, key = name.split(".")
        assert p.status == "identified", name
        assert p.value == pytest.approx(getattr(truth, section)[key], rel=0.02), name


def test_a_parameter_the_data_barely_see_is_held_and_said_so():
    """A barely coherent measurement (γ² = 0.3, 2 segments) cannot pin the flexure's
    damping to a factor of two: it is held at the base value with the reason."""
    truth = hidden_rig(RELATIVE, mechanics__flexure_damping=2.0)
    fit = fit_plant(RELATIVE, measured(truth, ("T1->phi1",), coherence=0.3, segments=2),
                    sample_rate_hz=RATE_HZ, min_coherence=0.25)
    held = [p for p in fit.parameters if p.status == "held (not determined)"]
    assert held and all(p.value == p.base for p in held)
    assert any(p.name in m for p in held for m in fit.messages)


def test_too_little_coherence_is_refused_with_what_to_do():
    truth = hidden_rig(RELATIVE)
    with pytest.raises(PlantFitError, match="no bin of any response has coherence >= 0.9"):
        fit_plant(RELATIVE, measured(truth, ENCODERS, coherence=0.5), sample_rate_hz=RATE_HZ)


def test_a_rigid_testbed_is_refused():
    rigid = load_testbed(ROOT / "profiles/testbeds/rigid_1dof.toml")
    with pytest.raises(PlantFitError, match="2-DOF"):
        fit_plant(rigid, [], sample_rate_hz=RATE_HZ)
