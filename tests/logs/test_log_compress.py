"""A log recorded without deflate (a fast campaign's) is compressed in place: the same
content under the same name, smaller, and a plain HDF5 file; a log not closed cleanly
is left exactly as it was; a failure on the way (the disk full) leaves the original and
no temporary file; the process behind a session compresses what it is handed and ends
when told that no more will come."""

from __future__ import annotations

import hashlib
import json
import subprocess
import sys
import textwrap

import h5py
import numpy as np

from conftest import HighRateFeeder
from groundstation.logs import LogReader, Recorder, schema
from groundstation.logs.compress import COMPRESSED, FAILED, SKIPPED, compress_log
from groundstation.logs.compress_behind import CompressBehind
from groundstation.logs.h5file import LogFile


def _uncompressed_log(dictionary, folder, name="fast", rows=3000):
    rec = Recorder(dictionary, folder, test_name=name, compression={}, flush_interval_s=0.05)
    rec.start()
    rec.note("a note in the journal")
    seq = np.arange(rows)
    HighRateFeeder(dictionary, rec)(seq, encoder_outer=np.sin(seq / 50.0) * 1e-3)
    status = rec.stop()
    assert status.state == "stopped", status.error
    return status.files[0]


def _contents(path):
    """Every object's path -> (its values, its attributes); the root's attributes."""
    out = {}
    with h5py.File(path, "r") as f:
        def take(name, obj):
            attrs = {k: np.asarray(v).tolist() for k, v in obj.attrs.items()}
            values = obj[()] if isinstance(obj, h5py.Dataset) else None
            out[name] = (values, attrs)
        f.visititems(take)
        root = {k: np.asarray(v).tolist() for k, v in f.attrs.items()}
    return out, root


def _digest(path) -> str:
    return hashlib.sha256(path.read_bytes()).hexdigest()


def test_an_uncompressed_log_is_deflated_in_place_and_keeps_everything(tmp_path, dictionary):
    path = _uncompressed_log(dictionary, tmp_path)
    before, root_before = _contents(path)
    with h5py.File(path, "r") as f:
        assert f["telemetry/HIGH_RATE/encoder_outer"].compression is None
    outcome = compress_log(path)
    assert outcome.state == COMPRESSED, outcome.text()
    assert outcome.bytes_after < outcome.bytes_before == outcome.bytes_before
    assert [p.name for p in tmp_path.iterdir() if p.name.startswith(".")] == []
    after, root_after = _contents(path)
    assert after.keys() == before.keys()
    for name, (values, attrs) in before.items():
        assert attrs == after[name][1], name
        if values is not None:
            assert np.array_equal(values, after[name][0]), name
    assert root_after.pop("compression") == json.dumps(schema.COMPRESSION)
    assert root_before.pop("compression") == json.dumps({})
    assert root_after == root_before
    with h5py.File(path, "r") as f:
        assert f["telemetry/HIGH_RATE/encoder_outer"].compression == "gzip"
        assert f["frames/HIGH_RATE/data"].compression == "gzip"
    with LogReader(path) as r:
        assert r.n_frames("HIGH_RATE") == 3000
        assert [rec.data["text"] for rec in r.journal(["note"])][0] == "a note in the journal"
    dump = subprocess.run(["h5dump", "-d", "/telemetry/HIGH_RATE/sequence", "-s", "2997", "-c", "3",
                           str(path)], capture_output=True, text=True)     # a plain HDF5 file
    assert dump.returncode == 0, dump.stderr
    assert "2997, 2998, 2999" in dump.stdout
    assert compress_log(path).state == SKIPPED              # done once is done


def test_a_log_not_closed_cleanly_stays_exactly_as_recorded(tmp_path, dictionary):
    path = tmp_path / "killed.h5"
    lf = LogFile(path, dictionary, test_name="killed", compression={})
    lf.close(clean=False)
    digest = _digest(path)
    outcome = compress_log(path)
    assert outcome.state == SKIPPED and "not closed cleanly" in outcome.note
    assert _digest(path) == digest


