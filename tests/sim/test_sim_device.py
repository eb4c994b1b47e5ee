"""The simulated testbed as a device: configuration errors, base stage, friction
compensation, stack-overflow reporting, stability of every shipped configuration."""

from __future__ import annotations

import math
import os
import signal
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

from groundstation.sim.firmware import Firmware
from groundstation.plant.model import discrete_model
from groundstation.plant.testbed import TESTBEDS_DIR, TestbedConfigError, load_testbed
from test_sim_reference import firmware, keep_alive, pid_sos, variant

ROOT = Path(__file__).resolve().parents[2]


@pytest.mark.parametrize("name", ["rigid_1dof", "relative_2dof", "inertial_2dof"])
@pytest.mark.parametrize("substeps", [1, 4, 8, 16])
def test_every_configuration_is_stable_at_any_substep_count(tmp_path, name, substeps):
    tb = load_testbed(variant(tmp_path, name, substeps=str(substeps)))
    model = discrete_model(tb)
    assert np.max(np.abs(np.linalg.eigvals(model.Ad))) <= 1.0 + 1e-12
    assert model.substep == pytest.approx(1 / (1200 * substeps))


@pytest.mark.parametrize("key, value, message", [
    ("J1", "-0.5", "mechanics.J1 = -0.5 in-oz-s^2 is outside the allowed range"),
    ("flexure_stiffness", '"stiff"', "mechanics.flexure_stiffness must be a number"),
    ("substeps", "0", "simulation.substeps = 0 is outside the allowed range [1, 64]"),
    ("model", '"LuGre"', "friction.model = 'LuGre'"),
    ("gyro_delay", "0.5", "sensors.gyro_delay = 0.5 s is outside the allowed range [0.0, 0.1] s"),
])
def test_bad_values_name_file_field_and_range(tmp_path, key, value, message):
    path = variant(tmp_path, "inertial_2dof", **{key: value})
    with pytest.raises(TestbedConfigError) as err:
        load_testbed(path)
    assert str(path) in str(err.value) and message in str(err.value)


def test_missing_value_names_the_range(tmp_path):
    text = (TESTBEDS_DIR / "relative_2dof.toml").read_text()
    path = tmp_path / "t.toml"
    path.write_text("\n".join(ln for ln in text.splitlines() if not ln.startswith("J2 =")))
    with pytest.raises(TestbedConfigError, match=r"\[mechanics\] is missing 'J2' \(allowed range"):
        load_testbed(path)


@pytest.mark.parametrize("table, message", [
    ("x,slope_ratio\n0,1\n1,2\n2,0\n", "monoton"),
    ("x,slope\n0,1\n2,0\n", "header"),
    ("x,slope_ratio\n0,1\n1.5,0\n", "2"),
])
def test_bad_friction_tables_are_refused_before_starting(tmp_path, dictionary, table, message):
    (tmp_path / "lut.csv").write_text(table)
    path = variant(tmp_path, "relative_2dof")
    path.write_text(path.read_text().replace(
        str(TESTBEDS_DIR.parent / "friction_slope_lut.csv"), str(tmp_path / "lut.csv")))
    with pytest.raises(Exception) as err:
        Firmware(dictionary, testbed=load_testbed(path))
    assert "lut.csv" in str(err.value) and message in str(err.value).lower()


def test_sim_refuses_a_bad_testbed_and_stops_cleanly_on_ctrl_c(tmp_path):
    bad = variant(tmp_path, "relative_2dof", J1="-1.0")
    out = subprocess.run([sys.executable, "-m", "groundstation", "sim", "--testbed", str(bad)],
                         capture_output=True, text=True, timeout=60, cwd=ROOT)
    assert out.returncode == 2 and "J1" in out.stderr and "Traceback" not in out.stderr
    proc = subprocess.Popen([sys.executable, "-m", "groundstation", "sim", "--tcp-port", "0",
                             "--testbed", str(TESTBEDS_DIR / "inertial_2dof.toml")],
                            stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True, cwd=ROOT,
                            env={**os.environ, "PYTHONUNBUFFERED": "1"})
    try:
        lines = [proc.stdout.readline() for _ in range(2)]
        assert any("simulated testbed on tcp://127.0.0.1:" in ln for ln in lines), lines
        proc.send_signal(signal.SIGINT)
        assert proc.wait(timeout=20) == 0
        assert "Traceback" not in proc.stderr.read()
    finally:
        if proc.poll() is None:
            proc.kill()
            proc.wait(timeout=10)
        proc.stdout.close()
        proc.stderr.close()


