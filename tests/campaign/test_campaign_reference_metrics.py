"""Each campaign's own reference metric lands in its report (campaign/reference_metrics.py,
reference_figures.py): short versions of the shipped campaigns - relative steps, open-loop
identification, a friction triangle, constant-velocity passes - run through the CLI on
the fast simulator, then their report files read back: the CSV's flat columns, the JSON's
details and summary, the text, the PNGs embedded in the page, the slope-table CSV.  The
figures are checked against the adapters called here directly, and against what the
simulator's testbed file holds (running friction T_c + b_f v, rest stiffness sigma·f(0)).
A metric that does not fit a log is that row's reference error, never an exception."""

from __future__ import annotations

import base64
import csv
import io
import json
import math
import re
import shutil
from pathlib import Path

import numpy as np
import pytest

from groundstation.campaign import read_campaign
from groundstation.cli.main import main

ROOT = Path(__file__).resolve().parents[2]
RELATIVE = ROOT / "profiles" / "testbeds" / "relative_2dof.toml"
DESIGN1 = ROOT / "profiles" / "controllers" / "relative_design1.toml"
DESIGN2 = ROOT / "profiles" / "controllers" / "relative_design2.toml"
CAMPAIGNS = ROOT / "profiles" / "campaigns"

PROFILES = {
    "step_short": '''
[profile]
name = "step_short"
target = "REFERENCE"
units = "rad"
origin = "relative"
description = "0.5 mrad step at 0.2 s, 10 ms minimum-jerk rise, back at 0.8 s"
duration_s = 1.2

[generator]
type = "step"
level_mrad = 0.5
t_step_s = 0.2
rise_s = 0.010
shape = "minimum_jerk"
return_at_s = 0.8
''',
    "noise_coarse": '''
[profile]
name = "noise_coarse"
target = "CURRENT_COARSE"
units = "A"
description = "open-loop noise 0.2 A RMS, 5-200 Hz, 4 s"
duration_s = 4.0
ramp_s = 0.2

[generator]
type = "noise"
rms_a = 0.2
f_low_hz = 5.0
f_high_hz = 200.0
seed = 3
''',
    "noise_fine": '''
[profile]
name = "noise_fine"
target = "CURRENT_FINE"
units = "A"
description = "open-loop noise 0.1 A RMS, 5-200 Hz, 4 s"
duration_s = 4.0
ramp_s = 0.2

[generator]
type = "noise"
rms_a = 0.1
f_low_hz = 5.0
f_high_hz = 200.0
seed = 4
''',
    # the bearing's friction is rate-independent: a triangle 50 x faster than the
    # reference's gives the same loop in 8 s (viscous torque 0.02 in-oz against 2.25)
    "triangle_fast": '''
[profile]
name = "triangle_fast"
target = "REFERENCE"
units = "rad"
origin = "relative"
description = "triangle +-0.05 deg at 0.05 deg/s, 2 cycles"

[generator]
type = "triangle"
amplitude_deg = 0.05
velocity_deg_per_s = 0.05
cycles = 2
turnaround_s = 0.2
''',
    "pass_2dps": '''
[profile]
name = "pass_2dps"
target = "REFERENCE"
units = "rad"
origin = "relative"
description = "constant-velocity passes at 2 deg/s over 2 deg"

[generator]
type = "constant_velocity"
velocity_deg_per_s = 2.0
stroke_deg = 2.0
accel_s = 0.1
dwell_s = 0.2
cycles = 1
lead_s = 0.2
''',
    "pass_8dps": '''
[profile]
name = "pass_8dps"
target = "REFERENCE"
units = "rad"
origin = "relative"
description = "constant-velocity passes at 8 deg/s over 8 deg"

[generator]
type = "constant_velocity"
velocity_deg_per_s = 8.0
stroke_deg = 8.0
accel_s = 0.1
dwell_s = 0.2
cycles = 1
lead_s = 0.2
''',
}

RUN_PROFILE = '''
[[run]]
action = "start_recording"
name = "{{campaign}}_{{{key}_stem}}"

[[run]]
action = "play"
profile = "{{{key}}}"
mode = "{mode}"

[[run]]
action = "stop_recording"
'''


