"""SPEC §6.3 (NOTHING_STAGED before a bound against the staged size), §11.2 (PROFILE_COMMIT
while a profile plays) and §7 (the events of a take-over and who receives them), on the
simulated device."""

from __future__ import annotations

import struct
import zlib

import pytest

from conftest import collect, wait_for
from groundstation.core.errors import CommandRejected
from groundstation.link import open_client


def rejected(client, name, **args) -> str:
    with pytest.raises(CommandRejected) as err:
        client.command(name, **args)
    return err.value.reason


def test_a_write_with_nothing_staged_is_nothing_staged_whatever_its_offset(client):
    client.connect()
    four = struct.pack(">f", 0.0)
    assert rejected(client, "PROFILE_WRITE", offset=4_000_000, samples=four) == "NOTHING_STAGED"
    assert rejected(client, "PARAM_WRITE", offset=4_000_000, data=four) == "NOTHING_STAGED"
    client.command("PROFILE_BEGIN", profile_id=1, target="CURRENT_COARSE", sample_count=1)
    assert rejected(client, "PROFILE_WRITE", offset=1, samples=four) == "OUT_OF_RANGE"


def stage(client, profile_id, samples):
    blob = struct.pack(f">{len(samples)}f", *samples)
    client.command("PROFILE_BEGIN", profile_id=profile_id, target="CURRENT_COARSE",
                   sample_count=len(samples))
    client.command("PROFILE_WRITE", offset=0, samples=blob)
    return zlib.crc32(blob)


def test_profile_commit_while_playing_is_invalid_state_and_playback_goes_on(client, device):
    client.connect()
    client.command("SET_MODE", mode="OPEN_LOOP")
    client.command("ARM")
    client.command("PROFILE_COMMIT", profile_crc=stage(client, 1, [0.1] * 100))
    crc2 = stage(client, 2, [0.2] * 100)             # staged before the start
    client.command("PROFILE_START")
    device.run_ticks(10)
    assert rejected(client, "PROFILE_COMMIT", profile_crc=crc2) == "INVALID_STATE"
    assert device.firmware.profile_active and device.firmware.profile["profile_id"] == 1
    device.run_ticks(95)                             # the rest of profile 1
    client.command("PROFILE_COMMIT", profile_crc=crc2)   # the staging was kept
    assert device.firmware.profile["profile_id"] == 2


def test_take_over_events_in_order_all_to_the_new_owner(client, device, dictionary):
    codes = {v: k for k, v in dictionary.event_codes.items()}
    client.connect()
    # subscribed before ARM: its ARMED event can arrive before the command's answer
    # returns (a stressed run missed it when collecting started after)
    old = collect(client)
    client.command("SET_MODE", mode="OPEN_LOOP")
    client.command("ARM")
    wait_for(lambda: any(codes[int(c)] == "ARMED" for b in old if b.name == "EVENT" for c in b["code"]))
    old.clear()
    other = open_client(dictionary, f"127.0.0.1:{device.tcp_port}", heartbeat=False)
    try:
        new = collect(other)
        other.connect(take_over=True)
        names = []

        def seen():
            names[:] = [codes[int(c)] for b in new if b.name == "EVENT" for c in b["code"]]
            return "SESSION_OPENED" in names
        wait_for(seen)
        assert names[names.index("SESSION_TAKEN_OVER"):] == [
            "SESSION_TAKEN_OVER", "DISARMED", "MODE_CHANGED", "SESSION_OPENED"]
        device.run_ticks(5)
        assert not [b for b in old if b.name == "EVENT"]
    finally:
        other.close()
