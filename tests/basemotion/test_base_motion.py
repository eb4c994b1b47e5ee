"""Base-motion profiles: PSD tables, multisine synthesis, stage pre-compensation, the
shipped BM1-BM3 tables, and the whole chain - a profile uploaded to the simulated
generator moves the simulated base stage, measured from the base encoder telemetry through
the real client; the `groundstation fg` command line."""

from __future__ import annotations

import math
import shutil
from pathlib import Path

import numpy as np
import pytest
from scipy import signal

from conftest import wait_for
from groundstation.basemotion import (BaseMotionError, BaseStageModel, PsdFileError,
                                      check_base_motion, csp_curves, load_profile, load_psd,
                                      make_profile, parse_psd, synthesise_angle)
from groundstation.cli.main import main
from groundstation.instruments import open_generator
from groundstation.link import open_client
from groundstation.sim import SimulatedDevice
from groundstation.sim.scpi_server import ScpiServer, attach_generator
from groundstation.sim.fg_instrument import SimulatedGenerator
from groundstation.plant.testbed import TESTBEDS_DIR, load_testbed

ROOT = Path(__file__).resolve().parents[2]
BM_DIR = ROOT / "profiles" / "base_motion"
INERTIAL = load_testbed(TESTBEDS_DIR / "inertial_2dof.toml")
STAGE = BaseStageModel.from_testbed(INERTIAL)
TARGETS = {"BM1": 3.0e-3, "BM2": 2.5e-3, "BM3": 2.1e-3}
YAML = Path(__file__).resolve().parents[1] / "fg_sim.yaml"
SIM_RESOURCE = "USB0::0xF4ED::0xEE3A::SIM4053B::INSTR"


# ------------------------------------------------------------------ PSD tables


@pytest.mark.parametrize("name", sorted(TARGETS))
def test_shipped_tables_load_with_their_rms_and_say_they_are_assumed(name):
    psd = load_psd(BM_DIR / f"{name}.csv")
    assert psd.name == name
    assert psd.rms_rad() == pytest.approx(TARGETS[name], rel=1e-5)
    assert any("ASSUMED" in c for c in psd.comments)
    lo, hi = psd.band_hz
    assert 0 < lo < hi <= 10.0


def test_interpolation_is_log_log_and_the_integral_exact():
    psd = parse_psd("frequency_hz,psd_rad2_per_hz\n1,1e-6\n4,1e-8  # -10 dB/octave\n")
    assert psd.density([0.5, 1, 2, 4, 5]) == pytest.approx([0, 1e-6, 1e-7, 1e-8, 0])
    f = np.linspace(1, 4, 200001)
    numeric = np.trapezoid(psd.density(f), f)
    assert psd.variance_rad2() == pytest.approx(numeric, rel=1e-6)
    assert psd.cumulative([0.0, 2.0, 9.0]) == pytest.approx(
        [0.0, np.trapezoid(psd.density(f[f <= 2]), f[f <= 2]), numeric], rel=1e-5)
    scaled = psd.scaled_to_rms(1e-3)
    assert scaled.rms_rad() == pytest.approx(1e-3)
    # a zero row interpolates linearly (no log of 0)
    edge = parse_psd("0,0\n2,2e-6\n")
    assert edge.density(1.0)[0] == pytest.approx(1e-6) and edge.variance_rad2() == pytest.approx(2e-6)


@pytest.mark.parametrize("text, line, message", [
    ("frequency_hz,psd_rad2_per_hz\n0.1,1e-6\n0.2\n", 3, "expected 2 comma-separated values"),
    ("0.1,1e-6\n0.2,abc\n", 2, "not a number"),
    ("# c\nfrequency_hz,psd\nf,psd\n0.1,1\n", 3, "only one header line"),
    ("f,psd\n0.1,1e-6\n0.05,1e-6\n", 3, "not above the previous row"),
    ("0.1,1e-6\n0.2,-1e-6\n", 2, "PSD -1e-06 rad^2/Hz is negative"),
    ("-0.1,1e-6\n0.2,1e-6\n", 1, "frequency -0.1 Hz is negative"),
    ("0.1,1e-6\n0.2,nan\n", 2, "finite"),
    ("frequency_hz,psd_deg2_per_hz\n0.1,1\n0.2,1\n", 1, "degrees"),
])
def test_malformed_tables_name_the_line(tmp_path, text, line, message):
    path = tmp_path / "bad.csv"
    path.write_text(text)
    with pytest.raises(PsdFileError) as err:
        load_psd(path)
    assert f"{path}:{line}: " in str(err.value) and message in str(err.value)


