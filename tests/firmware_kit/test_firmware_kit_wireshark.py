"""The exported Wireshark dissector (`groundstation protocol export-wireshark`), run by
tshark on a capture this test writes itself (pcap file format by hand: global header,
record headers, Ethernet/IPv4/UDP/TCP around the frames):

* UDP telemetry: datagrams of HIGH_RATE frames made by the simulator's own encoder while
  it runs open loop (so the values move), HOUSEKEEPING and EVENT frames, and one frame
  with a corrupted CRC; every HIGH_RATE field tshark shows equals the value the ground
  station's codec decodes (engineering values at tshark's display precision, wire
  counts, flags and states exactly);
* the TCP command channel: the simulated firmware's answers to real commands, frames
  split across segments and several in one, with arguments and replies decoded;
* the ports are preferences;
* on any other port heuristics find the protocol by a whole frame with a good CRC.
"""

from __future__ import annotations

import json
import shutil
import struct
import subprocess
import sys
from pathlib import Path

import pytest

from groundstation.codec import FrameCodec, StreamDeframer, encode_items
from groundstation.core.dictionary import load_dictionary
from groundstation.firmware_kit import export_wireshark, render_lua
from groundstation.firmware_kit.layout import lower

ROOT = Path(__file__).resolve().parents[2]
DEVICE_IP, HOST_IP = bytes([192, 168, 1, 20]), bytes([192, 168, 1, 2])
HOST_UDP, HOST_TCP = 40000, 50000


def tshark() -> str:
    path = shutil.which("tshark")
    if path is None:
        pytest.fail("tshark is not installed: run `make setup` (tools/system-deps.sh installs "
                    "the Debian package tshark), or `apt-get install tshark` as root")
    return path


# ------------------------------------------------------------------ a pcap, by hand
def _checksum(data: bytes) -> int:
    if len(data) % 2:
        data += b"\x00"
    s = sum(struct.unpack(f">{len(data) // 2}H", data))
    while s >> 16:
        s = (s & 0xFFFF) + (s >> 16)
    return ~s & 0xFFFF


def _ipv4(src: bytes, dst: bytes, proto: int, payload: bytes) -> bytes:
    head = struct.pack(">BBHHHBBH4s4s", 0x45, 0, 20 + len(payload), 0, 0x4000, 64, proto, 0, src, dst)
    return head[:10] + struct.pack(">H", _checksum(head)) + head[12:] + payload


def _ethernet(payload: bytes) -> bytes:
    return bytes.fromhex("02000000000102000000000208 00".replace(" ", "")) + payload


def udp_packet(sport: int, dport: int, payload: bytes) -> bytes:
    udp = struct.pack(">HHHH", sport, dport, 8 + len(payload), 0) + payload   # checksum 0: none
    return _ethernet(_ipv4(DEVICE_IP, HOST_IP, 17, udp))


class TcpFlow:
    """Segments of one TCP connection host:HOST_TCP <-> device:port, handshake included."""

    def __init__(self, port: int):
        self.port = port
        self.seq = {"host": 1000, "device": 5000}
        self.packets: list[bytes] = []
        self._segment("host", 0x02, b"")           # SYN
        self._segment("device", 0x12, b"")         # SYN ACK
        self._segment("host", 0x10, b"")           # ACK

    def _segment(self, side: str, flags: int, payload: bytes) -> None:
        other = "device" if side == "host" else "host"
        sport, dport = (HOST_TCP, self.port) if side == "host" else (self.port, HOST_TCP)
        src, dst = (HOST_IP, DEVICE_IP) if side == "host" else (DEVICE_IP, HOST_IP)
        ack = self.seq[other] if flags != 0x02 else 0
        tcp = struct.pack(">HHIIBBHHH", sport, dport, self.seq[side], ack, 5 << 4, flags, 65535, 0, 0)
        self.packets.append(_ethernet(_ipv4(src, dst, 6, tcp + payload)))
        self.seq[side] = (self.seq[side] + len(payload) + (1 if flags & 0x02 else 0)) & 0xFFFFFFFF

    def send(self, side: str, data: bytes) -> None:
        self._segment(side, 0x18, data)            # PSH ACK


