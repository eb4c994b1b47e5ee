"""`groundstation analyze FOLDER --table OUT` on Dask (analysis/batch*.py): a folder of
short logs from the fast simulator - a two-run campaign with its report, a script's log
in a subfolder - plus a file that is not HDF5 and a log cut off half-way.  The local
cluster's table must equal the serial loop's exactly, the bad files must be rows with
their errors, and the CLI's Parquet and CSV must read back as that table."""

from __future__ import annotations

import json
import os
import shutil
from pathlib import Path

import pandas as pd
import pytest

from groundstation import Testbed
from groundstation.analysis.batch import (TABLE_KEYS, BatchOptions, analyze_one, campaign_index,
                                          find_logs, run_serial)
from groundstation.analysis.allocator import MMAP_THRESHOLD_BYTES, TRIM_THRESHOLD_BYTES
from groundstation.analysis.batch_dask import (dask_client, local_cluster_pays, log_groups,
                                               run_dask, run_on)
from groundstation.analysis.batch_table import read_table, rows_frame, table_paths
from groundstation.campaign import CampaignRunner, load_campaign
from groundstation.cli.main import main

ROOT = Path(__file__).resolve().parents[2]
SEED_CAMPAIGN, SEED_SCRIPT = 7, 3
#: the relative testbed has no autocollimator: every log is scored on the inner encoder
OPTIONS = BatchOptions(sensor="encoder_inner")
SENSOR = ["--sensor", "encoder_inner"]

CAMPAIGN = """
[campaign]
name = "batch_test"
description = "two short runs: open loop and relative Design #2"
testbed = "{root}/profiles/testbeds/relative_2dof.toml"

[matrix]
design = ["open_loop", "{root}/profiles/controllers/relative_design2.toml"]

[[setup]]
action = "connect"

[[run]]
action = "start_recording"
name = "{{campaign}}_{{design_stem}}"
notes = "{{design_stem}} at rest"

[[run]]
action = "upload_design"
design = "{{design}}"
skip_if = {{design = "open_loop"}}

[[run]]
action = "set_mode"
mode = "RELATIVE"
skip_if = {{design = "open_loop"}}

[[run]]
action = "dwell"
seconds = 1.0

[[run]]
action = "stop_recording"
"""


