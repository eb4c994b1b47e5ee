"""The device client against the simulated device over loopback: session, verified
commands, retries, duplicates, watchdog, telemetry and link statistics, bad links."""

from __future__ import annotations

import shutil
import socket
import threading
import zlib
from pathlib import Path

import numpy as np
import pytest

from conftest import collect, frames_of, wait_for
from groundstation.codec import FrameCodec, StreamDeframer
from groundstation.core.dictionary import load_dictionary
from groundstation.core.errors import (CommandArgumentError, CommandRejected, CommandTimeout,
                                       DictionaryMismatchError, LinkError, LinkLostError,
                                       NotConnectedError, PortInUseError)
from groundstation.link import DeviceClient, open_client, parse_address
from groundstation.link.transports import TcpStream, UdpReceiver
from groundstation.sim import SimulatedDevice


# ------------------------------------------------------------------ session


def test_connect_exchanges_token_version_and_hash(client, dictionary):
    result = client.connect()
    assert [s.stage for s in result.stages] == ["SENT", "ACCEPTED", "COMPLETED"]
    assert client.session_token == result.reply["session_token"] != 0
    assert result.reply["protocol_major"] == dictionary.version_major
    assert result.reply["dictionary_hash"] == dictionary.hash
    info = client.command("GET_INFO").reply
    assert info["dictionary_hash"] == dictionary.hash
    assert "simulated" in info["description"]


def test_dictionary_mismatch_is_refused_naming_both_versions(tmp_path, device):
    proto = tmp_path / "protocol"
    shutil.copytree(Path(__file__).parents[2] / "protocol", proto)
    text = (proto / "telemetry.toml").read_text().replace("version_minor = 0", "version_minor = 7")
    (proto / "telemetry.toml").write_text(text)
    other = load_dictionary(proto)
    c = open_client(other, f"127.0.0.1:{device.tcp_port}", heartbeat=False)
    try:
        with pytest.raises(DictionaryMismatchError) as err:
            c.connect()
        msg = str(err.value)
        assert "1.7" in msg and "1.0" in msg
        assert f"{other.hash:08x}" in msg and f"{device.dictionary.hash:08x}" in msg
        assert c.session_token is None
    finally:
        c.close()


def test_commands_need_a_session_and_the_token(client, device, dictionary):
    with pytest.raises(NotConnectedError):
        client.command("ARM")
    client.connect()
    # a second host with a forged token is refused; its ABORT is still honoured
    codec = FrameCodec(dictionary)
    intruder = TcpStream("127.0.0.1", device.tcp_port)
    deframer = StreamDeframer(codec)
    arm = dictionary.command("ARM").opcode
    abort = dictionary.command("ABORT").opcode
    for seq, opcode in ((1, arm), (2, abort)):
        payload = (client.session_token ^ 1).to_bytes(4, "big") + opcode.to_bytes(2, "big")
        intruder.write(codec.frame(dictionary.packet("COMMAND").id, payload, seq, 0))
    answers = []
    wait_for(lambda: answers.extend(deframer.feed(intruder.read(0.05), 0.0)) or
             sum(len(b) for b in answers) >= 3)
    stages = [(int(b["command_sequence"][i]), int(b["stage"][i]), dictionary.error_name(int(b["reason"][i])))
              for b in answers for i in range(len(b))]
    assert (1, 2, "NOT_SESSION_OWNER") in stages
    assert (2, 1, "OK") in stages and (2, 3, "OK") in stages
    intruder.close()


def test_second_host_cannot_take_the_session_without_take_over(client, device, dictionary):
    client.connect()
    other = open_client(dictionary, f"127.0.0.1:{device.tcp_port}", heartbeat=False)
    try:
        with pytest.raises(CommandRejected) as err:
            other.connect()
        assert err.value.reason == "SESSION_BUSY"
        other.connect(take_over=True)
        with pytest.raises(CommandRejected) as err:
            client.command("SET_MODE", mode="OPEN_LOOP")
        assert err.value.reason == "NOT_SESSION_OWNER"
    finally:
        other.close()


# ------------------------------------------------------------------ commands


