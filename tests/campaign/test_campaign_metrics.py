"""The metrics a campaign leaves (campaign/metrics.py, report_figures.py): a real 2 x 2
campaign on the fast simulator - relative Design #1 and #2, each after a small and a
larger reference step - run through the CLI, then its logs scored and compared per step
size against Design #1.  The figures are checked against `analyze_log` called here on
the window found independently (the mark's host time against the frames' arrival
times); a truncated log is a row with its error; `campaign report` recomputes the same
CSV from the saved report; the [analysis] table's checks word their problems like the
rest of the file's."""

from __future__ import annotations

import csv
import io
import json
import re
import shutil
from pathlib import Path

import numpy as np
import pytest

from groundstation.analysis import analyze_log
from groundstation.campaign import CampaignReport, CampaignRunner, load_campaign, read_campaign
from groundstation.campaign.metrics import campaign_metrics
from groundstation.cli.main import main
from groundstation.logs import LogReader
from groundstation import Testbed

ROOT = Path(__file__).resolve().parents[2]
RELATIVE = ROOT / "profiles" / "testbeds" / "relative_2dof.toml"
INERTIAL = ROOT / "profiles" / "testbeds" / "inertial_2dof.toml"
DESIGN1 = ROOT / "profiles" / "controllers" / "relative_design1.toml"
DESIGN2 = ROOT / "profiles" / "controllers" / "relative_design2.toml"
WINDOW_S = 0.8
#: dT_i short enough for the high-pass to settle (3 dT_i) inside the window
PERIOD_S = 0.1
SENSOR = "encoder_inner"          # the relative rig's angle (its autocollimator sees no motion)

CAMPAIGN = f'''
[campaign]
name = "metrics_check"
testbed = "{RELATIVE}"

[matrix]
design = ["{DESIGN1}", "{DESIGN2}"]
ref = [0.0001, 0.0002]

[analysis]
start_after_mark = "step {{ref}} on"
duration_s = {WINDOW_S}
sensor = "{SENSOR}"
integration_period_s = {PERIOD_S}
group_by = "ref"
compare = "design"
baseline = "relative_design1"

[[setup]]
action = "connect"

[[run]]
action = "start_recording"
name = "{{campaign}}_{{design_stem}}_{{run}}"

[[run]]
action = "upload_design"
design = "{{design}}"

[[run]]
action = "set_mode"
mode = "RELATIVE"

[[run]]
action = "arm"

[[run]]
action = "dwell"
seconds = 0.3

[[run]]
action = "mark"
text = "step {{ref}} on"

[[run]]
action = "set_reference"
angle_rad = "{{ref}}"

[[run]]
action = "dwell"
seconds = 1.0

[[run]]
action = "disarm"

[[run]]
action = "stop_recording"
'''

#: run -> (design stem, step) as the matrix orders them (first key outermost)
RUNS = {1: ("relative_design1", 0.0001), 2: ("relative_design1", 0.0002),
        3: ("relative_design2", 0.0001), 4: ("relative_design2", 0.0002)}


@pytest.fixture(scope="module")
def campaign_run(tmp_path_factory):
    """The campaign run once through the CLI; its folder (logs, report, metrics)."""
    base = tmp_path_factory.mktemp("metrics")
    path = base / "metrics_check.toml"
    path.write_text(CAMPAIGN)
    folder = base / "logs"
    code = main(["campaign", "run", str(path), "--fast", "--log-folder", str(folder)])
    assert code == 0
    return path, folder


def copy_run(folder: Path, to: Path) -> Path:
    """The logs and the report copied to `to`, the report naming the copies."""
    to.mkdir()
    doc = json.loads((folder / "report.json").read_text())
    for rec in doc["recordings"]:
        copies = []
        for f in rec["files"]:
            shutil.copy(f, to / Path(f).name)
            copies.append(str(to / Path(f).name))
        rec["files"] = copies
    (to / "report.json").write_text(json.dumps(doc))
    return to / "report.json"


def read_csv(path: Path) -> list[dict[str, str]]:
    return list(csv.DictReader(io.StringIO(path.read_text())))


def independent_window(log: Path, ref: float) -> float:
    """The documented rule, written again: the device time (from the log's start) of the
    last HIGH_RATE frame that had arrived when the mark was written."""
    with LogReader(log) as r:
        mark = next(e for e in r.journal("event") if e.data.get("text") == f"step {ref} on")
        d = r.read("HIGH_RATE", ["tick"])
        k = int(np.searchsorted(d["host_time"], mark.time, side="right")) - 1
        assert k >= 0
        return float(d["device_time"][k]) - r.origin("device")


