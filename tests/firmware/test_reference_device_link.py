"""The C reference device against the ground station's own client (groundstation.link):
telemetry decodes with no framing error and no sequence gap, every channel carries a
plausible value, the watchdog and profiles keep to their ticks (SPEC §9.1, §11.2)."""

from __future__ import annotations

import struct
import zlib

import numpy as np
import pytest

from groundstation.core.dictionary import load_dictionary
from conftest import wait_for as poll_until
from groundstation.link import open_client
from reference_device_helpers import running_reference_device

DEFAULT_TABLE_CRC = 0x358F611E           # SPEC §11.1


@pytest.fixture(scope="module")
def dictionary():
    return load_dictionary()


def wait_for(predicate, timeout: float = 15.0):
    """The suite's bounded poll (conftest.wait_for), with room for a real-time device."""
    return poll_until(predicate, timeout=timeout)


def columns(blocks, packet, name):
    parts = [b.columns[name] for b in list(blocks) if b.name == packet]
    return np.concatenate(parts) if parts else np.array([])


@pytest.mark.parametrize("suffix", ["", "?telemetry=stream"])
def test_connect_and_stream_without_errors_or_gaps(dictionary, suffix):
    with running_reference_device() as address:
        client = open_client(dictionary, address + suffix)
        blocks = []
        client.subscribe(blocks.append)
        try:
            reply = client.connect().reply
            assert reply["dictionary_hash"] == dictionary.hash and reply["session_token"] != 0
            wait_for(lambda: len(columns(blocks, "HIGH_RATE", "tick")) >= 2400
                     and len(columns(blocks, "HOUSEKEEPING", "tick")) >= 3)
            snap = client.stats.snapshot()
        finally:
            client.close()
    for key in ("crc_errors", "resyncs", "junk_bytes", "version_errors", "length_errors",
                "unknown_packet_errors"):
        assert snap.framing[key] == 0, (key, snap.framing)
    for name in ("HIGH_RATE", "HOUSEKEEPING"):
        ps = snap.packets[name]
        assert (ps.dropped, ps.duplicates, ps.outliers) == (0, 0, 0), (name, ps)
    # one frame per control period: ticks and sequence numbers both step by exactly 1
    ticks = columns(blocks, "HIGH_RATE", "tick").astype(np.int64)
    seqs = columns(blocks, "HIGH_RATE", "sequence").astype(np.int64)
    assert np.all(np.diff(ticks) == 1) and np.all((np.diff(seqs) % 2**32) == 1)
    assert np.all(np.diff(columns(blocks, "HOUSEKEEPING", "tick")) == 120)

    # plausible values, in the dictionary's units
    hr = {item: columns(blocks, "HIGH_RATE", item) for item in
          ("mode", "armed", "fault", "encoder_outer", "current_coarse", "profile_index")}
    assert np.all(hr["mode"] == 0) and not hr["armed"].any() and not hr["fault"].any()
    assert np.all(np.abs(hr["encoder_outer"]) < 0.3) and np.all(hr["current_coarse"] == 0)
    assert np.all(hr["profile_index"] == 0)
    hk = {item: columns(blocks, "HOUSEKEEPING", item)[-1] for item in
          ("supply_motor", "supply_logic", "temp_flexure", "temp_motor_coarse", "watchdog",
           "heartbeat_age", "param_table_crc", "param_table_version", "fault_code",
           "firmware_version", "telemetry_overruns")}
    assert 26.0 <= hk["supply_motor"] <= 30.0 and 4.85 <= hk["supply_logic"] <= 5.15
    assert 15.0 <= hk["temp_flexure"] <= 40.0 and -10.0 <= hk["temp_motor_coarse"] <= 60.0
    assert hk["watchdog"] == 0 and hk["heartbeat_age"] < 1000          # OK, heartbeats arrive
    assert int(hk["param_table_crc"]) == DEFAULT_TABLE_CRC and hk["param_table_version"] == 0
    assert hk["fault_code"] == 0 and hk["firmware_version"] == 0x000100
    assert hk["telemetry_overruns"] == 0


