"""The log writer's speed work (docs/campaigns.md, "Speed"): a log's chunking is a
per-recording choice that changes nothing a reader sees, the low-level appends write
what h5py's slice assignment wrote, and a flushed log stays readable while it is open.

The logs are written by LogFile directly, with the flushes the writer process makes,
from the same simulated blocks: nothing depends on timing."""

from __future__ import annotations

import os
import shutil
from pathlib import Path

import h5py
import numpy as np
import pytest

from groundstation.logs import LogFile, LogReader, Recorder
from groundstation.logs import schema
from groundstation.logs.h5file import _Column

from test_logs_reader import HOST0, _simulate

SECONDS = 4.0                 # 4800 HIGH_RATE frames: 4.7 chunks of 1024 rows, 18.8 of 256


@pytest.fixture(scope="module")
def blocks(dictionary):
    fed: list = []
    _simulate(dictionary, SECONDS, fed.append)
    return fed


def _write(path: Path, dictionary, blocks, chunk_rows, flush_frames: int) -> Path:
    """A log of `blocks`, flushed every `flush_frames` HIGH_RATE frames (0: once)."""
    lf = LogFile(path, dictionary, test_name="chunks", chunk_rows=chunk_rows)
    lf.journal([(HOST0, "note", {"text": "starting"}, b"")])
    pending, count = [], 0
    for b in blocks:
        pending.append(b)
        count += len(b) if b.name == "HIGH_RATE" else 0
        if flush_frames and count >= flush_frames:
            lf.append(pending)
            lf.flush()
            pending, count = [], 0
    lf.append(pending)
    lf.journal([(HOST0 + 10, "recorder", {"action": "stopped"}, b"")])
    lf.flush()
    lf.close(clean=True)
    return path


def _content(path: Path) -> dict:
    out: dict = {}
    with LogReader(path) as log:
        for packet in log.packets():
            out[packet] = log.read(packet, raw=True)
            frames = log.frames(packet)
            out[f"{packet} frames"] = (frames if isinstance(frames, list)
                                       else [bytes(r) for r in np.asarray(frames)])
        out["journal"] = [(r.kind, r.data, r.blob) for r in log.journal()]
    return out


def _assert_same(a: dict, b: dict) -> None:
    assert a.keys() == b.keys()
    for key in a:
        if key == "journal" or key.endswith("frames"):
            assert a[key] == b[key], key
            continue
        assert a[key].keys() == b[key].keys(), key
        for col in a[key]:
            x, y = np.asarray(a[key][col]), np.asarray(b[key][col])
            assert x.dtype == y.dtype and x.shape == y.shape, (key, col)
            assert np.array_equal(x, y, equal_nan=x.dtype.kind == "f"), (key, col)


def _chunks(path: Path) -> dict[str, tuple]:
    out = {}
    with h5py.File(path, "r") as f:
        f.visititems(lambda name, o: out.__setitem__(name, o.chunks)
                     if isinstance(o, h5py.Dataset) and o.chunks else None)
    return out