@pytest.mark.parametrize("text, message", [
    ("# nothing\n0.1,1e-6\n", "at least 2 rows"),
    ("0.1,0\n0.2,0\n", "every PSD value is 0"),
])
def test_tables_without_motion_are_refused(tmp_path, text, message):
    path = tmp_path / "empty.csv"
    path.write_text(text)
    with pytest.raises(PsdFileError, match=message):
        load_psd(path)
    with pytest.raises(PsdFileError, match="not found"):
        load_psd(tmp_path / "missing.csv")


# ------------------------------------------------------------------ synthesis


def test_synthesis_is_reproducible_by_seed_and_exact_in_rms():
    psd = load_psd(BM_DIR / "BM2.csv")
    a = synthesise_angle(psd, duration_s=30, seed=7)
    assert np.array_equal(a, synthesise_angle(psd, duration_s=30, seed=7))
    assert not np.allclose(a, synthesise_angle(psd, duration_s=30, seed=8))
    assert len(a) == 16384 and abs(a.mean()) < 1e-15
    assert math.sqrt(np.mean(a ** 2)) == pytest.approx(psd.rms_rad(), rel=1e-12)   # 2.5 mrad
    b = synthesise_angle(psd, duration_s=30, seed=7, target_rms_rad=1.234e-3)
    assert math.sqrt(np.mean(b ** 2)) == pytest.approx(1.234e-3, rel=1e-12)
    assert np.allclose(b / a, 1.234e-3 / psd.rms_rad())     # the same shape, scaled


@pytest.mark.parametrize("name", sorted(TARGETS))
def test_the_spectrum_of_the_synthesised_signal_matches_the_table(name):
    psd = load_psd(BM_DIR / f"{name}.csv")
    duration = 60.0
    angle = synthesise_angle(psd, duration_s=duration, seed=3)
    fs = len(angle) / duration
    # over exactly one period, each line carries exactly the table's power in its bin
    f, pxx = signal.periodogram(angle, fs=fs, window="boxcar", detrend=False)
    table = psd.density(f)
    inband = table > 0.02 * table.max()
    assert pxx[inband] == pytest.approx(table[inband], rel=0.02)
    assert pxx[psd.density(f) == 0].max() < 1e-20 * table.max()
    # and Welch's estimate over the period, as used on recordings, agrees in CSP terms
    check = check_base_motion(angle, fs, psd)
    assert abs(check.rms_error) < 1e-9
    assert check.max_cumulative_rms_difference_rad[0] < 0.1 * TARGETS[name]
    assert check.in_band_fraction > 0.97


def test_synthesis_refuses_what_the_waveform_cannot_hold():
    psd = load_psd(BM_DIR / "BM3_stage4hz.csv")      # content up to 10 Hz
    with pytest.raises(BaseMotionError, match="shorten the duration to under 819.2 s"):
        synthesise_angle(psd, duration_s=1000.0)
    with pytest.raises(BaseMotionError, match="lengthen the duration"):
        synthesise_angle(psd, duration_s=0.15)          # lines at 6.7 and 13.3 Hz only
    with pytest.raises(BaseMotionError, match="even"):
        synthesise_angle(psd, points=1001)
    with pytest.raises(BaseMotionError, match="at most 16384 points"):
        make_profile(psd, STAGE, points=32768)
    with pytest.raises(BaseMotionError, match="base_stage.enabled is false"):
        BaseStageModel.from_testbed(load_testbed(TESTBEDS_DIR / "relative_2dof.toml"))


# ------------------------------------------------------------------ the stage and pre-compensation