def test_what_is_not_a_log_is_named_and_left_alone(tmp_path):
    junk = tmp_path / "junk.h5"
    junk.write_bytes(b"not hdf5 at all")
    outcome = compress_log(junk)
    assert outcome.state == FAILED and "cannot read it as a log" in outcome.note
    assert junk.read_bytes() == b"not hdf5 at all"
    assert compress_log(tmp_path / "missing.h5").state == FAILED


DISK_FULL = """
    import resource, signal, sys
    signal.signal(signal.SIGXFSZ, signal.SIG_IGN)      # a write past the limit fails instead
    resource.setrlimit(resource.RLIMIT_FSIZE, (300_000, 300_000))    # the compressing child's too
    from groundstation.cli.entry import main
    sys.exit(main(["log", "compress", sys.argv[1]]))
"""


def test_a_full_disk_on_the_way_leaves_the_original_and_no_temporary_file(tmp_path, dictionary):
    path = _uncompressed_log(dictionary, tmp_path, rows=6000)
    assert path.stat().st_size > 600_000        # its compressed copy outgrows the limit
    digest = _digest(path)
    run = subprocess.run([sys.executable, "-c", textwrap.dedent(DISK_FULL), str(path)],
                         capture_output=True, text=True, timeout=120)
    # HDF5 may raise or crash on the failed write: either way the command says so, exit 1
    assert run.returncode == 1, run.stderr
    assert "failed, left as recorded" in run.stdout, run.stdout
    assert _digest(path) == digest
    assert sorted(p.name for p in tmp_path.iterdir()) == [path.name]
    with LogReader(path) as r:
        assert r.n_frames("HIGH_RATE") == 6000


def test_the_command_compresses_each_log_and_names_what_it_could_not(tmp_path, dictionary, capsys):
    from groundstation.cli.entry import main

    path = _uncompressed_log(dictionary, tmp_path)
    junk = tmp_path / "junk.h5"
    junk.write_bytes(b"not hdf5")
    assert main(["log", "compress", str(path)]) == 0
    assert main(["log", "compress", str(path), str(junk)]) == 1
    out = capsys.readouterr().out.splitlines()
    assert out[0].startswith(f"{path.name}: compressed, ")
    assert out[1] == f"{path.name}: skipped, already compressed"
    assert out[2].startswith("junk.h5: failed, cannot read it as a log")


def test_the_process_behind_compresses_what_it_is_handed_and_ends(tmp_path, dictionary):
    paths = [_uncompressed_log(dictionary, tmp_path / f"run{i}", name=f"run{i}") for i in range(2)]
    said = []
    behind = CompressBehind(echo=said.append)
    behind.submit(paths)
    outcomes = behind.finish()
    assert sorted(o.path for o in outcomes) == sorted(paths)
    assert all(o.state == COMPRESSED for o in outcomes), [o.text() for o in outcomes]
    assert behind._proc.returncode == 0
    assert said[-1].startswith("compressed 2 log(s)")
    for path in paths:
        with h5py.File(path, "r") as f:
            assert f["telemetry/HIGH_RATE/gyro_rate"].compression == "gzip"


def test_stopping_the_process_behind_leaves_the_logs_whole_and_says_how_to_finish(tmp_path, dictionary):
    paths = [_uncompressed_log(dictionary, tmp_path / f"run{i}", name=f"run{i}") for i in range(3)]
    said = []
    behind = CompressBehind(echo=said.append)
    behind.submit(paths)
    behind.abandon()
    done = {o.path for o in behind.outcomes if o.state == COMPRESSED}
    for path in paths:                 # compressed or not, each is a whole, readable log
        with LogReader(path) as r:
            assert r.n_frames("HIGH_RATE") == 3000
        assert [p.name for p in path.parent.iterdir()] == [path.name]   # no temporary file
    left = [p for p in paths if p not in done]
    if left:
        assert "groundstation log compress" in said[-1]
        assert all(str(p) in said[-1] for p in left)
