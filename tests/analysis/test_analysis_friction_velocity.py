"""Running friction against velocity (analysis/friction_velocity.py): synthetic records
with a known answer - constant-velocity passes both ways between dwells, raised-cosine
blends whose inertia torque must not leak into the plateau, a friction torque that needs
travel to reach its running value, noise - then the log adapter on a short simulated
velocity pass (chunked reading equals one read; the CLI metric)."""

from __future__ import annotations

import json
import math
from pathlib import Path

import numpy as np
import pytest

from groundstation.analysis.friction_velocity import (BlockAccumulator, FrictionVelocityError,
                                                      coulomb_viscous_fit, friction_vs_velocity,
                                                      velocity_blocks)

RATE = 1200.0
TC = 2.25            # in-oz
B = 20.0             # in-oz-s/rad
J = 0.5              # in-oz-s^2
PRESLIDE = 2e-4      # rad: travel over which the friction builds up after a reversal


def passes(speeds, *, plateau_s=2.0, blend_s=0.2, dwell_s=0.5, offset=0.0, noise=0.0,
           seed=0, preslide=PRESLIDE):
    """(t, angle, torque, velocity) of passes at the signed speeds given, each: blend up,
    plateau, blend down, dwell.  The torque is J dw/dt + b w + offset + a friction that
    relaxes towards T_c sgn(w) exponentially with travel (a Dahl-like presliding)."""
    dt = 1.0 / RATE
    vel = [np.zeros(int(dwell_s * RATE))]
    for v in speeds:
        nb = int(blend_s * RATE)
        ramp = v * 0.5 * (1 - np.cos(np.pi * np.arange(nb) / nb))
        vel += [ramp, np.full(int(plateau_s * RATE), v), ramp[::-1], np.zeros(int(dwell_s * RATE))]
    w = np.concatenate(vel)
    t = np.arange(w.size) * dt
    angle = 0.01 + np.concatenate(([0.0], np.cumsum(0.5 * (w[1:] + w[:-1]) * dt)))
    acc = np.gradient(w, dt)
    friction = np.zeros(w.size)
    f = 0.0
    for i in range(1, w.size):
        d = angle[i] - angle[i - 1]
        if d != 0.0:
            target = TC * math.copysign(1.0, d)
            f = target + (f - target) * math.exp(-abs(d) / preslide)
        friction[i] = f
    torque = J * acc + B * w + friction + offset
    if noise:
        rng = np.random.default_rng(seed)
        angle = angle + rng.normal(0.0, 5e-9, angle.size)
        torque = torque + rng.normal(0.0, noise, torque.size)
    return t, angle, torque, w


def test_two_passes_give_their_speed_and_running_friction():
    v = 0.05                                      # rad/s (2.9 deg/s)
    t, angle, torque, _ = passes([v, -v], noise=0.01)
    fv = friction_vs_velocity(t, angle, torque)
    assert [s.direction for s in fv.segments] == [1, -1]
    for s, sign in zip(fv.segments, (1, -1)):
        assert s.settled
        assert s.velocity_rad_s == pytest.approx(sign * v, rel=1e-4)
        # the running friction plus the viscous part; the blends' J dw/dt stays out
        assert s.torque_in_oz == pytest.approx(sign * (TC + B * v), abs=3e-3)
        assert s.torque_std_in_oz == pytest.approx(0.01, rel=0.2)
        # the plateau found lies inside the constant-velocity part
        assert s.stop_s - s.start_s > 1.5
    assert fv.running_torque_in_oz == pytest.approx(TC + B * v, abs=3e-3)
    assert fv.offset_in_oz == pytest.approx(0.0, abs=3e-3)
    assert fv.mean(+1)[0] == pytest.approx(v, rel=1e-4)


def test_an_offset_the_same_both_ways_is_told_from_the_friction():
    v = 0.02
    t, angle, torque, _ = passes([-v, v], offset=0.4)
    fv = friction_vs_velocity(t, angle, torque)
    assert fv.running_torque_in_oz == pytest.approx(TC + B * v, abs=1e-3)
    assert fv.offset_in_oz == pytest.approx(0.4, abs=1e-3)


def test_the_slowest_reference_speed_is_found_under_encoder_noise():
    v = 0.01 * math.pi / 180                       # 0.01 deg/s
    t, angle, torque, _ = passes([v, -v], plateau_s=6.0, noise=0.001, preslide=2e-5)
    fv = friction_vs_velocity(t, angle, torque)
    assert len(fv.segments) == 2 and all(s.settled for s in fv.segments)
    assert fv.segments[0].speed_deg_s == pytest.approx(0.01, rel=1e-3)
    assert fv.running_torque_in_oz == pytest.approx(TC + B * v, abs=1e-3)


