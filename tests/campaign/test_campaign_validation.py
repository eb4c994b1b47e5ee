"""Campaign values are checked before anything runs (issue 13): every step of every run
against the protocol dictionary, the testbed's limits and the 4053B generator's; every
referenced file must load.  `campaign show` lists the steps without cutting text that
merely contains a slash.  Ctrl-C in `campaign run` ends the campaign cleanly."""

from __future__ import annotations

from pathlib import Path

import pytest

from groundstation.station.station import Station
from groundstation.campaign import (CampaignError, CampaignReport, CampaignRunner,
                                    load_campaign, read_campaign)
from groundstation.cli.main import build_parser, main
from groundstation.logs import LogReader
from groundstation import Testbed

ROOT = Path(__file__).resolve().parents[2]
CAMPAIGNS = ROOT / "profiles" / "campaigns"
INERTIAL = ROOT / "profiles" / "testbeds" / "inertial_2dof.toml"
RELATIVE = ROOT / "profiles" / "testbeds" / "relative_2dof.toml"
DESIGN2 = ROOT / "profiles" / "controllers" / "relative_design2.toml"
BM1 = ROOT / "profiles" / "base_motion" / "BM1.csv"


def write(tmp_path, body: str, *, testbed: Path = INERTIAL, matrix: str = "",
          name: str = "inertial_bm.toml") -> Path:
    path = tmp_path / name
    path.write_text(f'[campaign]\nname = "check"\ntestbed = "{testbed}"\n{matrix}\n'
                    f'[[setup]]\naction = "connect"\n\n{body}')
    return path


# --------------------------------------------------------------------------- values
def test_a_negative_dwell_is_refused_naming_file_run_step_and_field(tmp_path):
    path = write(tmp_path, '[[run]]\naction = "start_recording"\nname = "r{run}"\n\n'
                           '[[run]]\naction = "mark"\ntext = "x"\n\n'
                           '[[run]]\naction = "set_mode"\nmode = "IDLE"\n\n'
                           '[[run]]\naction = "dwell"\nseconds = "{dwell}"\n',
                 matrix="[matrix]\ndwell = [1.0, -5]\n")
    with pytest.raises(CampaignError) as err:
        load_campaign(path)
    assert err.value.problems == [
        "inertial_bm.toml: run 2 step 4 (dwell): seconds = -5 - must be a finite number > 0"]