def test_the_held_response_is_the_stage_driven_by_a_staircase():
    """Check the model against an independent simulation: the continuous stage fed with
    the generator's staircase, finely sampled, at the waveform's sample instants."""
    prof = make_profile(load_psd(BM_DIR / "BM3.csv"), STAGE, duration_s=10.0, points=2048, seed=1)
    up = 16
    stair = np.tile(np.repeat(prof.volts, up), 3)       # three periods to reach steady state
    t = np.arange(len(stair)) * prof.sample_interval_s / up
    num, den = STAGE._continuous()
    _, theta, _ = signal.lsim((num, den), stair, t, interp=False)
    last = theta[-len(prof.volts) * up::up]
    assert np.max(np.abs(last - prof.expected_angle_rad)) < 1e-3 * np.max(np.abs(last))


def test_pre_compensation_undoes_the_resonance_and_stays_bounded():
    psd = load_psd(BM_DIR / "BM2_stage4hz.csv")      # around the 4 Hz resonance
    comp = make_profile(psd, STAGE, duration_s=60.0, seed=0)
    raw = make_profile(psd, STAGE, duration_s=60.0, seed=0, precompensate=False)
    assert np.allclose(comp.expected_angle_rad, comp.target_angle_rad, atol=1e-9 * 2.5e-3)
    assert comp.expected_rms_rad == pytest.approx(comp.target_rms_rad, rel=1e-9)
    assert comp.target_rms_rad == pytest.approx(2.5e-3, rel=1e-5)
    assert raw.expected_rms_rad > 2.5 * 2.5e-3           # uncompensated: resonance amplifies
    assert np.allclose(raw.volts, raw.target_angle_rad / STAGE.dc_gain_rad_per_volt)
    assert 1.0 <= comp.compensation_peak < 10.0
    assert comp.frequency_hz == pytest.approx(1 / 60) and comp.points == 16384


@pytest.mark.parametrize("name", sorted(TARGETS))
def test_shipped_profiles_stay_within_the_testbeds_generator_limit(name):
    psd = load_psd(BM_DIR / f"{name}.csv")
    limit = INERTIAL.limits["fg_max_amplitude"]
    vpp = [make_profile(psd, STAGE, seed=seed).amplitude_vpp for seed in range(10)]
    assert max(vpp) < 0.9 * limit, vpp
    assert make_profile(psd, STAGE).compensation_peak < 10.0


# ------------------------------------------------------------------ the whole chain


@pytest.fixture
def inertial_rig(dictionary):
    """A manually clocked inertial testbed with its generator, and a connected client whose
    telemetry comes over the command stream (lossless however fast the ticks run)."""
    dev = SimulatedDevice(dictionary, pacing="manual", seed=1, testbed=INERTIAL).start()
    server = attach_generator(dev)
    client = open_client(dictionary, f"tcp://127.0.0.1:{dev.tcp_port}?telemetry=stream",
                         heartbeat=False)
    yield dev, server, client
    client.close()
    server.stop()
    dev.stop()


@pytest.mark.parametrize("name", sorted(TARGETS))
def test_an_uploaded_profile_moves_the_simulated_base_by_its_rms(inertial_rig, name):
    dev, server, client = inertial_rig
    base: list[np.ndarray] = []
    client.subscribe(lambda b: base.append(b["encoder_base"]) if b.name == "HIGH_RATE" else None)
    client.connect()
    period_s, settle_s = 20.0, 10.0
    profile = load_profile(BM_DIR / f"{name}.csv", INERTIAL, duration_s=period_s, seed=0)
    with open_generator(server.resource, testbed=INERTIAL) as fg:
        fg.upload_arbitrary(1, profile.volts, name=name, frequency_hz=profile.frequency_hz)
        fg.set_output(1, True)                  # the profile starts on the next period
        ticks = int((settle_s + period_s) * 1200)
        for done in range(6000, ticks + 1, 6000):
            dev.run_ticks(6000)
            wait_for(lambda: sum(map(len, base)) >= done, timeout=20)
    assert not server.generator.channels[1].on  # closing switched it off
    angle = np.concatenate(base)[int(settle_s * 1200):ticks]   # one whole period, settled
    check = check_base_motion(angle, 1200.0, profile)
    assert check.within(0.10), check.summary()
    assert check.achieved_rms_rad == pytest.approx(TARGETS[name], rel=0.10)
    curves = csp_curves(check)
    assert curves.frequency_hz.shape == curves.target_csp_rad2.shape == curves.achieved_csp_rad2.shape
    assert curves.target_cumulative_rms_rad[-1] == pytest.approx(TARGETS[name], rel=1e-3)
    assert "mrad achieved" in check.summary()