# --------------------------------------------------------------------------- the run
def test_each_run_is_one_row_tagged_with_its_matrix_values(campaign_run):
    _, folder = campaign_run
    report = CampaignReport.load(folder / "report.json")
    assert [rec["run"] for rec in report.recordings] == [1, 2, 3, 4]
    for rec in report.recordings:
        stem, ref = RUNS[rec["run"]]
        assert rec["variables"] == {"design": str(ROOT / "profiles" / "controllers" / f"{stem}.toml"),
                                    "design_stem": stem, "ref": ref}
    rows = read_csv(folder / "report.metrics.csv")
    assert [int(r["run"]) for r in rows] == [1, 2, 3, 4]
    for r in rows:
        stem, ref = RUNS[int(r["run"])]
        assert r["design_stem"] == stem and float(r["ref"]) == ref
        assert r["run_status"] == "completed" and r["error"] == ""
        assert r["window_start"] == "mark" and r["mark"] == f"step {ref} on"
        assert r["sensor"] == SENSOR
    doc = json.loads((folder / "report.metrics.json").read_text())
    assert len(doc["rows"]) == 4
    assert doc["rows"][0]["variables"]["design_stem"] == "relative_design1"
    assert doc["analysis"]["baseline"] == str(DESIGN1) and doc["analysis"]["group_by"] == "ref"
    # the text report gains the comparison in words
    text = (folder / "report.txt").read_text()
    assert "COMPLETED" in text and "comparison of design by ref, relative to relative_design1" in text
    assert re.search(r"relative_design2 (cuts|raises|leaves) jitter .* vs relative_design1 under ref "
                     r"0\.0001", text)


def test_the_window_and_the_figures_are_analyze_logs(campaign_run):
    """Each row's window starts where the mark was, and its figures are analyze_log's
    over that window; each group's baseline is 1.0 and the other design's ratio is its
    figure over the baseline's - all computed here independently."""
    _, folder = campaign_run
    doc = json.loads((folder / "report.metrics.json").read_text())
    independent = {}
    for row in doc["rows"]:
        log = Path(row["file"])
        ref = RUNS[row["run"]][1]
        start = independent_window(log, ref)
        assert row["window"]["start_s"] == pytest.approx(start, abs=1e-9)
        m = analyze_log(log, sensor=SENSOR, start_s=start, stop_s=start + WINDOW_S,
                        integration_period_s=PERIOD_S).row()
        assert m["to_s"] - m["from_s"] == pytest.approx(WINDOW_S, abs=2e-3)
        for key in ("std_urad", "highpass_rms_urad", "energy_total_j"):
            assert row["metrics"][key] == pytest.approx(m[key], rel=1e-12)
        independent[RUNS[row["run"]]] = m
    cells = {(c["group"], c["compare"]): c for c in doc["comparison"]}
    assert len(cells) == 4
    for ref in (0.0001, 0.0002):
        group = f"{ref:g}"
        base, other = cells[(group, "relative_design1")], cells[(group, "relative_design2")]
        assert base["baseline"] and not other["baseline"]
        for key in ("std_urad", "highpass_rms_urad", "energy_total_j"):
            assert base[f"{key}_ratio"] == 1.0 and base[f"{key}_change_pct"] == 0.0
            mine, theirs = independent[("relative_design2", ref)], independent[("relative_design1", ref)]
            expected = mine[key] / theirs[key]
            assert other[f"{key}_ratio"] == pytest.approx(expected, rel=1e-12)
            assert other[f"{key}_change_pct"] == pytest.approx((expected - 1) * 100, rel=1e-9)


def test_the_html_page_is_self_contained(campaign_run):
    _, folder = campaign_run
    page = (folder / "report.html").read_text()
    assert page.count("<table") == 2 and "relative_design2" in page
    sources = re.findall(r'src="([^"]*)"', page)
    assert len(sources) == 3                                   # jitter, energy, relative
    assert all(s.startswith("data:image/png;base64,") for s in sources)
    assert "href=" not in page and "<link" not in page and "<script" not in page
    for name in ("jitter", "energy", "relative"):
        assert (folder / f"report.{name}.png").read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"


