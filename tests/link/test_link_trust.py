"""The link trusts only the device it is connected to (issue 13, "Telemetry trusts any
sender"; "Sessions that end must say so").

Each test drives the real client against the simulated device over loopback; forged
frames are real frames with valid CRCs, sent the way a stranger or a confused program
would send them."""

from __future__ import annotations

import socket
import tempfile
import threading
from pathlib import Path

import numpy as np
import pytest

from groundstation.codec import FrameCodec
from groundstation.core.dictionary import load_dictionary
from groundstation.core.errors import DictionaryMismatchError, SessionEndedError
from groundstation.link import open_client
from groundstation.logs import LogReader, Recorder
from groundstation.logs.live import attach_recorder
from groundstation.sim import SimulatedDevice

from conftest import collect, frames_of, wait_for


def recording_session(client, dictionary, tmp_path):
    """A recording attached to the client, then the session opened (as `record` does):
    (recorder, detach, the blocks the client hands on)."""
    rec = Recorder(dictionary, tmp_path, flush_interval_s=0.05)
    rec.start()
    detach = attach_recorder(client, rec)
    blocks = collect(client)
    client.connect()
    return rec, detach, blocks


def high_rate_frame(dictionary, sequence: int, tick: int) -> bytes:
    codec = FrameCodec(dictionary)
    pkt = dictionary.packet("HIGH_RATE")
    return codec.frame(pkt.id, bytes(pkt.fixed_payload_size), sequence, tick)


def test_telemetry_from_another_sender_is_counted_and_never_decoded(client, device, dictionary):
    blocks = collect(client)
    client.connect()
    device.run_ticks(10)
    wait_for(lambda: frames_of(blocks, "HIGH_RATE") == 10)
    stranger = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
    try:
        # valid CRC, a plausible next sequence number and a wild one
        stranger.sendto(high_rate_frame(dictionary, 11, 11), ("127.0.0.1", client.telemetry.port))
        stranger.sendto(high_rate_frame(dictionary, 1_100_000_000, 12), ("127.0.0.1", client.telemetry.port))
        wait_for(lambda: client.intake.counters.foreign_datagrams == 2)
    finally:
        stranger.close()
    device.run_ticks(10)
    wait_for(lambda: frames_of(blocks, "HIGH_RATE") == 20)
    snap = client.stats.snapshot()
    assert snap.packets["HIGH_RATE"].frames == 20          # only the device's frames
    assert snap.packets["HIGH_RATE"].dropped == 0
    assert snap.framing["foreign_datagrams"] == 2
    assert any("ignored: only the connected device" in str(e) for e in client.stats.recent_errors())


def test_a_command_frame_on_the_telemetry_port_is_dropped_and_the_recording_goes_on(
        client, device, dictionary, tmp_path):
    """The stray COMMAND frame used to reach the log writer and stop the recording."""
    rec, detach, blocks = recording_session(client, dictionary, tmp_path)
    codec = FrameCodec(dictionary)
    stray = codec.frame(dictionary.packet("COMMAND").id,
                        (0).to_bytes(4, "big") + (4).to_bytes(2, "big"), 7, 0)
    injected = {"done": False}

    def swap_one(datagram):          # sent from the device's own socket: passes the source check
        if not injected["done"]:
            injected["done"] = True
            return stray
        return datagram

    device.datagram_filter = swap_one
    device.run_ticks(240)
    device.datagram_filter = None
    wait_for(lambda: client.intake.counters.unexpected_packets == 1)
    device.run_ticks(240)
    wait_for(lambda: frames_of(blocks, "HIGH_RATE") >= 479)
    wait_for(lambda: rec.status().frames >= 479 + 4)
    assert rec.state == "recording"
    st = rec.stop()
    detach()
    assert st.state == "stopped" and not st.error
    with LogReader(st.path) as r:
        assert r.n_frames("HIGH_RATE") == frames_of(blocks, "HIGH_RATE")
    assert all(b.name != "COMMAND" for b in blocks)


