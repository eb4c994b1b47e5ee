"""The telemetry receiver keeps up with a stream faster than its batch size per wait
(the 10x burst, 12 000 datagrams/s): after a batch that stopped at max_datagrams it
does not wait before draining again.  Deterministic: the wait (time.sleep in the
transports module) is recorded, not timed."""

from __future__ import annotations

import socket

import pytest

from groundstation.link import transports
from groundstation.link.transports import UdpReceiver


@pytest.fixture
def receiver_and_sender():
    rx = UdpReceiver("127.0.0.1", 0)
    tx = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
    yield rx, tx
    tx.close()
    rx.close()


def _send(tx, rx, n):
    for i in range(n):
        tx.sendto(i.to_bytes(4, "little"), (rx.host, rx.port))


def test_no_wait_after_a_full_batch(receiver_and_sender, monkeypatch):
    rx, tx = receiver_and_sender
    waits = []
    monkeypatch.setattr(transports.time, "sleep", lambda s: waits.append(s))
    _send(tx, rx, 25)
    got, _ = rx.receive(1.0, max_datagrams=10, coalesce_s=0.025)
    assert len(got) == 10 and rx.backlog
    assert waits == [0.025]                       # the first batch waits to coalesce
    got2, _ = rx.receive(1.0, max_datagrams=10, coalesce_s=0.025)
    assert len(got2) == 10 and rx.backlog
    assert waits == [0.025]                       # a backlog: drained at once
    got3, _ = rx.receive(1.0, max_datagrams=10, coalesce_s=0.025)
    assert len(got3) == 5 and not rx.backlog
    assert waits == [0.025]
    _send(tx, rx, 3)
    got4, _ = rx.receive(1.0, max_datagrams=10, coalesce_s=0.025)
    assert len(got4) == 3
    assert waits == [0.025, 0.025]                # caught up: waits again
    order = [int.from_bytes(d, "little") for d in got + got2 + got3 + got4]
    assert order == list(range(25)) + list(range(3))


def test_without_coalescing_never_waits(receiver_and_sender, monkeypatch):
    rx, tx = receiver_and_sender
    waits = []
    monkeypatch.setattr(transports.time, "sleep", lambda s: waits.append(s))
    _send(tx, rx, 12)
    assert len(rx.receive(1.0, max_datagrams=10)[0]) == 10
    assert len(rx.receive(1.0, max_datagrams=10)[0]) == 2
    assert waits == []