def test_stages_are_reported_and_rejections_carry_the_reason(client):
    client.connect()
    seen = []
    client.command("SET_MODE", mode="OPEN_LOOP", on_stage=lambda s: seen.append(s.stage))
    assert seen[0] == "SENT" and seen[-1] == "COMPLETED" and "ACCEPTED" in seen
    client.command("SET_MODE", mode="IDLE")
    with pytest.raises(CommandRejected) as err:
        client.command("ARM")
    assert err.value.reason == "INVALID_STATE"
    assert "ARM" in str(err.value) and "INVALID_STATE" in str(err.value)


def test_bad_arguments_are_refused_before_anything_is_sent(client, device):
    client.connect()
    before = client.command_link.bytes_written
    with pytest.raises(CommandArgumentError, match="current_coarse"):
        client.command("SET_CURRENTS", current_coarse=5.0, current_fine=0.0)
    with pytest.raises(CommandArgumentError, match="BOGUS"):
        client.command("SET_MODE", mode="BOGUS")
    with pytest.raises(CommandArgumentError, match="missing"):
        client.command("SET_CURRENTS", current_coarse=0.1)
    assert client.command_link.bytes_written == before


class _DropFirstWrites(TcpStream):
    """TCP client that loses its first `n` writes, as a congested link would."""

    def __init__(self, host, port, n):
        super().__init__(host, port)
        self.to_drop = n

    def _write(self, data):
        if self.to_drop:
            self.to_drop -= 1
            return
        super()._write(data)


def test_unanswered_commands_are_retried_with_the_same_sequence(dictionary, device):
    client = DeviceClient(dictionary, _DropFirstWrites("127.0.0.1", device.tcp_port, 2),
                          heartbeat=False)
    client.start()
    try:
        result = client.connect()
        assert result.retries == 2
        assert [s.stage for s in result.stages] == ["SENT", "RETRY", "RETRY", "ACCEPTED", "COMPLETED"]
    finally:
        client.close()


def test_device_executes_a_repeated_command_once(device, dictionary):
    fw = device.firmware
    events_before = len(fw.events)
    opcode = dictionary.command("ABORT").opcode
    first = fw.handle_command(77, 0, opcode, b"")
    again = fw.handle_command(77, 0, opcode, b"")
    assert first is again                       # the recorded answer, not a new execution
    assert fw.accepted == 1
    assert len(fw.events) == events_before + 1  # one ABORTED event only


def test_command_timeout_names_the_command(dictionary):
    silent = socket.socket()
    silent.bind(("127.0.0.1", 0))
    silent.listen(1)
    port = silent.getsockname()[1]
    accepted = []
    t = threading.Thread(target=lambda: accepted.append(silent.accept()), daemon=True)
    t.start()
    client = open_client(dictionary, f"tcp://127.0.0.1:{port}?telemetry=stream", heartbeat=False)
    try:
        with pytest.raises(CommandTimeout, match="CONNECT.*no answer.*3 retries"):
            client.connect()
    finally:
        client.close()
        t.join(1)
        for conn, _ in accepted:
            conn.close()
        silent.close()


def test_a_device_speaking_another_major_version_is_named(dictionary):
    """A firmware of protocol 2 answers in frames this ground station cannot read."""
    codec = FrameCodec(dictionary)
    server = socket.socket()
    server.bind(("127.0.0.1", 0))
    server.listen(1)

    def newer_firmware():
        conn, _ = server.accept()
        with conn:
            conn.recv(4096)
            frame = bytearray(codec.frame(dictionary.packet("RESPONSE").id, bytes(9), 0, 0))
            frame[2] = 2                                   # protocol major version 2
            body = bytes(frame[:-4])
            conn.sendall(body + zlib.crc32(body).to_bytes(4, "little"))
            while conn.recv(4096):          # until the client gives up and closes
                pass

    t = threading.Thread(target=newer_firmware, daemon=True)
    t.start()
    client = open_client(dictionary, f"tcp://127.0.0.1:{server.getsockname()[1]}?telemetry=stream",
                         heartbeat=False)
    try:
        with pytest.raises(DictionaryMismatchError, match="protocol version 2.*speaks version 1"):
            client.connect()
    finally:
        client.close()
        t.join(2)
        server.close()


# ------------------------------------------------------------------ watchdog and abort


