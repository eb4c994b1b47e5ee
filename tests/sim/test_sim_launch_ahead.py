"""A fast simulator's child launched ahead (sim/launch_ahead.py): the session that asks
for exactly that simulator takes it instead of starting one; one asking for another
simulator starts its own; a child nobody took is ended - and `campaign run --fast`
leaves none behind, whether its campaign ran or was refused by the check."""

from __future__ import annotations

import os
from pathlib import Path

from conftest import process_alive, wait_for
from groundstation import Testbed
from groundstation.cli.entry import main
from groundstation.sim import launch_ahead
from groundstation.station.options import FastSimOptions

ROOT = Path(__file__).resolve().parents[2]
RELATIVE = ROOT / "profiles" / "testbeds" / "relative_2dof.toml"
IN_A_CHILD = FastSimOptions(where="process")      # what `campaign run --fast` uses


def _simulator_children() -> list[int]:
    """Our child processes running the fast simulator."""
    out = []
    for entry in Path("/proc").iterdir():
        if not entry.name.isdigit():
            continue
        try:
            ppid = int((entry / "stat").read_text().rsplit(")", 1)[1].split()[1])
            cmd = (entry / "cmdline").read_bytes()
        except (OSError, IndexError, ValueError):
            continue
        if ppid == os.getpid() and b"groundstation.sim.stepped_process" in cmd:
            out.append(int(entry.name))
    return out


def test_the_session_takes_the_simulator_launched_for_it(tmp_path):
    launch_ahead.launch_ahead(testbed=RELATIVE, seed=3)    # before any dictionary is loaded
    [launched] = [d.proc.pid for d in launch_ahead._waiting]
    with Testbed("sim", testbed=RELATIVE, fast=IN_A_CHILD, seed=3, log_folder=tmp_path,
                 history=tmp_path / "history", echo=lambda text: None) as tb:
        assert tb.simulator.proc.pid == launched
        assert tb.simulator.dictionary is not None             # the session's, given on taking
        assert launch_ahead._waiting == []
        tb.dwell(0.5)                                      # and it runs the session
    wait_for(lambda: not process_alive(launched))


def test_a_session_asking_for_another_simulator_starts_its_own(tmp_path):
    launch_ahead.launch_ahead(testbed=RELATIVE, seed=3)
    [launched] = [d.proc.pid for d in launch_ahead._waiting]
    try:
        with Testbed("sim", testbed=RELATIVE, fast=IN_A_CHILD, seed=4, log_folder=tmp_path,
                     history=tmp_path / "history", echo=lambda text: None) as tb:
            assert tb.simulator.proc.pid != launched
    finally:
        launch_ahead.discard()
    assert launch_ahead._waiting == []
    wait_for(lambda: not process_alive(launched))


def test_campaign_run_leaves_no_simulator_behind_run_or_refused(tmp_path, monkeypatch):
    monkeypatch.chdir(tmp_path)
    ok = ROOT / "profiles" / "campaigns" / "relative_steps.toml"
    assert main(["campaign", "run", str(ok), "--device", "sim", "--fast", "--no-analysis",
                 "--log-folder", str(tmp_path / "logs")]) == 0
    # a campaign the check refuses: its testbed is a real one, a design is missing
    bad = tmp_path / "bad.toml"
    bad.write_text(ok.read_text().replace("../testbeds/", f"{RELATIVE.parent}/")
                   .replace("../controllers/relative_design1.toml", "no_such_design.toml")
                   .replace("../controllers/", f"{ROOT / 'profiles' / 'controllers'}/")
                   .replace("../waveforms/", f"{ROOT / 'profiles' / 'waveforms'}/"))
    launched = []
    real_launch = launch_ahead.launch_ahead

    def launch_and_note(*args, **kw):                  # the real launch, observed
        real_launch(*args, **kw)
        launched.append(launch_ahead._waiting[-1].proc.pid)

    monkeypatch.setattr(launch_ahead, "launch_ahead", launch_and_note)
    assert main(["campaign", "run", str(bad), "--device", "sim", "--fast", "--no-analysis"]) != 0
    assert len(launched) == 1                          # launched, then refused by the check
    assert launch_ahead._waiting == []
    wait_for(lambda: not process_alive(launched[0]))
    wait_for(lambda: _simulator_children() == [])
