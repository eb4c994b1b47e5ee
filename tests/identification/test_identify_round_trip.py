"""`groundstation identify` on a hidden rig: a testbed file with parameters moved away
from the reference's runs as the simulated rig, the shipped open-loop excitation
profiles are recorded on it (shortened), and `identify` - starting from the reference's
file, as a lab would - must find the moved values again and write a testbed file that
loads everywhere.  One relative and one inertial 2-DOF rig.

Tolerances: on the twin, whose bearing has Dahl friction the linear plant leaves out,
the fit is biased by under 1 % for the inertias, the flexure and the fine motor
(docs/identification.md, measured); 3 % is asserted.  The relative rig's friction
(T_c +20 %, b_f x1.5, a steeper slope table) is identified from a hysteresis triangle
and constant-velocity passes: T_c and b_f came out within 0.05 %, the table within
8 % over its first tenth of the swing and 3 % beyond (measured); 1 %, 2 % and 12 % / 5 %
are asserted.  On the inertial rig no friction log is given: b_f is fitted as an
effective damping from the responses and not written (pipeline.py)."""

from __future__ import annotations

import json
import re
from pathlib import Path

import numpy as np
import pytest

from groundstation import Testbed
from groundstation.cli.main import main
from identification_helpers import record_sysid_logs
from groundstation.plant.slope_table import load_slope_table
from groundstation.plant.testbed import load_testbed
from groundstation.profiles.profile import profile_from_dict

ROOT = Path(__file__).resolve().parents[2]
WAVEFORMS = ROOT / "profiles/waveforms"
RECORD_S = 8.0

#: (base file, {key: factor}) of each hidden rig; keys as 'section.key'
RIGS = {
    "relative": ("relative_2dof.toml", {"mechanics.J1": 1.08, "mechanics.flexure_stiffness": 0.88,
                                        "mechanics.flexure_damping": 2.0,
                                        "motor_fine.torque_constant": 0.95,
                                        "mechanics.bearing_viscous": 1.5,
                                        "friction.coulomb_torque": 1.2}),
    "inertial": ("inertial_2dof.toml", {"mechanics.J2": 0.93, "mechanics.flexure_stiffness": 1.1,
                                        "mechanics.flexure_damping": 1.5,
                                        "sensors.gyro_delay": 1.12}),
}


#: the hidden relative rig's bearing: the shipped table's shape bent (steeper at the
#: reversal, shallower late), so that identify cannot find it by keeping the base's
def hidden_slope_table(folder: Path) -> Path:
    rows = [line.split(",") for line in (ROOT / "profiles/friction_slope_lut.csv").read_text()
            .splitlines() if line and line[0].isdigit()]
    out = folder / "hidden_slope_table.csv"
    out.write_text("x,slope_ratio\n" + "".join(
        f"{float(x)!r},{float(f) * 0.8 * (1.3 - 0.15 * float(x))!r}\n" for x, f in rows))
    return out


def hidden_file(base: Path, factors: dict[str, float], folder: Path) -> Path:
    """The base file's text with the factors applied: the rig nobody tells `identify`."""
    text, section = [], ""
    for line in base.read_text().splitlines():
        header = re.match(r"^\[([a-z_]+)\]", line)
        section = header.group(1) if header else section
        m = re.match(r"^([A-Za-z_0-9]+) = ([0-9.e+-]+)", line)
        if m and f"{section}.{m.group(1)}" in factors:
            value = float(m.group(2)) * factors[f"{section}.{m.group(1)}"]
            line = f"{m.group(1)} = {value!r}"
        elif line.startswith("slope_table = "):
            line = f'slope_table = "{hidden_slope_table(folder).as_posix()}"'
        text.append(line)
    out = folder / f"hidden_{base.name}"
    out.write_text("\n".join(text) + "\n")
    return out