def upload_table(client, dictionary, **changes) -> None:
    """PARAM_BEGIN/WRITE/COMMIT of the default table with `changes`, packed by the
    ground station's own packer (groundstation.params.table)."""
    from groundstation.params.table import default_values, pack
    values = default_values(dictionary)
    values.update(changes)
    table = pack(dictionary, values)
    client.command("PARAM_BEGIN", table_version=5, table_length=len(table))
    for off in range(0, len(table), 1000):
        client.command("PARAM_WRITE", offset=off, data=table[off:off + 1000])
    client.command("PARAM_COMMIT", table_crc=zlib.crc32(table))


# (watchdog_timeout, periods after the last reset in which it trips); None: the default 1.0
@pytest.mark.parametrize("timeout_s,trips_after", [(None, 1201), (0.7, 840)])
def test_a_silent_host_trips_the_watchdog_in_the_documented_period(dictionary, timeout_s,
                                                                   trips_after):
    """SPEC §9.1: armed, no heartbeat: the first period with more than
    watchdog_timeout x 1200 ticks since the last reset disarms, IDLE, fault WATCHDOG.
    f32 0.7 s is 839.99998 ticks, so the 840th period is already beyond it."""
    assert float(np.float32(0.7)) * 1200 < 840
    with running_reference_device() as address:
        client = open_client(dictionary, address, heartbeat=False)
        blocks = []
        client.subscribe(blocks.append)
        try:
            client.connect()
            if timeout_s is not None:
                upload_table(client, dictionary, watchdog_timeout=timeout_s)
            client.command("SET_MODE", mode="OPEN_LOOP")
            arm = client.command("ARM")
            arm_tick = [s.device_tick for s in arm.stages if s.stage == "COMPLETED"][0]
            wait_for(lambda: any(columns(blocks, "HOUSEKEEPING", "watchdog") == 2))
            hk_fault = columns(blocks, "HOUSEKEEPING", "fault_code")[-1]
            ticks = columns(blocks, "HIGH_RATE", "tick").astype(np.int64)
            armed = columns(blocks, "HIGH_RATE", "armed").astype(bool)
            mode = columns(blocks, "HIGH_RATE", "mode")
            events = columns(blocks, "EVENT", "code")
            client.command("DISARM")                   # acknowledges the fault
            wait_for(lambda: columns(blocks, "HOUSEKEEPING", "fault_code")[-1] == 0)
        finally:
            client.close()
    assert hk_fault == 1                               # WATCHDOG
    after = ticks > arm_tick
    first_off = ticks[after][~armed[after]][0]
    assert first_off == arm_tick + trips_after
    assert mode[ticks == first_off][0] == 0            # IDLE in that very period
    assert 14 in events and 12 in events               # WATCHDOG_EXPIRED, DISARMED


def test_a_profile_plays_sample_exact(dictionary):
    """SPEC §11.2: in the k-th period after PROFILE_START sample k-1 drives the target and
    HIGH_RATE shows profile_index = k; EVENT PROFILE_STARTED then PROFILE_FINISHED."""
    samples = np.linspace(0.0, 1e-3, 240, dtype=">f4")
    data = samples.tobytes()
    with running_reference_device() as address:
        client = open_client(dictionary, address)
        blocks = []
        client.subscribe(blocks.append)
        try:
            client.connect()
            client.command("SET_MODE", mode="RELATIVE")
            client.command("ARM")
            client.command("PROFILE_BEGIN", profile_id=7, target="REFERENCE",
                           sample_count=len(samples))
            client.command("PROFILE_WRITE", offset=0, samples=data[:800])
            client.command("PROFILE_WRITE", offset=200, samples=data[800:])
            client.command("PROFILE_COMMIT", profile_crc=zlib.crc32(data))
            client.command("PROFILE_START")
            wait_for(lambda: 31 in columns(blocks, "EVENT", "code"))
            wait_for(lambda: any(columns(blocks, "HOUSEKEEPING", "active_profile") == 7))
            client.command("DISARM")
        finally:
            client.close()
    index = columns(blocks, "HIGH_RATE", "profile_index").astype(np.int64)
    active = columns(blocks, "HIGH_RATE", "profile_active").astype(bool)
    ticks = columns(blocks, "HIGH_RATE", "tick").astype(np.int64)
    ref = columns(blocks, "HIGH_RATE", "reference")
    playing = index > 0
    assert np.array_equal(index[playing], np.arange(1, len(samples) + 1))
    assert np.all(np.diff(ticks[playing]) == 1) and np.array_equal(active, playing)
    scale = 2 * np.pi / 2**32
    assert np.all(np.abs(ref[playing] - samples.astype(np.float64)) <= scale)
    # after the last sample the target holds its value
    assert abs(ref[-1] - float(samples[-1])) <= scale
    codes = list(columns(blocks, "EVENT", "code"))
    assert codes.index(30) < codes.index(31)


