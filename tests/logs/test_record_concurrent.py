"""Recordings started together never share a file, and a recording that cannot start
leaves nothing behind (issue 29, parts 2 and 7).

Part 2: two `record --name same` started at the same moment chose the same name (same
second, same run number) - one died of HDF5's "unable to lock file", or, once the first
log was in SWMR mode (which drops HDF5's lock), the second truncated it and the first
went on writing into a corrupt file.  Part 7: a `record` whose device refused the
connection left an empty 97 KB log.

The commands run as real child processes (`python -m groundstation record`), each with
its own simulated testbed on loopback; every child has a time bound, so a hang fails
the test instead of stalling the suite.  Nothing here measures speed or waits for time
to pass in place of a condition."""

from __future__ import annotations

import os
import signal
import subprocess
import sys
import threading
from datetime import datetime
from pathlib import Path

import pytest

from groundstation.logs import LogReader, Recorder
from groundstation.logs.recorder import RecorderError, reserve_log_path

ROOT = Path(__file__).resolve().parents[2]

#: the bound on one `record` child: far above what it takes on a loaded machine (imports,
#: a simulator start and a 1 s recording), there only so that a hang fails
CHILD_TIMEOUT_S = 240.0

# the exit status `record --help` documents for "nothing could start"
EXIT_NOTHING_STARTED = 2


def _start_record(folder: Path, *args: str) -> subprocess.Popen:
    return subprocess.Popen([sys.executable, "-m", "groundstation", "record",
                             "--folder", str(folder), *args],
                            stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True,
                            cwd=ROOT, start_new_session=True,
                            env={**os.environ, "PYTHONUNBUFFERED": "1"})


def _finish(procs: list[subprocess.Popen]) -> list[tuple[int, str, str]]:
    """Each child's (exit status, stdout, stderr); a child still running after the
    bound is killed with its process group (its simulator, its writer) and fails."""
    results = []
    try:
        for proc in procs:
            try:
                out, err = proc.communicate(timeout=CHILD_TIMEOUT_S)
            except subprocess.TimeoutExpired:
                pytest.fail(f"`record` did not end within {CHILD_TIMEOUT_S} s (a hang)")
            results.append((proc.returncode, out, err))
    finally:
        for proc in procs:
            if proc.poll() is None:
                os.killpg(proc.pid, signal.SIGKILL)
                proc.communicate()
    return results


def _recorded_path(out: str) -> Path:
    lines = [line for line in out.splitlines() if line.startswith("recording to ")]
    assert len(lines) == 1, out
    return Path(lines[0][len("recording to "):].strip())


@pytest.mark.parametrize("n", [2, 8])
def test_concurrent_recordings_of_one_name_get_distinct_valid_logs(tmp_path, n):
    folder = tmp_path / "logs"
    # all started before any is waited for: they reach the choice of a file name within
    # moments of each other, mostly in the same second, the case that collided
    procs = [_start_record(folder, "--name", "same", "--device", "sim", "--duration", "1")
             for _ in range(n)]
    results = _finish(procs)
    paths = []
    for code, out, err in results:
        if code != 0 or "Traceback" in err or "leaked" in err:
            pytest.fail(f"`record` ended with status {code}\n--- stdout\n{out}\n--- stderr\n{err}")
        paths.append(_recorded_path(out))
    assert len(set(paths)) == n, paths
    # exactly the logs the commands named: nothing shared, nothing left over (no
    # reserved-but-unused names, no hidden temporary files)
    assert sorted(p.name for p in folder.iterdir()) == sorted(p.name for p in paths)
    for path in paths:
        with LogReader(path) as log:
            assert log.attrs["clean_close"], path
            assert log.attrs["test_name"] == "same"
            assert log.n_frames("HIGH_RATE") > 0, path
            # each file is one recording's: one start record, one closing record
            actions = [j.data.get("action") for j in log.journal(["recorder"])]
            assert actions.count("started") == 1 and actions.count("stopped") == 1, actions
            # the run number in the file is the one in its name (a clash moves the later
            # recording on to the next free run number, in its name and in its file)
            assert path.stem.endswith(f"_run{int(log.attrs['run']):03d}"), path