@pytest.fixture(scope="module", params=sorted(RIGS))
def rig(request, tmp_path_factory):
    base_name, factors = RIGS[request.param]
    folder = tmp_path_factory.mktemp(f"identify_{request.param}")
    base = ROOT / "profiles/testbeds" / base_name
    hidden = hidden_file(base, factors, folder)
    logs = record_sysid_logs(hidden, folder, RECORD_S)
    if request.param == "relative":
        logs += friction_logs(hidden, folder)
    return {"base": base, "hidden": load_testbed(hidden), "factors": factors, "logs": logs,
            "folder": folder}


#: a hysteresis triangle (+-0.05 deg at 0.01 deg/s, two cycles: 40 s of device time, 10x
#: the reference's speed, still quasi-static) and two of the shipped velocity ramps
TRIANGLE = {"profile": {"name": "friction_triangle_test", "target": "REFERENCE", "units": "rad",
                        "origin": "relative"},
            "generator": {"type": "triangle", "amplitude_deg": 0.05, "velocity_deg_per_s": 0.01,
                          "cycles": 2, "turnaround_s": 0.5}}


def friction_logs(hidden: Path, folder: Path) -> list[Path]:
    """The friction campaigns' kind of log, in closed loop with relative Design #2."""
    logs = []
    for name, profile in (("triangle", profile_from_dict(TRIANGLE)),
                          ("ramp_1dps", WAVEFORMS / "velocity_ramp_1dps.toml"),
                          ("ramp_10dps", WAVEFORMS / "velocity_ramp_10dps.toml")):
        with Testbed("sim", testbed=hidden, fast=True, generator=None, log_folder=folder / "logs",
                     history=folder / "history") as tb:
            tb.upload_design(ROOT / "profiles/controllers/relative_design2.toml",
                             accept_risk="marginal on the hidden rig; a friction record in a test")
            logs.append(tb.start_recording(name))
            tb.play(profile)
            tb.stop_recording()
    return logs


def standard_deviation(row: dict) -> float:
    """The estimate's standard deviation from its 95 % interval (symmetric in the value's
    own units for an offset, in its logarithm for the others: the half-width is the same
    to first order)."""
    lo, hi = row["ci95"]
    return (hi - lo) / (2 * 1.959964)


def test_identify_finds_the_hidden_rig_and_writes_a_file_that_loads(rig, capsys):
    out = rig["folder"] / "my_rig.toml"
    report = rig["folder"] / "identify.json"
    status = main(["identify", *map(str, rig["logs"]), "--testbed", str(rig["base"]),
                   "--out", str(out), "--json", str(report)])
    text = capsys.readouterr().out
    assert status == 0, text
    assert f"written: {out.resolve()}" in text
    figures = {p["name"]: p for p in json.loads(report.read_text())["parameters"]}
    identified = load_testbed(out)
    hidden = rig["hidden"]
    for name in rig["factors"]:
        section, key = name.split(".")
        truth = float(getattr(hidden, section)[key])
        row = figures[name]
        assert row["status"] == "identified", row
        assert row["value"] == pytest.approx(truth, rel=0.03), row
        # the fit's bias measured on a twin of the result and taken out, the error is the
        # noise the interval states (without the correction J2, k, b and K_t2 were
        # 0.6-0.7 % off with intervals of +-0.1 %).  Asserted at 3.29 sd (99.9 %): with
        # a dozen parameters checked, one outside its 95 % interval is to be expected
        assert abs(row["value"] - truth) <= 3.29 * standard_deviation(row), row
        assert getattr(identified, section)[key] == pytest.approx(row["value"], rel=1e-6)
    # what was not moved comes back close to the reference's value
    assert figures["mechanics.J1" if "mechanics.J1" not in rig["factors"] else "mechanics.J2"][
        "value"] == pytest.approx(figures["mechanics.J1" if "mechanics.J1" not in rig["factors"]
                                          else "mechanics.J2"]["base"], rel=0.03)
    assert figures["motor_coarse.torque_constant"]["status"] == "held (scale)"
    if "friction.coulomb_torque" not in rig["factors"]:
        assert figures["mechanics.bearing_viscous"]["status"] == "held (friction)"
        assert identified.mechanics["bearing_viscous"] == hidden.mechanics["bearing_viscous"]
        assert identified.slope_table_path == (ROOT / "profiles/friction_slope_lut.csv").resolve()
    # the identified file is a testbed file like any other: the twin runs on it
    with Testbed("sim", testbed=out, fast=True, generator=None,
                 log_folder=rig["folder"] / "logs2", history=rig["folder"] / "h2") as tb:
        tb.dwell(0.1)
        assert tb.state.tick > 0                      # its telemetry arrives