@pytest.mark.parametrize("flush_frames", [300, 0])
@pytest.mark.parametrize("chunk_rows", [1024, schema.FAST_CHUNK_ROWS])
def test_chunking_changes_nothing_a_reader_sees(dictionary, blocks, tmp_path, flush_frames,
                                                 chunk_rows):
    """1024 rows: several whole chunks and a partial one; FAST_CHUNK_ROWS: one chunk,
    filled in place by flush after flush."""
    live = _write(tmp_path / "live.h5", dictionary, blocks, None, 300)
    fast = _write(tmp_path / "fast.h5", dictionary, blocks, chunk_rows, flush_frames)
    a, b = _content(live), _content(fast)
    _assert_same(a, b)
    assert len(a["HIGH_RATE frames"]) == int(SECONDS * 1200)
    ca, cb = _chunks(live), _chunks(fast)
    assert ca.keys() == cb.keys()
    for name in ca:
        if name.startswith("journal/") or name.endswith(("/offset", "/length")):
            assert ca[name] == cb[name], name                  # the journal, byte streams: as before
    assert ca["telemetry/HIGH_RATE/tick"] == (schema.CHUNK_ROWS,)
    assert cb["telemetry/HIGH_RATE/tick"] == (chunk_rows,)
    assert cb["telemetry/HIGH_RATE/raw/encoder_inner"] == (chunk_rows,)
    # raw frames, the widest rows (78 bytes), are chunked at most WIDE_ROW_CHUNK_BYTES a chunk
    assert cb["frames/HIGH_RATE/data"] == (min(chunk_rows, schema.WIDE_ROW_CHUNK_BYTES // 78), 78)
    assert cb["journal/time"] == ca["journal/time"] == (1024,)


def test_chunk_rows_must_be_positive(dictionary, tmp_path):
    with pytest.raises(ValueError, match="chunk_rows"):
        LogFile(tmp_path / "x.h5", dictionary, chunk_rows=0)
    assert not (tmp_path / "x.h5").exists()


def test_flushed_rows_are_readable_while_the_log_is_open(dictionary, blocks, tmp_path):
    """Crash safety with large chunks: after a flush, a reader (SWMR, as after a crash)
    sees every row flushed, including the partial last chunk; rows appended after it
    and not flushed are not required."""
    path = tmp_path / "open.h5"
    lf = LogFile(path, dictionary, test_name="open", chunk_rows=schema.FAST_CHUNK_ROWS)
    hr = [b for b in blocks if b.name == "HIGH_RATE"]
    first = hr[:len(hr) // 3]
    n_first = sum(len(b) for b in first)
    assert n_first % schema.FAST_CHUNK_ROWS                 # ends inside a chunk
    lf.append(first)
    lf.flush()
    # a copy of the file as it is on disk now: what a crash right after the flush leaves
    crashed = tmp_path / "crashed.h5"
    shutil.copyfile(path, crashed)
    lf.append(hr[len(hr) // 3:])
    lf.flush()
    with LogReader(crashed) as log:
        seq = log.read("HIGH_RATE", "sequence")["sequence"]
        frames = np.asarray(log.frames("HIGH_RATE"))
    expected = np.concatenate([b["sequence"] for b in first])
    assert np.array_equal(seq, expected)
    assert np.array_equal(frames, np.concatenate([b.raw.view(np.uint8).reshape(len(b), -1)
                                                  for b in first]))
    lf.close(clean=True)
    with LogReader(path) as log:
        assert len(log.read("HIGH_RATE", "sequence")["sequence"]) == sum(len(b) for b in hr)


@pytest.mark.parametrize("dtype,row_shape,values", [
    (np.float32, (), np.array([0.1, -2.5e-7, 3.0e9, np.nan])),         # float64 cast to float32
    (np.bool_, (), np.array([True, False, True])),
    (np.uint32, (), np.array([1, 2, 4_000_000_000], dtype=np.int64)),  # another integer type
    (np.uint8, (3,), np.arange(12, dtype=np.uint8).reshape(4, 3)),    # rows of bytes
    (np.float64, (), np.zeros(0)),                                    # nothing to append
])
def test_low_level_append_writes_what_slice_assignment_wrote(tmp_path, dtype, row_shape, values):
    with h5py.File(tmp_path / "a.h5", "w", libver=schema.LIBVER) as f:
        kw = dict(shape=(0, *row_shape), maxshape=(None, *row_shape), dtype=dtype,
                  chunks=(2, *row_shape), **schema.COMPRESSION)
        ours, theirs = f.create_dataset("ours", **kw), f.create_dataset("theirs", **kw)
        col = _Column(ours)
        for _ in range(2):                                   # twice: the second one appends
            col.append(values)
            n = len(values)
            if n:
                start = theirs.shape[0]
                theirs.resize((start + n, *row_shape))
                theirs[start:start + n] = values
        assert col.rows == ours.shape[0] == theirs.shape[0] == 2 * len(values)
        a, b = ours[()], theirs[()]
        assert a.dtype == b.dtype
        assert np.array_equal(a, b, equal_nan=a.dtype.kind == "f")


def test_recorder_passes_its_chunking_to_the_writer(dictionary, blocks, tmp_path):
    rec = Recorder(dictionary, tmp_path, test_name="chunked", chunk_rows=512)
    rec.start()
    for b in blocks[:40]:
        rec(b)
    status = rec.stop()
    assert status.state == "stopped" and rec.discarded_blocks == 0
    chunks = _chunks(status.files[0])
    assert chunks["telemetry/HIGH_RATE/tick"] == (512,)
    assert chunks["frames/HIGH_RATE/host_time"] == (512,)
    assert status.frames == sum(len(b) for b in blocks[:40])


def test_recorder_lowers_its_writers_priority_when_asked(dictionary, tmp_path):
    ours = os.getpriority(os.PRIO_PROCESS, 0)
    rec = Recorder(dictionary, tmp_path, test_name="nice", writer_niceness=3)
    rec.start()                 # returns once the writer has said it started: reniced by then
    try:
        assert os.getpriority(os.PRIO_PROCESS, rec._proc.pid) == min(19, ours + 3)
    finally:
        status = rec.stop()
    assert status.state == "stopped"
    plain = Recorder(dictionary, tmp_path, test_name="plain")
    plain.start()
    try:
        assert os.getpriority(os.PRIO_PROCESS, plain._proc.pid) == ours
    finally:
        plain.stop()
    with pytest.raises(ValueError, match="writer_niceness"):
        Recorder(dictionary, tmp_path, writer_niceness=-1)
