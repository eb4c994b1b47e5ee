"""Controller design files -> discrete sections -> a parameter table, and the loop checks
made before a table is sent (groundstation.params.design_file, discretise, loop)."""

from __future__ import annotations

import dataclasses
import math
import re
from pathlib import Path

import numpy as np
import pytest

from groundstation.cli.main import main
from groundstation.params import table as ptable
from groundstation.params.tf_algebra import CONTROL_RATE_HZ, DesignError, TransferFunction
from groundstation.params.discretise import (bilinear_rate_hz, cascade_match, discretisation_match,
                                             discretise, discretise_design, section_responses,
                                             sos_response)
from groundstation.params.design_file import load_design, table_values
from groundstation.params.loop import validate
from groundstation.params.loop_response import loop_model
from groundstation.params.loop_response import bode
from groundstation.plant.model import plant_transfer_functions

ROOT = Path(__file__).resolve().parents[2]
CONTROLLERS = ROOT / "profiles" / "controllers"
TESTBEDS = ROOT / "profiles" / "testbeds"
DESIGNS = ("relative_design1", "relative_design2", "inertial_design1", "inertial_design2")
ALL_FILES = DESIGNS + tuple(f"{d}_friction_comp" for d in DESIGNS)


@pytest.fixture(scope="module")
def designs():
    return {name: load_design(CONTROLLERS / f"{name}.toml") for name in ALL_FILES}


@pytest.fixture(scope="module")
def reports(designs, dictionary):
    return {name: validate(designs[name], dictionary=dictionary) for name in DESIGNS}


def roots(*factors):
    return np.sort_complex(TransferFunction.from_factors(1.0, factors).zeros)


def same_roots(a, b, rtol=1e-12):
    a, b = np.sort_complex(np.asarray(a)), np.sort_complex(np.asarray(b))
    return a.shape == b.shape and np.allclose(a, b, rtol=rtol, atol=1e-12)


# ======================================================================================
# the thesis designs as files
# ======================================================================================
@pytest.mark.parametrize("name", ALL_FILES)
def test_each_thesis_design_loads_with_its_testbed_gains_and_limits(designs, name):
    d = designs[name]
    assert d.mode == name.split("_")[0]
    assert d.testbed.path.name == f"{d.mode}_2dof.toml"
    assert (d.saturation_coarse_in_oz, d.saturation_fine_in_oz) == (81.3, 16.1)
    assert d.outer_loop_gain_per_s == (25.0 if d.mode == "inertial" else None)
    assert d.friction.enabled == name.endswith("_friction_comp")
    assert d.c2.order == 0 and d.c2.gain == 1.0 and d.q is d.c1      # c1' = Q, c2' = 1


def test_the_factors_are_the_references(designs):
    """Spot checks of testbed.md §6, factor by factor."""
    r2 = designs["relative_design2"]
    assert r2.c0.gain == 30801 and same_roots(r2.c0.zeros, roots([36.28], [25.92, 8.61e4]))
    assert same_roots(r2.c0.poles, roots([108.8], [410.8, 8.61e4]))
    assert r2.q.gain == 2834.4 and same_roots(r2.q.poles, roots([0], [1283], [314.2], [377.2, 7.26e4]))
    assert r2.q.integrators == 1
    r1 = designs["relative_design1"]
    assert r1.q.gain == 13.928 and same_roots(r1.q.zeros, [-60.27, -60.27])
    assert same_roots(r1.q.poles, [-839.5, -839.5])
    i1 = designs["inertial_design1"]
    assert i1.c0.gain == 117.14 and i1.c0.integrators == 1
    assert same_roots(i1.c0.zeros, roots([100], [234.5], [234.5], [15.62], [11.15, 1.96e4]))
    assert same_roots(i1.q.zeros, [-16.84, -16.84]) and i1.q.gain == 7.062
    i2 = designs["inertial_design2"]
    assert i2.q.gain == 674.3 and same_roots(i2.q.zeros, roots([50.27], [21.02], [85.53, 2258]))
    assert "(s+234.5)^2" in i1.c0.text() and i1.c0.text().startswith("117.14(s+100)")


