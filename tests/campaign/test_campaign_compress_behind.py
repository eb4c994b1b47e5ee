"""A fast session records its logs without deflate and compresses them behind the runs
(logs/compress_behind.py): once the session has closed, every log it reports is
compressed, complete and alone in its folder (no temporary copy), and the session said
so."""

from __future__ import annotations

import json
from pathlib import Path

import h5py

from groundstation import Testbed
from groundstation.campaign import CampaignRunner, load_campaign
from groundstation.logs import LogReader, schema

CAMPAIGNS = Path(__file__).resolve().parents[2] / "profiles" / "campaigns"


def test_a_fast_campaigns_logs_are_compressed_when_its_session_closes(tmp_path):
    c = load_campaign(CAMPAIGNS / "relative_steps.toml")
    said: list[str] = []
    with Testbed("sim", testbed=c.testbed, fast=True, log_folder=tmp_path / "logs",
                 history=tmp_path / "history", echo=said.append) as tb:
        report = CampaignRunner(c, tb, max_step_seconds=1.0).run()
        frames = {rec["files"][0]: rec["frames"] for rec in tb.recordings}
    assert report.status == "completed", report.summary()
    assert len(frames) == 2
    for path, n in frames.items():
        with h5py.File(path, "r") as f:
            assert f.attrs["clean_close"]
            assert json.loads(f.attrs["compression"]) == schema.COMPRESSION
            assert f["telemetry/HIGH_RATE/encoder_inner"].compression == "gzip"
            assert f["frames/HIGH_RATE/data"].compression == "gzip"
        with LogReader(path) as log:
            assert sum(log.n_frames(p) for p in log.packets()) == n
    folder = Path(next(iter(frames))).parent
    assert sorted(p.name for p in folder.iterdir()) == sorted(Path(p).name for p in frames)
    assert any(line.startswith("compressed 2 log(s)") for line in said), said


def test_a_real_time_session_records_its_log_compressed(tmp_path):
    with Testbed("sim", log_folder=tmp_path / "logs", history=tmp_path / "history",
                 echo=lambda text: None) as tb:
        tb.start_recording("live")
        tb.dwell(0.3)
        path = tb.stop_recording()["files"][0]
        assert tb.recording.compress_behind is None      # nothing to do behind it
    with h5py.File(path, "r") as f:
        assert f["telemetry/HIGH_RATE/encoder_inner"].compression == "gzip"