BAD_STEPS = [
    ('action = "dwell"\nseconds = -5', "(dwell): seconds = -5 - must be a finite number > 0"),
    ('action = "dwell"\nseconds = "ten"', "(dwell): seconds = 'ten' - must be a finite number > 0"),
    ('action = "dwell"\nseconds = nan', "(dwell): seconds = nan - must be a finite number > 0"),
    ('action = "dwell"\nseconds = inf', "(dwell): seconds = inf - must be a finite number > 0"),
    ('action = "dwell"\nseconds = 0', "(dwell): seconds = 0 - must be a finite number > 0"),
    ('action = "set_mode"\nmode = "TURBO"', "(set_mode): mode = 'TURBO' - not a mode of the protocol"),
    ('action = "play"\nprofile = "' + str(ROOT / "profiles/waveforms/step_relative_1mrad.toml")
     + '"\nmode = "relative"', "(play): mode = 'relative' - not a mode of the protocol"),
    ('action = "set_currents"\ncoarse_a = 100.0', "(set_currents): coarse_a = 100 - outside [-2.53, 2.53]"),
    ('action = "set_currents"\nfine_a = -1.5', "(set_currents): fine_a = -1.5 - outside [-1, 1]"),
    ('action = "set_reference"\nangle_rad = 5.0', "(set_reference): angle_rad = 5 - outside [-0.349, 0.349]"),
    ('action = "friction_comp"\nenabled = "yes"', "(friction_comp): enabled = 'yes' - must be true or false"),
    ('action = "generator_set"\nwaveform = "SINE"\nfrequency_hz = 1.0\namplitude_vpp = 50.0',
     "(generator_set): amplitude_vpp = 50 - outside [0.002, 20] (4053B limit"),
    ('action = "generator_set"\nwaveform = "SINE"\nfrequency_hz = 1.0\namplitude_vpp = 5.0',
     "(generator_set): amplitude_vpp = 5 - above the testbed's limit of 2 Vpp (inertial_2dof.toml "
     "[limits] fg_max_amplitude)"),
    ('action = "generator_set"\nwaveform = "SINE"\nfrequency_hz = 1.0\namplitude_vpp = 0.5\noffset_v = 1.0',
     "(generator_set): offset_v = 1 - beyond the testbed's limit of +-0.2 V"),
    ('action = "generator_set"\nwaveform = "SINE"\nfrequency_hz = 2e7\namplitude_vpp = 0.5',
     "(generator_set): frequency_hz = 2e+07 - outside [1e-06, 1e+07] (4053B limit"),
    ('action = "generator_set"\nwaveform = "TRIANGLE"', "(generator_set): waveform = 'TRIANGLE' - not a waveform"),
    ('action = "generator_set"\nwaveform = "SINE"\nchannel = 3', "(generator_set): channel = 3 - must be one of"),
    ('action = "play_base_motion"\npsd = "' + str(BM1) + '"\nrms_mrad = 30.0',
     "(play_base_motion): psd: the profile needs"),
    ('action = "play_base_motion"\npsd = "' + str(BM1) + '"\nduration_s = -60.0',
     "(play_base_motion): duration_s = -60 - must be a finite number > 0"),
    ('action = "start_recording"\nname = ""', "(start_recording): name = '' - must be text"),
]


@pytest.mark.parametrize("step, message", BAD_STEPS, ids=[m.split(")")[0].strip("(") + str(i)
                                                          for i, (_, m) in enumerate(BAD_STEPS)])
def test_each_bad_value_is_refused(tmp_path, step, message):
    path = write(tmp_path, "[[run]]\n" + step + "\n")
    with pytest.raises(CampaignError) as err:
        load_campaign(path)
    assert len(err.value.problems) == 1, err.value.problems
    assert err.value.problems[0].startswith("inertial_bm.toml: run 1 step 1 "), err.value.problems
    assert message in err.value.problems[0], err.value.problems


def test_every_problem_of_every_run_is_listed_at_once(tmp_path):
    path = write(tmp_path, '[[run]]\naction = "dwell"\nseconds = "{seconds}"\n\n'
                           '[[run]]\naction = "set_mode"\nmode = "FLY"\n\n'
                           '[[run]]\naction = "upload_design"\ndesign = "missing_{run}.toml"\n\n'
                           '[[teardown]]\naction = "set_currents"\ncoarse_a = 3.0\n',
                 matrix="[matrix]\nseconds = [1.0, nan]\n")
    campaign, problems = read_campaign(path)
    assert problems == [
        f"inertial_bm.toml: run 1 step 3 (upload_design): design: no file {tmp_path / 'missing_1.toml'}",
        f"inertial_bm.toml: run 2 step 3 (upload_design): design: no file {tmp_path / 'missing_2.toml'}",
        "inertial_bm.toml: run 1 step 2 (set_mode): mode = 'FLY' - not a mode of the protocol "
        "(SET_MODE: IDLE, OPEN_LOOP, RELATIVE, INERTIAL)",
        "inertial_bm.toml: run 2 step 1 (dwell): seconds = nan - must be a finite number > 0",
        "inertial_bm.toml: run 2 step 2 (set_mode): mode = 'FLY' - not a mode of the protocol "
        "(SET_MODE: IDLE, OPEN_LOOP, RELATIVE, INERTIAL)",
        "inertial_bm.toml: teardown step 1 (set_currents): coarse_a = 3 - outside [-2.53, 2.53] "
        "(SET_CURRENTS current_coarse range in protocol/commands.toml)",
    ]
    with pytest.raises(CampaignError) as err:
        load_campaign(path)
    assert err.value.problems == problems
    assert str(err.value).startswith("inertial_bm.toml: 6 problems, nothing was run")