def test_friction_variants_differ_from_their_designs_only_in_friction_settings(designs, dictionary):
    for name in DESIGNS:
        plain = table_values(designs[name], dictionary=dictionary)
        comp = table_values(designs[f"{name}_friction_comp"], dictionary=dictionary)
        changed = {k for k in plain if plain[k] != comp[k]}
        assert "friction_comp_enabled" in changed
        assert all(k.startswith("friction_comp_") for k in changed), (name, changed)
        assert comp["friction_comp_enabled"] == 1 and comp["friction_comp_model"] == 3   # DB-DHM
        assert (comp["friction_comp_sigma"], comp["friction_comp_coulomb"]) == (5730.0, 2.25)
        assert comp["friction_comp_table_points"] == 12 and comp["friction_comp_table_x"][11] == 2.0


# ======================================================================================
# output-equivalent c0
# ======================================================================================
@pytest.mark.parametrize("name, partner", [("relative_design1", "relative_design2"),
                                           ("inertial_design2", "inertial_design1")])
def test_output_equivalent_c0_gives_the_partners_loop_gain(designs, name, partner):
    b, a = designs[name], designs[partner]
    (n1, den), (n2, _) = plant_transfer_functions(b.testbed)
    s = 2j * np.pi * np.logspace(-2, math.log10(600), 400)
    g1, g2 = np.polyval(n1, s) / np.polyval(den, s), np.polyval(n2, s) / np.polyval(den, s)
    # inertial: the rate loop multiplies both by s (and the gyro model); the ratio is the same
    out = s if b.mode == "inertial" else 1.0
    L_a = a.c0.response(s) * (a.q.response(s) * g1 + g2) * out
    L_b = b.c0.response(s) * (b.q.response(s) * g1 + g2) * out
    assert np.max(np.abs(L_b / L_a - 1)) < 1e-9
    assert b.c0_equivalent_to == a.path and b.c0_order == 12
    assert b.c0.order == 12 and any("order 12" in n for n in b.notes)


def test_output_equivalent_c0_cancels_the_common_factors(designs):
    # inertial #2: c0_1's (s+234.5)^2 against Q1's poles, and c0_1's integrator against Q2's
    i2 = designs["inertial_design2"]
    assert "cancelling 3 pole/zero pair(s)" in i2.notes[0]
    assert i2.c0.integrators == 0 and not np.any(np.isclose(i2.c0.zeros, -234.5))
    # relative #1 takes Q2's integrator into c0
    assert designs["relative_design1"].c0.integrators == 1


# ======================================================================================
# discretisation
# ======================================================================================
@pytest.mark.parametrize("name", DESIGNS)
def test_discretisation_is_exactly_the_prewarped_bilinear_map(designs, name):
    """The sections are the Tustin map and nothing else: the discrete response at f is the
    continuous one at the warped frequency 2 fs' tan(pi f / fs) / (2 pi), to rounding."""
    d = designs[name]
    fs_map = bilinear_rate_hz(CONTROL_RATE_HZ, d.prewarp_hz)
    f = np.linspace(0.01, 0.45 * CONTROL_RATE_HZ, 3000)
    warped = 2 * fs_map * np.tan(np.pi * f / CONTROL_RATE_HZ)
    for cascade in discretise_design(d).values():
        tf = d.cascades[cascade.name]
        got = sos_response(cascade.sos, np.exp(2j * np.pi * f / CONTROL_RATE_HZ))
        assert np.max(np.abs(got / tf.response(1j * warped) - 1)) < 1e-9, cascade.name
        assert np.all(cascade.sos[:, 3] == 1.0)
        poles = np.concatenate([np.roots(row[3:]) for row in cascade.sos if np.any(row[4:])] or [[]])
        assert np.sum(np.abs(poles - 1) < 1e-12) == tf.integrators == cascade.integrators
        assert np.all((np.abs(poles) < 1 - 1e-9) | (np.abs(poles - 1) < 1e-12))


def test_the_gain_is_shared_equally_across_sections(designs):
    sos = discretise_design(designs["relative_design1"])["c0"].sos
    mags = np.abs(section_responses(sos, np.exp(2j * np.pi * 10.0 / CONTROL_RATE_HZ)))
    assert sos.shape[0] == 6 and np.allclose(mags, mags[0], rtol=1e-12)


