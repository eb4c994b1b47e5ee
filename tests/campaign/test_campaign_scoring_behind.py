"""Each log scored while the next run records (campaign/scoring_behind.py): a real
campaign on the fast simulator whose recordings are handed to ScoringBehind as they end.
The rows it scored are the ones scoring every log again at the end gives, its run
statuses filled in at the end; what it did not score (a log not handed over) is scored
at the end; a missing log is a row with its error; a closed one scores nothing and
never raises."""

from __future__ import annotations

import json

import pytest

from groundstation import Testbed
from groundstation.campaign import CampaignRunner, load_campaign
from groundstation.campaign.metrics import campaign_metrics
from groundstation.campaign.scoring_behind import ScoringBehind

# the metrics tests' 2 x 2 campaign: relative Design #1 and #2, each after two step sizes
from test_campaign_metrics import CAMPAIGN, RUNS


@pytest.fixture(scope="module")
def behind_run(tmp_path_factory):
    """The campaign run once with its recordings handed to a ScoringBehind as they
    ended: (campaign, report, the ScoringBehind, what it was handed)."""
    base = tmp_path_factory.mktemp("behind")
    path = base / "metrics_check.toml"
    path.write_text(CAMPAIGN)
    c = load_campaign(path)
    behind = ScoringBehind(c)
    handed: list[dict] = []

    def hand_over(recording: dict) -> None:
        handed.append(recording)
        behind.submit(recording)

    with Testbed("sim", testbed=c.testbed, fast=True, log_folder=base / "logs",
                 history=base / "history") as tb:
        report = CampaignRunner(c, tb, on_recording=hand_over).run()
    assert report.status == "completed", report.reason
    yield c, report, behind, handed
    behind.close()


def _comparable(rows: list[dict]) -> str:
    return json.dumps(rows, sort_keys=True, default=str)


def test_each_recording_is_handed_over_as_the_report_lists_it(behind_run):
    c, report, _, handed = behind_run
    assert len(handed) == 4
    assert handed == report.recordings
    assert [(r["run"], r["variables"]["design_stem"], r["variables"]["ref"]) for r in handed] == \
        [(run, *RUNS[run]) for run in sorted(RUNS)]


def test_rows_scored_behind_are_the_rows_scored_at_the_end(behind_run):
    c, report, behind, _ = behind_run
    taken_before = behind.taken
    ahead = campaign_metrics(report, c, scored=behind)
    assert behind.taken - taken_before == 4          # every log came from the thread
    again = campaign_metrics(report, c)
    assert _comparable(ahead.rows) == _comparable(again.rows)
    assert ahead.comparison == again.comparison
    assert all(r["run_status"] == "completed" for r in ahead.rows)
    assert all(not r["error"] for r in ahead.rows)
    # each row is handed back once: a second pass scores them itself
    campaign_metrics(report, c, scored=behind)
    assert behind.taken - taken_before == 4


def test_a_log_not_handed_over_is_scored_at_the_end(behind_run, tmp_path):
    c, report, _, _ = behind_run
    fresh = ScoringBehind(c)
    try:
        fresh.submit(report.recordings[0])
        metrics = campaign_metrics(report, c, scored=fresh)
    finally:
        fresh.close()
    assert fresh.taken == 1
    assert _comparable(metrics.rows) == _comparable(campaign_metrics(report, c).rows)


def test_a_missing_log_is_a_row_with_its_error_either_way(behind_run, tmp_path):
    c, report, _, _ = behind_run
    gone = dict(report.recordings[0], files=[str(tmp_path / "no_such_log.h5")])
    fresh = ScoringBehind(c)
    try:
        fresh.submit(gone)
        row = fresh.take(gone["files"][0], gone["run"], gone["variables"], gone["name"], None)
    finally:
        fresh.close()
    assert row is not None and row[0]["error"]
    assert "no_such_log.h5" in row[0]["file"]


def test_a_closed_one_takes_nothing_and_never_raises(behind_run):
    c, report, _, _ = behind_run
    closed = ScoringBehind(c)
    closed.close()
    closed.submit(report.recordings[0])              # no error, nothing queued
    rec = report.recordings[0]
    assert closed.take(rec["files"][0], rec["run"], rec["variables"], rec["name"], None) is None
    closed.close()                                   # twice: fine
    assert closed.taken == 0


def test_scorings_imports_are_done_as_soon_as_it_is_made():
    """Made before the session starts, its thread imports scipy.signal and the analysis
    while the simulator's child starts - not when the first log arrives, in the middle
    of the next run.  In a fresh interpreter: nothing of it before, all of it after,
    with no log handed over."""
    import subprocess
    import sys
    from pathlib import Path

    root = Path(__file__).resolve().parents[2]
    code = ("import sys\n"
            "from groundstation.campaign import load_campaign\n"
            "from groundstation.campaign.scoring_behind import ScoringBehind\n"
            f"c = load_campaign({str(root / 'profiles' / 'campaigns' / 'relative_steps.toml')!r})\n"
            "before = [m in sys.modules for m in ('scipy.signal', 'groundstation.analysis.log_metrics')]\n"
            "b = ScoringBehind(c)\n"
            "b._pool.submit(lambda: None).result()     # one worker, in order: what came first is done\n"
            "b.close()\n"
            "print(before, [m in sys.modules for m in ('scipy.signal', 'groundstation.analysis.log_metrics')])")
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True,
                         timeout=120, cwd=root).stdout.split("\n")[-2]
    assert out == "[False, False] [True, True]"