def campaign_text(name: str, metrics: str, matrix: str, key: str, mode: str,
                  design: Path | None) -> str:
    setup = '[[setup]]\naction = "connect"\n'
    if design is not None:
        setup += f'\n[[setup]]\naction = "upload_design"\ndesign = "{design}"\n'
    return (f'[campaign]\nname = "{name}"\ntestbed = "{RELATIVE}"\n\n'
            f'[analysis]\nsensor = "encoder_inner"\nmetrics = [{metrics}]\n\n'
            f'[matrix]\n{matrix}\n\n{setup}\n' + RUN_PROFILE.format(key=key, mode=mode))


STEPS = f'''
[campaign]
name = "steps_short"
testbed = "{RELATIVE}"

[analysis]
sensor = "encoder_inner"
compare = "design"
baseline = "relative_design1"
metrics = ["step"]

[matrix]
design = ["{DESIGN1}", "{DESIGN2}"]

[[setup]]
action = "connect"

[[run]]
action = "start_recording"
name = "{{campaign}}_{{design_stem}}"

[[run]]
action = "upload_design"
design = "{{design}}"

[[run]]
action = "play"
profile = "PROFILES/step_short.toml"
mode = "RELATIVE"

[[run]]
action = "stop_recording"
'''


@pytest.fixture(scope="module")
def base(tmp_path_factory) -> Path:
    folder = tmp_path_factory.mktemp("reference")
    (folder / "profiles").mkdir()
    for name, text in PROFILES.items():
        (folder / "profiles" / f"{name}.toml").write_text(text)
    return folder


def run_campaign(base: Path, name: str, text: str) -> Path:
    path = base / f"{name}.toml"
    path.write_text(text.replace("PROFILES", str(base / "profiles")))
    folder = base / name
    assert main(["campaign", "run", str(path), "--fast", "--log-folder", str(folder)]) == 0
    return folder


def files(base: Path, *names: str) -> str:
    return ", ".join(f'"{base / "profiles" / n}.toml"' for n in names)


@pytest.fixture(scope="module")
def steps(base):
    return run_campaign(base, "steps_short", STEPS)


@pytest.fixture(scope="module")
def sysid(base):
    return run_campaign(base, "sysid_short", campaign_text(
        "sysid_short", '"frf"', f"profile = [{files(base, 'noise_coarse', 'noise_fine')}]",
        "profile", "OPEN_LOOP", None))


@pytest.fixture(scope="module")
def triangle(base):
    return run_campaign(base, "triangle_short", campaign_text(
        "triangle_short", '"hysteresis"', f"profile = [{files(base, 'triangle_fast')}]",
        "profile", "RELATIVE", DESIGN2))


@pytest.fixture(scope="module")
def passes(base):
    return run_campaign(base, "passes_short", campaign_text(
        "passes_short", '"friction_velocity"', f"profile = [{files(base, 'pass_2dps', 'pass_8dps')}]",
        "profile", "RELATIVE", DESIGN2))


def rows_of(folder: Path) -> list[dict[str, str]]:
    return list(csv.DictReader(io.StringIO((folder / "report.metrics.csv").read_text())))


def doc_of(folder: Path) -> dict:
    return json.loads((folder / "report.metrics.json").read_text())


def embedded_pngs(folder: Path) -> list[bytes]:
    page = (folder / "report.html").read_text()
    return [base64.b64decode(m) for m in re.findall(r'src="data:image/png;base64,([^"]+)"', page)]


def assert_png(path: Path) -> bytes:
    data = path.read_bytes()
    assert data.startswith(b"\x89PNG\r\n\x1a\n"), path
    return data


# --------------------------------------------------------------------------- shipped files
def test_the_shipped_campaigns_name_their_reference_metric():
    expected = {"relative_steps": ("step",), "open_loop_sysid": ("frf",),
                "friction_hysteresis_1dof": ("hysteresis",),
                "friction_hysteresis_2dof": ("hysteresis",),
                "steady_state_friction": ("friction_velocity",)}
    for name, metrics in expected.items():
        c, problems = read_campaign(CAMPAIGNS / f"{name}.toml")
        assert problems == [], problems
        assert c.analysis.metrics == metrics, name
        assert c.analysis.sensor == "encoder_inner"       # no autocollimator on these rigs