@pytest.mark.parametrize("name", DESIGNS)
def test_discrete_controllers_match_the_continuous_designs_within_1pct_1deg(designs, reports, name):
    """1 % / 1 deg holds up to 50 Hz for every design, and to 100 Hz for inertial #1.

    Beyond that the bilinear map itself is the limit, not the implementation (the test
    above shows it is exact): the discrete response at f is the continuous one at a
    frequency 1.8-2.3 % higher at 100 Hz, so a controller whose gain or phase changes
    there (relative #1's Q rises as (s+60.27)^2/(s+839.5)^2, slope about +1.3) is off by
    that much times its slope, and no pre-warp frequency removes it across a band
    (next test).  What the error does to the closed loop is small for the relative
    designs, whose loops cross over at 10 Hz (checked here)."""
    d = designs[name]
    match = discretisation_match(d, band_hz=50.0)
    for path, err in match.paths.items():
        assert err.within(1.0, 1.0), (path, err.text())
    if name == "inertial_design1":
        assert discretisation_match(d).worst.within(1.0, 1.0)
    if d.mode == "relative":
        assert reports[name].match.closed_loop.within(1.0, 1.0), reports[name].match.closed_loop


def test_no_prewarp_frequency_brings_relative_design1_Q_within_1pct_up_to_100hz(designs):
    q = designs["relative_design1"].q
    worst = min(cascade_match(q, discretise(q, prewarp_hz=f)).magnitude_pct
                for f in np.arange(5.0, 101.0, 5.0))
    assert 1.5 < worst < 2.0          # the best (about 70 Hz) is still 1.6 %


def test_prewarping_at_the_notch_keeps_it_on_the_flexure_mode(designs, dictionary):
    """Plain Tustin moves relative #2's 46.7 Hz notch by 0.5 %, which leaves a 6 deg / 6 %
    ripple where it cancels the lightly damped flexure mode; validation says so."""
    plain = dataclasses.replace(designs["relative_design2"], prewarp_hz=None)
    c0 = discretisation_match(plain).cascades["c0"]
    assert c0.phase_deg > 5 and abs(c0.phase_at_hz - 46.7) < 1
    report = validate(plain, dictionary=dictionary)
    assert report.ok and any("prewarp_hz" in w for w in report.warnings)
    assert discretisation_match(designs["relative_design2"]).cascades["c0"].phase_deg < 1


# ======================================================================================
# table values
# ======================================================================================
@pytest.mark.parametrize("name", ALL_FILES)
def test_table_values_pass_the_devices_rules_and_pack(designs, dictionary, name):
    d = designs[name]
    values = table_values(d, dictionary=dictionary)
    assert ptable.problems(dictionary, values) == []
    assert len(ptable.pack(dictionary, values)) == ptable.table_size(dictionary)
    rows = dict((p.name, p.shape) for p in dictionary.parameters)[f"{d.mode}_c0"][0]
    c0 = np.asarray(values[f"{d.mode}_c0"])
    used = discretise_design(d)["c0"].sections
    assert c0.shape == (rows, 6) and np.all(c0[used:] == [1, 0, 0, 1, 0, 0])
    other = "inertial" if d.mode == "relative" else "relative"
    assert values[f"{other}_c0"] == ptable.default_values(dictionary)[f"{other}_c0"]


def test_table_values_keep_everything_else_from_the_base_table(designs, dictionary):
    base = table_values(designs["inertial_design1"], dictionary=dictionary)
    base["watchdog_timeout"] = 2.5
    base["complementary_crossover"] = 1.0
    values = table_values(designs["relative_design2"], base=base, dictionary=dictionary)
    assert values["watchdog_timeout"] == 2.5 and values["complementary_crossover"] == 1.0
    assert values["inertial_c0"] == base["inertial_c0"] and values["outer_loop_gain"] == 25.0
    assert values["relative_c0"] != base["relative_c0"]
    with pytest.raises(DesignError, match="does not know"):
        table_values(designs["relative_design2"], base={**base, "bogus": 1}, dictionary=dictionary)


