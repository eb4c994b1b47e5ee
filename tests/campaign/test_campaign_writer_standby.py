"""A campaign starts its first log writer ahead and hands each writer that ended a run's
recording cleanly to the next run (logs/standby.py), and leaves no writer behind when
its session closes."""

from __future__ import annotations

from pathlib import Path

from conftest import process_alive, wait_for
from groundstation import Testbed
from groundstation.campaign import CampaignRunner, load_campaign
from groundstation.logs import LogReader

CAMPAIGNS = Path(__file__).resolve().parents[2] / "profiles" / "campaigns"


def test_each_run_records_with_a_writer_started_ahead(tmp_path):
    c = load_campaign(CAMPAIGNS / "relative_steps.toml")
    with Testbed("sim", testbed=c.testbed, fast=True, log_folder=tmp_path / "logs",
                 history=tmp_path / "history") as tb:
        report = CampaignRunner(c, tb, max_step_seconds=1.0).run()
        standby = tb.recording.standby
        figures = standby.used, standby.spawned, standby.reused
        left_over = standby.waiting_pids()
    assert report.status == "completed", report.summary()
    # one spare before run 1 and one more when run 1 took it; run 2 took run 1's writer
    # back: two processes for two runs, the second never waited for
    assert figures == (2, 2, 1)
    assert len(left_over) == 2
    for pid in left_over:                      # the session's close ended the writers left
        wait_for(lambda pid=pid: not process_alive(pid))
    for rec in report.recordings:
        with LogReader(rec["files"][0]) as log:
            assert log.n_frames("HIGH_RATE") >= 600
            assert log.journal("parameter_table")
