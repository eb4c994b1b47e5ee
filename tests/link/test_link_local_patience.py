"""A device this process started (the simulated testbed) is waited for while it is
there: on a busy machine a starved simulator answers late, and that is not a lost link
(issue 29 part 8).  A device that is gone, and any device nobody watches, is given up
after the dictionary's retries as before.

The device is starved deterministically: the test holds its lock, so it reads no
command until the test lets go - no sleep stands for the load."""

from __future__ import annotations

import threading

import pytest

from conftest import wait_for
from groundstation.core.errors import CommandTimeout
from groundstation.link import open_client
from groundstation.sim import SimulatedDevice

#: generous bounds on conditions that arrive in milliseconds on a quiet machine
PATIENCE_S = 60.0


@pytest.fixture
def held_device(dictionary):
    dev = SimulatedDevice(dictionary, pacing="manual").start()
    yield dev
    dev.stop()


@pytest.fixture
def watched_client(dictionary, held_device):
    client = open_client(dictionary, f"127.0.0.1:{held_device.tcp_port}?telemetry=stream",
                         heartbeat=False)
    client.device_gone = held_device.gone
    client.connect()
    yield client
    client.close()


def _read_in_background(client, stages):
    outcome: dict = {}

    def run():
        try:
            outcome["result"] = client.command("GET_INFO", on_stage=stages.append)
        except Exception as exc:           # the test asserts on what was raised
            outcome["error"] = exc
    thread = threading.Thread(target=run, daemon=True)
    thread.start()
    return thread, outcome


def _retries(stages) -> int:
    return sum(1 for s in list(stages) if s.stage == "RETRY")


def test_a_starved_local_device_is_answered_after_more_than_the_dictionary_retries(
        dictionary, held_device, watched_client):
    limit = int(dictionary.command_defaults["retries"])
    stages: list = []
    with held_device._lock:                     # the simulator gets no CPU, as at load 10
        thread, outcome = _read_in_background(watched_client, stages)
        wait_for(lambda: _retries(stages) > limit, timeout=PATIENCE_S)
    thread.join(PATIENCE_S)
    assert not thread.is_alive()
    assert "error" not in outcome, outcome.get("error")
    assert outcome["result"].final_stage == "COMPLETED"
    # executed once although it was sent more often than the dictionary's retries
    assert [s.stage for s in stages].count("ACCEPTED") == 1


def test_a_local_device_that_is_gone_is_given_up_naming_why(
        dictionary, held_device, watched_client):
    limit = int(dictionary.command_defaults["retries"])
    stages: list = []
    why = []
    watched_client.device_gone = lambda: why[0] if why else ""
    with held_device._lock:
        thread, outcome = _read_in_background(watched_client, stages)
        wait_for(lambda: _retries(stages) > limit, timeout=PATIENCE_S)   # still patient
        why.append("its process ended (status -9)")                       # now it dies
        thread.join(PATIENCE_S)
    assert not thread.is_alive()
    error = outcome.get("error")
    assert isinstance(error, CommandTimeout), outcome
    assert "GET_INFO" in str(error) and "is gone: its process ended (status -9)" in str(error)


def test_an_unwatched_device_is_given_up_after_the_dictionary_retries(dictionary, held_device):
    client = open_client(dictionary, f"127.0.0.1:{held_device.tcp_port}?telemetry=stream",
                         heartbeat=False)
    try:
        client.connect()
        limit = int(dictionary.command_defaults["retries"])
        stages: list = []
        with held_device._lock:
            thread, outcome = _read_in_background(client, stages)
            thread.join(PATIENCE_S)
        assert not thread.is_alive()
        assert isinstance(outcome.get("error"), CommandTimeout)
        assert f"after {limit} retries" in str(outcome["error"])
        assert _retries(stages) == limit
    finally:
        client.close()