# ------------------------------------------------------------------ raw frames (SPEC §6)
class RawHost:
    """A command connection of its own, frames built with struct/zlib from SPEC §2, so the
    device's own checks are seen (the client checks arguments before sending)."""

    next_start = 0

    def __init__(self, address: str):
        import socket
        host, port = address[len("tcp://"):].split(":")
        self.sock = socket.create_connection((host, int(port)), timeout=10)
        self.buf = b""
        # SPEC §6.4: the device remembers (sequence, opcode) pairs of every connection
        # alike, so two hosts must not share numbers: each RawHost starts far from the last
        RawHost.next_start += 1_000_000
        self.seq = RawHost.next_start
        self.token = 0
        self.udp = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
        self.udp.bind(("127.0.0.1", 0))             # a telemetry port nobody reads

    def close(self):
        self.sock.close()
        self.udp.close()

    def send(self, opcode: int, args: bytes = b"", *, seq: int | None = None,
             token: int | None = None, version: int = 1) -> int:
        seq = self.seq = self.seq + 1 if seq is None else seq
        payload = struct.pack(">IH", self.token if token is None else token, opcode) + args
        body = struct.pack(">BBBBHII", 0xEB, 0x90, version, 0x10, len(payload), seq, 0) + payload
        self.sock.sendall(body + struct.pack("<I", zlib.crc32(body)))
        return seq

    def response(self):
        """(header sequence, command_sequence, opcode, stage, reason, data) of the next
        RESPONSE frame on this connection."""
        while True:
            if len(self.buf) >= 14:
                length = struct.unpack(">H", self.buf[4:6])[0]
                if len(self.buf) >= 18 + length:
                    frame, self.buf = self.buf[:18 + length], self.buf[18 + length:]
                    assert zlib.crc32(frame) == 0x2144DF1C         # SPEC §2.1 residue
                    if frame[3] == 0x11:
                        seq = struct.unpack(">I", frame[6:10])[0]
                        cseq, op, stage, reason = struct.unpack(">IHBH", frame[14:23])
                        return seq, cseq, op, stage, reason, frame[23:14 + length]
                    continue
            chunk = self.sock.recv(65536)
            assert chunk, "connection closed"
            self.buf += chunk

    def exchange(self, opcode: int, args: bytes = b"", **kw):
        """Send; return [(stage, reason, data), ...] up to the final stage."""
        seq = self.send(opcode, args, **kw)
        out = []
        while not out or out[-1][0] == 1:
            _, cseq, op, stage, reason, data = self.response()
            assert (cseq, op) == (seq, opcode)
            out.append((stage, reason, data))
        return out

    def connect(self, dictionary, *, take_over: int = 0, hash_: int | None = None):
        args = struct.pack(">BBIHB", 1, 0, dictionary.hash if hash_ is None else hash_,
                           self.udp.getsockname()[1], take_over)
        stages = self.exchange(0x0001, args, token=0)
        if stages[-1][0] == 3:
            self.token = struct.unpack(">I", stages[-1][2][:4])[0]
        return stages


ACCEPTED, REJECTED, COMPLETED, FAILED = 1, 2, 3, 4
CONNECT, HEARTBEAT, SET_MODE, ARM, DISARM, ABORT = 0x01, 0x03, 0x10, 0x11, 0x12, 0x13
SET_CURRENTS, SET_REFERENCE = 0x15, 0x16
PARAM_BEGIN, PARAM_WRITE, PARAM_COMMIT, PARAM_READ = 0x20, 0x21, 0x22, 0x23


def f32(*values):
    return struct.pack(f">{len(values)}f", *values)


