"""The Session's command order (groundstation/gui/session_commands.py): one sender in
the order given; ABORT's drop_waiting() forgets what has not gone out."""

from __future__ import annotations

import threading

from groundstation.gui.session.commands import CommandQueue


def start_thread(threads):
    def start(target, name):
        t = threading.Thread(target=target, name=name, daemon=True)
        threads.append(t)
        t.start()
    return start


class HeldSend:
    """A command's send that stays out until released (as one waiting for the device's
    answer would), then records its name."""

    def __init__(self, name: str, sent: list[str]):
        self.name, self.sent = name, sent
        self.started, self.release = threading.Event(), threading.Event()

    def __call__(self) -> None:
        self.started.set()
        assert self.release.wait(10.0)
        self.sent.append(self.name)


def _one_held_out(name: str) -> tuple[list[threading.Thread], CommandQueue, list[str], HeldSend]:
    """A queue whose sender threads are listed, with `name` submitted and held out
    (sent, not yet answered); the names sent, in order."""
    threads: list[threading.Thread] = []
    queue = CommandQueue(start_thread(threads))
    sent: list[str] = []
    held = HeldSend(name, sent)
    queue.submit(name, held)
    assert held.started.wait(10.0)
    return threads, queue, sent, held


def test_commands_are_sent_in_the_order_given_by_one_sender():
    threads, queue, sent, first = _one_held_out("SET_MODE")
    # while SET_MODE is out, the others wait in line behind it
    for name in ("ARM", "SET_CURRENTS", "SET_REFERENCE"):
        queue.submit(name, lambda name=name: sent.append(name))
    assert len(threads) == 1                      # no second sender was started
    first.release.set()
    threads[0].join(10.0)
    assert not threads[0].is_alive()
    assert sent == ["SET_MODE", "ARM", "SET_CURRENTS", "SET_REFERENCE"]
    # the queue empty, the next command starts a sender again
    queue.submit("DISARM", lambda: sent.append("DISARM"))
    assert len(threads) == 2
    threads[1].join(10.0)
    assert sent[-1] == "DISARM"


def test_drop_waiting_forgets_what_has_not_gone_out():
    threads, queue, sent, current = _one_held_out("SET_CURRENTS")
    queue.submit("SET_MODE", lambda: sent.append("SET_MODE"))
    queue.submit("ARM", lambda: sent.append("ARM"))
    assert queue.drop_waiting() == ["SET_MODE", "ARM"]
    assert queue.drop_waiting() == []
    current.release.set()                         # the one being sent goes to its end
    threads[0].join(10.0)
    assert sent == ["SET_CURRENTS"]
