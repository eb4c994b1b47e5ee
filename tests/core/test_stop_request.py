"""core/stop_request.py: a signal becomes a request with its reason; a timed loop learns
why it ends (the request or its duration) and when its next status line is due."""

from __future__ import annotations

import os
import signal
import time

from groundstation.core.stop_request import StopRequest


def test_sigterm_is_a_request_with_its_reason_and_the_handler_comes_back():
    before = signal.getsignal(signal.SIGTERM)
    with StopRequest() as stop:
        assert stop.ending(None, None) is None
        os.kill(os.getpid(), signal.SIGTERM)
        assert stop.event.wait(10)
        assert stop.ending(None, None) == "terminated (SIGTERM)"
        assert stop.status_due(None) is False       # no waiting once stopped
    assert signal.getsignal(signal.SIGTERM) is before


def test_a_passed_deadline_ends_the_loop_with_its_duration():
    stop = StopRequest()
    assert stop.ending(time.monotonic() - 1.0, 2.5) == "duration of 2.5 s reached"
    assert stop.ending(time.monotonic() + 3600.0, 3600) is None
    assert stop.status_due(time.monotonic() - 1.0) is True   # deadline past: no wait