@pytest.mark.parametrize("rig", ["relative"], indirect=True)
def test_the_friction_of_the_hidden_rig_is_identified(rig, capsys):
    """The friction campaigns are relative-rig campaigns: friction logs are recorded there."""
    out = rig["folder"] / "friction_rig.toml"
    report = rig["folder"] / "friction.json"
    assert main(["identify", *map(str, rig["logs"]), "--testbed", str(rig["base"]),
                 "--out", str(out), "--json", str(report)]) == 0
    text = capsys.readouterr().out
    assert "(friction: a position profile)" in text
    figures = {p["name"]: p for p in json.loads(report.read_text())["parameters"]}
    hidden, identified = rig["hidden"], load_testbed(out)
    for name, tolerance in (("friction.coulomb_torque", 0.01), ("mechanics.bearing_viscous", 0.02)):
        section, key = name.split(".")
        row = figures[name]
        assert row["status"] == "identified" and row["sources"], row
        assert row["value"] == pytest.approx(getattr(hidden, section)[key], rel=tolerance), row
        assert getattr(identified, section)[key] == pytest.approx(row["value"], rel=1e-9)
    assert figures["friction.sigma"]["status"] == "held (scale)"
    # the table is written beside the file and read from there
    assert identified.slope_table_path == (rig["folder"] / "friction_rig_slope_table.csv").resolve()
    x, f = load_slope_table(identified.slope_table_path)
    tx, tf = load_slope_table(hidden.slope_table_path)
    truth = np.interp(x, tx, tf)
    early, middle = (x < 0.15), (x >= 0.15) & (x <= 1.7)
    assert np.all(np.abs(f[early] / truth[early] - 1) < 0.12), (f[early], truth[early])
    assert np.all(np.abs(f[middle] / truth[middle] - 1) < 0.05), (f[middle], truth[middle])
    row = figures["friction.slope_table f(0)"]
    assert row["ci95"][0] <= truth[0] <= row["ci95"][1], row


def test_logs_of_another_kind_of_rig_are_refused(rig, capsys):
    other = "inertial_2dof.toml" if rig["base"].name.startswith("relative") else "relative_2dof.toml"
    out = rig["folder"] / "wrong.toml"
    status = main(["identify", *map(str, rig["logs"]), "--testbed",
                   str(ROOT / "profiles/testbeds" / other), "--out", str(out)])
    err = capsys.readouterr().err
    assert status == 1 and "identify each rig from its own logs" in err
    assert "nothing written" in err and not out.exists()


#: a short campaign: a shipped design holding the line of sight for a second
HOLD = """
[campaign]
name = "hold"
description = "A shipped design holds the LOS for a second on the identified rig"
testbed = "{testbed}"

[[setup]]
action = "connect"

[[run]]
action = "start_recording"
name = "hold"

[[run]]
action = "upload_design"
design = "{design}"
accept_risk = "the thesis design, marginal on this rig: a one-second hold in a test"

[[run]]
action = "set_mode"
mode = "{mode}"

[[run]]
action = "arm"

[[run]]
action = "dwell"
seconds = 1.0

[[run]]
action = "stop_recording"
"""
DESIGNS = {"relative": ("relative_design2.toml", "RELATIVE"),
           "inertial": ("inertial_design1.toml", "INERTIAL")}