def test_a_refused_connect_leaves_no_file_and_says_so(tmp_path):
    folder = tmp_path / "logs"
    # port 1 on loopback: nothing listens there, the connection is refused at once
    procs = [_start_record(folder, "--name", "refused", "--device", "tcp://127.0.0.1:1",
                           "--duration", "1") for _ in range(2)]
    for code, out, err in _finish(procs):
        if code != EXIT_NOTHING_STARTED or "Traceback" in err or "leaked" in err:
            pytest.fail(f"`record` ended with status {code}\n--- stdout\n{out}\n--- stderr\n{err}")
        assert "connection refused" in err              # why the exit status is not 0
        assert err.count("nothing was recorded") == 1, err   # the note that the file went, once
    assert list(folder.iterdir()) == []


# ------------------------------------------------------------------ the name itself

def test_names_reserved_at_the_same_moment_are_distinct_and_created(tmp_path):
    """The race at its cause, made certain: many threads released together ask for a
    name of the same second.  Each gets its own file, created by that call."""
    now = datetime(2026, 1, 2, 3, 4, 5)
    barrier = threading.Barrier(16)
    got: list[tuple[Path, int]] = []
    lock = threading.Lock()

    def take() -> None:
        barrier.wait(timeout=30)
        reserved = reserve_log_path(tmp_path, "same", now=now)
        with lock:
            got.append(reserved)

    threads = [threading.Thread(target=take) for _ in range(16)]
    for t in threads:
        t.start()
    for t in threads:
        t.join(30)
    assert not any(t.is_alive() for t in threads)
    assert sorted(run for _, run in got) == list(range(1, 17))
    assert len({path for path, _ in got}) == 16
    assert all(path.is_file() and path.name == f"20260102_030405_same_run{run:03d}.h5"
               for path, run in got)


def test_a_taken_name_is_never_overwritten(tmp_path):
    now = datetime(2026, 1, 2, 3, 4, 5)
    first, run = reserve_log_path(tmp_path, "same", now=now)
    first.write_bytes(b"another recording's data")
    second, run2 = reserve_log_path(tmp_path, "same", now=now)
    assert (run, run2) == (1, 2) and second != first
    assert first.read_bytes() == b"another recording's data"


def test_a_template_without_a_run_number_is_refused_once_taken(tmp_path):
    now = datetime(2026, 1, 2, 3, 4, 5)
    template = "{date}_{test}.h5"
    reserve_log_path(tmp_path, "fixed", template, now=now)
    with pytest.raises(RecorderError, match="taken"):
        reserve_log_path(tmp_path, "fixed", template, now=now)


def test_a_recorder_that_receives_nothing_keeps_no_file(tmp_path, dictionary):
    rec = Recorder(dictionary, tmp_path, test_name="idle")
    path = rec.start()
    assert path.is_file()
    status = rec.stop(reason="connect failed: refused")
    assert status.removed == [path] and not path.exists()
    assert "nothing was recorded" in status.note
    assert list(tmp_path.iterdir()) == []


def test_a_recorder_with_a_journal_record_keeps_its_file(tmp_path, dictionary):
    rec = Recorder(dictionary, tmp_path, test_name="noted")
    path = rec.start()
    rec.note("the operator's note is worth a log")
    status = rec.stop(reason="done")
    assert status.removed == [] and path.is_file()
    with LogReader(path) as log:
        assert log.attrs["clean_close"]


def test_a_writer_that_cannot_start_leaves_no_file(tmp_path, dictionary, monkeypatch):
    """The start fails after the name was reserved (here the writer process never
    answers): the reserved file goes, with the writer, its queues and its temp folder."""
    rec = Recorder(dictionary, tmp_path, test_name="nostart")
    monkeypatch.setattr(rec, "_start_writer", _failing_start(rec))
    with pytest.raises(RecorderError, match="did not start"):
        rec.start()
    assert list(tmp_path.iterdir()) == []
    assert rec.state == "idle" and rec._inbox is None and rec._tmpdir is None


def _failing_start(rec):
    def start_writer(path, run, timeout):
        assert path.is_file()                     # reserved before the writer starts
        rec._protocol_dir()                       # what a real start has made by then
        raise RecorderError("the log writer did not start within 0 s")
    return start_writer