# ------------------------------------------------------------------ the command line


@pytest.fixture
def fg_server():
    srv = ScpiServer(SimulatedGenerator()).start()
    yield srv
    srv.stop()


def test_cli_upload_to_a_generator(fg_server, capsys):
    g = fg_server.generator
    rc = main(["fg", "upload", "--resource", fg_server.resource, "--profile",
               str(BM_DIR / "BM1.csv"), "--duration", "20", "--seed", "2"])
    out = capsys.readouterr().out
    assert rc == 0 and "uploaded BM1 to channel 1: 16384 points" in out
    assert g.channels[1].waveform == "ARB" and g.channels[1].arb_name == "BM1"
    assert g.channels[1].frequency_hz == pytest.approx(0.05) and not g.channels[1].on
    expected = load_profile(BM_DIR / "BM1.csv", INERTIAL, duration_s=20, seed=2)
    assert g.channels[1].amplitude_vpp == pytest.approx(expected.amplitude_vpp)


def test_cli_refusals_exit_non_zero_and_send_nothing(fg_server, tmp_path, capsys):
    g = fg_server.generator
    rc = main(["fg", "upload", "--resource", fg_server.resource, "--profile",
               str(BM_DIR / "BM1.csv"), "--rms-mrad", "10"])
    err = capsys.readouterr().err
    assert rc == 2 and err.startswith("error: ") and "fg_max_amplitude" in err
    assert not any("WVDT" in c for c in g.command_log)
    bad = tmp_path / "bad.csv"
    bad.write_text("frequency_hz,psd_rad2_per_hz\n1,x\n")
    assert main(["fg", "upload", "--resource", fg_server.resource, "--profile", str(bad)]) == 2
    assert f"{bad}:2: not a number" in capsys.readouterr().err
    for bad_args, message in ((["--seed", "-1"], "seed"), (["--duration", "-5"], "duration")):
        assert main(["fg", "upload", "--resource", fg_server.resource, "--profile",
                     str(BM_DIR / "BM2.csv"), *bad_args]) == 2
        assert message in capsys.readouterr().err
    with pytest.raises(SystemExit) as exit_:
        main(["fg", "set", "--channel", "1"])          # no --resource
    assert exit_.value.code == 2
    fg_server.stop()
    rc = main(["fg", "off", "--resource", fg_server.resource, "--timeout", "0.5"])
    assert rc == 2 and "error: cannot open" in capsys.readouterr().err


def test_cli_set_identify_list_and_off_on_a_pyvisa_sim_instrument(tmp_path, capsys):
    yaml = tmp_path / "fg.yaml"
    shutil.copyfile(YAML, yaml)
    common = ["--resource", SIM_RESOURCE, "--backend", str(yaml)]
    assert main(["fg", "list", "--backend", str(yaml)]) == 0
    assert "SIM4053B" in capsys.readouterr().out
    assert main(["fg", "identify", *common]) == 0
    assert "4053B" in capsys.readouterr().out
    rc = main(["fg", "set", *common, "--channel", "2", "--waveform", "sine", "--frequency", "2",
               "--amplitude", "0.5", "--offset", "0", "--output", "on", "--hold", "0"])
    out = capsys.readouterr().out
    assert rc == 0 and "C2: SINE, f 2 Hz, amp 0.5 Vpp" in out and "switched off" in out
    rc = main(["fg", "set", *common, "--amplitude", "2.5"])
    assert rc == 2 and "nothing was sent" in capsys.readouterr().err
    assert main(["fg", "off", *common]) == 0
    assert "output off" in capsys.readouterr().out


def test_cli_upload_to_the_simulated_testbed(capsys):
    rc = main(["fg", "upload", "--resource", "sim", "--profile", str(BM_DIR / "BM3.csv"),
               "--duration", "20", "--output", "on", "--hold", "0"])
    out = capsys.readouterr().out
    assert rc == 0, out
    assert "started the simulated testbed" in out and "::SOCKET" in out
    assert "uploaded BM3" in out and "output ON" in out and "switched off" in out
