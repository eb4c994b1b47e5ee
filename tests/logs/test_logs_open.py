"""One way to open a log for reading, one row search, small modules.

The reader, log check, export and replay all open a log through logs/opening.py, and
replay finds its rows with the reader's search (logs/rows.py).  These tests pin what
that open is (SWMR read, no HDF5 file lock) and why it matters, that replay's seek lands
where numpy.searchsorted says, and that the split kept every old import working.
"""

from __future__ import annotations

import importlib
import subprocess
import sys
from pathlib import Path

import h5py
import numpy as np
import pytest

from groundstation.codec import StreamDeframer
from groundstation.logs import LogFile, LogReader, ReplaySource, iter_blocks
from groundstation.logs.blocks import BlockMerger
from groundstation.logs.rows import search_sorted
from groundstation.sim import SimulatedDevice

from conftest import wait_for

LOGS_PACKAGE = Path(__file__).resolve().parents[2] / "groundstation" / "logs"
HOST_T0 = 1_700_000_000.0


def _blocks(dictionary, seconds=2.0):
    """Simulated telemetry, one arrival time per 0.1 s batch (ties between packets)."""
    dev = SimulatedDevice(dictionary, pacing="manual", seed=3)
    dfr = StreamDeframer(dev.codec)
    out, k = [], [0]

    def consume(data: bytes) -> None:
        k[0] += 1
        out.extend(dfr.feed(data, HOST_T0 + 0.1 * k[0]))

    dev.run_fast(seconds, consume, batch=120)
    return out


@pytest.fixture(scope="module")
def log(dictionary, tmp_path_factory):
    path = tmp_path_factory.mktemp("open") / "open.h5"
    lf = LogFile(path, dictionary, test_name="open")
    lf.append(_blocks(dictionary))
    lf.close()
    return path


# ---------------------------------------------------------------------- one way to open
def test_reader_check_and_replay_open_the_file_the_same_way(log, monkeypatch):
    """Read-only, SWMR, without the file lock (opening.py opens with HDF5's low-level
    call, to bound SWMR's metadata read attempts on the file-access properties)."""
    opened = []
    real = h5py.h5f.open

    def spy(name, flags, fapl=None, **kwargs):
        opened.append((flags == h5py.h5f.ACC_RDONLY | h5py.h5f.ACC_SWMR_READ,
                       fapl.get_file_locking()[0]))
        return real(name, flags, fapl=fapl, **kwargs)

    monkeypatch.setattr(h5py.h5f, "open", spy)
    with LogReader(log) as r:
        assert r.n_frames("HIGH_RATE") > 0
    assert sum(1 for _ in iter_blocks(log)) > 0
    with ReplaySource(log, speed=None) as src:
        src.play()
        assert src.wait_finished(30)
    from groundstation.logs.check import check_log
    assert check_log(log).status == "intact"
    assert opened and set(opened) == {(True, False)}


def test_readers_hold_no_lock_that_would_stop_the_recorders_final_reopen(log):
    """The recorder marks a log clean_close by reopening it r+ with HDF5's file lock, in
    its own process.  A reader holding the file open (the GUI replays a log while
    reading its events) must not make that fail."""
    code = "import h5py, sys; h5py.File(sys.argv[1], 'r+').close()"
    with LogReader(log) as r, ReplaySource(log, speed=None) as src:
        src.step(5)
        assert src.wait_idle(10)
        assert r.n_frames("HIGH_RATE") > 0
        done = subprocess.run([sys.executable, "-c", code, str(log)], capture_output=True,
                              text=True, timeout=60)
    assert done.returncode == 0, done.stderr


def test_a_log_written_in_this_process_is_read_and_replayed_while_open(dictionary, tmp_path):
    """HDF5 wants one locking flag per file and process: a LogFile written here holds
    the lock, so the readers open it with the lock too - still SWMR, and both ways."""
    path = tmp_path / "live.h5"
    lf = LogFile(path, dictionary, test_name="live")
    try:
        blocks = _blocks(dictionary, 1.0)
        lf.append(blocks)
        lf.flush()
        frames = sum(len(b) for b in blocks if b.name == "HIGH_RATE")
        with LogReader(path) as r:
            assert r.n_frames("HIGH_RATE") == frames
        assert sum(len(b) for b in iter_blocks(path) if b.name == "HIGH_RATE") == frames
        with ReplaySource(path, speed=None) as src:
            src.play()
            wait_for(lambda: src.finished, timeout=10)
            assert src.frames_delivered == sum(len(b) for b in blocks)
    finally:
        lf.close()


