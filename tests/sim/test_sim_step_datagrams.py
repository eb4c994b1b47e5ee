"""The stepped device's telemetry (SimulatedDevice.step, the fast clock's advance): with
`datagram_bytes`, EVENT and HOUSEKEEPING frames travel packed like HIGH_RATE ones, so a
0.75 s chunk is a handful of datagrams instead of one per HOUSEKEEPING frame; the host
receives the same frames either way."""

from __future__ import annotations

import numpy as np

from conftest import collect, wait_for
from groundstation.sim.device import _packed


def test_packing_keeps_frames_whole_and_in_order():
    frames = [bytes([i]) * n for i, n in enumerate([10, 30, 25, 5, 60, 1])]
    datagrams = _packed(frames, 40)
    assert b"".join(datagrams) == b"".join(frames)
    assert [len(d) for d in datagrams] == [10 + 30, 25 + 5, 60, 1]    # 60 > 40: alone
    assert _packed([], 40) == []


def _run(client, device, datagram_bytes: int) -> tuple[int, dict, int]:
    blocks = collect(client)
    sizes: list[int] = []

    def count(datagram: bytes) -> bytes:
        sizes.append(len(datagram))
        return datagram

    device.datagram_filter = count
    first = device.firmware.tick + 1
    device.firmware._emit("INFO", "PROFILE_FINISHED", "an event to carry")
    last = device.step(900, datagram_bytes=datagram_bytes)
    wait_for(lambda: any(b.name == "HIGH_RATE" and int(b["tick"][-1]) == last for b in blocks))
    device.datagram_filter = None
    client.unsubscribe(blocks.append)
    got = {}
    for name in ("HIGH_RATE", "HOUSEKEEPING", "EVENT"):
        ticks = np.concatenate([np.asarray(b["tick"], dtype=np.int64) for b in blocks
                                if b.name == name] or [np.zeros(0, np.int64)])
        got[name] = ticks[ticks >= first - 1]       # not the session's opening events
    return len(sizes), got, max(sizes)


def test_a_chunk_is_a_few_datagrams_and_the_same_frames(client, device):
    client.connect()
    opening = collect(client)
    device.step(10)                  # the session's opening events go out with these
    wait_for(lambda: any(b.name == "HIGH_RATE" and int(b["tick"][-1]) == 10 for b in opening))
    client.unsubscribe(opening.append)
    tick0 = device.firmware.tick
    n_one, one, _ = _run(client, device, 0)             # one frame a datagram, as a rig
    n_packed, packed, biggest = _run(client, device, 32768)
    # 900 HIGH_RATE + 7 or 8 HOUSEKEEPING + 1 EVENT frames, one a datagram ...
    assert n_one == 900 + len(one["HOUSEKEEPING"]) + len(one["EVENT"])
    # ... or all EVENT and HOUSEKEEPING frames in one datagram, HIGH_RATE in three
    assert n_packed == 1 + 3 and biggest <= 32768
    assert np.array_equal(one["HIGH_RATE"], np.arange(tick0 + 1, tick0 + 901))
    assert np.array_equal(packed["HIGH_RATE"], np.arange(tick0 + 901, tick0 + 1801))
    every = device.housekeeping_divider
    for got, ticks in ((one, range(tick0 + 1, tick0 + 901)), (packed, range(tick0 + 901, tick0 + 1801))):
        assert list(got["HOUSEKEEPING"]) == [t for t in ticks if t % every == 0]
    assert len(packed["EVENT"]) == len(one["EVENT"]) == 1


def test_response_frames_are_what_the_general_encoder_makes(device, dictionary):
    """The device packs RESPONSE frames with a struct built from the dictionary; the
    bytes are those of the encoder every other frame uses."""
    from groundstation.sim.firmware import Stage
    assert device._response_layout is not None          # the shipped dictionary's layout
    for stage in (Stage(1), Stage(3, 0, b"\x01\x02reply"), Stage(2, 7), Stage(4, 13, b"")):
        seq = device._seq["RESPONSE"]
        fast = device._response(0xDEADBEEF, 0x0031, stage)
        general = device.codec.encode_variable("RESPONSE", {
            "command_sequence": 0xDEADBEEF, "opcode": 0x0031, "stage": stage.stage,
            "reason": stage.reason, "data": stage.data}, seq, device.firmware.tick)
        assert fast == general
        assert device._seq["RESPONSE"] == seq + 1