# ======================================================================================
# validation of the thesis designs
# ======================================================================================
@pytest.mark.parametrize("name", ["relative_design1", "relative_design2"])
def test_relative_designs_are_stable_with_positive_margins(reports, name):
    r = reports[name]
    assert r.ok and r.problems == [] and r.warnings == []
    assert r.max_pole_radius < 0.99
    assert r.margins.gain_margin_db > 20 and 30 < r.margins.phase_margin_deg < 40
    assert r.margins.crossover_hz == pytest.approx(10.2, abs=0.1)
    assert r.controller_pole_radius < 1


@pytest.mark.parametrize("name", ["inertial_design1", "inertial_design2"])
def test_inertial_designs_are_refused_on_the_testbed_model_with_the_gyro_delay(
        designs, reports, dictionary, name):
    """A finding, not a wish: on inertial_2dof.toml's model the rate loop has under 10 deg
    of phase margin at the flexure mode (22.8 Hz), where c0's notch leaves a peak of the
    loop gain and the gyro (150 Hz, 2.6 ms as the reference's T_d with the hold included)
    and the hold take about 34 deg; the position loop's K_p = 25 costs the last 10 deg
    (K_p/omega at 22.8 Hz).  The closed loop then grows by e in about 13 s: the damping of
    the reference's own continuous loop (benchmarks/inertial_loop.py, docs/fidelity.md H4).
    The simulator agrees (test_the_loop_model_reproduces_the_simulated_testbed).  With
    K_p <= 10 it is stable."""
    r = reports[name]
    assert not r.ok and len(r.problems) == 1
    assert "closed loop is unstable" in r.problems[0] and "22.8 Hz" in r.problems[0]
    assert 1.0 < r.max_pole_radius < 1.0002
    assert r.inner_margins.gain_margin_db > 10 and 8 < r.inner_margins.phase_margin_deg < 11
    assert r.margins.phase_margin_deg < 0
    assert 4.5 < r.outer_margins.gain_crossovers_hz[0] < 5.0        # the reference's ~5 Hz
    values = table_values(designs[name], dictionary=dictionary)
    values["outer_loop_gain"] = 10.0
    slower = validate(designs[name], values, dictionary)
    # stable, but not by much: refused as marginal (sent only with the margins accepted)
    assert not slower.ok and slower.problems == [] and slower.marginal
    assert slower.max_pole_radius < 1 and slower.margins.phase_margin_deg > 0


@pytest.mark.parametrize("name, seconds", [("relative_design2", 1.0), ("inertial_design1", 2.0)])
def test_the_loop_model_reproduces_the_simulated_testbed(designs, dictionary, tmp_path, name, seconds):
    """Step of the reference on the simulator (friction viscous, sensor noise off) against
    the closed-loop state matrix that validation uses: same to the sensors' quantisation."""
    from groundstation.sim import core
    from groundstation.sim.engine import Engine
    from groundstation.plant.testbed import load_testbed

    d = designs[name]
    text = d.testbed.path.read_text()
    for key in ("encoder_noise", "gyro_arw", "gyro_bias_stability", "autocollimator_noise"):
        text = "\n".join(f"{key} = 0.0" if ln.startswith(f"{key} ") else ln for ln in text.splitlines())
    # the loop model is linear: friction viscous and no bearing ripple in the simulator
    linear = re.sub(r"(?m)^amplitude = [0-9.]+", "amplitude = 0.0", text.replace('model = "DB-DHM"', 'model = "viscous"'))
    (tmp_path / "tb.toml").write_text(linear)
    tb = load_testbed(tmp_path / "tb.toml")
    values = table_values(d, dictionary=dictionary)
    engine = Engine(tb, values)
    engine.run(1)
    step = 1e-4                                    # rad: small enough not to saturate
    fw = engine.fw
    fw[core.FW_MODE] = core.MODE_RELATIVE if d.mode == "relative" else core.MODE_INERTIAL
    fw[core.FW_ARMED], fw[core.FW_REF] = 1.0, step
    engine.reset_controllers()
    n = int(seconds * CONTROL_RATE_HZ)
    _, truth, _ = engine.run(n)

    lm = loop_model(dataclasses.replace(d, testbed=tb), values, dictionary)
    M, m = lm.loop.closed_loop(lm.c0, lm.c1, lm.c2)
    x, predicted = np.zeros(len(m)), np.empty(n)
    for k in range(n):
        predicted[k] = lm.loop.c_angle @ x[:len(lm.loop.c_angle)]
        x = M @ x + m * step
    assert np.max(np.abs(truth[:, 1] - predicted)) < 2e-4 * step     # theta2, the LOS


