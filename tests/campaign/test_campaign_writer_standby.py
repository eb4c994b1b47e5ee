"""A campaign starts each run's log writer ahead, during the run before it (logs/standby.py),
and leaves no spare writer behind when its session closes."""

from __future__ import annotations

from pathlib import Path

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
        used, spawned, left_over = standby.used, standby.spawned, standby._spare.proc
    assert report.status == "completed", report.summary()
    # one spare before run 1, one more at each run's start: both runs wrote with a spare
    assert (used, spawned) == (2, 3)
    assert not left_over.is_alive()            # the session's close ended the spare left over
    for rec in report.recordings:
        with LogReader(rec["files"][0]) as log:
            assert log.n_frames("HIGH_RATE") >= 600
            assert log.journal("parameter_table")
