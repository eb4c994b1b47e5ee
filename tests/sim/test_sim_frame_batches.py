"""The simulator's telemetry encoded a batch at a time (sim/telemetry_batch.py) is, byte
for byte, what encoding frame by frame gives: the compiled CRCs are zlib's, a batch's
frames are the frames encoded one at a time by an independent reference (struct + the
dictionary's own conversion + zlib), and the device sends the same HIGH_RATE bytes fast,
period by period, and paced over loopback datagrams, whatever the batch sizes."""

from __future__ import annotations

import struct
import zlib

import numpy as np
import pytest

from conftest import wait_for
from groundstation.codec import StreamDeframer
from groundstation.codec.frames import FrameCodec
from groundstation.core.dictionary import HEADER_DTYPE
from groundstation.sim.device import SimulatedDevice
from groundstation.sim.frame_crc import crc_rows


@pytest.mark.parametrize("length", [1, 3, 17, 59, 74, 200])
@pytest.mark.parametrize("rows", [0, 1, 5, 8, 1203])
def test_compiled_crcs_are_zlibs(length, rows):
    rng = np.random.default_rng(length * 1000 + rows)
    block = rng.integers(0, 256, (rows, length + 6), dtype=np.uint8)
    view = block[:, 2:2 + length]                      # strided, as the encoder passes it
    expected = [zlib.crc32(bytes(r)) for r in view]
    assert crc_rows(view).tolist() == expected


def _reference_frame(d, pkt, values: dict, seq: int, tick: int) -> bytes:
    """One frame by hand: big-endian header, each item through Item.to_raw, flags ORed
    in, zlib CRC appended least significant byte first (SPEC §2)."""
    header = np.zeros(1, HEADER_DTYPE)
    header[0] = (d.sync, d.version_major, pkt.id, pkt.fixed_payload_size, seq, tick)
    payload = b""
    for item in pkt.items:
        raw = item.to_raw(values[item.name]) if item.name in values else 0
        word = int(raw) if item.wire_dtype.kind in "iu" else float(raw)
        for flag, bit in item.bits.items():
            if flag in values:
                word |= int(bool(values[flag])) << bit
        payload += np.asarray(word, dtype=item.wire_dtype).tobytes()
    body = header.tobytes() + payload
    return body + struct.pack("<I", zlib.crc32(body))


def _random_values(pkt, rng, n: int) -> dict[str, np.ndarray]:
    values = {}
    for item in pkt.items:
        dt = item.wire_dtype
        if item.bits:
            for flag in item.bits:
                values[flag] = rng.random(n) < 0.5
            continue
        if dt.kind in "iu":
            info = np.iinfo(dt)
            raw = rng.integers(max(info.min, -2**40), min(info.max, 2**40), n, endpoint=True)
        else:
            raw = rng.normal(0.0, 1e3, n)
        # engineering values whose round trip lands anywhere in the wire range
        values[item.name] = (raw * item.scale + item.offset) if item.scale is not None else raw
    return values


@pytest.mark.parametrize("packet", ["HIGH_RATE", "HOUSEKEEPING"])
def test_a_batch_is_its_frames_encoded_one_by_one(dictionary, packet):
    pkt = dictionary.packet(packet)
    rng = np.random.default_rng(7)
    n = 257
    values = _random_values(pkt, rng, n)
    seq = np.arange(2**32 - 100, 2**32 - 100 + n)       # wraps inside the batch
    ticks = np.arange(5000, 5000 + n)
    for crc in (None, crc_rows):
        batch = FrameCodec(dictionary).encoder(packet, crc).encode(values, seq, ticks)
        size = pkt.frame_dtype.itemsize
        assert len(batch) == n * size
        for i in range(n):
            one = {k: v[i] for k, v in values.items()}
            assert batch[i * size:(i + 1) * size] == _reference_frame(
                dictionary, pkt, one, int(seq[i]) & 0xFFFFFFFF, int(ticks[i])), (crc, i)


def _packet_bytes(codec, stream: bytes, packet: str = "HIGH_RATE") -> bytes:
    """The frames of one packet in a stream, in order (a batch hands on its HIGH_RATE
    frames, then its HOUSEKEEPING ones, so the interleaving depends on the batch)."""
    blocks = StreamDeframer(codec).feed(stream, 0.0)
    return b"".join(b.raw.tobytes() if b.raw is not None else b"".join(b.frames)
                    for b in blocks if b.name == packet)


