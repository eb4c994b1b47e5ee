"""A fast session's logs are chunked for the log writer's sake (FAST_CHUNK_ROWS: the
fast simulator delivers thousands of frames a flush, docs/campaigns.md "Speed"), and its
writer process runs at a lower priority (FAST_WRITER_NICENESS); every other recording
keeps the schema's CHUNK_ROWS and the usual priority.  Content is unaffected either way
(tests/logs/test_logs_chunking.py, tests/campaign/test_campaign_speed.py)."""

from __future__ import annotations

import os
from pathlib import Path

import h5py

from groundstation import Testbed
from groundstation.logs import schema
from groundstation.logs.reader import LogReader
from groundstation.plant.testbed import TESTBEDS_DIR


def test_fast_session_records_with_fast_chunks(tmp_path):
    with Testbed("sim", testbed=TESTBEDS_DIR / "relative_2dof.toml", fast=True,
                 log_folder=tmp_path) as tb:
        tb.start_recording("chunks")
        writer = tb.recording.recorder._proc.pid
        assert os.getpriority(os.PRIO_PROCESS, writer) == min(
            19, os.getpriority(os.PRIO_PROCESS, 0) + schema.FAST_WRITER_NICENESS)
        tb.dwell(1.0)
        entry = tb.stop_recording()
    path = Path(entry["files"][0])
    assert entry["dropped"] == 0 and entry["discarded_blocks"] == 0
    with h5py.File(path, "r") as f:
        assert f["telemetry/HIGH_RATE/tick"].chunks == (schema.FAST_CHUNK_ROWS,)
        assert f["telemetry/HOUSEKEEPING/tick"].chunks == (schema.FAST_CHUNK_ROWS,)
        # raw frames, the widest rows (78 bytes), are chunked at most WIDE_ROW_CHUNK_BYTES a chunk
        assert f["frames/HIGH_RATE/data"].chunks[0] == min(schema.FAST_CHUNK_ROWS,
                                                           schema.WIDE_ROW_CHUNK_BYTES // 78)
        assert f["journal/time"].chunks == (1024,)
    with LogReader(path) as log:
        ticks = log.read("HIGH_RATE", "tick")["tick"]
    assert len(ticks) >= 1200 and (ticks[1:] - ticks[:-1] == 1).all()
