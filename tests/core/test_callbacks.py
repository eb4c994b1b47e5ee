"""core/callbacks.py: a raising callback is logged and counted and the others still run;
removal of an unknown callback is no error; a callback may remove itself while called."""

from __future__ import annotations

import logging

from groundstation.core.callbacks import Callbacks


def test_a_raising_callback_is_counted_and_the_rest_still_run(caplog):
    calls = []
    cbs = Callbacks("telemetry subscriber", logging.getLogger("test.callbacks"))

    def broken(x):
        raise ValueError("chart gone")

    cbs.add(calls.append)
    cbs.add(broken)
    cbs.add(lambda x: calls.append(-x))
    with caplog.at_level(logging.ERROR, logger="test.callbacks"):
        cbs(3)
        cbs(4)
    assert calls == [3, -3, 4, -4]
    assert cbs.failures == 2
    assert "telemetry subscriber" in caplog.text and "chart gone" in caplog.text


def test_remove_is_idempotent_and_a_callback_may_remove_itself():
    cbs = Callbacks("link listener", logging.getLogger("test.callbacks"))
    seen = []

    def once(state, message):
        seen.append(state)
        cbs.remove(once)

    cbs.add(once)
    assert once in cbs and len(cbs) == 1
    cbs("up", "")
    cbs("lost", "x")
    assert seen == ["up"] and once not in cbs and len(cbs) == 0
    cbs.remove(once)                     # not there any more: no error


def test_subscribers_after_others_are_called_last():
    order: list[str] = []
    calls = Callbacks("test subscriber", logging.getLogger(__name__))
    calls.add(lambda: order.append("first"))
    calls.add(lambda: order.append("observer"), last=True)
    later = lambda: order.append("later")      # noqa: E731
    calls.add(later)
    calls()
    assert order == ["first", "later", "observer"]
    calls.remove(later)
    assert len(calls) == 2 and later not in calls