def test_a_stroke_too_short_for_the_friction_to_settle_is_flagged():
    """A presliding travel as long as the pass: the torque still climbs at its end, so
    the segment is reported but marked unsettled and left out of the direction's mean."""
    v = 1e-3
    t, angle, torque, _ = passes([v, -v], plateau_s=1.0, preslide=1e-3)
    fv = friction_vs_velocity(t, angle, torque)
    assert len(fv.segments) == 2
    assert not any(s.settled for s in fv.segments)
    assert fv.running_torque_in_oz is None and fv.mean(+1) is None
    assert any("drifts" in n for n in fv.notes)


def test_a_pass_without_a_plateau_is_left_out_with_a_note():
    v = 0.05
    t, angle, torque, _ = passes([v], plateau_s=0.0, blend_s=0.5)   # up and straight down
    fv = friction_vs_velocity(t, angle, torque)
    assert fv.segments == ()
    assert any("without a constant-velocity stretch" in n for n in fv.notes)


def test_saturation_flags_are_counted_per_segment():
    v = 0.05
    t, angle, torque, _ = passes([v, -v])
    flags = np.zeros(t.size, dtype=bool)
    flags[(t > 1.5) & (t < 2.0)] = True            # inside the first plateau's settled part
    fv = friction_vs_velocity(t, angle, torque, flags)
    assert fv.segments[0].saturated_fraction > 0 and fv.segments[1].saturated_fraction == 0


@pytest.mark.parametrize("chunk", [1, 37, 1000, 10 ** 6])
def test_blocks_from_pieces_equal_the_whole_record(chunk):
    t, angle, torque, _ = passes([0.03, -0.03], noise=0.01)
    flags = (np.arange(t.size) % 7) == 0
    whole = velocity_blocks(t, angle, torque, flags)
    acc = BlockAccumulator()
    for i in range(0, t.size, chunk):
        acc.add(t[i:i + chunk], angle[i:i + chunk], torque[i:i + chunk], flags[i:i + chunk])
    parts = acc.result()
    assert len(parts) == len(whole)
    for name in ("time_s", "angle_rad", "torque_in_oz", "torque_var"):
        np.testing.assert_allclose(getattr(parts, name), getattr(whole, name), rtol=1e-12, atol=1e-12)
    np.testing.assert_allclose(parts.velocity_rad_s, whole.velocity_rad_s, rtol=1e-9, atol=1e-12)
    np.testing.assert_array_equal(parts.samples, whole.samples)
    np.testing.assert_array_equal(parts.saturated, whole.saturated)


def test_a_block_velocity_is_the_slope_and_holes_use_the_frames_times():
    t = np.arange(0, 1.0, 1 / RATE)
    keep = np.ones(t.size, dtype=bool)
    keep[300:420] = False                           # 0.1 s of frames missing
    angle = 0.3 + 0.002 * t                         # 2 mrad/s on top of 0.3 rad
    b = velocity_blocks(t[keep], angle[keep], np.ones(keep.sum()))
    finite = np.isfinite(b.velocity_rad_s)
    np.testing.assert_allclose(b.velocity_rad_s[finite], 0.002, rtol=1e-7)
    assert b.samples.sum() == keep.sum()


def test_coulomb_viscous_fit_recovers_its_parameters():
    v = np.array([0.001, 0.01, 0.1, 0.5, -0.001, -0.01, -0.1, -0.5])
    q = 0.1 + TC * np.sign(v) + B * v
    fit = coulomb_viscous_fit(v, q)
    assert fit.coulomb_in_oz == pytest.approx(TC, rel=1e-9)
    assert fit.viscous_in_oz_s_per_rad == pytest.approx(B, rel=1e-9)
    assert fit.offset_in_oz == pytest.approx(0.1, abs=1e-9)
    assert fit.residual_rms_in_oz == pytest.approx(0.0, abs=1e-9)
    np.testing.assert_allclose(fit.torque(v), q, atol=1e-9)
    one_way = coulomb_viscous_fit(v[:4], q[:4] - 0.1)    # one direction: no offset
    assert one_way.offset_in_oz is None and one_way.coulomb_in_oz == pytest.approx(TC, rel=1e-9)
    one_speed = coulomb_viscous_fit([0.1], [TC + B * 0.1])
    assert one_speed.viscous_in_oz_s_per_rad is None
    assert one_speed.coulomb_in_oz == pytest.approx(TC + B * 0.1)
    with pytest.raises(FrictionVelocityError, match="no moving point"):
        coulomb_viscous_fit([0.0], [1.0])