def test_referenced_files_must_load(tmp_path):
    broken_design = tmp_path / "broken_design.toml"
    broken_design.write_text("[design]\nname = 'x'\n")
    broken_profile = tmp_path / "broken_profile.toml"
    broken_profile.write_text("this is not toml = = \n")
    broken_psd = tmp_path / "broken.csv"
    broken_psd.write_text("frequency_hz,psd\nten,1\n")
    path = write(tmp_path, f'[[run]]\naction = "upload_design"\ndesign = "{broken_design}"\n\n'
                           f'[[run]]\naction = "play"\nprofile = "{broken_profile}"\n\n'
                           f'[[run]]\naction = "play_base_motion"\npsd = "{broken_psd}"\n')
    _, problems = read_campaign(path)
    assert [p.split(":")[1].strip() for p in problems] == [
        "run 1 step 1 (upload_design)", "run 1 step 2 (play)", "run 1 step 3 (play_base_motion)"]
    assert problems[0].startswith("inertial_bm.toml: run 1 step 1 (upload_design): design: ")
    assert "broken_design.toml" in problems[0]
    assert problems[1].startswith("inertial_bm.toml: run 1 step 2 (play): profile: ")
    assert problems[2].startswith("inertial_bm.toml: run 1 step 3 (play_base_motion): psd: ")


@pytest.mark.parametrize("path", sorted(CAMPAIGNS.glob("*.toml")), ids=lambda p: p.stem)
def test_the_shipped_campaigns_pass_the_checks(path):
    campaign, problems = read_campaign(path)
    assert problems == [] and campaign.steps


def test_a_number_from_the_matrix_keeps_its_type(tmp_path):
    path = write(tmp_path, '[[run]]\naction = "dwell"\nseconds = "{seconds}"\n',
                 matrix="[matrix]\nseconds = [0.25, 2]\n")
    c = load_campaign(path)
    assert [s.args["seconds"] for s in c.steps if s.action == "dwell"] == [0.25, 2]


def test_cli_refuses_a_bad_campaign_before_connecting(tmp_path, capsys, monkeypatch):
    path = write(tmp_path, '[[run]]\naction = "start_recording"\nname = "r"\n\n'
                           '[[run]]\naction = "dwell"\nseconds = -5\n\n'
                           '[[run]]\naction = "stop_recording"\n')

    def no_session(*args, **kwargs):
        raise AssertionError("a session was opened for a refused campaign")

    monkeypatch.setattr(Station, "__init__", no_session)
    logs = tmp_path / "logs"
    code = main(["campaign", "run", str(path), "--fast", "--log-folder", str(logs)])
    err = capsys.readouterr().err
    assert code == 2
    assert "error: inertial_bm.toml: run 1 step 2 (dwell): seconds = -5 - must be a finite number > 0" in err
    assert not logs.exists()                      # nothing recorded, no report of a run
    code = main(["campaign", "show", str(path)])
    out = capsys.readouterr()
    assert code == 2
    assert "error: inertial_bm.toml: run 1 step 2 (dwell): seconds = -5 - must be a finite number > 0" \
        in out.err
    assert "dwell" in out.out                     # the steps are still listed


# --------------------------------------------------------------------------- show
def test_show_shortens_only_file_references(tmp_path, capsys):
    path = write(tmp_path, '[[run]]\naction = "start_recording"\nname = "r"\n'
                           'notes = "A/B test, 1/2 of the load, see logs/x/y"\n\n'
                           f'[[run]]\naction = "upload_design"\ndesign = "{DESIGN2}"\n'
                           'accept_risk = "reviewed 2026/11/24 by J/K"\n\n'
                           '[[run]]\naction = "mark"\ntext = "on/off"\n', testbed=RELATIVE)
    assert main(["campaign", "show", str(path)]) == 0
    out = capsys.readouterr().out
    assert "notes=A/B test, 1/2 of the load, see logs/x/y" in out
    assert "accept_risk=reviewed 2026/11/24 by J/K" in out
    assert "text=on/off" in out
    assert "design=relative_design2.toml," in out and str(DESIGN2.parent) not in out


