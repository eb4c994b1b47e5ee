"""Campaigns on the fast simulated testbed: the shipped ones end to end, a failure that
must leave the rig safe and the logs valid, resume, and the CLI.

What these tests assert does not depend on the machine's speed.  With --fast the device
clock runs flat out only in dwells and while a profile plays; between steps (uploads,
commands, the generator) the simulator runs in real time, so how many frames a log holds
and how long the axis sits armed before a step vary from run to run (4,716-7,416 frames
for the same relative_steps run on a loaded machine).  The tests hold the campaign to what
it guarantees: every dwell and every profile sample in the log, sample-exact playback,
no frame lost, and outcomes with a margin to spare."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from groundstation.campaign import (CampaignError, CampaignReport, CampaignRunner,
                                    load_campaign)
from groundstation.cli.main import main
from groundstation.logs import LogReader
from groundstation import Testbed

ROOT = Path(__file__).resolve().parents[2]
CAMPAIGNS = ROOT / "profiles" / "campaigns"


def run_campaign(path, tmp_path, *, max_step_seconds=1.0, resume=None, operator=None):
    c = load_campaign(path)
    with Testbed("sim", testbed=c.testbed, fast=True, log_folder=tmp_path / "logs",
                 history=tmp_path / "history", operator=operator) as tb:
        report = CampaignRunner(c, tb, max_step_seconds=max_step_seconds).run(resume)
        generator_on = tb.generator.get_output(1) if tb.generator is not None else None
        armed = tb.simulator.firmware.armed            # the device itself, not telemetry in flight
    return report, generator_on, armed


def check_log(path, name_part, min_frames=600):
    """A valid log of this campaign, with at least the frames its dwells or profiles
    guarantee (the real-time parts between steps add a machine-dependent number)."""
    with LogReader(path) as log:
        assert name_part in Path(path).name
        assert log.n_frames("HIGH_RATE") >= min_frames
        tables = log.journal("parameter_table")
        assert tables and tables[0].data["source"] == "active at recording start"
        return log.attrs, tables


def test_relative_steps_campaign(tmp_path):
    report, _, armed = run_campaign(CAMPAIGNS / "relative_steps.toml", tmp_path)
    assert report.status == "completed", report.summary()
    assert report.completed_runs == [1, 2] and not armed
    assert len(report.recordings) == 2
    rate = 1200
    for rec, design in zip(report.recordings, ("relative_design1", "relative_design2")):
        assert rec["discarded_blocks"] == 0 and rec["dropped"] == 0
        attrs, tables = check_log(rec["files"][0], design)
        assert len(tables) == 2 and design in tables[1].data["source"]     # the run's upload
        with LogReader(rec["files"][0]) as log:
            d = log.read("HIGH_RATE", ["tick", "encoder_inner", "coarse_saturated", "fine_saturated",
                                       "armed", "profile_index"])
        # no frame missing, and the profile (capped at 1 s) played sample-exact: every
        # sample once, in order, on consecutive ticks
        assert (np.diff(d["tick"].astype(np.int64)) == 1).all()
        played = d["profile_index"][d["profile_index"] > 0].astype(np.int64)
        assert played.tolist() == list(range(1, rate + 1))
        # the reference's raw 0.5 mrad step (at 0.5 s): Design #1's coarse motor
        # saturates for a few control periods right after the jump, its fine motor never;
        # Design #2 saturates neither (test_relative_raw_step.py holds the whole response)
        step = rate // 2
        coarse = d["profile_index"][d["coarse_saturated"]].astype(np.int64)
        assert not d["fine_saturated"].any()
        if design == "relative_design2":
            assert len(coarse) == 0
        else:
            assert 1 <= len(coarse) <= 12 and ((coarse > step) & (coarse <= step + rate // 50)).all(), coarse
        # the axis follows the step and comes back
        moved = d["encoder_inner"][d["armed"] > 0]
        assert 0.45e-3 < moved.max() - moved.min() < 0.8e-3
    saved = report.save(tmp_path / "report.json")
    again = CampaignReport.load(saved)
    assert again.completed_runs == [1, 2] and "COMPLETED" in saved.with_suffix(".txt").read_text()


def test_inertial_campaign_produces_twelve_logs_from_verified_start_states(tmp_path):
    """Twelve runs (an open-loop baseline and three designs under BM1-BM3), twelve valid
    logs.  Every run that starts was checked at rest, in range and unfaulted first (its
    log says so); the baseline uploads nothing and never arms.  A run that cannot hold
    the base motion, or cannot start because the rig is not ready, is a result in the
    report with its reason (on_run_failure = "next_run"), made safe, and the campaign
    goes on."""
    report, generator_on, armed = run_campaign(CAMPAIGNS / "inertial_bm.toml", tmp_path,
                                               max_step_seconds=0.5)
    assert report.status in ("completed", "completed_with_failures"), report.summary()
    assert len(report.recordings) == 12
    assert sorted(report.completed_runs + [int(r) for r in report.failed_runs]) == list(range(1, 13))
    assert generator_on is False and not armed
    names = [Path(r["files"][0]).name for r in report.recordings]
    assert [n.split("_run")[0].split("inertial_bm_")[1] for n in names[:3]] == \
        ["open_loop_BM1", "open_loop_BM2", "open_loop_BM3"]
    assert any("inertial_design2_friction_comp_BM3" in n for n in names)
    for run, rec in enumerate(report.recordings, 1):
        _, tables = check_log(rec["files"][0], "inertial_bm_", min_frames=1)
        with LogReader(rec["files"][0]) as log:
            d = log.read("HIGH_RATE", ["armed", "fault"])
            texts = [e.data.get("text", "") for e in log.journal("event")]
        baseline = run <= 3
        if baseline:
            assert len(tables) == 1 and not d["armed"].any()      # nothing uploaded, never armed
        if run in report.completed_runs:
            assert any(t.startswith("start state verified:") for t in texts)
            if not baseline:
                assert any("accepted" in t.data.get("source", "") for t in tables)
                # both dwells (5 s settling and 60 s of base motion, capped at 0.5 s each)
                # were played armed in full
                assert np.count_nonzero(d["armed"]) >= 2 * 600
        else:
            reason = report.failed_runs[str(run)]
            if "settle" in reason:          # the rig was not ready: the run never started
                assert "out of range" in reason or "not at rest" in reason
            else:                           # a run that faulted: the log goes on to the fault
                assert "fault" in reason and d["fault"][-1]


def failing_campaign(tmp_path) -> Path:
    text = f'''
[campaign]
name = "inject"
testbed = "{ROOT / 'profiles/testbeds/inertial_2dof.toml'}"

[matrix]
design = ["{ROOT / 'profiles/controllers/recentre_inertial.toml'}",
          "{ROOT / 'profiles/controllers/inertial_design1.toml'}"]

[[run]]
action = "start_recording"
name = "inject_{{run}}"

[[run]]
action = "generator_set"
waveform = "SINE"
frequency_hz = 1.0
amplitude_vpp = 0.2

[[run]]
action = "dwell"
seconds = 0.5

[[run]]
action = "pause"
prompt = "check the stage"

[[run]]
action = "upload_design"
design = "{{design}}"

[[run]]
action = "stop_recording"
'''
    path = tmp_path / "inject.toml"
    path.write_text(text)
    return path


def test_a_failure_mid_campaign_leaves_the_rig_safe_and_resume_continues(tmp_path):
    path = failing_campaign(tmp_path)
    # run 2 uploads an inertial design that validation refuses (no accept_risk): it fails
    report, generator_on, armed = run_campaign(path, tmp_path, operator=lambda prompt: True)
    assert report.status == "failed" and report.failed_run == 2
    assert "refused by validation" in report.reason
    assert generator_on is False and not armed
    assert report.completed_runs == [1]
    files = [f for r in report.recordings for f in r["files"]]
    assert len(files) == 2
    for f in files:                                        # every log valid, the failed one too
        with LogReader(f) as log:
            assert log.n_frames("HIGH_RATE") > 300
    with LogReader(files[1]) as log:
        texts = [e.data.get("text", "") for e in log.journal("event")]
    assert any(t.startswith("stopped: step") for t in texts)
    # the operator aborts at the pause: status aborted, the rig safe
    report2, generator_on, _ = run_campaign(path, tmp_path, operator=lambda prompt: False)
    assert report2.status == "aborted" and report2.failed_run == 1 and generator_on is False
    # resume the first report: run 1 is skipped, run 2 runs again (and fails again, the
    # design is still refused) - nothing of run 1 is repeated
    report3, _, _ = run_campaign(path, tmp_path, resume=report, operator=lambda prompt: True)
    assert [s.status for s in report3.steps[:6]] == ["skipped"] * 6
    assert report3.failed_run == 2 and report3.completed_runs == [1]


def test_resume_finishes_an_aborted_campaign(tmp_path):
    path = failing_campaign(tmp_path)
    text = path.read_text().replace("inertial_design1.toml", "recentre_inertial.toml")
    path.write_text(text)
    answers = iter([True, False, True])                   # run 1 ok, abort in run 2, then ok
    report, _, _ = run_campaign(path, tmp_path, operator=lambda prompt: next(answers))
    assert report.status == "aborted" and report.failed_run == 2 and report.completed_runs == [1]
    done, _, _ = run_campaign(path, tmp_path, resume=report, operator=lambda prompt: next(answers))
    assert done.status == "completed" and done.completed_runs == [1, 2]
    assert len(done.recordings) == 3                      # 2 from the first attempt, 1 now


@pytest.mark.parametrize("text, message", [
    ("[campaign]\nname='x'\n", "testbed"),
    ("[campaign]\nname='x'\ntestbed='../testbeds/relative_2dof.toml'\n[[run]]\naction='fly'\n", "not one of"),
    ("[campaign]\nname='x'\ntestbed='../testbeds/relative_2dof.toml'\n[[run]]\naction='dwell'\n", "missing seconds"),
    ("[campaign]\nname='x'\ntestbed='../testbeds/relative_2dof.toml'\n[[run]]\naction='dwell'\nseconds=1\nspeed=2\n",
     "unknown key"),
    ("[campaign]\nname='x'\ntestbed='../testbeds/relative_2dof.toml'\n[[run]]\naction='mark'\ntext='{nope}'\n",
     "placeholder"),
    ("[campaign]\nname='x'\ntestbed='../testbeds/relative_2dof.toml'\n[[run]]\naction='upload_design'\n"
     "design='missing.toml'\n", "no file"),
])
def test_malformed_campaigns_name_the_step_and_field(tmp_path, text, message):
    folder = tmp_path / "campaigns"
    folder.mkdir()
    (tmp_path / "testbeds").mkdir()
    (tmp_path / "testbeds" / "relative_2dof.toml").write_text(
        (ROOT / "profiles/testbeds/relative_2dof.toml").read_text())
    path = folder / "bad.toml"
    path.write_text(text)
    with pytest.raises(CampaignError, match=message):
        load_campaign(path)


def test_cli_show_and_run(tmp_path, capsys):
    assert main(["campaign", "show", str(CAMPAIGNS / "inertial_bm.toml")]) == 0
    out = capsys.readouterr().out
    assert "12 run(s)" in out and "play_base_motion" in out
    code = main(["campaign", "run", str(CAMPAIGNS / "relative_steps.toml"), "--fast",
                 "--log-folder", str(tmp_path / "logs"), "--max-step-seconds", "0.5"])
    out = capsys.readouterr().out
    assert code == 0, out
    assert "COMPLETED" in out and (tmp_path / "logs" / "report.json").is_file()
    bad = tmp_path / "bad.toml"
    bad.write_text("[campaign]\n")
    assert main(["campaign", "run", str(bad), "--fast"]) == 2


@pytest.mark.parametrize("name", ["friction_hysteresis_1dof", "friction_hysteresis_2dof",
                                  "steady_state_friction", "open_loop_sysid"])
def test_thesis_procedures_run_end_to_end(tmp_path, name):
    """Each shipped procedure, its profiles shortened to 0.5 s by the test override (the
    campaign file is unchanged): every run completes with one valid log that carries the
    table and the profile played."""
    c = load_campaign(CAMPAIGNS / f"{name}.toml")
    report, _, armed = run_campaign(CAMPAIGNS / f"{name}.toml", tmp_path, max_step_seconds=0.5)
    assert report.status == "completed", report.summary()
    assert report.completed_runs == list(range(1, c.runs + 1)) and not armed
    assert len(report.recordings) == c.runs
    for rec in report.recordings:
        assert rec["dropped"] == 0 and rec["discarded_blocks"] == 0
        check_log(rec["files"][0], name)
        with LogReader(rec["files"][0]) as log:
            played = [p.data for p in log.journal("profile")]
            index = log.read("HIGH_RATE", ["profile_index"])["profile_index"].astype(np.int64)
        assert any(p.get("action") == "played" for p in played), played
        # sample-exact: every sample of the (0.5 s) profile once, in order
        assert index[index > 0].tolist() == list(range(1, 600 + 1))