def test_bode_data_carries_the_margins_of_the_report(designs, reports):
    b = bode(designs["relative_design2"])
    assert b.freqs_hz[-1] < 600 and b.response.shape == b.freqs_hz.shape
    assert b.margins == reports["relative_design2"].margins
    i = np.argmin(np.abs(b.freqs_hz - b.margins.crossover_hz))
    assert abs(b.magnitude_db[i]) < 0.5


# ======================================================================================
# refusals
# ======================================================================================
def write_design(path: Path, c0: str = "", *, mode="relative", extra="", q=None, design_extra=""):
    testbed = TESTBEDS / f"{mode}_2dof.toml"
    c0 = c0 or "gain = 30801.0\nnumerator = [[36.28], [25.92, 8.61e4]]\ndenominator = [[108.8], [410.8, 8.61e4]]"
    q = q if q is not None else ("[Q]\ngain = 2834.4\nnumerator = [[94.25], [39.88], [237.1, 2.87e4]]\n"
                                 "denominator = [[0], [1283], [314.2], [377.2, 7.26e4]]\n")
    kp = "outer_loop_gain_per_s = 25.0\n" if mode == "inertial" else ""
    path.write_text(f'[design]\nname = "test"\nmode = "{mode}"\ntestbed = "{testbed}"\n{kp}{design_extra}\n'
                    f"[saturation]\ncoarse_in_oz = 81.3\nfine_in_oz = 16.1\n\n"
                    f"[friction_compensation]\nenabled = false\n\n[c0]\n{c0}\n\n{q}\n{extra}")
    return path


def test_a_fixture_copy_of_relative_design2_is_accepted(tmp_path, dictionary):
    assert validate(load_design(write_design(tmp_path / "ok.toml")), dictionary=dictionary).ok


def test_a_loop_gain_100_times_too_high_is_refused(tmp_path, dictionary):
    d = load_design(write_design(tmp_path / "hot.toml", "gain = 3080100.0\nnumerator = [[36.28], "
                                 "[25.92, 8.61e4]]\ndenominator = [[108.8], [410.8, 8.61e4]]"))
    r = validate(d, dictionary=dictionary)
    assert not r.ok and r.max_pole_radius > 1
    assert any("closed loop is unstable" in p and "lower the loop gain" in p for p in r.problems)


def test_an_unstable_controller_pole_is_refused(tmp_path, dictionary):
    # (s - 10) in c0's denominator: a pole at s = +10 rad/s, z = 1.0084
    d = load_design(write_design(tmp_path / "rhp.toml", "gain = 30801.0\nnumerator = [[36.28]]\n"
                                 "denominator = [[-10.0]]"))
    r = validate(d, dictionary=dictionary)
    assert not r.ok
    assert any("relative_c0" in p and "controller itself is unstable" in p and "s = +10" in p
               for p in r.problems)
    assert ptable.problems(dictionary, r.values)            # the device would refuse it too


def test_saturation_above_the_motor_peak_is_refused(tmp_path, dictionary):
    path = write_design(tmp_path / "sat.toml")
    path.write_text(path.read_text().replace("fine_in_oz = 16.1", "fine_in_oz = 20.0"))
    r = validate(load_design(path), dictionary=dictionary)
    assert not r.ok and any("saturation_fine" in p and "peak torque 16.1" in p for p in r.problems)


@pytest.mark.parametrize("entry", ["relative_c0", "relative_c2", "outer_loop_gain"])
def test_a_nan_in_the_table_is_refused(designs, dictionary, entry):
    values = table_values(designs["relative_design2"], dictionary=dictionary)
    if entry == "outer_loop_gain":
        values[entry] = math.nan
    else:
        values[entry][3][1] = math.nan                # an unused (identity) row counts as well
    r = validate(designs["relative_design2"], values, dictionary)
    assert not r.ok and any(entry in p and "not finite" in p for p in r.problems)
    assert r.margins is None                           # no analysis of a broken table