# ---------------------------------------------------------------------- one row search
@pytest.mark.parametrize("chunk", [1, 7, 256])
def test_search_sorted_is_numpy_searchsorted_on_a_dataset(tmp_path, chunk):
    values = np.repeat(np.arange(40, dtype=np.float64), 3)        # ties, as arrival times have
    with h5py.File(tmp_path / "s.h5", "w") as f:
        ds = f.create_dataset("t", data=values, maxshape=(None,), chunks=(chunk,))
        for n in (0, 1, 5, len(values)):
            for v in (-1.0, 0.0, 0.5, 12.0, 39.0, 39.5, 100.0):
                for side in ("left", "right"):
                    assert search_sorted(ds, n, v, side) == np.searchsorted(values[:n], v, side)


def test_replay_seek_lands_where_the_row_search_says(log):
    with h5py.File(log, "r") as f:
        dev = f["telemetry/HIGH_RATE/device_time"][:]
        host = {name: f[f"frames/{name}/host_time"][:] for name in f["frames"]}
    merger = BlockMerger(log)
    try:
        main = merger.main_track
        for t in (dev[0] - 1.0, dev[0], dev[100], (dev[500] + dev[501]) / 2, dev[-1], dev[-1] + 1.0):
            rows, landed = merger.locate(float(t))
            r = int(np.searchsorted(dev, t, "left"))
            if r == len(dev):
                assert landed is None
                continue
            assert rows[merger.main] == r and landed == dev[r]
            key = host["HIGH_RATE"][r]
            for track, row in zip(merger.tracks, rows):
                if track is not main:       # packets ranked before HIGH_RATE go first on a tie
                    side = "right" if track.rank < main.rank else "left"
                    assert row == np.searchsorted(host[track.pkt.name], key, side)
    finally:
        merger.close()
    first = next(b for b in iter_blocks(log, start=float(dev[700])) if b.name == "HIGH_RATE")
    assert first["tick"][0] == np.round(dev[700] * 1200) % 2**32


# ---------------------------------------------------------------------- files of one job
def test_no_module_of_the_logs_package_is_over_600_lines():
    long = {p.name: n for p in LOGS_PACKAGE.glob("*.py")
            if (n := len(p.read_text(encoding="utf-8").splitlines())) > 600}
    assert not long


@pytest.mark.parametrize("module, names", [
    # the package's API
    ("groundstation.logs", ["LogDamagedError", "LogError", "LogFile", "LogFormatError", "LogQueryError",
                            "LogReader", "Recorder", "ReplayDamagedError", "ReplayError", "ReplaySource",
                            "check_log", "export_csv", "export_mat", "iter_blocks", "log_path"]),
    # each part's own names, where they are defined (no module passes on another's)
    ("groundstation.logs.opening", ["EmptyRangeError", "H5_READ_ERRORS", "LogDamagedError", "LogError",
                                    "LogFormatError", "LogQueryError", "file_truncation",
                                    "first_unreadable", "open_log_file", "truncation_text"]),
    ("groundstation.logs.reader", ["JournalRecord", "LogReader"]),
    ("groundstation.logs.channels", ["Channel"]),
    ("groundstation.logs.summary", ["LogInfo", "PacketSummary"]),
    ("groundstation.logs.rows", ["search_sorted"]),
    ("groundstation.logs.blocks", ["ReplayDamagedError", "ReplayError", "iter_blocks"]),
    ("groundstation.logs.replay", ["ReplaySource"]),
])
def test_names_are_importable_where_they_are_defined(module, names):
    m = importlib.import_module(module)
    assert [n for n in names if not hasattr(m, n)] == []
    if module != "groundstation.logs":
        assert [n for n in names if getattr(getattr(m, n), "__module__", module) != module] == []
