"""The recorder under stress: a SIGKILL mid-run, a full disk, an unwritable folder,
roll-over, and the link never waiting for the disk."""

from __future__ import annotations

import os
import signal
import subprocess
import sys
import textwrap
import time
from pathlib import Path

import h5py
import numpy as np
import pytest

from groundstation.codec import StreamDeframer
from groundstation.logs import Recorder, RecorderError
from groundstation.sim import SimulatedDevice

ROOT = Path(__file__).resolve().parents[2]


LIVE_RECORDING = """
    import sys, time
    from groundstation.core.dictionary import load_dictionary
    from groundstation.link import open_client
    from groundstation.logs import Recorder
    from groundstation.sim import SimulatedDevice
    d = load_dictionary()
    dev = SimulatedDevice(d, pacing="realtime").start()
    client = open_client(d, f"127.0.0.1:{dev.tcp_port}")
    def flushed(status, last):
        print(f"FLUSHED {status.frames} {last if last is not None else 0:.6f}", flush=True)
    rec = Recorder(d, sys.argv[1], test_name="crash",
                   on_flush=flushed)
    print("FILE", rec.start(), flush=True)
    client.subscribe(rec)
    client.connect()
    time.sleep(60)
"""


def test_sigkill_mid_run_keeps_every_flushed_frame(tmp_path):
    proc = subprocess.Popen([sys.executable, "-c", textwrap.dedent(LIVE_RECORDING), str(tmp_path)],
                            cwd=ROOT, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True,
                            env={**os.environ, "PYTHONUNBUFFERED": "1"}, start_new_session=True)
    last_flush = (0, 0.0)
    path = None
    try:
        deadline = time.monotonic() + 60
        while time.monotonic() < deadline:
            line = proc.stdout.readline()
            assert line, proc.stderr.read()
            if line.startswith("FILE"):
                path = Path(line.split(None, 1)[1].strip())
            elif line.startswith("FLUSHED"):
                _, frames, last = line.split()
                last_flush = (int(frames), float(last))
                if last_flush[0] > 2400:           # two seconds and more of telemetry
                    break
        os.killpg(proc.pid, signal.SIGKILL)        # the recorder and its writer process
        proc.wait(timeout=10)
    finally:
        if proc.poll() is None:
            proc.kill()
            proc.wait()
        proc.stdout.close()
        proc.stderr.close()
    assert path is not None and last_flush[0] > 2400
    # opens as it is, in SWMR read mode (what LogReader does); no repair needed
    with h5py.File(path, "r", libver="latest", swmr=True) as f:
        assert not f.attrs["clean_close"]          # and says it was not closed cleanly
        hr = f["telemetry/HIGH_RATE"]
        seq = hr["sequence"][:].astype(np.int64)
        frames = f["frames/HIGH_RATE/data"].shape[0]
        counted = sum(f[f"telemetry/{p}/sequence"].shape[0] for p in f["telemetry"])
        # the flush reports the newest arrival of any packet (a HOUSEKEEPING frame can
        # arrive after the last HIGH_RATE one: a stressed run saw 8.7 us)
        newest = max(float(f[f"telemetry/{p}/host_time"][-1]) for p in f["telemetry"]
                     if f[f"telemetry/{p}/host_time"].shape[0])
    assert counted >= last_flush[0]                # every frame up to the last flush
    assert frames == len(seq) and np.all(np.diff(seq) == 1)
    assert newest >= last_flush[1] - 1e-6
    # How much the crash cost in time (frames that arrived after the last flush) is a
    # figure of the machine's speed, not a verdict: benchmarks/bench_faults.py measures
    # it ('SIGKILL of the recorder', seconds_lost); a wall-clock bound would depend on the load.
    # HDF5's own tools read it too, once its "open for writing" mark is cleared
    copy = tmp_path / "copy.h5"
    copy.write_bytes(path.read_bytes())
    subprocess.run(["h5clear", "-s", str(copy)], check=True, capture_output=True)
    dump = subprocess.run(["h5dump", "-d", "/telemetry/HIGH_RATE/sequence", "-s", "0", "-c", "3",
                           str(copy)], capture_output=True, text=True)
    assert dump.returncode == 0, dump.stderr
    assert f"{seq[0]}, {seq[1]}, {seq[2]}" in dump.stdout


