"""Stopping a recording whose writer is behind: it is waited for as long as it makes
progress (a one-hour fast recording at load 8 lost its second half to a fixed 30 s
timeout that killed a writer still draining its queue), and given up on only when it
makes none - a writer frozen with SIGSTOP is stopped within the timeout, the command
does not hang."""

from __future__ import annotations

import os
import signal

import numpy as np

from conftest import HighRateFeeder
from groundstation.logs import Recorder


def test_the_wait_goes_on_while_the_writer_makes_progress_and_only_then(dictionary, tmp_path):
    rec = Recorder(dictionary, tmp_path, test_name="backlog")
    rec.start()
    try:
        calls = []

        def progressing() -> bool:              # the writer flushes more at every look
            calls.append(1)
            rec._frames += 1
            return len(calls) >= 20
        # a timeout of 0: only the progress seen keeps the wait going
        assert rec._while_writing(0.0, progressing) is True and len(calls) == 20
        idle = []
        assert rec._while_writing(0.0, lambda: idle.append(1) and False) is False
        assert len(idle) <= 2                      # gave up at the first look without progress
    finally:
        rec.stop(reason="test over")
    assert rec.status().state == "stopped"


def test_a_frozen_writer_is_given_up_on_and_the_stop_returns(dictionary, tmp_path):
    rec = Recorder(dictionary, tmp_path, test_name="frozen")
    rec.start()
    feed = HighRateFeeder(dictionary, rec)
    os.kill(rec._proc.pid, signal.SIGSTOP)         # alive, and makes no progress at all
    try:
        for start in range(0, 12_000, 1200):
            feed(np.arange(start, start + 1200), encoder_outer=np.zeros(1200))
        status = rec.stop(timeout=0.5, reason="test over")
    finally:
        if rec._proc is not None and rec._proc.is_alive():
            os.kill(rec._proc.pid, signal.SIGCONT)
    assert status.state != "stopped"               # said, not hidden: the log is not closed
    assert rec._proc is None                       # the frozen writer was ended