# --------------------------------------------------------------------------- steps
def test_step_rows_carry_rise_time_and_overshoot(steps):
    from groundstation.analysis.log_step import step_from_log

    rows = rows_of(steps)
    assert [r["design_stem"] for r in rows] == ["relative_design1", "relative_design2"]
    for r in rows:
        assert r["error"] == "" and r["reference_error"] == ""
        direct = step_from_log(r["file"]).metrics
        assert float(r["step_size_urad"]) == pytest.approx(500.0, abs=0.01)   # reference counts
        assert float(r["step_rise_time_s"]) == pytest.approx(direct.rise_time_s, rel=1e-12)
        assert 0.005 < float(r["step_rise_time_s"]) < 0.05
        assert float(r["step_overshoot_pct"]) == pytest.approx(direct.overshoot_percent, rel=1e-12)
        assert float(r["step_overshoot_pct"]) >= 0
        assert float(r["step_settling_time_s"]) > float(r["step_rise_time_s"])
        assert r["step_effort_channel"] == "current_coarse" and float(r["step_peak_effort"]) > 0
    # the jitter/energy comparison is still there, beside the reference metric
    doc = doc_of(steps)
    assert doc["analysis"]["metrics"] == ["step"]
    assert {c["compare"] for c in doc["comparison"]} == {"relative_design1", "relative_design2"}
    text = (steps / "report.txt").read_text()
    assert len(re.findall(r"step: 500 urad at .* rise \d+\.\d ms, overshoot", text)) == 2
    png = assert_png(steps / "report.step.png")
    assert png in embedded_pngs(steps)
    page = (steps / "report.html").read_text()
    assert "Reference metrics: step" in page and "rise 10-90 % (ms)" in page


# --------------------------------------------------------------------------- frf
def test_the_frf_rows_name_the_excited_input_and_its_coherence(sysid):
    from groundstation.analysis.log_frf import frf_from_log

    rows = rows_of(sysid)
    assert [r["frf_input"] for r in rows] == ["current_coarse", "current_fine"]
    assert [r["frf_model"] for r in rows] == ["T1->phi2", "T2->phi2"]
    for r in rows:
        assert r["reference_error"] == "" and r["frf_output"] == "encoder_inner"
        assert int(r["frf_coherent_bins"]) > 40          # of ~83 between 5 and 200 Hz
        assert float(r["frf_band_median_coherence"]) > 0.9
        assert float(r["frf_coherent_from_hz"]) < 50 and float(r["frf_coherent_to_hz"]) > 100
        direct = frf_from_log(r["file"], r["frf_input"], "encoder_inner")
        assert float(r["frf_rms_db"]) == pytest.approx(direct.comparison.rms_magnitude_ratio_db, rel=1e-9)
        # a friction-free model and a large excitation: measured and model agree
        assert float(r["frf_rms_db"]) < 3.0
    doc = doc_of(sysid)
    choice = doc["rows"][0]["reference"]["frf"]["input_choice"]
    assert choice.startswith("input current_coarse: it varies most") and "current_fine 0 A" in choice
    pngs = embedded_pngs(sysid)
    for name in ("frf_current_coarse", "frf_current_fine"):
        assert assert_png(sysid / f"report.{name}.png") in pngs
    assert "frf: current_fine -> encoder_inner" in (sysid / "report.txt").read_text()


# --------------------------------------------------------------------------- hysteresis
def test_the_hysteresis_slope_table_is_written_beside_the_report_and_parses(triangle):
    from groundstation.plant.slope_table import load_slope_table

    (r,) = rows_of(triangle)
    assert r["reference_error"] == ""
    assert int(r["hyst_complete_branches"]) >= 2 and r["hyst_slope_table"] == "True"
    table = Path(r["hyst_slope_table_file"])
    assert table.parent == triangle and table.name == f"report.slope_table.{Path(r['file']).stem}.csv"
    x, f = load_slope_table(table)
    assert x[0] == 0.0 and x[-1] == 2.0 and np.all(np.diff(f) <= 0) and f[-1] == 0.0
    assert f[0] == pytest.approx(float(r["hyst_slope_f0"]))
    # the simulator's bearing: T_c 2.25 in-oz.  (Its turnaround slope, sigma·f(0) = 5730 x 12
    # in-oz/rad, needs the reference's 0.001 deg/s: at 0.05 deg/s the first 1 % of the swing
    # lasts under a millisecond, so only "much steeper than late" is checked here.)
    assert float(r["hyst_coulomb_in_oz"]) == pytest.approx(2.25, rel=0.1)
    assert (float(r["hyst_turnaround_slope_in_oz_per_rad"])
            > 20 * float(r["hyst_late_slope_in_oz_per_rad"]) > 0)
    doc = doc_of(triangle)
    ref = doc["rows"][0]["reference"]["hysteresis"]
    assert len(ref["branches"]) == int(r["hyst_branches"])
    np.testing.assert_allclose(ref["slope_table"]["f"], f, rtol=1e-12)
    pngs = embedded_pngs(triangle)
    for name in ("hysteresis", "slope_table"):
        assert assert_png(triangle / f"report.{name}.png") in pngs
    assert "slope table identified" in (triangle / "report.txt").read_text()