def test_watchdog_stops_the_motors_when_heartbeats_stop(client, device, dictionary):
    blocks = collect(client)
    client.connect()
    client.command("SET_MODE", mode="OPEN_LOOP")
    client.command("ARM")
    # small currents: the axis must not reach its travel limit before the watchdog acts
    client.command("SET_CURRENTS", current_coarse=0.02, current_fine=0.01)
    device.run_ticks(10)
    wait_for(lambda: frames_of(blocks, "HIGH_RATE") >= 10)
    hr = [b for b in blocks if b.name == "HIGH_RATE"][-1]
    assert hr["armed"][-1] and abs(hr["current_coarse"][-1] - 0.02) < 1e-3
    timeout_ticks = int(device.firmware.params["watchdog_timeout"] * dictionary.control_rate_hz)
    device.run_ticks(timeout_ticks + 2)     # no command, no heartbeat for longer than the timeout
    wait_for(lambda: any(b.name == "EVENT" and "WATCHDOG_EXPIRED" in
                         [dictionary.event_name(int(c)) for c in b["code"]] for b in blocks))
    wait_for(lambda: frames_of(blocks, "HIGH_RATE") >= 10 + timeout_ticks + 2)
    hr = np.concatenate([b["current_coarse"] for b in blocks if b.name == "HIGH_RATE"])
    armed = np.concatenate([b["armed"] for b in blocks if b.name == "HIGH_RATE"])
    assert not armed[-1] and hr[-1] == 0.0
    # the expiry happened in the period after the timeout, not later
    assert np.count_nonzero(armed) <= 10 + timeout_ticks + 1
    with pytest.raises(CommandRejected) as err:
        client.command("ARM")
    assert err.value.reason == "FAULT_LATCHED"
    client.command("DISARM")                 # the operator acknowledges the fault
    client.command("SET_MODE", mode="OPEN_LOOP")   # the watchdog left the device in IDLE
    client.command("ARM")


def test_heartbeat_thread_keeps_the_session_alive(dictionary):
    with SimulatedDevice(dictionary, pacing="realtime") as dev:
        c = open_client(dictionary, f"127.0.0.1:{dev.tcp_port}", heartbeat=True)
        try:
            c.connect()
            start = dev.firmware.accepted
            wait_for(lambda: dev.firmware.accepted >= start + 3, timeout=5)
            assert c.heartbeat_failures == 0
            assert c.stats.clock.offset is not None
        finally:
            c.close()


def test_abort_zeroes_both_motors_within_one_period(client, device):
    blocks = collect(client)
    client.connect()
    client.command("SET_MODE", mode="OPEN_LOOP")
    client.command("ARM")
    client.command("SET_CURRENTS", current_coarse=1.0, current_fine=0.5)
    device.run_ticks(5)
    client.abort()
    device.run_ticks(1)
    wait_for(lambda: frames_of(blocks, "HIGH_RATE") >= 6)
    hr = [b for b in blocks if b.name == "HIGH_RATE"]
    cur = np.concatenate([b["current_coarse"] for b in hr])
    fine = np.concatenate([b["current_fine"] for b in hr])
    mode = np.concatenate([b["mode"] for b in hr])
    assert cur[4] == pytest.approx(1.0, abs=1e-3) and cur[5] == 0.0 and fine[5] == 0.0
    assert mode[5] == 0


# ------------------------------------------------------------------ telemetry


def test_udp_telemetry_arrives_complete_with_statistics(client, device):
    blocks = collect(client)
    client.connect()
    device.run_ticks(1200)
    wait_for(lambda: frames_of(blocks, "HIGH_RATE") >= 1200)
    seq = np.concatenate([b["sequence"] for b in blocks if b.name == "HIGH_RATE"])
    assert np.all(np.diff(seq.astype(np.int64)) == 1)
    wait_for(lambda: frames_of(blocks, "HOUSEKEEPING") >= 10)
    snap = client.stats.snapshot()
    assert snap.packets["HIGH_RATE"].frames == 1200 and snap.dropped == 0
    assert snap.framing["crc_errors"] == 0
    hk = [b for b in blocks if b.name == "HOUSEKEEPING"][-1]
    assert hk["param_table_crc"][-1] == device.firmware.param_crc
    assert hk["watchdog"][-1] == 0