def test_a_nan_in_the_design_file_is_a_design_error(tmp_path):
    with pytest.raises(DesignError, match=r"c0\.gain = nan"):
        load_design(write_design(tmp_path / "nan.toml", "gain = nan"))
    with pytest.raises(DesignError, match=r"Q\.numerator\[1\]"):
        load_design(write_design(tmp_path / "nan2.toml", q="[Q]\ngain = 1.0\nnumerator = [[1.0], [nan]]\n"))


# ======================================================================================
# malformed files
# ======================================================================================
@pytest.mark.parametrize("edit, message", [
    (lambda t: t.replace('mode = "relative"\n', ""), r"design\.mode is missing"),
    (lambda t: t.replace("fine_in_oz = 16.1\n", ""), r"saturation\.fine_in_oz is missing"),
    (lambda t: t.replace("gain = 30801.0", 'gain = "big"'), r"c0\.gain = 'big'"),
    (lambda t: t.replace("[[36.28], [25.92", "[[36.28, 1, 2], [25.92"), r"c0\.numerator\[0\]"),
    (lambda t: t.replace('mode = "relative"', 'mode = "absolute"'), r"allowed: \"relative\""),
    (lambda t: t.replace("relative_2dof.toml", "nowhere.toml"), r"design\.testbed: .*nowhere\.toml"),
    (lambda t: t.replace("enabled = false", "enabled = 1"), r"friction_compensation\.enabled"),
    (lambda t: t.replace("[saturation]", "[saturation]\ncoarse = 1"), r"unknown key.*coarse'"),
    (lambda t: t.replace("denominator = [[108.8], [410.8, 8.61e4]]", ""), r"c0 has 3 zeros and 0 poles"),
    (lambda t: t + "\n[c1]\ngain = 1.0\n", r"either \[Q\].*or both \[c1\] and \[c2\]"),
    (lambda t: t.replace("[c0]", "[c00]"), r"unknown key.*c00"),
    (lambda t: t.replace('mode = "relative"', 'mode = "inertial"'), r"needs a testbed with a gyro"),
])
def test_a_malformed_design_names_the_field(tmp_path, edit, message):
    path = write_design(tmp_path / "bad.toml")
    path.write_text(edit(path.read_text()))
    with pytest.raises(DesignError, match=message) as err:
        load_design(path)
    assert str(err.value).startswith(str(path))


def test_missing_and_unparsable_files(tmp_path):
    with pytest.raises(DesignError, match="design file not found"):
        load_design(tmp_path / "none.toml")
    (tmp_path / "broken.toml").write_text("[design\n")
    with pytest.raises(DesignError, match="malformed TOML"):
        load_design(tmp_path / "broken.toml")


def test_a_cycle_of_equivalent_to_is_refused(tmp_path):
    write_design(tmp_path / "a.toml", 'equivalent_to = "b.toml"')
    write_design(tmp_path / "b.toml", 'equivalent_to = "a.toml"')
    with pytest.raises(DesignError, match=r"cycle \(a\.toml -> b\.toml -> a\.toml\)") as err:
        load_design(tmp_path / "a.toml")
    assert "c0.equivalent_to" in str(err.value)
    write_design(tmp_path / "self.toml", 'equivalent_to = "self.toml"')
    with pytest.raises(DesignError, match="cycle"):
        load_design(tmp_path / "self.toml")


def test_a_cycle_of_base_files_is_refused(tmp_path):
    (tmp_path / "a.toml").write_text('base = "b.toml"\n')
    (tmp_path / "b.toml").write_text('base = "a.toml"\n')
    with pytest.raises(DesignError, match=r"base 'b\.toml'.*cycle"):
        load_design(tmp_path / "a.toml")