def test_a_campaign_runs_on_the_identified_rig(rig, capsys, monkeypatch):
    """A shipped design, judged by the upload gate on the identified plant, holds the
    LOS.  Both are marginal there: the relative design's gain margin falls from 29.1 dB
    to 5.9 dB (as on the hidden rig itself), the inertial design's phase margin is 14
    deg; the campaign accepts the risk, and the gate records that it did."""
    out = rig["folder"] / "campaign_rig.toml"
    assert main(["identify", *map(str, rig["logs"]), "--testbed", str(rig["base"]),
                 "--out", str(out)]) == 0
    design, mode = DESIGNS[rig["base"].name.split("_")[0]]
    campaign = rig["folder"] / "hold.toml"
    campaign.write_text(HOLD.format(testbed=rig["base"].as_posix(), mode=mode,
                                    design=(ROOT / "profiles/controllers" / design).as_posix()))
    monkeypatch.chdir(rig["folder"])
    status = main(["campaign", "run", str(campaign), "--device", "sim", "--fast",
                   "--testbed", str(out), "--no-analysis", "--generator", "none"])
    text = capsys.readouterr().out
    assert status == 0, text
    assert "COMPLETED - 7 step(s) done, 1 run(s) complete" in text
    # the upload gate judged the design on the identified plant, not the one it names
    assert f"{design}: validated on this session's testbed campaign_rig.toml" in text
    assert "margins accepted" in text


@pytest.mark.parametrize("rig", ["relative"], indirect=True)
def test_the_identified_friction_model_retraces_the_measured_loops(rig):
    """Both friction models driven along the measured triangle from its first reversal:
    the identified one retraces the loop within 0.3 % of T_c RMS on the twin (measured),
    the base one (T_c 20 % low, the shipped table) misses it by about 7 %."""
    from groundstation.identification.pipeline import identify

    result = identify(rig["logs"], rig["base"])
    curves = result.friction.loop_curves()
    assert [c.source for c in curves] == [p.name for p in rig["logs"] if "triangle" in p.name]
    t_c = rig["hidden"].friction["coulomb_torque"]
    for c in curves:
        drawn = np.isfinite(c.identified_in_oz)
        assert np.isnan(c.identified_in_oz[0]) and drawn[-1]       # from the first reversal
        identified = np.sqrt(np.mean((c.identified_in_oz[drawn] - c.measured_in_oz[drawn]) ** 2))
        base = np.sqrt(np.mean((c.base_in_oz[drawn] - c.measured_in_oz[drawn]) ** 2))
        assert identified < 0.01 * t_c < 0.03 * t_c < base, (identified, base)


@pytest.mark.parametrize("rig", ["relative"], indirect=True)
def test_the_twin_correction_takes_out_the_linear_fit_s_friction_bias(rig, capsys):
    """Without the twin, the Dahl friction the linear fit cannot hold biases the flexure
    by about 0.7 %, several of its standard deviations; with it the error is noise."""
    rows = {}
    for flag in ([], ["--no-twin-correction"]):
        report = rig["folder"] / f"twin{len(flag)}.json"
        assert main(["identify", *map(str, rig["logs"]), "--testbed", str(rig["base"]),
                     "--json", str(report), *flag]) == 0
        rows[bool(flag)] = {p["name"]: p for p in json.loads(report.read_text())["parameters"]}
    text = capsys.readouterr().out
    assert "mechanics.flexure_stiffness: +0." in text and "bias taken out" in text
    truth = rig["hidden"].mechanics["flexure_stiffness"]
    plain, corrected = rows[True]["mechanics.flexure_stiffness"], rows[False]["mechanics.flexure_stiffness"]
    assert abs(plain["value"] - truth) > 3.29 * standard_deviation(plain)
    assert abs(corrected["value"] - truth) <= 3.29 * standard_deviation(corrected)
    assert abs(corrected["value"] / truth - 1) < 0.25 * abs(plain["value"] / truth - 1)
