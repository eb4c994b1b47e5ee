"""A writer process started ahead of its recording (logs/standby.py): the recording takes
it instead of starting one, the log is the same, a writer that ended its recording
cleanly writes the next one and one that failed does not, a spare that died is replaced
by an ordinary start, and no spare outlives its owner."""

from __future__ import annotations

import os
import signal
import subprocess
import sys
import textwrap
from pathlib import Path

import h5py
import numpy as np

from conftest import HighRateFeeder, process_alive, wait_for
from groundstation.logs import LogReader, Recorder
from groundstation.logs.standby import WriterStandby

ROOT = Path(__file__).resolve().parents[2]


def _record(dictionary, folder, standby, name, first_seq, **options):
    rec = Recorder(dictionary, folder, test_name=name, standby=standby, flush_interval_s=0.05,
                   **options)
    rec.start()
    writer_pid = rec._proc.pid
    feed = HighRateFeeder(dictionary, rec)
    seq = np.arange(first_seq, first_seq + 1200)
    feed(seq, encoder_outer=np.linspace(0.0, 1e-3, seq.size))
    status = rec.stop()
    assert status.state == "stopped", status.error
    return status, writer_pid, seq


def test_recordings_take_the_spare_writer_and_write_the_same_log(tmp_path, dictionary):
    standby = WriterStandby()
    try:
        standby.prepare()
        [spare_pid] = standby.waiting_pids()
        status, writer_pid, seq = _record(dictionary, tmp_path, standby, "warm", 0)
        assert writer_pid == spare_pid                 # the spare wrote it
        assert (standby.spawned, standby.used) == (2, 1)   # and the next one was spawned
        # it ended cleanly: back to waiting, the one taken next
        assert standby.waiting_pids()[-1] == writer_pid and len(standby.waiting_pids()) == 2
        status2, writer_pid2, seq2 = _record(dictionary, tmp_path, standby, "warm", 5000)
        assert writer_pid2 == writer_pid
        assert (standby.spawned, standby.used, standby.reused) == (2, 2, 1)
        # a log written by a spare, first or second, is a log like any other
        cold, _, _ = _record(dictionary, tmp_path / "cold", None, "cold", 0)
        for st, expected in ((status, seq), (status2, seq2), (cold, seq)):
            with h5py.File(st.files[0], "r") as f:
                assert f.attrs["clean_close"]
                assert np.array_equal(f["telemetry/HIGH_RATE/sequence"][:], expected)
        waiting = standby.waiting_pids()
        assert len(waiting) == 2
    finally:
        standby.close()
    for pid in waiting:                                # close() ended the writers left over
        wait_for(lambda pid=pid: not process_alive(pid))


def test_a_writer_whose_recording_failed_is_not_used_again(tmp_path, dictionary):
    """A recording whose writer died (as after a failed write) ends failed; its writer
    is not handed back, and the next recording gets another process, whose log is whole."""
    standby = WriterStandby()
    try:
        standby.prepare()
        rec = Recorder(dictionary, tmp_path, test_name="doomed", standby=standby)
        rec.start()
        doomed = rec._proc.pid
        os.kill(doomed, signal.SIGKILL)
        wait_for(lambda: rec.state == "failed")
        assert rec.stop().state == "failed"
        assert doomed not in standby.waiting_pids()
        status, writer_pid, seq = _record(dictionary, tmp_path, standby, "next", 0)
        assert writer_pid != doomed and standby.reused == 0
        with LogReader(str(status.files[0])) as log:
            assert np.array_equal(log.read("HIGH_RATE", ["sequence"])["sequence"], seq)
    finally:
        standby.close()


def test_the_next_spare_is_spawned_once_the_recording_has_started_not_when_taken(tmp_path, dictionary):
    """A spare spawned while the recording that took the last one creates its file would
    take the CPU that start waits for: `take` spawns nothing, `Recorder.start` asks for
    the next spare once it has its file."""
    standby = WriterStandby()
    try:
        standby.prepare()
        [spare_pid] = standby.waiting_pids()
        taken = standby.take(standby.queue_blocks)
        assert taken.proc.pid == spare_pid
        assert standby.waiting_pids() == [] and standby.spawned == 1
        standby.give_back(taken)
        rec = Recorder(dictionary, tmp_path, test_name="next", standby=standby)
        rec.start()
        try:
            assert rec._proc.pid == spare_pid
            [next_pid] = standby.waiting_pids()            # spawned by the start, after it
            assert next_pid != spare_pid and standby.spawned == 2
        finally:
            assert rec.stop().state == "stopped"
    finally:
        standby.close()


def test_a_reused_writer_lowers_its_priority_once_not_once_a_recording(tmp_path, dictionary):
    standby = WriterStandby()
    try:
        standby.prepare()
        base = os.getpriority(os.PRIO_PROCESS, 0)
        for run in range(3):
            _, writer_pid, _ = _record(dictionary, tmp_path, standby, "nice", run * 2000,
                                       writer_niceness=3)
            # still waiting for the next recording: its niceness as the recording left it
            assert os.getpriority(os.PRIO_PROCESS, writer_pid) == min(base + 3, 19)
        assert standby.reused == 2
    finally:
        standby.close()


def test_a_spare_that_died_is_replaced_by_an_ordinary_start(tmp_path, dictionary):
    standby = WriterStandby()
    try:
        standby.prepare()
        dead = standby._waiting[0].proc
        dead.kill()
        dead.join(10)
        status, writer_pid, seq = _record(dictionary, tmp_path, standby, "after-death", 0)
        assert writer_pid != dead.pid and standby.used == 0
        with LogReader(str(status.files[0])) as log:
            assert log.n_frames("HIGH_RATE") == seq.size
    finally:
        standby.close()


def test_a_spare_whose_owner_is_gone_ends_by_itself(tmp_path):
    """An owner killed without closing its standby (SIGKILL, a crash) leaves no writer
    process behind: the spare sees its parent gone and ends."""
    script = tmp_path / "owner.py"
    script.write_text(textwrap.dedent("""
        import os, sys
        from groundstation.logs.standby import WriterStandby
        if __name__ == "__main__":
            standby = WriterStandby()
            standby.prepare()
            print(standby.waiting_pids()[0], flush=True)
            os._exit(0)                      # no close(): as if killed
    """))
    done = subprocess.run([sys.executable, str(script)], capture_output=True, text=True,
                          timeout=120, cwd=tmp_path, env=dict(os.environ, PYTHONPATH=str(ROOT)))
    assert done.returncode == 0, done.stderr
    spare_pid = int(done.stdout.split()[0])
    wait_for(lambda: not process_alive(spare_pid), timeout=60)