def test_campaign_report_recomputes_the_same_csv(campaign_run, tmp_path, capsys):
    _, folder = campaign_run
    report = copy_run(folder, tmp_path / "again")
    assert main(["campaign", "report", str(report)]) == 0
    out = capsys.readouterr().out
    assert "comparison of design by ref" in out
    mine = (tmp_path / "again" / "report.metrics.csv").read_text()
    # the same rows, file for file (only the folder of the copied logs differs)
    assert mine == (folder / "report.metrics.csv").read_text().replace(str(folder), str(tmp_path / "again"))
    # and in place, from the report the run saved: byte for byte
    before = (folder / "report.metrics.csv").read_text()
    assert main(["campaign", "report", str(folder / "report.json")]) == 0
    assert (folder / "report.metrics.csv").read_text() == before


def test_html_only_writes_the_page_alone(campaign_run, tmp_path):
    _, folder = campaign_run
    report = copy_run(folder, tmp_path / "page")
    assert main(["campaign", "report", str(report), "--html-only"]) == 0
    written = sorted(p.name for p in report.parent.iterdir() if not p.name.endswith(".h5"))
    assert written == ["report.html", "report.json"]
    assert "data:image/png;base64," in (report.parent / "report.html").read_text()


def test_a_truncated_log_is_a_row_with_its_error(campaign_run, tmp_path, capsys):
    """The baseline's log of the first group cut short: that row says why, the others
    are scored, and the first group's other design has no relative figures (said so)."""
    _, folder = campaign_run
    report = copy_run(folder, tmp_path / "cut")
    doc = json.loads(report.read_text())
    victim = Path(doc["recordings"][0]["files"][0])
    data = victim.read_bytes()
    victim.write_bytes(data[: len(data) // 3])
    assert main(["campaign", "report", str(report)]) == 1          # some log could not be scored
    rows = read_csv(report.parent / "report.metrics.csv")
    assert len(rows) == 4
    assert rows[0]["error"] and rows[0]["run"] == "1" and rows[0]["design_stem"] == "relative_design1"
    assert all(r["error"] == "" and r["std_urad"] for r in rows[1:])
    cells = json.loads((report.parent / "report.metrics.json").read_text())["comparison"]
    first = {c["compare"]: c for c in cells if c["group"] == "0.0001"}
    assert first["relative_design1"]["error"] and first["relative_design2"]["std_urad_ratio"] is None
    assert "baseline's log could not be scored" in first["relative_design2"]["note"]
    second = {c["compare"]: c for c in cells if c["group"] == "0.0002"}
    assert second["relative_design1"]["std_urad_ratio"] == 1.0
    assert second["relative_design2"]["std_urad_ratio"] is not None
    assert "ERROR" in capsys.readouterr().out
    assert (report.parent / "report.html").is_file()


def test_a_report_from_before_the_tags_is_scored_not_compared(campaign_run):
    _, folder = campaign_run
    report = CampaignReport.load(folder / "report.json")
    for rec in report.recordings:
        rec.pop("run"), rec.pop("variables")
    metrics = campaign_metrics(report, load_campaign(campaign_run[0]))
    assert len(metrics.rows) == 4 and all(not r["error"] and r["run"] == 0 for r in metrics.rows)
    assert all(c["note"] == "no log" for c in metrics.comparison)
    assert "carry no run or matrix values" in metrics.notes[0]
    # the mark's placeholder cannot be filled without the run's values: whole logs, said so
    assert all(r["window"]["start"] == "log start (mark not found)" for r in metrics.rows)


# --------------------------------------------------------------------------- tags on failure
def test_a_recording_closed_by_a_failure_carries_its_run(tmp_path):
    """Run 2 uploads a design validation refuses: make_safe closes its recording, and the
    report's entry for it still names run 2 and its matrix values."""
    path = tmp_path / "fail.toml"
    path.write_text(f'''
[campaign]
name = "fail"
testbed = "{INERTIAL}"

[matrix]
design = ["{ROOT / 'profiles/controllers/recentre_inertial.toml'}",
          "{ROOT / 'profiles/controllers/inertial_design1.toml'}"]

[[run]]
action = "start_recording"
name = "fail_{{run}}"

[[run]]
action = "dwell"
seconds = 0.2

[[run]]
action = "upload_design"
design = "{{design}}"

[[run]]
action = "stop_recording"
''')
    c = load_campaign(path)
    with Testbed("sim", testbed=c.testbed, fast=True, log_folder=tmp_path / "logs",
                 history=tmp_path / "history") as tb:
        report = CampaignRunner(c, tb).run()
    assert report.status == "failed" and report.failed_run == 2
    assert [(r["run"], r["variables"]["design_stem"]) for r in report.recordings] == \
        [(1, "recentre_inertial"), (2, "inertial_design1")]
    assert report.recordings[1].get("stop_reason")                 # closed by make_safe
    metrics = campaign_metrics(report, c)
    assert [r["run_status"].split(":")[0] for r in metrics.rows] == ["completed", "failed"]


# --------------------------------------------------------------------------- [analysis] checks
def analysis_problems(tmp_path, table: str) -> list[str]:
    path = tmp_path / "check.toml"
    path.write_text(f'''{table}

[campaign]
name = "check"
testbed = "{RELATIVE}"

[matrix]
design = ["{DESIGN1}", "{DESIGN2}"]
ref = [0.0001, 0.0002]

[[run]]
action = "mark"
text = "step {{ref}} on"

[[run]]
action = "set_reference"
angle_rad = "{{ref}}"
''')
    _, problems = read_campaign(path)
    return [p for p in problems if "[analysis]" in p]


@pytest.mark.parametrize("table, message", [
    ('[analysis]\nwindow = 5', "check.toml: [analysis]: unknown key(s) window (allowed: start_after_mark, "
                               "duration_s, sensor, integration_period_s, group_by, compare, baseline, "
                               "metrics, max_excluded_fraction)"),
    ('[analysis]\nduration_s = -5', "check.toml: [analysis] duration_s = -5 - must be a finite number > 0 "
                                    "(seconds)"),
    ('[analysis]\nduration_s = "60"',
     "check.toml: [analysis] duration_s = '60' - must be a finite number > 0"),
    ('[analysis]\nintegration_period_s = nan',
     "[analysis] integration_period_s = nan - must be a finite number"),
    ('[analysis]\nsensor = "gyro"', "check.toml: [analysis] sensor = 'gyro' - not a scored sensor (one of "
                                    "autocollimator, los_estimate, encoder_inner)"),
    ('[analysis]\ngroup_by = "speed"', "check.toml: [analysis] group_by = 'speed' - must name a key of "
                                       "[matrix] (design, ref)"),
    ('[analysis]\ncompare = 3', "[analysis] compare = 3 - must name a key of [matrix] (design, ref)"),
    ('[analysis]\ngroup_by = "ref"\ncompare = "ref"',
     "[analysis] compare = 'ref' - must be another matrix key"),
    ('[analysis]\nbaseline = "relative_design1"', "[analysis] baseline = 'relative_design1' - needs compare"),
    ('[analysis]\ncompare = "design"\nbaseline = "design3"',
     "[analysis] baseline = 'design3' - not a value of [matrix] design (as written, or a file's name "
     "without its extension)"),
    ('[analysis]\nstart_after_mark = "base motion"',
     "check.toml: [analysis] start_after_mark = 'base motion' - no mark step of run 1 has this text "
     "(its marks: 'step 0.0001 on')"),
    ('[analysis]\nstart_after_mark = "step {speed}"', "[analysis] start_after_mark = 'step {speed}' - "
                                                       "unknown or bad placeholder 'speed'"),
    ('[analysis]\nstart_after_mark = ""', "[analysis] start_after_mark = '' - must be text"),
    ('analysis = 5', "check.toml: [analysis] must be a table"),
    ('[analysis]\nmetrics = ["stepp"]', "check.toml: [analysis] metrics = ['stepp'] - unknown metric "
                                        "'stepp' (known: step, frf, hysteresis, friction_velocity"),
    ('[analysis]\nmetrics = ["step", "bode", "loop"]', "unknown metrics 'bode', 'loop' (known: "),
    ('[analysis]\nmetrics = "step"', "[analysis] metrics = 'step' - must be a list of metric names"),
    ('[analysis]\nmetrics = [1]', "[analysis] metrics = [1] - must be a list of metric names"),
    ('[analysis]\nmetrics = ["jitter"]', "'jitter': jitter and control energy are scored for every log "
                                         "anyway"),
    ('[analysis]\nmax_excluded_fraction = 5', "check.toml: [analysis] max_excluded_fraction = 5 - must be "
                                             "a fraction from 0 to 1"),
    ('[analysis]\nmax_excluded_fraction = "1 %"', "[analysis] max_excluded_fraction = '1 %' - must be a "
                                                 "fraction"),
])
def test_analysis_table_problems_are_named(tmp_path, table, message):
    problems = analysis_problems(tmp_path, table)
    assert len(problems) == 1, problems
    assert message in problems[0]


def test_a_good_analysis_table_is_read(tmp_path):
    assert analysis_problems(tmp_path, '[analysis]\nstart_after_mark = "step {ref} on"\n'
                                       'duration_s = 2\nsensor = "encoder_inner"\ngroup_by = "ref"\n'
                                       'compare = "design"\nbaseline = "relative_design2"') == []
    c, _ = read_campaign(tmp_path / "check.toml")
    a = c.analysis
    assert a.given and a.duration_s == 2.0 and a.baseline == str(DESIGN2)
    # without a baseline the first value compared is the baseline; without a table: defaults
    analysis_problems(tmp_path, '[analysis]\ncompare = "design"')
    assert read_campaign(tmp_path / "check.toml")[0].analysis.baseline == str(DESIGN1)
    analysis_problems(tmp_path, "")
    a = read_campaign(tmp_path / "check.toml")[0].analysis
    assert not a.given and a.sensor == "autocollimator" and a.compare == "" and a.metrics == ()
    # the reference metrics: in order, once each
    assert analysis_problems(tmp_path, '[analysis]\nmetrics = ["frf", "step", "frf"]') == []
    a = read_campaign(tmp_path / "check.toml")[0].analysis
    assert a.metrics == ("frf", "step") and a.as_dict()["metrics"] == ["frf", "step"]
    # the validity limit: the analysis default unless the table sets it
    assert a.max_excluded_fraction is None and a.excluded_limit() == 0.01
    assert analysis_problems(tmp_path, '[analysis]\nmax_excluded_fraction = 0.05') == []
    a = read_campaign(tmp_path / "check.toml")[0].analysis
    assert a.excluded_limit() == 0.05 and a.as_dict()["max_excluded_fraction"] == 0.05


def test_every_row_of_a_clean_campaign_is_valid(campaign_run):
    """The relative rig's encoder never leaves its range and the simulator loses no
    frame: every row says so, and the comparison ranks them all."""
    _, folder = campaign_run
    doc = json.loads((folder / "report.metrics.json").read_text())
    for row in doc["rows"]:
        m = row["metrics"]
        assert m["valid"] is True and m["excluded_fraction"] == 0.0 and m["invalid_reason"] == ""
        assert m["max_excluded_fraction"] == 0.01
    assert all(c["valid"] and c["baseline_valid"] for c in doc["comparison"])
    header = next(csv.reader(io.StringIO((folder / "report.metrics.csv").read_text())))
    assert {"excluded_fraction", "valid", "highpass_samples_used"} <= set(header)


def test_campaign_report_refuses_a_bad_analysis_table(campaign_run, tmp_path, capsys):
    path, folder = campaign_run
    bad = tmp_path / "bad.toml"
    bad.write_text(path.read_text().replace('sensor = "encoder_inner"', 'sensor = "gyro"'))
    assert main(["campaign", "report", str(folder / "report.json"), "--campaign", str(bad),
                 "--html-only"]) == 2
    assert "sensor = 'gyro'" in capsys.readouterr().err


def test_closed_loop_runs_get_the_mode_check(campaign_run):
    """Each run closed a relative design's loop: its row carries the share of the
    jitter in the band of that design's least-damped closed-loop mode, the band from
    the design's own sampled loop (with the table the log recorded)."""
    from groundstation.analysis.loop_mode import design_mode
    from groundstation.params.design_file import load_design

    _, folder = campaign_run
    doc = json.loads((folder / "report.metrics.json").read_text())
    expected = {p.stem: design_mode(load_design(p)) for p in (DESIGN1, DESIGN2)}
    for row in doc["rows"]:
        m = row["metrics"]
        mode = expected[row["variables"]["design_stem"]]
        assert m["mode_frequency_hz"] == pytest.approx(mode.frequency_hz, rel=1e-9)
        lo, hi = m["mode_band_hz"]
        assert lo < mode.frequency_hz < hi
        assert 0.0 <= m["mode_share"] <= 1.0 and m["mode_dominates"] == (m["mode_share"] > 0.5)
        assert "least-damped closed-loop pole pair" in m["mode_band_rule"]
    assert all(c["mode_share"] is not None for c in doc["comparison"])
    text = (folder / "report.txt").read_text()
    assert "of its variance in" in text