def test_bad_input_gets_a_specific_message():
    t = np.arange(10) / RATE
    with pytest.raises(FrictionVelocityError, match="angle_rad has 9 samples"):
        friction_vs_velocity(t, np.zeros(9), np.zeros(10))
    with pytest.raises(FrictionVelocityError, match="non-finite value at sample 3"):
        friction_vs_velocity(t, np.where(np.arange(10) == 3, np.nan, 0.0), np.zeros(10))
    with pytest.raises(FrictionVelocityError, match="increase strictly"):
        friction_vs_velocity(t[::-1], np.zeros(10), np.zeros(10))
    with pytest.raises(FrictionVelocityError, match="tolerance"):
        friction_vs_velocity(t, np.zeros(10), np.zeros(10), tolerance=0.0)
    with pytest.raises(FrictionVelocityError, match="block_s"):
        friction_vs_velocity(t, np.zeros(10), np.zeros(10), block_s=-1)
    acc = BlockAccumulator()
    acc.add(t[:5], np.zeros(5), np.zeros(5))
    with pytest.raises(FrictionVelocityError, match="piece to piece"):
        acc.add(t[:5], np.zeros(5), np.zeros(5))


# --------------------------------------------------------------------------- from a log
ROOT = Path(__file__).resolve().parents[2]
TESTBED = ROOT / "profiles" / "testbeds" / "relative_2dof.toml"
DESIGN = ROOT / "profiles" / "controllers" / "relative_design2.toml"
PROFILE = """
[profile]
name = "fv_test_pass"
target = "REFERENCE"
units = "rad"
origin = "relative"
description = "two short passes at 2 deg/s"

[generator]
type = "constant_velocity"
velocity_deg_per_s = 2.0
stroke_deg = 2.0
accel_s = 0.1
dwell_s = 0.2
cycles = 1
lead_s = 0.2
"""


@pytest.fixture(scope="module")
def pass_log(tmp_path_factory) -> Path:
    from groundstation import Testbed

    folder = tmp_path_factory.mktemp("fv_log")
    profile = folder / "fv_test_pass.toml"
    profile.write_text(PROFILE)
    with Testbed("sim", testbed=TESTBED, fast=True, generator=None, log_folder=folder,
                 history=folder / "h") as tb:
        tb.upload_design(DESIGN)
        log = tb.start_recording("fv")
        tb.play(profile, mode="RELATIVE")
        tb.stop_recording()
    return Path(log)


def test_the_log_adapter_reads_in_chunks_with_the_same_result(pass_log):
    from groundstation.analysis.log_friction_velocity import friction_velocity_from_log

    whole = friction_velocity_from_log(pass_log)
    small = friction_velocity_from_log(pass_log, chunk_rows=97)
    assert whole.torque_formula == "T1 - T2 + k*(phi2 - phi1)"
    assert any("narrowed to the profile" in n for n in whole.notes)
    assert len(whole.result.segments) == len(small.result.segments) >= 2
    for a, b in zip(whole.result.segments, small.result.segments):
        assert a.velocity_rad_s == pytest.approx(b.velocity_rad_s, rel=1e-9)
        assert a.torque_in_oz == pytest.approx(b.torque_in_oz, rel=1e-9)
    # the simulator's bearing: running Dahl torque T_c plus its viscous b_f (testbed file)
    v = 2.0 * math.pi / 180
    settled = [s for s in whole.result.segments if s.settled]
    assert len(settled) >= 2
    for s in settled:
        assert abs(s.velocity_rad_s) == pytest.approx(v, rel=0.01)
        assert abs(s.torque_in_oz) == pytest.approx(2.25 + 20.0 * v, rel=0.02)


def test_a_log_without_a_pass_is_a_specific_error(pass_log):
    from groundstation.analysis.log_friction_velocity import friction_velocity_from_log
    from groundstation.analysis.log_window import LogIdentificationError, NoExcitationError

    with pytest.raises(NoExcitationError, match="no constant-velocity pass"):
        friction_velocity_from_log(pass_log, 0.0, 0.1, trim_to_profile=False)
    with pytest.raises(LogIdentificationError, match="drive channel"):
        friction_velocity_from_log(pass_log, drive_channel="encoder_inner")


def test_the_cli_metric(pass_log, capsys):
    from groundstation.cli.main import main

    assert main(["analyze", str(pass_log), "--metrics", "friction_velocity"]) == 0
    out = capsys.readouterr().out
    assert "friction_velocity:" in out and "segment(s) settled; friction" in out
    assert main(["analyze", str(pass_log), "--metrics", "friction_velocity", "--json"]) == 0
    row = json.loads(capsys.readouterr().out)[0]
    assert row["fv_segments"] >= 2 and row["fv_friction_in_oz"] > 2.25
    assert row["fv_torque_formula"] == "T1 - T2 + k*(phi2 - phi1)" and row["error"] == ""
