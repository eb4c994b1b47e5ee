"""The C reference device on the rules SPEC now states where it once left them to the
simulator: §1.1 connections beyond capacity, §6.3 NOTHING_STAGED before a bound against
the staged size, §11.2 PROFILE_COMMIT while a profile plays."""

from __future__ import annotations

import socket
import struct
import zlib
from urllib.parse import urlparse

import pytest

from groundstation.core.dictionary import load_dictionary
from groundstation.core.errors import CommandRejected
from groundstation.link import open_client
from reference_device_helpers import running_reference_device

CAPACITY = 4                         # MAX_CONNECTIONS in src/device.h (README: net.c)


@pytest.fixture(scope="module")
def dictionary():
    return load_dictionary()


def rejected(client, name, **args) -> str:
    with pytest.raises(CommandRejected) as err:
        client.command(name, **args)
    return err.value.reason


def stage(client, profile_id, samples):
    blob = struct.pack(f">{len(samples)}f", *samples)
    client.command("PROFILE_BEGIN", profile_id=profile_id, target="CURRENT_COARSE",
                   sample_count=len(samples))
    for i in range(0, len(samples), 200):
        client.command("PROFILE_WRITE", offset=i, samples=blob[4 * i:4 * (i + 200)])
    return zlib.crc32(blob)


def test_staging_and_profile_commit_rules(dictionary):
    with running_reference_device() as address:
        client = open_client(dictionary, address, heartbeat=False)
        try:
            client.connect()
            four = struct.pack(">f", 0.0)
            assert rejected(client, "PROFILE_WRITE", offset=4_000_000, samples=four) == "NOTHING_STAGED"
            assert rejected(client, "PARAM_WRITE", offset=4_000_000, data=four) == "NOTHING_STAGED"
            client.command("SET_MODE", mode="OPEN_LOOP")
            client.command("ARM")
            client.command("PROFILE_COMMIT", profile_crc=stage(client, 1, [0.1] * 6000))   # 5 s
            crc2 = stage(client, 2, [0.2] * 10)           # staged before the start
            client.command("PROFILE_START")
            assert rejected(client, "PROFILE_COMMIT", profile_crc=crc2) == "INVALID_STATE"
            client.command("PROFILE_STOP")
            client.command("PROFILE_COMMIT", profile_crc=crc2)     # the staging was kept
        finally:
            client.close()


def test_a_connection_beyond_capacity_is_closed_before_any_frame():
    with running_reference_device() as address:
        url = urlparse(address)
        socks = [socket.create_connection((url.hostname, url.port), timeout=5) for _ in range(CAPACITY + 1)]
        try:
            assert socks[-1].recv(1) == b""            # end of stream, no frame
            socks[0].settimeout(0.3)
            with pytest.raises(socket.timeout):        # the served ones stay open
                socks[0].recv(1)
        finally:
            for s in socks:
                s.close()