def test_dropped_datagrams_are_counted_from_sequence_gaps(client, device):
    blocks = collect(client)
    client.connect()
    count = {"n": 0, "dropped": 0}

    def lose_every_7th(datagram):
        count["n"] += 1
        if count["n"] % 7 == 0 and datagram[3] == 0x01:   # HIGH_RATE datagrams only
            count["dropped"] += 1
            return None
        return datagram

    device.datagram_filter = lose_every_7th
    device.run_ticks(700)
    device.datagram_filter = None
    # a loss shows when the frame after the gap arrives and the next one confirms it
    device.run_ticks(2)
    expected = 702 - count["dropped"]
    wait_for(lambda: frames_of(blocks, "HIGH_RATE") >= expected)
    snap = client.stats.snapshot()
    assert snap.packets["HIGH_RATE"].dropped == count["dropped"] > 50
    assert len(snap.gap_events) == count["dropped"]


def test_telemetry_on_the_command_stream(dictionary, device):
    c = open_client(dictionary, f"tcp://127.0.0.1:{device.tcp_port}?telemetry=stream",
                    heartbeat=False)
    try:
        blocks = collect(c)
        c.connect()
        device.run_ticks(240)
        wait_for(lambda: frames_of(blocks, "HIGH_RATE") >= 240)
        wait_for(lambda: frames_of(blocks, "HOUSEKEEPING") >= 2)
        assert frames_of(blocks, "HOUSEKEEPING") == 2 and frames_of(blocks, "HIGH_RATE") == 240
    finally:
        c.close()


def test_serial_link_over_a_pseudo_terminal(dictionary, device):
    from groundstation.sim.pty import PtyMasterStream

    pty = PtyMasterStream()
    device.attach_stream(pty)
    c = open_client(dictionary, f"serial://{pty.slave_name}?baud=2000000", heartbeat=False)
    blocks = collect(c)
    lost = []
    c.add_link_listener(lambda state, msg: lost.append((state, msg)))
    try:
        c.connect()
        c.command("SET_MODE", mode="RELATIVE")
        device.run_ticks(120)
        wait_for(lambda: frames_of(blocks, "HIGH_RATE") >= 120)
        hr = [b for b in blocks if b.name == "HIGH_RATE"][-1]
        assert hr["mode"][-1] == 2
        received = frames_of(blocks, "HIGH_RATE")
        pty.close()                           # the adapter is unplugged
        wait_for(lambda: c.link_state == "lost")
        assert "serial" in c.link_error and pty.slave_name in c.link_error
        assert lost[-1][0] == "lost"
        assert frames_of(blocks, "HIGH_RATE") == received   # nothing received is lost
        with pytest.raises(LinkLostError):
            c.command("HEARTBEAT")
    finally:
        c.close()


def test_lost_tcp_link_fails_pending_and_keeps_what_was_received(dictionary):
    dev = SimulatedDevice(dictionary, pacing="manual").start()
    c = open_client(dictionary, f"127.0.0.1:{dev.tcp_port}", heartbeat=False)
    blocks = collect(c)
    try:
        c.connect()
        dev.run_ticks(100)
        wait_for(lambda: frames_of(blocks, "HIGH_RATE") >= 100)
        dev.stop()
        wait_for(lambda: c.link_state == "lost")
        assert "closed the connection" in c.link_error or "lost" in c.link_error
        assert frames_of(blocks, "HIGH_RATE") == 100
        with pytest.raises(LinkLostError):
            c.command("GET_INFO")
    finally:
        c.close()


# ------------------------------------------------------------------ bad configuration


def test_ports_in_use_are_reported(dictionary, device):
    with pytest.raises(PortInUseError, match=f"{device.tcp_port}.*--tcp-port"):
        SimulatedDevice(dictionary, tcp_port=device.tcp_port, pacing="manual").start()
    from groundstation.sim.scpi_server import attach_generator
    with pytest.raises(PortInUseError, match=f"{device.tcp_port}.*--fg-port"):
        attach_generator(device, port=device.tcp_port)
    taken = UdpReceiver("127.0.0.1", 0)
    try:
        with pytest.raises(PortInUseError, match=f"UDP port {taken.port}"):
            UdpReceiver("127.0.0.1", taken.port)
    finally:
        taken.close()


def test_nothing_listening_gives_a_clear_error(dictionary):
    s = socket.socket()
    s.bind(("127.0.0.1", 0))
    port = s.getsockname()[1]
    s.close()
    with pytest.raises(LinkError, match="connection refused"):
        open_client(dictionary, f"127.0.0.1:{port}")