def _fast(dictionary, periods: int, batch: int | None, generator: bool = False,
          testbed: str | None = None) -> bytes:
    firmware = None
    if testbed is not None:
        from groundstation.plant.testbed import TESTBEDS_DIR, load_testbed
        from groundstation.sim.firmware import Firmware
        firmware = Firmware(dictionary, seed=1, testbed=load_testbed(TESTBEDS_DIR / testbed))
    dev = SimulatedDevice(dictionary, pacing="manual", seed=1, firmware=firmware)
    if generator:           # the base stage driven by a 7 Hz sine, evaluated per batch
        from groundstation.sim.fg_instrument import SimulatedGenerator
        gen = SimulatedGenerator(tick_source=lambda: dev.firmware.tick,
                                 control_rate_hz=dictionary.control_rate_hz, base_channel=1)
        assert gen.handle_line("C1:BSWV WVTP,SINE,FRQ,7,AMP,0.8;C1:OUTP ON;*ESR?") == ["0"]
        dev.base_drive = gen.base_drive
    out: list[bytes] = []
    dev.run_fast(periods / dictionary.control_rate_hz, out.append, batch=batch)
    return b"".join(out)


def test_fast_output_is_the_same_at_any_batch_size(dictionary):
    periods = 1500
    codec = FrameCodec(dictionary)
    whole = _fast(dictionary, periods, None)                       # 1200 a batch
    for batch in (1, 7, 500):                      # frame by frame; across housekeeping
        other = _fast(dictionary, periods, batch)
        for packet in ("HIGH_RATE", "HOUSEKEEPING", "EVENT"):
            assert _packet_bytes(codec, other, packet) == _packet_bytes(codec, whole, packet), \
                (batch, packet)
    assert len(_packet_bytes(codec, whole, "HOUSEKEEPING")) == \
        periods // 120 * dictionary.packet("HOUSEKEEPING").frame_dtype.itemsize


def test_a_driven_base_is_the_same_at_any_batch_size(dictionary):
    """The generator's output is evaluated once per batch, sliced per piece: the frames
    do not depend on where the batches are cut, and the drive moves the base."""
    periods, testbed = 1500, "inertial_2dof.toml"            # a testbed with a base stage
    codec = FrameCodec(dictionary)
    whole = _packet_bytes(codec, _fast(dictionary, periods, None, True, testbed))
    for batch in (1, 7, 500):
        assert _packet_bytes(codec, _fast(dictionary, periods, batch, True, testbed)) == whole, batch
    assert whole != _packet_bytes(codec, _fast(dictionary, periods, None, False, testbed))


@pytest.mark.parametrize("datagram_bytes", [0, 32768])
def test_paced_datagrams_carry_the_fast_high_rate_frames(dictionary, device, client,
                                                         datagram_bytes):
    """The device stepped in odd batches with a host connected over loopback sends, in
    its datagrams, the HIGH_RATE frames a fast run of the same twin hands its consumer."""
    client.connect()
    sent: list[bytes] = []

    def capture(datagram: bytes) -> bytes:
        sent.append(datagram)
        return datagram
    device.datagram_filter = capture
    rng = np.random.default_rng(4)
    periods = 0
    last = None
    while periods < 1500:
        n = int(min(rng.integers(1, 400), 1500 - periods))
        last = device.step(n, datagram_bytes=datagram_bytes)
        periods += n
    heard: list = []
    client.subscribe(heard.append)
    wait_for(lambda: any(b.name == "HIGH_RATE" and int(b["tick"][-1]) == last for b in heard))
    paced = _packet_bytes(device.codec, b"".join(sent))
    assert paced == _packet_bytes(device.codec, _fast(dictionary, periods, None))
    assert len(paced) == 1500 * dictionary.packet("HIGH_RATE").frame_dtype.itemsize


def test_a_batch_checks_every_column_as_one_frame_would(dictionary):
    """The encoder checks a batch's float columns together; what passes or fails, and
    the message, are those of the column checked alone."""
    from groundstation.core.errors import EncodeError
    enc = FrameCodec(dictionary).encoder("HIGH_RATE", crc_rows)
    n = 50
    ok = {"error_angle": np.zeros(n), "current_coarse": np.zeros(n), "mode": np.ones(n)}
    seq = np.arange(n)
    with_inf = {**ok, "error_angle": np.r_[np.inf, np.nan, np.zeros(n - 2)]}
    frames = enc.records(with_inf, seq, seq)              # a float item may carry inf/NaN
    assert np.isinf(frames["error_angle"][0]) and np.isnan(frames["error_angle"][1])
    item = dictionary.packet("HIGH_RATE").item_by_name["current_coarse"]
    too_big = np.zeros(n)
    too_big[7] = (np.iinfo(np.int16).max + 1) * item.scale + item.offset
    for bad, message in (({**ok, "current_coarse": too_big}, "value outside the wire range of i16"),
                         ({**ok, "mode": np.r_[np.nan, np.ones(n - 1)]}, "non-finite value"),
                         ({**ok, "error_angle": np.r_[1e39, np.zeros(n - 1)]}, "outside the range of f32")):
        with pytest.raises(EncodeError, match=message):
            enc.records(bad, seq, seq)