# --------------------------------------------------------------------------- Ctrl-C
def interrupt_campaign(tmp_path) -> Path:
    return write(tmp_path, '[[run]]\naction = "start_recording"\nname = "ctrlc_{run}"\n\n'
                           '[[run]]\naction = "generator_set"\nwaveform = "SINE"\nfrequency_hz = 1.0\n'
                           'amplitude_vpp = 0.2\n\n'
                           '[[run]]\naction = "dwell"\nseconds = 0.3\n\n'
                           '[[run]]\naction = "mark"\ntext = "after the dwell"\n\n'
                           '[[run]]\naction = "stop_recording"\n',
                 matrix="[matrix]\nn = [1, 2]\n", name="ctrlc.toml")


def ctrl_c_in_dwell(monkeypatch, run: int):
    """The operator's Ctrl-C arrives (as KeyboardInterrupt in the main thread) while
    run `run` dwells."""
    real = Station.dwell
    calls = []

    def dwell(self, seconds, progress=None):
        calls.append(seconds)
        if len(calls) == run:
            real(self, seconds / 2, progress)
            raise KeyboardInterrupt
        return real(self, seconds, progress)

    monkeypatch.setattr(Station, "dwell", dwell)


def check_closed_log(path):
    with LogReader(path) as log:
        assert log.n_frames("HIGH_RATE") > 0
        events = [e.data.get("text", "") for e in log.journal("event")]
        notes = [n.data.get("text", "") for n in log.journal("note")]
    assert any(t.startswith("stopped: step") and "interrupted by the operator (Ctrl-C)" in t
               for t in events), events
    closing = [n for n in notes if n.startswith("recording closed: ")]
    assert len(closing) == 1 and "interrupted by the operator (Ctrl-C)" in closing[0], notes
    assert "after the dwell" not in events


def test_ctrl_c_in_a_step_ends_the_campaign_cleanly(tmp_path, monkeypatch):
    ctrl_c_in_dwell(monkeypatch, run=2)
    c = load_campaign(interrupt_campaign(tmp_path))
    with Testbed("sim", testbed=c.testbed, fast=True, log_folder=tmp_path / "logs",
                 history=tmp_path / "history") as tb:
        report = CampaignRunner(c, tb).run()
        generator_on = tb.generator.get_output(1)
        armed = tb.simulator.firmware.armed
        mode = tb.simulator.firmware.mode
    assert report.status == "interrupted"
    assert report.completed_runs == [1] and report.failed_run == 2
    assert report.reason.endswith("dwell: interrupted by the operator (Ctrl-C)")
    assert [s.status for s in report.steps][-1] == "interrupted"
    assert generator_on is False and not armed and int(mode) == 0      # ABORT: IDLE, disarmed
    assert len(report.recordings) == 2
    assert "interrupted by the operator" in report.recordings[1]["stop_reason"]
    check_closed_log(report.recordings[1]["files"][0])
    saved = report.save(tmp_path / "r" / "report.json")
    text = saved.with_suffix(".txt").read_text()
    assert "INTERRUPTED" in text and f"--resume {saved}" in text