def test_refusal_codes_and_the_devices_own_range_checks(dictionary):
    with running_reference_device() as address:
        a = RawHost(address)
        try:
            # no session yet: NOT_SESSION_OWNER with the text SPEC §7 gives
            assert a.exchange(HEARTBEAT) == [(REJECTED, 4, b"no session open")]
            # dictionary mismatch: the CONNECT reply layout with token 0 and the device's hash
            (stage, reason, data), = a.connect(dictionary, hash_=dictionary.hash ^ 1)
            assert (stage, reason) == (REJECTED, 6)
            token, major, minor, dhash, _tick = struct.unpack(">IBBII", data)
            assert (token, major, minor, dhash) == (0, 1, 0, dictionary.hash)
            assert [s[:2] for s in a.connect(dictionary)] == [(ACCEPTED, 0), (COMPLETED, 0)]
            assert a.exchange(0x7777) == [(REJECTED, 1, b"")]                 # unknown
            assert a.exchange(SET_MODE, b"")[0][:2] == (REJECTED, 2)          # length
            assert a.exchange(SET_MODE, b"\x09")[0][:2] == (REJECTED, 3)      # not a state
            # f32 ranges compared in f32: the bound itself passes the range check (and
            # then meets the state rule: IDLE), one step beyond it does not; NaN never
            assert a.exchange(SET_REFERENCE, f32(0.349))[0][:2] == (REJECTED, 7)
            assert a.exchange(SET_REFERENCE, f32(0.3491))[0][:2] == (REJECTED, 3)
            assert a.exchange(SET_REFERENCE, f32(float("nan")))[0][:2] == (REJECTED, 3)
            assert a.exchange(ARM)[0][:2] == (REJECTED, 7)                    # IDLE
            assert a.exchange(SET_MODE, b"\x01")[-1][:2] == (COMPLETED, 0)
            assert a.exchange(SET_CURRENTS, f32(0.1, 0.0))[0][:2] == (REJECTED, 8)   # not armed
            assert a.exchange(SET_CURRENTS, f32(2.54, 0.0))[0][:2] == (REJECTED, 3)
            # a wrong token: the text names the owner
            (stage, reason, data), = a.exchange(HEARTBEAT, token=a.token ^ 0xFFFF)
            assert (stage, reason) == (REJECTED, 4) and data.startswith(b"owner 127.0.0.1:")
        finally:
            a.close()


def test_a_resent_command_is_executed_once_and_its_answer_repeated(dictionary):
    with running_reference_device() as address:
        a = RawHost(address)
        try:
            a.connect(dictionary)
            first = a.exchange(SET_MODE, b"\x02")                 # RELATIVE
            seq_relative = a.seq
            assert [s[:2] for s in a.exchange(SET_MODE, b"\x01")] == [(ACCEPTED, 0), (COMPLETED, 0)]
            # the first SET_MODE again, byte for byte: its answers again, not executed
            headers = []
            a.send(SET_MODE, b"\x02", seq=seq_relative)
            replay = []
            for _ in range(2):
                hseq, cseq, op, stage, reason, data = a.response()
                headers.append(hseq)
                replay.append((stage, reason, data))
            assert replay == first and headers[1] == headers[0] + 1
            # still OPEN_LOOP: ARM and SET_CURRENTS (OPEN_LOOP only) are accepted
            assert a.exchange(ARM)[-1][:2] == (COMPLETED, 0)
            assert a.exchange(SET_CURRENTS, f32(0.0, 0.0))[-1][:2] == (COMPLETED, 0)
            assert a.exchange(DISARM)[-1][:2] == (COMPLETED, 0)
        finally:
            a.close()


def test_sessions_busy_abort_from_anyone_and_take_over(dictionary):
    with running_reference_device() as address:
        a, b = RawHost(address), RawHost(address)
        try:
            a.connect(dictionary)
            assert a.exchange(SET_MODE, b"\x01")[-1][:2] == (COMPLETED, 0)
            assert a.exchange(ARM)[-1][:2] == (COMPLETED, 0)
            assert b.connect(dictionary) == [(REJECTED, 5, b"")]             # SESSION_BUSY
            assert [s[:2] for s in b.exchange(ABORT, token=0)] == [(ACCEPTED, 0), (COMPLETED, 0)]
            assert a.exchange(ARM)[0][:2] == (REJECTED, 7)                   # ABORT: IDLE now
            assert a.exchange(HEARTBEAT)[-1][:2] == (COMPLETED, 0)           # session kept
            assert b.connect(dictionary, take_over=1)[-1][:2] == (COMPLETED, 0)
            (stage, reason, data), = a.exchange(HEARTBEAT)
            assert (stage, reason) == (REJECTED, 4) and data.startswith(b"owner 127.0.0.1:")
            # the owner's own CONNECT is never busy
            assert b.connect(dictionary)[-1][:2] == (COMPLETED, 0)
        finally:
            a.close()
            b.close()


