"""A .json file beside the logs that is not a campaign report (issue 29, part 4):
`groundstation analyze logs --table out` gives the table of the real logs and a note
naming each skipped file, instead of an AttributeError and no table."""

from __future__ import annotations

from pathlib import Path

import pytest

from groundstation.analysis.batch import campaign_reports, find_logs
from groundstation.analysis.batch_table import read_table
from groundstation.campaign.report import CampaignReport
from groundstation.cli.main import main
from groundstation import Testbed

ROOT = Path(__file__).resolve().parents[2]

#: files a folder of logs may hold beside a campaign's report, none of them a report
FOREIGN = {
    "other.json": '{"recordings": ["run1.h5"]}',                       # the file
    "list.json": '["run1.h5"]',
    "typed.json": '{"campaign": "x", "file": "c.toml", "started": 0, "recordings": 5}',
    "entry.json": '{"campaign": "x", "file": "c.toml", "started": 0, '
                  '"recordings": [{"run": 1, "files": [7]}]}',
    "broken.json": '{"recordings": [',
    "deep.json": "[" * 100_000 + "]" * 100_000,
    "latin1.json": b'{"caf\xe9": 1}',
}


@pytest.fixture(scope="module")
def logs(tmp_path_factory) -> Path:
    """One real log, the campaign report that lists it, and the foreign files."""
    folder = tmp_path_factory.mktemp("logs")
    with Testbed("sim", testbed=ROOT / "profiles/testbeds/inertial_2dof.toml", fast=True,
                 seed=5, generator=None, log_folder=folder,
                 history=folder.parent / "history") as tb:
        tb.start_recording("real", notes="open loop, seed=5")
        tb.set_mode("OPEN_LOOP")
        tb.arm()
        tb.set_currents(0.05, 0.01)
        tb.dwell(1.0)
        entry = tb.stop_recording()
    report = CampaignReport(campaign="foreign_test", file="foreign_test.toml", started=0.0,
                            status="completed",
                            recordings=[{"run": 1, "files": entry["files"],
                                         "variables": {"design_stem": "pid_a", "seed": 5}}])
    report.save(folder / "report.json")
    for name, text in FOREIGN.items():
        path = folder / name
        path.write_bytes(text) if isinstance(text, bytes) else path.write_text(text)
    return folder


def test_foreign_json_files_are_skipped_each_with_why(logs):
    paths = find_logs([logs])
    known, skipped = campaign_reports(paths)
    assert sorted(p.name for p, _ in skipped) == sorted(FOREIGN)
    why = {p.name: reason for p, reason in skipped}
    assert "no 'campaign', 'file', 'started': not a campaign report" in why["other.json"]
    assert "a JSON list" in why["list.json"]
    assert "'recordings' not a list" in why["typed.json"]
    assert "recording 1 is not a campaign report's" in why["entry.json"]
    assert why["broken.json"].startswith("not JSON") and why["deep.json"].startswith("not JSON")
    assert why["latin1.json"].startswith("not JSON")
    (ident,) = known.values()                           # the real report still counts
    assert ident == {"campaign": "foreign_test", "campaign_run": 1, "design": "pid_a",
                     "base_motion": None, "seed": 5}


def test_analyze_table_gives_the_real_logs_and_notes_the_skipped_files(logs, tmp_path, capsys):
    out = tmp_path / "out"
    # the command (one local Dask worker: the machine may be busy)
    code = main(["analyze", str(logs), "--table", str(out), "--workers", "1",
                 "--sensor", "encoder_inner"])
    captured = capsys.readouterr()
    assert code == 0, captured.err
    assert "Traceback" not in captured.err + captured.out
    for name in FOREIGN:
        assert f"note: skipped {logs / name}: " in captured.err
    assert "1 logs, 1 analysed without error, 0 with errors" in captured.out
    table = read_table(out.with_name("out.csv"))
    assert table["log"].tolist() == [Path(p).name for p in find_logs([logs])]
    assert table["campaign"].tolist() == ["foreign_test"]
    assert table["design"].tolist() == ["pid_a"] and table["seed"].tolist() == [5]
    assert out.with_name("out.parquet").exists()