@pytest.mark.parametrize("text, message", [
    ("tcp://host", "HOST:PORT"),
    ("udp://h:1", "unknown scheme"),
    ("serial://", "no serial port"),
    ("serial:///dev/ttyUSB0?baud=fast", "baud"),
    ("tcp://h:1?telemetry=carrier-pigeon", "telemetry"),
])
def test_bad_addresses(text, message):
    with pytest.raises(LinkError, match=message):
        parse_address(text)


def test_addresses():
    a = parse_address("192.168.1.20:5020")
    assert (a.kind, a.host, a.port, a.telemetry) == ("tcp", "192.168.1.20", 5020, "udp")
    s = parse_address("serial:///dev/ttyUSB0?baud=115200")
    assert (s.kind, s.serial_port, s.baud) == ("serial", "/dev/ttyUSB0", 115200)


def test_udp_batches_keep_each_datagrams_arrival_time():
    """The reader may wait to batch datagrams; each keeps the time it arrived, so the
    latency statistics do not grow by the batching delay."""
    import select
    import time
    rx = UdpReceiver("127.0.0.1", 0)
    tx = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
    try:
        if rx.kernel_timestamps:
            # Linux switches arrival stamping on a moment after the first socket asks for
            # it (deferred work); until then it stamps a datagram when it is read.  Probe
            # until a stamp predates our own read of the clock after readiness, i.e. the
            # kernel stamps on arrival (bounded: a few hundred probes at most).
            for _ in range(500):
                tx.sendto(b"probe", (rx.host, rx.port))
                assert select.select([rx._sock], [], [], 10.0)[0]
                ready_at = time.time()
                _, probe_times = rx.receive(1.0)
                if probe_times[0] <= ready_at:
                    break
            else:
                raise AssertionError("the kernel never stamped a datagram on arrival")
        sent_at = time.time()
        tx.sendto(bytes([0]) * 10, (rx.host, rx.port))
        # the first datagram has certainly arrived once the socket is readable (on a busy
        # machine loopback delivery can lag sendto); only then is `between` read
        assert select.select([rx._sock], [], [], 10.0)[0]
        between = time.time()
        for i in range(1, 5):
            tx.sendto(bytes([i]) * 10, (rx.host, rx.port))
        datagrams, times = rx.receive(1.0, coalesce_s=0.3)
    finally:
        tx.close()
        rx.close()
    assert [d[0] for d in datagrams] == [0, 1, 2, 3, 4]
    assert times == sorted(times)
    if rx.kernel_timestamps:
        # stamped on arrival: the first before `between`, the others after it - not all
        # when drained at the end of receive()'s 0.3 s batching wait.  An order of events,
        # so it holds on a busy machine too.
        assert times[0] <= between <= times[1]
    assert times[0] >= sent_at - 1.0


def test_a_wake_ends_a_receive_waiting_for_telemetry():
    """Closing a socket does not end a recv another thread waits in; wake() does, so a
    session's close does not sleep out the reader's timeout (bounded join: a reader
    still waiting for its 60 s would fail the test, not hang it)."""
    rx = UdpReceiver("127.0.0.1", 0)
    got = []
    reader = threading.Thread(target=lambda: got.append(rx.receive(60.0)), daemon=True)
    try:
        reader.start()
        rx.wake()
        reader.join(30.0)
        assert not reader.is_alive()
        assert got == [([], [])]
        reader = threading.Thread(target=lambda: got.append(rx.receive(60.0)), daemon=True)
        reader.start()
        rx.close()                          # a close wakes it too
        reader.join(30.0)
        assert not reader.is_alive()
    finally:
        rx.close()


def test_closing_hands_on_every_frame_already_queued_on_loopback(client, device):
    """On loopback the drain at close waits a short quiet time only (the device's
    datagrams are in the socket before its answer, or just after on a busy machine):
    none is lost."""
    assert client.drain_quiet_s < 0.1
    blocks = collect(client)
    client.connect()
    first = device._seq["HIGH_RATE"]
    device.run_ticks(1200)
    sent = device._seq["HIGH_RATE"] - first
    client.close()
    assert sent == 1200
    assert frames_of(blocks, "HIGH_RATE") == sent


def test_a_remote_device_is_drained_until_quiet():
    from groundstation.link.client import _on_loopback
    assert _on_loopback(("127.0.0.1", 5020)) and _on_loopback(("::1", 5020, 0, 0))
    assert not _on_loopback(("192.168.1.20", 5020)) and not _on_loopback(None)
    assert not _on_loopback(("not-an-address", 1))
