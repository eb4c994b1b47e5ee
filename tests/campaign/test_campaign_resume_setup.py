"""Resuming a campaign on the set-up it ran with, and Ctrl-C that returns at once
(issue 29, parts 5 and 6).

A resumed report compares runs from before and after the resume, so both halves must
come from the same device, clock, seed and testbed: the report keeps them, the resume
takes them, a contradicting option is refused unless asked for explicitly, and the hint
printed after a failure is a command that works when pasted.  An interrupted campaign
writes its report and leaves the scoring to `campaign report`."""

from __future__ import annotations

import json
import os
import shlex
import signal
import subprocess
import sys
from pathlib import Path

import pytest

from groundstation.campaign import CampaignError
from groundstation.campaign.run_setup import resolve_setup, resume_command
from groundstation.cli.main import main

ROOT = Path(__file__).resolve().parents[2]
PROFILES = ROOT / "profiles"


def failing_at_run_2(tmp_path: Path) -> Path:
    """Run 1 uploads a design validation accepts; run 2 one it refuses (no accept_risk)."""
    path = tmp_path / "fails.toml"
    path.write_text(f'''
[campaign]
name = "fails"
testbed = "{PROFILES / 'testbeds/inertial_2dof.toml'}"

[matrix]
design = ["{PROFILES / 'controllers/recentre_inertial.toml'}",
          "{PROFILES / 'controllers/inertial_design1.toml'}"]

[[run]]
action = "start_recording"
name = "fails_{{run}}"

[[run]]
action = "dwell"
seconds = 0.2

[[run]]
action = "upload_design"
design = "{{design}}"

[[run]]
action = "stop_recording"
''')
    return path


def resume_hint(out: str) -> list[str]:
    (line,) = [ln for ln in out.splitlines() if ln.startswith("resume with: ")]
    words = shlex.split(line[len("resume with: "):])
    assert words[:3] == ["groundstation", "campaign", "run"]
    return words[1:]


def test_the_report_keeps_its_setup_and_the_pasted_hint_resumes_on_it(tmp_path, capsys):
    campaign = failing_at_run_2(tmp_path)
    folder = tmp_path / "logs"
    code = main(["campaign", "run", str(campaign), "--fast", "--fast-sim", "inline", "--seed", "3",
                 "--no-analysis", "--log-folder", str(folder)])
    out = capsys.readouterr().out
    assert code == 1, out
    report = json.loads((folder / "report.json").read_text())
    assert report["setup"] == {"device": "sim", "fast": True, "fast_sim": "inline", "seed": 3,
                               "testbed": None, "log_folder": str(folder)}
    hint = resume_hint(out)
    assert "--fast" in hint and hint[hint.index("--seed") + 1] == "3"
    assert hint[hint.index("--device") + 1] == "sim"
    # pasted as printed: runs 2 again on the same set-up (and fails again: still refused)
    code = main(hint + ["--no-analysis"])
    out = capsys.readouterr().out
    assert code == 1, out
    assert "resuming with the report's set-up: device sim, fast (simulator inline), seed 3" in out
    resumed = json.loads((folder / "report.json").read_text())
    assert resumed["completed_runs"] == [1] and resumed["failed_run"] == 2
    assert resumed["setup"]["seed"] == 3
    assert [s["status"] for s in resumed["steps"][:4]] == ["skipped"] * 4


def test_a_resume_on_another_device_is_refused_before_anything_runs(tmp_path, capsys):
    campaign = failing_at_run_2(tmp_path)
    folder = tmp_path / "logs"
    assert main(["campaign", "run", str(campaign), "--fast", "--fast-sim", "inline",
                 "--no-analysis", "--log-folder", str(folder)]) == 1
    capsys.readouterr()
    report = folder / "report.json"
    before = report.read_text()
    code = main(["campaign", "run", str(campaign), "--resume", str(report),
                 "--device", "tcp://127.0.0.1:1"])
    err = capsys.readouterr().err
    assert code == 2
    assert "--device sim" in err and "--device tcp://127.0.0.1:1" in err
    assert "--allow-setup-change" in err
    assert report.read_text() == before                   # nothing ran, nothing rewritten
    code = main(["campaign", "run", str(campaign), "--resume", str(report), "--seed", "7"])
    assert code == 2 and "--seed 0" in capsys.readouterr().err


def test_setup_resolution():
    assert resolve_setup({}, None)[0]["device"] == "sim"
    setup, notes = resolve_setup({"device": "sim"}, {})
    assert "does not record the set-up" in notes[0]
    stored = {"device": "tcp://10.0.0.2:5020", "fast": False, "fast_sim": "process", "seed": 0,
              "testbed": None, "log_folder": "logs/x"}
    setup, notes = resolve_setup({}, stored)
    assert setup == stored and notes[0].startswith("resuming with the report's set-up: device tcp://")
    with pytest.raises(CampaignError, match="two different set-ups"):
        resolve_setup({"device": "sim", "fast": True}, stored)
    setup, notes = resolve_setup({"device": "sim"}, stored, allow_change=True)
    assert setup["device"] == "sim" and "tcp://10.0.0.2:5020 -> sim" in notes[1]
    # a log folder elsewhere is not a different rig
    setup, _ = resolve_setup({"log_folder": "elsewhere"}, stored)
    assert setup["log_folder"] == "elsewhere"
    command = resume_command("c.toml", "my logs/report.json", stored)
    assert shlex.split(command) == ["groundstation", "campaign", "run", "c.toml", "--resume",
                                    "my logs/report.json", "--device", "tcp://10.0.0.2:5020",
                                    "--seed", "0", "--log-folder", "logs/x"]


def test_ctrl_c_writes_the_report_at_once_and_leaves_the_scoring(tmp_path):
    """A real process interrupted as a terminal does it (SIGINT) mid-campaign: exit 130,
    the report written with status interrupted, no scoring, the command to score it."""
    folder = tmp_path / "logs"
    proc = subprocess.Popen(
        [sys.executable, "-m", "groundstation", "campaign", "run",
         str(PROFILES / "campaigns" / "relative_steps.toml"), "--fast", "--log-folder", str(folder)],
        stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True, cwd=tmp_path,
        env={**os.environ, "PYTHONUNBUFFERED": "1"})
    seen = []
    try:
        for line in proc.stdout:                 # bounded: the campaign ends by itself
            seen.append(line)
            if "recording " in line:            # a run's log is open: interrupt mid-run
                proc.send_signal(signal.SIGINT)
                break
        out = "".join(seen) + proc.communicate(timeout=300)[0]
    finally:
        if proc.poll() is None:
            proc.kill()
    assert proc.returncode == 130, out
    report = json.loads((folder / "report.json").read_text())
    assert report["status"] == "interrupted"
    assert "metrics not computed after the interrupt: groundstation campaign report" in out
    assert not (folder / "report.metrics.json").exists()
    assert "Traceback" not in out