# --------------------------------------------------------------------------- friction vs velocity
def test_friction_velocity_rows_per_run_and_the_fit_across_runs(passes):
    rows = rows_of(passes)
    assert len(rows) == 2
    b_f, t_c = 20.0, 2.25          # the relative testbed file: bearing_viscous, coulomb_torque
    for r, speed in zip(rows, (2.0, 8.0)):
        assert r["reference_error"] == ""
        assert int(r["fv_segments"]) >= 2 and int(r["fv_settled_segments"]) >= 2
        assert float(r["fv_speed_deg_s"]) == pytest.approx(speed, rel=0.01)
        expected = t_c + b_f * speed * math.pi / 180
        assert float(r["fv_friction_in_oz"]) == pytest.approx(expected, rel=0.02)
        assert r["fv_torque_formula"] == "T1 - T2 + k*(phi2 - phi1)"
    doc = doc_of(passes)
    fit = doc["reference_summary"]["friction_velocity"]
    assert fit["logs"] == 2 and fit["points"] >= 4
    assert fit["coulomb_in_oz"] == pytest.approx(t_c, abs=0.05)
    assert fit["viscous_in_oz_s_per_rad"] == pytest.approx(b_f, rel=0.05)
    assert fit["testbed"]["coulomb_in_oz"] == t_c
    segs = doc["rows"][0]["reference"]["friction_velocity"]["segments"]
    assert {s["direction"] for s in segs} == {1, -1}
    assert assert_png(passes / "report.friction_velocity.png") in embedded_pngs(passes)
    text = (passes / "report.txt").read_text()
    assert "friction against velocity, " in text and "T_c 2.2" in text


# --------------------------------------------------------------------------- failures
def test_a_metric_that_does_not_fit_a_log_is_its_rows_reference_error(steps, tmp_path, capsys):
    """Friction against velocity on the step logs: no constant-velocity pass - each row
    says so, the jitter, energy and comparison are still there, the report is written, and
    the command's exit status says not everything could be scored."""
    other = tmp_path / "passes_on_steps.toml"
    other.write_text((steps.parent / "steps_short.toml").read_text()
                     .replace('metrics = ["step"]', 'metrics = ["friction_velocity"]'))
    to = tmp_path / "copy"
    to.mkdir()
    shutil.copy(steps / "report.json", to / "report.json")      # names the logs where they are
    assert main(["campaign", "report", str(to / "report.json"), "--campaign", str(other)]) == 1
    capsys.readouterr()
    rows = rows_of(to)
    assert len(rows) == 2
    for r in rows:
        assert r["error"] == "" and float(r["energy_total_j"]) > 0
        assert r["reference_error"].startswith("friction_velocity: ")
        assert "no constant-velocity pass" in r["reference_error"]
    assert len(doc_of(to)["comparison"]) == 2
    assert "reference metric error: friction_velocity:" in (to / "report.txt").read_text()
    assert "Could not be computed" in (to / "report.html").read_text()
    assert not (to / "report.friction_velocity.png").exists()


def test_an_unreadable_log_is_a_row_with_its_error(steps, tmp_path, capsys):
    to = tmp_path / "copy"
    to.mkdir()
    doc = json.loads((steps / "report.json").read_text())
    for rec in doc["recordings"]:
        rec["files"] = [str(shutil.copy(f, to / Path(f).name)) for f in rec["files"]]
    Path(doc["recordings"][0]["files"][0]).write_bytes(b"not a log")
    (to / "report.json").write_text(json.dumps(doc))
    assert main(["campaign", "report", str(to / "report.json"),
                 "--campaign", str(steps.parent / "steps_short.toml")]) == 1
    capsys.readouterr()
    bad, good = rows_of(to)
    assert bad["error"] and bad["step_rise_time_s"] == "" and bad["reference_error"] == ""
    assert good["error"] == "" and float(good["step_rise_time_s"]) > 0