@pytest.fixture(scope="module")
def folder(tmp_path_factory) -> Path:
    """campaign/ (two logs and report.json), script/ (one log), corrupt.h5, half.h5."""
    top = tmp_path_factory.mktemp("batch_logs")
    camp = top / "campaign"
    camp.mkdir()
    spec = top / "batch_test.toml"
    spec.write_text(CAMPAIGN.format(root=ROOT))
    c = load_campaign(spec)
    with Testbed("sim", testbed=c.testbed, fast=True, seed=SEED_CAMPAIGN, generator=None,
                 log_folder=camp, history=top / "history") as tb:
        report = CampaignRunner(c, tb).run()
    assert report.status == "completed", report.summary()
    # as `campaign run` writes it (cli/campaign.py): how it was run, the seed included
    report.setup = {"device": "sim", "fast": True, "seed": SEED_CAMPAIGN}
    report.save(camp / "report.json")
    script = top / "script"
    with Testbed("sim", testbed=ROOT / "profiles/testbeds/inertial_2dof.toml", fast=True,
                 seed=SEED_SCRIPT, generator=None, log_folder=script,
                 history=top / "history") as tb:
        tb.start_recording("script", notes=f"open loop, constant currents, seed={SEED_SCRIPT}")
        tb.set_mode("OPEN_LOOP")
        tb.arm()
        tb.set_currents(0.05, 0.01)
        tb.dwell(1.5)
        entry = tb.stop_recording()
    whole = Path(entry["files"][0])
    (top / "corrupt.h5").write_bytes(b"this is not an HDF5 file\n" * 40)
    data = whole.read_bytes()
    (top / "half.h5").write_bytes(data[:len(data) // 2])      # a copy cut off half-way
    return top


@pytest.fixture(scope="module")
def serial_rows(folder):
    paths = find_logs([folder])
    return paths, run_serial(paths, OPTIONS, campaign_index(paths))


def test_the_folder_is_found_whole_and_sorted(folder, serial_rows):
    paths, _ = serial_rows
    assert [p.relative_to(folder).parts[0] for p in paths] == \
        ["campaign", "campaign", "corrupt.h5", "half.h5", "script"]
    assert find_logs([str(folder / "*.h5")]) == [folder / "corrupt.h5", folder / "half.h5"]
    assert find_logs([folder / "campaign", str(folder / "campaign/*.h5")]) == paths[:2]


def test_the_local_cluster_gives_the_serial_table_exactly(serial_rows):
    paths, rows = serial_rows
    seen = []
    dask_rows = run_dask(paths, OPTIONS, campaign_index(paths), workers=2,
                         progress=lambda done, total: seen.append((done, total)))
    assert seen == [(k, len(paths)) for k in range(1, len(paths) + 1)]
    assert [r["path"] for r in dask_rows] == [str(p) for p in paths]
    assert [list(r) for r in dask_rows] == [TABLE_KEYS] * len(paths)
    pd.testing.assert_frame_equal(rows_frame(dask_rows, TABLE_KEYS), rows_frame(rows, TABLE_KEYS),
                                  check_exact=True)


def _worker_environment() -> tuple[str | None, str | None, str | None]:
    return (os.environ.get("MALLOC_TRIM_THRESHOLD_"), os.environ.get("MALLOC_MMAP_THRESHOLD_"),
            os.environ.get("OPENBLAS_NUM_THREADS"))


def _worker_settings() -> tuple[str, str, bool]:
    import dask
    return (dask.config.get("distributed.admin.tick.interval"),
            dask.config.get("distributed.admin.system-monitor.interval"),
            dask.config.get("distributed.worker.profile.enabled"))


class _UnloadableInAWorker:
    """Pickles to int('not a number'): a worker cannot load the task that carries it,
    so the task fails there as a worker dying on a log would - with no flakiness."""

    def __reduce__(self):
        return int, ("not a number",)


def test_logs_grouped_in_tasks_give_the_serial_table_and_a_failed_task_its_logs_only(serial_rows):
    paths, rows = serial_rows
    known = campaign_index(paths)
    poisoned = {**known, str(paths[4]): _UnloadableInAWorker()}
    seen: list[tuple[int, int]] = []
    with dask_client("local", 2) as client:
        # distributed's MALLOC_TRIM_THRESHOLD_ cost a worker a third more CPU per log
        # (page faults of every large temporary): the serial loop's thresholds instead
        # (analysis/allocator.py); one BLAS thread kept
        assert set(client.run(_worker_environment).values()) == {
            (str(TRIM_THRESHOLD_BYTES), str(MMAP_THRESHOLD_BYTES), "1")}
        # no dashboard: no profiler, and the event loops' watchdog and the system
        # monitor slowed, which take the interpreter's lock from the task thread
        assert set(client.run(_worker_settings).values()) == {("1s", "5s", False)}
        grouped = run_on(client, paths, OPTIONS, known, tasks=2,
                         progress=lambda done, total: seen.append((done, total)))
        hit = run_on(client, paths, OPTIONS, poisoned, tasks=2)
    assert len(seen) == 2 and seen[-1] == (len(paths), len(paths))      # a step per task
    pd.testing.assert_frame_equal(rows_frame(grouped, TABLE_KEYS), rows_frame(rows, TABLE_KEYS),
                                  check_exact=True)
    # the failed group ran again a log a task: only the log that cannot run has no figures
    assert hit[4]["error"].startswith("task failed: ") and hit[4]["path"] == str(paths[4])
    pd.testing.assert_frame_equal(rows_frame(hit[:4], TABLE_KEYS), rows_frame(rows[:4], TABLE_KEYS),
                                  check_exact=True)


def test_log_groups_are_balanced_by_size_and_keep_every_log_once():
    sizes = [90, 10, 10, 10, 40, 40, 5, 5, 60, 30]
    groups = log_groups(sizes, 3)
    assert sorted(i for g in groups for i in g) == list(range(len(sizes)))
    loads = [sum(sizes[i] for i in g) for g in groups]
    assert max(loads) - min(loads) <= max(sizes) and max(loads) <= 105      # total 300: 100 each
    assert all(g == sorted(g) for g in groups) and [g[0] for g in groups] == sorted(g[0] for g in groups)
    assert log_groups([7, 7], 8) == [[0], [1]]                              # never an empty task
    assert log_groups([], 4) == []


def test_the_serial_loop_is_chosen_and_said_when_a_cluster_would_not_pay(folder, capsys, tmp_path):
    pays, serial_s, cluster_s = local_cluster_pays([10_000_000] * 5, workers=2)
    assert not pays and serial_s < cluster_s
    assert not local_cluster_pays([10_000_000] * 100_000, workers=1)[0]      # one worker: never
    # a lab's year of 60 s logs on two workers pays wherever there are two cores
    assert local_cluster_pays([10_000_000] * 6000, workers=2)[0] == ((os.cpu_count() or 1) > 1)
    out = tmp_path / "small.csv"
    assert main(["analyze", str(folder / "campaign"), "--table", str(out), *SENSOR]) == 0
    err = capsys.readouterr().err
    assert "2 logs (" in err and "analysed in this process" in err and "--scheduler local" in err
    assert "local worker process" not in err


def test_each_row_says_who_the_run_was(serial_rows):
    _, rows = serial_rows
    open_loop, design2, _, _, script = rows                  # in the order of the paths
    for row, run, design in ((open_loop, 1, "open_loop"), (design2, 2, "relative_design2")):
        assert (row["campaign"], row["campaign_run"], row["design"]) == ("batch_test", run, design)
        assert row["test_name"] == f"batch_test_{design}" and row["clean_close"] is True
        assert row["error"] == "" and row["frames"] >= 1200 and row["std_urad"] is not None
        assert row["bytes"] == Path(row["path"]).stat().st_size
        assert row["seed"] == SEED_CAMPAIGN  # the campaign's simulator seed, from its report
    # no campaign report beside it: the log's own record, the seed from its notes
    assert (script["campaign"], script["campaign_run"], script["design"]) == ("", None, "")
    assert script["seed"] == SEED_SCRIPT and script["error"] == ""
    assert script["energy_total_j"] > 0


def test_bad_files_are_rows_with_their_error(serial_rows):
    _, rows = serial_rows
    corrupt = next(r for r in rows if r["log"] == "corrupt.h5")
    half = next(r for r in rows if r["log"] == "half.h5")
    assert "not an HDF5 file" in corrupt["error"]
    assert "truncated" in half["error"]
    for row in (corrupt, half):
        assert row["bytes"] > 0 and row["frames"] is None and row["std_urad"] is None


def test_a_batch_row_has_the_single_log_figures(folder, serial_rows, capsys):
    """`analyze LOG --json` and the batch compute a log's figures with one code path."""
    _, rows = serial_rows
    row = next(r for r in rows if "relative_design2" in r["log"])
    assert main(["analyze", row["path"], "--json", *SENSOR]) == 0
    single = json.loads(capsys.readouterr().out)[0]
    assert {k: v for k, v in single.items() if k != "test_name"} == \
        {k: row[k] for k in single if k != "test_name"}


def test_cli_writes_parquet_and_csv_that_read_back(folder, serial_rows, tmp_path, capsys):
    _, rows = serial_rows
    out = tmp_path / "tables" / "all"
    assert main(["analyze", str(folder), "--table", str(out), "--workers", "1", *SENSOR]) == 1   # 2 bad
    captured = capsys.readouterr()
    assert "5 logs, 3 analysed without error, 2 with errors" in captured.out
    assert "5/5 logs" in captured.err
    parquet, csv_file = table_paths(out)
    expected = rows_frame(rows, TABLE_KEYS)
    pd.testing.assert_frame_equal(read_table(parquet), expected, check_exact=True)
    back = read_table(csv_file)
    assert list(back.columns) == TABLE_KEYS and len(back) == len(rows)
    assert list(back["path"]) == [r["path"] for r in rows]
    assert back["std_urad"].tolist()[:2] == pytest.approx([r["std_urad"] for r in rows[:2]],
                                                          rel=1e-15)
    assert back["error"].isna().tolist() == [not r["error"] for r in rows]


def test_cli_serial_with_a_suffix_writes_that_file_only(folder, serial_rows, tmp_path, capsys):
    _, rows = serial_rows
    out = tmp_path / "campaign.parquet"
    assert main(["analyze", str(folder / "campaign"), "--serial", "--table", str(out), *SENSOR]) == 0
    assert sorted(p.name for p in tmp_path.iterdir()) == ["campaign.parquet"]
    pd.testing.assert_frame_equal(read_table(out), rows_frame(rows[:2], TABLE_KEYS),
                                  check_exact=True)
    assert "2 logs, 2 analysed without error, 0 with errors" in capsys.readouterr().out


def test_cli_refuses_single_log_options_in_a_batch(folder, capsys):
    assert main(["analyze", str(folder), "--table", "x", "--plot", "p.png"]) == 2
    assert "--plot is for single logs" in capsys.readouterr().err
    assert main(["analyze", str(folder / "nothing-here.h5"), "--serial"]) == 2
    assert "no such log or folder: " in capsys.readouterr().err
    # with Dask: refused before a cluster is started (it took 21 s to say nothing useful)
    assert main(["analyze", str(folder / "nothing-here.h5"), "--table", "t"]) == 2
    assert "nothing-here.h5" in capsys.readouterr().err
    assert main(["analyze", str(folder / "campaign"), str(folder / "nothing-here.h5"),
                 "--serial", "--csv", *SENSOR]) == 1
    out, err = capsys.readouterr()
    assert "note: no such log: " in err
    assert "error: 1 of 3 log(s) could not be analysed:" in err
    assert "nothing-here.h5: " in err and "nothing-here.h5" in out
    assert main(["analyze", str(folder / "campaign/*.txt"), "--serial"]) == 2
    assert "no .h5 logs in" in capsys.readouterr().err
    with pytest.raises(SystemExit):
        main(["analyze", str(folder), "--scheduler", "somewhere"])


def test_a_moved_campaign_folder_keeps_its_identity(folder, tmp_path):
    """The report names where the logs were written; matched by name in its folder."""
    moved = tmp_path / "moved"
    shutil.copytree(folder / "campaign", moved)
    paths = find_logs([moved])
    row = analyze_one(paths[1], BatchOptions(metrics=("jitter",), sensor="encoder_inner"), campaign_index(paths)[str(paths[1])])
    assert (row["campaign"], row["campaign_run"], row["design"]) == ("batch_test", 2,
                                                                     "relative_design2")
