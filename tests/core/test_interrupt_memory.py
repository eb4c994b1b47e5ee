"""core/stop_request.InterruptMemory: a Ctrl-C raises at once and is remembered, so that a
campaign whose KeyboardInterrupt never surfaced stops at its next step."""

import os
import signal
import threading

import pytest

from groundstation.cli.campaign import _Progress
from groundstation.core.stop_request import InterruptMemory


def test_ctrl_c_raises_at_once_and_is_remembered():
    before = signal.getsignal(signal.SIGINT)
    with InterruptMemory() as memory:
        assert not memory.requested.is_set()
        with pytest.raises(KeyboardInterrupt):
            os.kill(os.getpid(), signal.SIGINT)
        assert memory.requested.is_set()
    assert signal.getsignal(signal.SIGINT) is before


class _Step:
    index = 2

    @staticmethod
    def label() -> str:
        return "step 3 (run 1): upload_design"


def test_a_remembered_ctrl_c_stops_the_campaign_at_its_next_step(capsys):
    requested = threading.Event()
    progress = _Progress(9, requested)
    progress(_Step(), 0.0)                    # nothing asked: the step goes on
    assert "[3/9] step 3" in capsys.readouterr().out
    requested.set()                           # noted, its KeyboardInterrupt lost
    with pytest.raises(KeyboardInterrupt):
        progress(_Step(), 1.0)