def test_the_session_token_is_not_predictable_from_the_seed(dictionary):
    tokens = []
    for _ in range(2):
        dev = SimulatedDevice(dictionary, pacing="manual", seed=1).start()
        try:
            with open_client(dictionary, f"127.0.0.1:{dev.tcp_port}", heartbeat=False) as c:
                tokens.append(c.connect().reply["session_token"])
        finally:
            dev.stop()
    assert tokens[0] != tokens[1]


def test_a_station_whose_session_is_taken_over_is_told_who_took_it(dictionary, device):
    first = open_client(dictionary, f"127.0.0.1:{device.tcp_port}", heartbeat=False)
    second = open_client(dictionary, f"127.0.0.1:{device.tcp_port}", heartbeat=False)
    states = []
    first.add_link_listener(lambda state, message: states.append((state, message)))
    try:
        first.connect()
        first.command("HEARTBEAT")
        second.connect(take_over=True)
        with pytest.raises(SessionEndedError, match="taken over by 127.0.0.1:"):
            first.command("HEARTBEAT")
        assert first.link_state == "ended"
        assert first.session_token is None
        assert states[-1][0] == "ended" and "taken over by 127.0.0.1:" in states[-1][1]
        # the link still carries what anyone may send
        first.abort()
        assert first.command("GET_INFO").reply["description"]
    finally:
        second.close()
        first.close()
    assert first.link_state == "ended"           # closing keeps the reason it ended


def test_a_device_of_another_major_version_is_named_with_both_versions(tmp_path, dictionary):
    """The simulated device, built from a protocol of major version 2, answers a version-1
    CONNECT with REJECTED DICTIONARY_MISMATCH in its own version (SPEC §7)."""
    proto = tmp_path / "protocol"
    proto.mkdir()
    for name, text in dictionary.source_texts.items():
        if name == "telemetry.toml":
            text = text.replace("version_major = 1 ", "version_major = 2 ", 1)
        (proto / name).write_text(text)
    newer = load_dictionary(proto)
    assert newer.version_major == 2
    dev = SimulatedDevice(newer, pacing="manual", seed=1).start()
    try:
        with open_client(dictionary, f"127.0.0.1:{dev.tcp_port}", heartbeat=False) as c:
            with pytest.raises(DictionaryMismatchError,
                               match=r"protocol version 2, this ground station speaks version 1\.0"):
                c.connect()
    finally:
        dev.stop()


def test_one_wild_sequence_number_from_the_device_is_not_a_billion_drops(
        client, device, dictionary, tmp_path, capsys):
    """A frame with a wild sequence number that does come from the device (a firmware
    bug, a corrupted header whose CRC still matched) is recorded as received, and both
    the live statistics and `log info` count it as an outlier, not as 1.1e9 drops."""
    from groundstation.cli.main import main

    rec, detach, blocks = recording_session(client, dictionary, tmp_path)
    codec = FrameCodec(dictionary)
    hr = dictionary.packet("HIGH_RATE").id
    count = {"n": 0}

    def one_wild(datagram):
        if datagram[3] == hr:
            count["n"] += 1
            if count["n"] == 100:          # same payload and tick, a wild sequence number
                tick = int.from_bytes(datagram[10:14], "big")
                return codec.frame(hr, datagram[14:-4], 1_100_000_000, tick)
        return datagram

    device.datagram_filter = one_wild
    device.run_ticks(300)
    device.datagram_filter = None
    wait_for(lambda: frames_of(blocks, "HIGH_RATE") == 300)
    # the wild frame took the place of one real frame: that one is really missing
    ps = client.stats.snapshot().packets["HIGH_RATE"]
    assert (ps.dropped, ps.outliers) == (1, 1)
    wait_for(lambda: rec.status().frames >= 300)
    st = rec.stop()
    detach()
    capsys.readouterr()
    assert main(["log", "info", str(st.path)]) == 0
    out = capsys.readouterr().out
    line = next(l for l in out.splitlines() if "HIGH_RATE" in l and "frames" in l)
    assert "1099999" not in out and "1,099,999" not in out
    with LogReader(st.path) as r:
        summary = r.summary().packets["HIGH_RATE"]
        assert (summary.drops, summary.gaps, summary.duplicates) == (1, 1, 1), line