def test_parameter_commit_rules(dictionary):
    from groundstation.params.table import default_values, pack
    default = pack(dictionary, default_values(dictionary))      # the ground station's packer
    assert zlib.crc32(default) == DEFAULT_TABLE_CRC
    with running_reference_device() as address:
        a = RawHost(address)
        try:
            a.connect(dictionary)
            (stage, reason, data), = a.exchange(PARAM_READ, struct.pack(">IH", 0, 1000))[1:]
            assert (stage, reason) == (COMPLETED, 0) and data[4:] == default[:1000]
            assert a.exchange(PARAM_READ, struct.pack(">IH", 4000, 9))[0][:2] == (REJECTED, 3)
            assert a.exchange(PARAM_COMMIT, struct.pack(">I", 0))[0][:2] == (REJECTED, 11)
            assert a.exchange(PARAM_BEGIN, struct.pack(">HI", 3, 4007))[0][:2] == (REJECTED, 3)
            assert a.exchange(PARAM_BEGIN, struct.pack(">HI", 3, len(default)))[-1][0] == COMPLETED
            table = bytearray(default)
            table[50:58] = struct.pack(">d", 2.0)            # relative_c0 row 0: a0 = 2
            for off in range(0, len(table), 1000):
                assert a.exchange(PARAM_WRITE, struct.pack(">I", off) + bytes(table[off:off + 1000]))[-1][0] == COMPLETED
            assert a.exchange(PARAM_WRITE, struct.pack(">I", 4000) + bytes(9))[0][:2] == (REJECTED, 3)
            crc = zlib.crc32(bytes(table))
            assert a.exchange(PARAM_COMMIT, struct.pack(">I", crc ^ 1))[-1][:2] == (FAILED, 9)
            assert a.exchange(PARAM_COMMIT, struct.pack(">I", crc))[-1][:2] == (FAILED, 10)
            # the staging is kept after a failed commit: repair the one section, commit
            table[50:58] = struct.pack(">d", 1.0)
            table[0:4] = struct.pack(">f", 2.5)              # watchdog_timeout
            assert a.exchange(PARAM_WRITE, struct.pack(">I", 0) + bytes(table[:100]))[-1][0] == COMPLETED
            crc = zlib.crc32(bytes(table))
            (stage, reason, data), = a.exchange(PARAM_COMMIT, struct.pack(">I", crc))[1:]
            assert (stage, reason) == (COMPLETED, 0) and struct.unpack(">I", data[:4])[0] == crc
            assert a.exchange(PARAM_COMMIT, struct.pack(">I", crc))[0][:2] == (REJECTED, 11)
            (stage, reason, data), = a.exchange(PARAM_READ, struct.pack(">IH", 0, 4))[1:]
            assert data[4:] == struct.pack(">f", 2.5)
        finally:
            a.close()


def test_connect_of_another_major_version_is_answered_dictionary_mismatch(dictionary):
    """SPEC §7: such a frame fails framing (a version error), yet a device should answer
    a CONNECT in it with REJECTED DICTIONARY_MISMATCH, in a frame of its own version."""
    with running_reference_device() as address:
        a = RawHost(address)
        try:
            args = struct.pack(">BBIHB", 2, 0, 0x12345678, a.udp.getsockname()[1], 0)
            a.sock.sendall(b"junk\xeb")                  # the device must find it anyway
            seq = a.send(CONNECT, args, token=0, version=2)
            _, cseq, op, stage, reason, data = a.response()
            assert (cseq, op, stage, reason) == (seq, CONNECT, REJECTED, 6)
            token, major, minor, dhash, _tick = struct.unpack(">IBBII", data)
            assert (token, major, minor, dhash) == (0, 1, 0, dictionary.hash)
            # other commands of another version get no answer; a good CONNECT still works
            a.send(HEARTBEAT, token=0, version=2)
            assert [s[:2] for s in a.connect(dictionary)] == [(ACCEPTED, 0), (COMPLETED, 0)]
        finally:
            a.close()