def test_generator_voltage_moves_the_base_stage(dictionary):
    tb = load_testbed(TESTBEDS_DIR / "inertial_2dof.toml")
    fw = Firmware(dictionary, testbed=tb, seed=2)
    f0, n = 1.0, 12000
    volts = 0.5 * np.sin(2 * np.pi * f0 * np.arange(n) / 1200)
    cols, truth = fw.run(n, volts)
    b = tb.base_stage
    r = f0 / b["natural_frequency"]
    gain = b["amplifier_gain"] * b["actuator_gain"] / math.hypot(1 - r * r, 2 * b["damping"] * r)
    seg = cols["encoder_base"][-2400:]                    # after the stage's transient
    amplitude = np.abs(np.fft.rfft(seg))[2] * 2 / len(seg)
    assert amplitude == pytest.approx(0.5 * gain, rel=0.03)
    lsb = 2 * math.pi / 2**19
    assert np.allclose(seg / lsb, np.round(seg / lsb))
    # at 1 Hz the bearing's friction holds: the axis rides on the base (inertial LOS
    # moves nearly as much as the base, the relative angle much less)
    assert np.std(truth[-2400:, 1] - truth[-2400:, 2]) < 0.2 * np.std(truth[-2400:, 2])


def test_relative_setup_has_a_fixed_base(dictionary):
    fw = Firmware(dictionary, testbed=load_testbed(TESTBEDS_DIR / "relative_2dof.toml"))
    cols, truth = fw.run(1200, np.ones(1200))
    assert np.all(truth[:, 2] == 0.0) and np.all(cols["encoder_base"] == 0.0)
    assert np.all(cols["gyro_rate"] == 0.0)           # no IMU in this set-up


def test_friction_compensation_is_switchable_and_reported(tmp_path, dictionary):
    path = variant(tmp_path, "rigid_1dof")
    fw, op = firmware(dictionary, path)
    J = load_testbed(path).mechanics["J"]
    w = 2 * np.pi * 10
    op.upload(relative_c0=pid_sos(kp=J * w * w, ki=0.0, kd=2 * J * w, tau=1 / 3000))
    op("SET_MODE", mode="RELATIVE")
    op("ARM")
    t = np.arange(6000) / 1200
    op.profile(1e-3 * np.sin(2 * np.pi * 0.5 * t), "REFERENCE")

    def run(comp_on):
        op("FRICTION_COMP", enable=int(comp_on))
        op("PROFILE_START")
        cols, _ = keep_alive(fw, op, 6000)
        return cols
    off = run(False)
    on = run(True)
    assert not off["friction_comp_on"].any() and np.all(off["friction_comp_torque"] == 0)
    assert on["friction_comp_on"].all() and np.abs(on["friction_comp_torque"]).max() > 1.5
    # without an integrator the PD loop leaves a friction-sized error; compensation shrinks it
    assert np.sqrt(np.mean(on["error_angle"]**2)) < 0.5 * np.sqrt(np.mean(off["error_angle"]**2))


def test_friction_stack_overflow_is_reported(tmp_path, dictionary):
    path = variant(tmp_path, "rigid_1dof", stack_capacity="4")
    fw, op = firmware(dictionary, path)
    op("SET_MODE", mode="OPEN_LOOP")
    op("ARM")
    # nested reversals of shrinking amplitude: more open minor loops than the stack holds
    amps = 0.05 * 0.7 ** np.arange(12)
    samples = np.concatenate([np.full(30, a * (-1) ** i) for i, a in enumerate(amps)])
    op.profile(samples, "CURRENT_COARSE")
    op("PROFILE_START")
    keep_alive(fw, op, len(samples))
    texts = [t for _, code, t, _ in fw.events if code == dictionary.event_codes["SIMULATOR"]]
    assert any("stack overflowed" in t for t in texts)