def write_pcap(path: Path, packets: list[bytes]) -> None:
    """pcap: magic, version 2.4, UTC offset 0, accuracy 0, snaplen, link type 1 (Ethernet);
    then per packet: seconds, microseconds, captured and original length."""
    with open(path, "wb") as f:
        f.write(struct.pack("<IHHiIII", 0xA1B2C3D4, 2, 4, 0, 0, 65535, 1))
        for i, pkt in enumerate(packets):
            f.write(struct.pack("<IIII", 1_700_000_000 + i // 1000, (i % 1000) * 833, len(pkt), len(pkt)))
            f.write(pkt)


# ------------------------------------------------------------------ traffic
def frames_of(codec, data: bytes) -> list[bytes]:
    d = StreamDeframer(codec)
    frames = []
    for b in d.feed(data, 0.0) + d.flush(0.0):
        frames += [r.tobytes() for r in b.raw] if b.raw is not None else list(b.frames)
    return sorted(frames, key=data.index)


@pytest.fixture(scope="module")
def traffic(dictionary):
    """The simulator's firmware driven through real commands (open loop, currents set),
    then 0.2 s of its telemetry.  Returns the COMMAND/RESPONSE exchange and the frames."""
    from groundstation.sim import SimulatedDevice

    codec = FrameCodec(dictionary)
    dev = SimulatedDevice(dictionary, pacing="manual", seed=5)
    fw = dev.firmware
    exchange: list[tuple[str, bytes]] = []
    rsp_seq = iter(range(100, 200))
    state = {"seq": 41, "token": 0}

    def command(name, values=None, token=None, peer=1):
        cmd = dictionary.command(name)
        args = encode_items(cmd.args, values or {}, name)
        state["seq"] += 1
        tok = state["token"] if token is None else token
        exchange.append(("host", codec.encode_variable("COMMAND", {
            "session_token": tok, "opcode": cmd.opcode, "arguments": args}, state["seq"], 0)))
        stages = fw.handle_command(state["seq"], tok, cmd.opcode, args, peer=peer)
        for st in stages:
            exchange.append(("device", codec.encode_variable("RESPONSE", {
                "command_sequence": state["seq"], "opcode": cmd.opcode, "stage": st.stage,
                "reason": st.reason, "data": st.data}, next(rsp_seq), fw.tick)))
        return stages

    hello = {"protocol_major": dictionary.version_major, "protocol_minor": dictionary.version_minor,
             "dictionary_hash": dictionary.hash, "telemetry_port": HOST_UDP, "take_over": 0}
    stages = command("CONNECT", hello)
    state["token"] = int.from_bytes(stages[-1].data[:4], "big")
    command("SET_MODE", {"mode": "OPEN_LOOP"})
    command("ARM")
    command("SET_CURRENTS", {"current_coarse": 0.8, "current_fine": -0.25})
    command("ARM", token=state["token"] ^ 1, peer=2)                        # NOT_SESSION_OWNER
    command("CONNECT", {**hello, "dictionary_hash": dictionary.hash ^ 1}, token=0, peer=3)
    out: list[bytes] = []
    dev.run_fast(0.2, out.append, batch=60)
    return {"exchange": exchange, "frames": frames_of(codec, b"".join(out)), "token": state["token"]}


@pytest.fixture(scope="module")
def dictionary():
    return load_dictionary()


def datagrams(frames: list[bytes], hr_id: int, per: int = 4) -> list[bytes]:
    """As the simulator sends them: HIGH_RATE frames batched `per` to a datagram (the last
    batch shorter), every other frame alone."""
    out, batch = [], []
    for f in frames:
        if f[3] == hr_id:
            batch.append(f)
            if len(batch) == per:
                out.append(b"".join(batch))
                batch = []
        else:
            out.append(f)
    return out + ([b"".join(batch)] if batch else [])


def run_tshark(pcap: Path, lua: Path, fields: list[str], *options: str) -> list[dict]:
    cmd = [tshark(), "-r", str(pcap), "-X", f"lua_script:{lua}", *options, "-T", "json"]
    for f in fields:
        cmd += ["-e", f]
    res = subprocess.run(cmd, capture_output=True, text=True, timeout=120)
    assert res.returncode == 0, res.stderr
    errors = [ln for ln in res.stderr.splitlines() if "Lua" in ln or "lua" in ln]
    assert not errors, res.stderr
    return [p["_source"]["layers"] for p in json.loads(res.stdout or "[]")]


def shown_equals(shown: str, value: float, digits: int) -> bool:
    """tshark prints a double with 15 significant digits and a float with 6: the shown
    text must be the exact value, or the exact value rounded as tshark rounds it."""
    return float(shown) == value or shown == f"{value:.{digits}g}"


# ------------------------------------------------------------------ tests
@pytest.fixture(scope="module")
def capture(tmp_path_factory, dictionary, traffic):
    base = tmp_path_factory.mktemp("wireshark")
    lua = export_wireshark(dictionary, base / "hfb_protocol.lua")
    hr = dictionary.packet("HIGH_RATE")
    grams = datagrams(traffic["frames"], hr.id)
    bad = bytearray(traffic["frames"][10])
    bad[20] ^= 0x01                                  # one corrupted frame, alone
    packets = {}
    for port in (5020, 7020):
        flow = TcpFlow(port)
        for side, frame in traffic["exchange"][:2]:
            flow.send(side, frame[:9])               # split inside the header ...
            flow.send(side, frame[9:])               # ... and the rest
        pending = b""                                # device bytes not sent yet
        for side, frame in traffic["exchange"][2:]:
            if side == "host":
                flow.send(side, frame)
                continue
            pending += frame
            if len(pending) > 40:
                flow.send(side, pending[:len(pending) - 10])   # frames run over segments
                pending = pending[len(pending) - 10:]
        if pending:
            flow.send("device", pending)
        # then junk, a frame with a bad CRC and a good frame, from the host
        beat = [codec_frame(dictionary, "HEARTBEAT", seq, traffic["token"]) for seq in (90, 91)]
        flow.send("host", b"\x00noise\xEB\x90\x07" + beat[0][:-1] + bytes([beat[0][-1] ^ 0xFF]))
        flow.send("host", beat[1])
        udp = [udp_packet(port, HOST_UDP, g) for g in grams + [bytes(bad)]]
        packets[port] = udp[:5] + flow.packets + udp[5:]
        write_pcap(base / f"port{port}.pcap", packets[port])
    return {"dir": base, "lua": lua, "datagrams": grams, "bad": bytes(bad)}


def codec_frame(dictionary, name: str, seq: int, token: int) -> bytes:
    cmd = dictionary.command(name)
    return FrameCodec(dictionary).encode_variable("COMMAND", {
        "session_token": token, "opcode": cmd.opcode, "arguments": b""}, seq, 0)


def hr_fields(dictionary) -> dict[str, tuple]:
    """tshark field -> (item, how to get the Python value from a decoded block, digits)."""
    hr = dictionary.packet("HIGH_RATE")
    out = {"hfb.sequence": (None, "sequence", 0), "hfb.tick": (None, "tick", 0)}
    for item in hr.items:
        abbrev = f"hfb.high_rate.{lower(item.name)}"
        if item.scale is not None:
            out[abbrev] = (item, "eng", 15)
            out[abbrev + ".raw"] = (item, "raw", 0)
        elif item.type == "f32":
            out[abbrev] = (item, "eng", 6)
        else:
            out[abbrev] = (item, "raw", 0)
        for flag in item.bits:
            out[f"{abbrev}.{lower(flag)}"] = (item, f"flag:{flag}", 0)
    return out


def test_every_high_rate_field_tshark_shows_equals_the_decoded_value(capture, dictionary):
    codec = FrameCodec(dictionary)
    fields = hr_fields(dictionary)
    listed = subprocess.run([tshark(), "-G", "fields", "-X", f"lua_script:{capture['lua']}"],
                            capture_output=True, text=True, timeout=120).stdout.splitlines()
    hr_listed = {ln.split("\t")[2]: ln.split("\t") for ln in listed
                 if ln.startswith("F\t") and ln.split("\t")[2].startswith("hfb.high_rate.")}
    assert set(hr_listed) == set(fields) - {"hfb.sequence", "hfb.tick"}
    for item in dictionary.packet("HIGH_RATE").items:         # units in label and description
        if item.units:
            row = hr_listed[f"hfb.high_rate.{lower(item.name)}"]
            assert f"[{item.units}]" in row[1] and item.units in row[-1], row

    layers = run_tshark(capture["dir"] / "port5020.pcap", capture["lua"],
                        [*fields, "hfb.crc.good", "hfb.packet_id"], "-Y", "udp")
    hr_id = dictionary.packet("HIGH_RATE").id
    expected = [codec.decode_frame(g[i:i + 78]) for g in capture["datagrams"] if g[3] == hr_id
                for i in range(0, len(g), 78)]
    shown = [lay for lay in layers if "hfb.high_rate.mode" in lay]
    rows = []
    for lay in shown:
        n = len(lay["hfb.high_rate.mode"])
        assert all(len(lay[f]) == n for f in [*fields, "hfb.crc.good"]), "a field is missing"
        rows += [{f: lay[f][k] for f in [*fields, "hfb.crc.good"]} for k in range(n)]
    bad = [r for r in rows if r["hfb.crc.good"] != "1"]       # the corrupted one, shown too
    assert len(bad) == 1 and int(bad[0]["hfb.sequence"]) == int.from_bytes(capture["bad"][6:10], "big")
    rows = [r for r in rows if r["hfb.crc.good"] == "1"]
    assert len(rows) == len(expected) > 200
    moving = set()
    for row, block in zip(rows, expected):
        for name, (item, how, digits) in fields.items():
            if item is None:
                want = int(block[how][0])
                assert row[name] == str(want), name
                continue
            raw = block.raw[item.name][0].item()
            if how == "eng":
                want = float(block[item.name][0])
                assert shown_equals(row[name], want, digits), (name, row[name], want)
                if want != 0:
                    moving.add(name)
            elif how == "raw":
                assert int(row[name], 0) == raw, (name, row[name], raw)      # 0x.. for bit fields
            else:
                assert int(row[name]) == bool(block[how.split(":")[1]][0]), name
    assert {"hfb.high_rate.encoder_outer", "hfb.high_rate.current_coarse",
            "hfb.high_rate.torque_coarse_cmd"} <= moving     # open loop: the values move
    # the corrupted frame is found and flagged; every other frame's CRC is good
    crc = [v for lay in layers for v in lay.get("hfb.crc.good", [])]
    assert crc.count("0") == 1 and crc.count("1") == len(crc) - 1
    ids = [int(v, 0) for lay in layers for v in lay.get("hfb.packet_id", [])]
    assert {1, 2, 3} <= set(ids)                              # HOUSEKEEPING and EVENT too


def test_the_command_channel_is_reassembled_and_decoded(capture, dictionary, traffic):
    fields = ["hfb.packet_id", "hfb.sequence", "hfb.crc.good", "hfb.cmd.connect.dictionary_hash",
              "hfb.cmd.set_mode.mode", "hfb.cmd.set_currents.current_coarse",
              "hfb.cmd.set_currents.current_fine", "hfb.reply.connect.session_token",
              "hfb.response.stage", "hfb.response.reason", "hfb.response.owner",
              "hfb.reply.connect.dictionary_hash", "hfb.command.opcode", "hfb.junk"]
    layers = run_tshark(capture["dir"] / "port5020.pcap", capture["lua"], fields, "-Y", "tcp")
    values = {f: [v for lay in layers for v in lay.get(f, [])] for f in fields}
    frames = [f for _, f in traffic["exchange"]]
    frames += [codec_frame(dictionary, "HEARTBEAT", seq, traffic["token"]) for seq in (90, 91)]
    shown = list(zip((int(v, 0) for v in values["hfb.packet_id"]), map(int, values["hfb.sequence"])))
    for pid in {f[3] for f in frames}:                  # every frame, in order per direction
        assert [s for p, s in shown if p == pid] == [int.from_bytes(f[6:10], "big")
                                                    for f in frames if f[3] == pid]
    assert len(shown) == len(frames)
    assert values["hfb.crc.good"] == ["1"] * (len(frames) - 2) + ["0", "1"]   # the damaged one
    # junk up to the false sync word, then the false header (version 7) up to the frame
    assert [v.replace(":", "") for v in values["hfb.junk"]] == ["006e6f697365", "eb9007"]
    hashes = [int(v, 0) for v in values["hfb.cmd.connect.dictionary_hash"]]
    assert hashes == [dictionary.hash, dictionary.hash ^ 1]
    assert values["hfb.cmd.set_mode.mode"] == [str(dictionary.command("SET_MODE").args[0].states["OPEN_LOOP"])]
    assert shown_equals(values["hfb.cmd.set_currents.current_coarse"][0], float(struct.unpack(">f", struct.pack(">f", 0.8))[0]), 6)
    assert shown_equals(values["hfb.cmd.set_currents.current_fine"][0], -0.25, 6)
    # CONNECT's reply carries the token; the mismatch rejection carries the device's hash
    assert int(values["hfb.reply.connect.session_token"][0], 0) == traffic["token"]
    assert [int(v, 0) for v in values["hfb.reply.connect.dictionary_hash"]] == [dictionary.hash] * 2
    err = dictionary.error_codes
    assert values["hfb.response.reason"].count(str(err["NOT_SESSION_OWNER"])) == 1
    assert values["hfb.response.reason"].count(str(err["DICTIONARY_MISMATCH"])) == 1
    assert values["hfb.response.owner"] and values["hfb.response.owner"][0].startswith("owner ")
    assert len(values["hfb.command.opcode"]) == sum(1 for s, _ in traffic["exchange"] if s == "host") + 2
    # a CONNECT with another dictionary hash is flagged (an expert item, filterable)
    flagged = run_tshark(capture["dir"] / "port5020.pcap", capture["lua"], ["hfb.cmd.connect.dictionary_hash"],
                         "-Y", "hfb.hash.differs")
    assert [int(v, 0) for lay in flagged for v in lay["hfb.cmd.connect.dictionary_hash"]] == [dictionary.hash ^ 1]


NO_HEURISTICS = ("-o", "hfb.heuristics:FALSE")


def test_the_ports_are_preferences(capture, dictionary):
    pcap, lua = capture["dir"] / "port7020.pcap", capture["lua"]
    # without the heuristics only the preference's port is decoded (default: 5020) ...
    assert run_tshark(pcap, lua, ["hfb.packet_id"], *NO_HEURISTICS, "-Y", "hfb") == []
    layers = run_tshark(pcap, lua, ["hfb.packet_id"], "-o", "hfb.udp_port:7020",
                        "-o", "hfb.tcp_port:7020", *NO_HEURISTICS, "-Y", "hfb")
    ids = {int(v, 0) for lay in layers for v in lay["hfb.packet_id"]}
    assert ids == {p.id for p in dictionary.packets}


def test_the_dissector_is_generated_deterministically(tmp_path, dictionary):
    out = subprocess.run([sys.executable, "-m", "groundstation", "protocol", "export-wireshark",
                          str(tmp_path / "x.lua"), "--port", "6000"], capture_output=True,
                         text=True, timeout=60, cwd=ROOT)
    assert out.returncode == 0, out.stderr
    text = (tmp_path / "x.lua").read_bytes()
    assert text == render_lua(dictionary, 6000).encode() == render_lua(dictionary, 6000).encode()
    assert b'Pref.uint("UDP telemetry port", 6000' in text
    assert f"DICTIONARY_HASH = 0x{dictionary.hash:08X}".encode() in text



def _frames_shown(pcap: Path, lua: Path, transport: str) -> dict[int, tuple]:
    """capture frame number -> (sequences, CRC verdicts, junk) of the HFB frames in it."""
    fields = ["frame.number", "hfb.sequence", "hfb.crc.good", "hfb.junk"]
    return {int(lay["frame.number"][0]): tuple(tuple(lay.get(f, ())) for f in fields[1:])
            for lay in run_tshark(pcap, lua, fields, "-Y", f"{transport} && hfb")}


def test_any_other_port_is_found_by_the_heuristics(capture, dictionary):
    """The dissector exported for 5020 decodes a device on 7020 with no preference set:
    UDP from the first datagram, the bad-CRC frame too (the conversation is claimed);
    TCP from the first segment that starts with a whole good frame, then as on 5020
    (reassembly, junk, a damaged frame)."""
    lua = capture["lua"]
    on_port = {t: _frames_shown(capture["dir"] / "port5020.pcap", lua, t) for t in ("udp", "tcp")}
    found = {t: _frames_shown(capture["dir"] / "port7020.pcap", lua, t) for t in ("udp", "tcp")}
    assert found["udp"] == on_port["udp"]
    assert [v for f in found["udp"].values() for v in f[1]].count("0") == 1      # the damaged frame
    # the stream's first frames are split inside their headers (no whole frame to
    # recognise): the first segment holding one is frame 14, a command
    first = min(found["tcp"])
    assert first == 14 and found["tcp"][first] == on_port["tcp"][first]
    later = {n: v for n, v in on_port["tcp"].items() if n > 15}       # 15 ends a frame begun in 13
    assert {n: v for n, v in found["tcp"].items() if n > 15} == later
    assert any(len(v[0]) > 1 for v in later.values())                 # frames over segments
    assert later[max(later)][1] == ("1",) and later[max(later) - 1][1] == ("0",)


def test_the_heuristics_want_a_good_crc(capture, tmp_path):
    """A datagram on another port that has the frame's header but not its CRC is not
    taken for the protocol (nor is one whose version differs)."""
    bad = capture["bad"]
    other_version = bytearray(capture["datagrams"][0])
    other_version[2] ^= 0x40
    write_pcap(tmp_path / "lookalike.pcap", [udp_packet(7021, HOST_UDP, bad),
                                             udp_packet(7022, HOST_UDP, bytes(other_version))])
    assert run_tshark(tmp_path / "lookalike.pcap", capture["lua"], ["hfb.packet_id"], "-Y", "hfb") == []
    write_pcap(tmp_path / "good.pcap", [udp_packet(7021, HOST_UDP, capture["datagrams"][0])])
    assert run_tshark(tmp_path / "good.pcap", capture["lua"], ["hfb.packet_id"], "-Y", "hfb") != []
