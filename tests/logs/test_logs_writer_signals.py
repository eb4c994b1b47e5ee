"""Ctrl-C around the log writer's spawn: the writer process starts with SIGINT held and
ignores it from then on; a Ctrl-C that reaches the recording process during the spawn
is held for it, not thrown away (it raises KeyboardInterrupt once the spawn is done)."""

import os
import signal

import pytest

from groundstation.logs import Recorder
from groundstation.logs.recorder import _terminal_interrupt_held


def _signal_masks(pid: int) -> dict[str, int]:
    """SigBlk / SigIgn of `pid`'s main thread, as bit masks (bit n-1 is signal n)."""
    fields = {}
    with open(f"/proc/{pid}/status") as f:
        for line in f:
            key, _, value = line.partition(":")
            if key in ("SigBlk", "SigIgn"):
                fields[key] = int(value.strip(), 16)
    return fields


def _has(mask: int, sig: int) -> bool:
    return bool(mask >> (sig - 1) & 1)


@pytest.fixture(autouse=True)
def _ctrl_c_as_in_a_terminal():
    """Python's own Ctrl-C handler for these tests, whatever the suite inherited: a
    suite started in the background of a non-interactive shell (`sh -c 'make test &'`)
    begins with SIGINT ignored, and Python then leaves it ignored."""
    previous = signal.signal(signal.SIGINT, signal.default_int_handler)
    yield
    signal.signal(signal.SIGINT, previous)


def test_a_ctrl_c_during_the_writer_spawn_is_held_and_then_raised():
    before = signal.pthread_sigmask(signal.SIG_BLOCK, set())
    with pytest.raises(KeyboardInterrupt):
        with _terminal_interrupt_held():
            os.kill(os.getpid(), signal.SIGINT)     # the operator's Ctrl-C, mid-spawn
        # the held signal is delivered when the block ends; Python raises at its next
        # check, a call at the latest
        signal.getsignal(signal.SIGINT)
    assert signal.pthread_sigmask(signal.SIG_BLOCK, set()) == before


def test_the_writer_ignores_ctrl_c_and_holds_nothing_once_started(dictionary, tmp_path):
    rec = Recorder(dictionary, tmp_path, test_name="signals")
    rec.start()             # returns once the writer said Started: its handlers are set
    try:
        masks = _signal_masks(rec._proc.pid)
        assert _has(masks["SigIgn"], signal.SIGINT)
        assert _has(masks["SigIgn"], signal.SIGTERM)
        assert not _has(masks["SigBlk"], signal.SIGINT)
        # and this process is as it was: SIGINT neither blocked nor ignored
        assert signal.SIGINT not in signal.pthread_sigmask(signal.SIG_BLOCK, set())
        assert signal.getsignal(signal.SIGINT) is signal.default_int_handler
    finally:
        rec.stop(reason="test over")