DISK_FULL = """
    import resource, signal, sys, time
    signal.signal(signal.SIGXFSZ, signal.SIG_IGN)    # a write past the limit fails instead
    resource.setrlimit(resource.RLIMIT_FSIZE, (4_000_000, 4_000_000))
    from groundstation.codec import StreamDeframer
    from groundstation.core.dictionary import load_dictionary
    from groundstation.logs import Recorder
    from groundstation.sim import SimulatedDevice
    d = load_dictionary()
    dev = SimulatedDevice(d, pacing="manual", seed=4)
    failures = []
    rec = Recorder(d, sys.argv[1], test_name="full", on_failure=failures.append)
    print("FILE", rec.start(), flush=True)
    dfr = StreamDeframer(dev.codec)
    decoded = [0]
    def feed(data):
        for b in dfr.feed(data, time.time()):
            decoded[0] += len(b)
            rec(b)
        time.sleep(0.05)                             # let the writer flush now and then
    dev.run_fast(120.0, feed)
    rec.stop()
    print("STATE", rec.state, flush=True)
    print("ERROR", failures[0] if failures else "", flush=True)
    print("DECODED", decoded[0], flush=True)         # the link went on after the failure
"""


def test_full_disk_stops_recording_with_a_message_and_a_valid_file(tmp_path):
    out = subprocess.run([sys.executable, "-c", textwrap.dedent(DISK_FULL), str(tmp_path)],
                         cwd=ROOT, capture_output=True, text=True, timeout=300)
    assert out.returncode == 0, out.stderr
    lines = dict(ln.split(" ", 1) for ln in out.stdout.splitlines() if " " in ln)
    assert lines["STATE"] == "failed"
    assert "file size limit" in lines["ERROR"] and "recording stopped" in lines["ERROR"]
    assert int(lines["DECODED"]) > 120 * 1200       # every frame was still decoded
    path = Path(lines["FILE"])
    with h5py.File(path, "r") as f:
        assert f.attrs["clean_close"]               # stopped in time to close properly
        seq = f["telemetry/HIGH_RATE/sequence"][:].astype(np.int64)
        rows = f["frames/HIGH_RATE/data"].shape[0]
    assert len(seq) > 1200 and np.all(np.diff(seq) == 1) and rows == len(seq)


def test_unwritable_folder_is_refused_at_start(tmp_path, dictionary):
    blocker = tmp_path / "not-a-folder"
    blocker.write_text("x")
    rec = Recorder(dictionary, blocker / "logs")
    with pytest.raises(RecorderError, match="not a folder"):
        rec.start()
    assert rec.state == "idle"


def test_rollover_by_duration_keeps_every_frame(tmp_path, dictionary):
    dev = SimulatedDevice(dictionary, pacing="manual", seed=5)
    rec = Recorder(dictionary, tmp_path, test_name="roll", rollover_seconds=0.3,
                   flush_interval_s=0.1)
    rec.start()
    dfr = StreamDeframer(dev.codec)
    sent = []

    def feed(data):
        for b in dfr.feed(data, time.time()):
            if b.name == "HIGH_RATE":
                sent.append(b["sequence"])
            rec(b)
        time.sleep(0.05)
    dev.run_fast(10.0, feed, batch=600)
    status = rec.stop()
    assert status.state == "stopped" and len(status.files) >= 2
    seqs = []
    for path in status.files:
        with h5py.File(path, "r") as f:
            assert f.attrs["clean_close"]
            seqs.append(f["telemetry/HIGH_RATE/sequence"][:])
    assert np.array_equal(np.concatenate(seqs), np.concatenate(sent))
    dump = subprocess.run(["h5dump", "-A", "-g", "/telemetry/HIGH_RATE", str(status.files[0])],
                          capture_output=True, text=True)        # a plain HDF5 file
    assert dump.returncode == 0 and "rate_hz" in dump.stdout
    assert [int(p.stem.split("run")[-1]) for p in status.files] == list(range(1, len(status.files) + 1))


def test_a_full_queue_drops_to_disk_never_blocks_the_link(tmp_path, dictionary):
    dev = SimulatedDevice(dictionary, pacing="manual")
    rec = Recorder(dictionary, tmp_path, queue_blocks=3)
    rec.start()
    dfr = StreamDeframer(dev.codec)
    blocks = []
    dev.run_fast(2.0, lambda data: blocks.extend(dfr.feed(data, time.time())), batch=20)
    t = time.perf_counter()
    for b in blocks:
        rec(b)                                       # returns at once even when full
    elapsed = time.perf_counter() - t
    status = rec.stop()
    assert status.discarded_blocks > 0
    assert elapsed < 1.0                             # generous: it is a few puts


def test_a_recorder_detached_from_a_link_leaves_nothing_behind(dictionary, client, tmp_path):
    """The GUI's link outlives many recordings: each must take its listeners with it."""
    from groundstation.logs.live import attach_recorder
    before = (len(client._subscribers), len(client._command_listeners), len(client._link_listeners))
    detach = attach_recorder(client, Recorder(dictionary, tmp_path))
    assert (len(client._subscribers), len(client._command_listeners),
            len(client._link_listeners)) == tuple(n + 1 for n in before)
    detach()
    assert (len(client._subscribers), len(client._command_listeners),
            len(client._link_listeners)) == before