def test_equivalent_to_a_design_of_the_other_mode_or_a_broken_one(tmp_path):
    write_design(tmp_path / "rel.toml", f'equivalent_to = "{CONTROLLERS / "inertial_design1.toml"}"')
    with pytest.raises(DesignError, match="names a design for inertial mode"):
        load_design(tmp_path / "rel.toml")
    write_design(tmp_path / "partner.toml", "gain = nan")
    write_design(tmp_path / "eq.toml", 'equivalent_to = "partner.toml"')
    with pytest.raises(DesignError, match=r"eq\.toml: c0\.equivalent_to 'partner\.toml': .*c0\.gain"):
        load_design(tmp_path / "eq.toml")


def test_a_base_file_is_overridden_key_by_key_and_transfer_functions_whole(tmp_path):
    write_design(tmp_path / "base.toml", design_extra="prewarp_hz = 46.7\n")
    (tmp_path / "sub").mkdir()
    (tmp_path / "sub" / "fast.toml").write_text(
        'base = "../base.toml"\n[design]\nname = "faster"\n[Q]\ngain = 13.928\n'
        "numerator = [[60.27], [60.27]]\ndenominator = [[839.5], [839.5]]\n")
    d = load_design(tmp_path / "sub" / "fast.toml")
    assert d.name == "faster" and d.prewarp_hz == 46.7 and d.mode == "relative"
    assert d.q.gain == 13.928 and d.q.integrators == 0 and d.c0.gain == 30801.0


# ======================================================================================
# command line
# ======================================================================================
def test_cli_validate_accepts_a_good_design(capsys):
    assert main(["params", "validate", str(CONTROLLERS / "relative_design2.toml")]) == 0
    out = capsys.readouterr().out
    assert "Relative Design #2" in out and "OK" in out and "phase margin" in out
    assert "c0:       order 3, 2 section(s)" in out and "closed-loop max |z| = 0.98" in out


def test_cli_validate_refuses_an_unstable_design(capsys):
    assert main(["params", "validate", str(CONTROLLERS / "inertial_design1.toml")]) == 1
    out = capsys.readouterr().out
    assert "REFUSED" in out and "problem:  the closed loop is unstable" in out


def test_cli_validate_reports_an_unreadable_file(tmp_path, capsys):
    path = write_design(tmp_path / "bad.toml", "gain = true")
    assert main(["params", "validate", str(path)]) == 2
    err = capsys.readouterr().err
    assert err.startswith(f"error: {path}: c0.gain = True")
    assert main(["params", "validate", str(tmp_path / "none.toml")]) == 2
    assert "none.toml: design file not found" in capsys.readouterr().err


def test_a_design_that_commands_no_torque_leaves_the_axis_free(tmp_path, dictionary):
    d = load_design(write_design(tmp_path / "zero.toml", "gain = 0.0"))
    r = validate(d, dictionary=dictionary)
    assert not r.ok and r.margins.crossover_hz is None and math.isinf(r.margins.gain_margin_db)
    assert "closed loop is unstable" in r.problems[0] and "z = 1 (0 Hz)" in r.problems[0]


# ----------------------------------------------------------------- anti-windup of a design
def test_a_design_runs_its_filters_through_saturation_unless_it_asks_for_conditional_integration(
        tmp_path, designs, dictionary):
    """The reference's controller is the designs plus the motors' limits (testbed.md §6):
    every shipped design leaves anti-windup off; a design file may ask for the device's
    conditional integration, and a misspelt choice is refused with the words allowed."""
    for name, design in designs.items():
        assert design.anti_windup == "none", name
        assert table_values(design, dictionary=dictionary)["anti_windup"] == 0, name
    text = (CONTROLLERS / "relative_design2.toml").read_text()
    frozen = tmp_path / "frozen.toml"
    frozen.write_text(text.replace("[saturation]", '[saturation]\nanti_windup = "conditional_integration"')
                      .replace('"../testbeds/', f'"{ROOT}/profiles/testbeds/'))
    assert table_values(load_design(frozen), dictionary=dictionary)["anti_windup"] == 1
    frozen.write_text(frozen.read_text().replace('"conditional_integration"', '"freeze"'))
    with pytest.raises(DesignError, match="saturation.anti_windup must be one of 'none', "
                                          "'conditional_integration', got 'freeze'"):
        load_design(frozen)