def test_ctrl_c_between_steps_is_an_interruption_too(tmp_path):
    c = load_campaign(interrupt_campaign(tmp_path))

    def progress(step, fraction):
        if step.run == 1 and step.action == "mark" and fraction == 0.0:
            raise KeyboardInterrupt

    with Testbed("sim", testbed=c.testbed, fast=True, log_folder=tmp_path / "logs",
                 history=tmp_path / "history") as tb:
        report = CampaignRunner(c, tb, progress=progress).run()
        generator_on = tb.generator.get_output(1)
    assert report.status == "interrupted" and report.failed_run == 1 and report.completed_runs == []
    assert "interrupted by the operator (Ctrl-C)" in report.reason
    assert generator_on is False
    with LogReader(report.recordings[0]["files"][0]) as log:
        notes = [n.data.get("text", "") for n in log.journal("note")]
    assert any(n.startswith("recording closed: ") and "interrupted by the operator (Ctrl-C)" in n
               for n in notes), notes


def test_cli_exit_status_130_and_resume_hint(tmp_path, capsys, monkeypatch):
    ctrl_c_in_dwell(monkeypatch, run=1)
    path = interrupt_campaign(tmp_path)
    report_path = tmp_path / "out" / "report.json"
    code = main(["campaign", "run", str(path), "--fast", "--log-folder", str(tmp_path / "logs"),
                 "--report", str(report_path)])
    out = capsys.readouterr().out
    assert code == 130, out
    assert "INTERRUPTED" in out and f"--resume {report_path}" in out
    report = CampaignReport.load(report_path)
    assert report.status == "interrupted" and report.failed_run == 1
    check_closed_log(report.recordings[0]["files"][0])
    # the hint works: resuming runs the interrupted run again and finishes
    monkeypatch.undo()
    code = main(["campaign", "run", str(path), "--fast", "--log-folder", str(tmp_path / "logs"),
                 "--report", str(tmp_path / "out" / "report2.json"), "--resume", str(report_path)])
    assert code == 0, capsys.readouterr().out
    assert CampaignReport.load(tmp_path / "out" / "report2.json").completed_runs == [1, 2]


def test_help_documents_exit_status_130(capsys):
    with pytest.raises(SystemExit):
        build_parser().parse_args(["campaign", "run", "--help"])
    out = capsys.readouterr().out
    assert "130" in out and "Ctrl-C" in out and "--resume" in out


@pytest.mark.parametrize("bad", ["-1", "0", "nan", "inf", "ten"])
def test_max_step_seconds_must_be_positive(bad):
    with pytest.raises(SystemExit):
        build_parser().parse_args(["campaign", "run", "x.toml", "--max-step-seconds", bad])


# --------------------------------------------------------------------------- skip_if
def test_skip_if_leaves_a_step_out_of_the_runs_whose_matrix_value_matches(tmp_path):
    path = write(tmp_path, '[[run]]\naction = "set_mode"\nmode = "INERTIAL"\n'
                           'skip_if = {design = "open_loop"}\n\n'
                           '[[run]]\naction = "dwell"\nseconds = 1.0\n',
                 matrix=f'[matrix]\ndesign = ["open_loop", "{DESIGN2}"]\n')
    c = load_campaign(path)
    runs = {run: [s.action for s in c.steps if s.run == run] for run in (1, 2)}
    assert runs == {1: ["dwell"], 2: ["set_mode", "dwell"]}


@pytest.mark.parametrize("cond, words", [
    ('skip_if = "open_loop"', "skip_if must be a table of matrix keys and values"),
    ('skip_if = {profile = "x"}', "skip_if names 'profile', which is not a [matrix] key (known: design)"),
    ('skip_if = {design = "closed_loop"}', "skip_if design = ['closed_loop']: not among the matrix's values"),
])
def test_a_malformed_skip_if_is_refused_with_what_is_wrong(tmp_path, cond, words):
    path = write(tmp_path, f'[[run]]\naction = "dwell"\nseconds = 1.0\n{cond}\n',
                 matrix=f'[matrix]\ndesign = ["open_loop", "{DESIGN2}"]\n')
    with pytest.raises(CampaignError) as err:
        load_campaign(path)
    assert any(words in p and "run 1 step 1 (dwell)" in p for p in err.value.problems), err.value.problems
