"""SPEC §2: a frame that is not sent does not use up a sequence number.  With no session
open the simulated device sends no telemetry over Ethernet (§1.3), so its counters must
stand still meanwhile: the first frames of the next session continue the numbers of the
last ones.  (It used to encode and number frames for nobody - the C reference device
did not, and the conformance suite's author noticed the difference.)"""

from conftest import wait_for


def _last(blocks, packet):
    return [int(s) for b in blocks if b.name == packet for s in b["sequence"]]


def test_numbers_stand_still_while_nobody_receives(client, device):
    blocks = []
    client.subscribe(blocks.append)
    client.connect()
    device.run_ticks(240)                                   # two HOUSEKEEPING periods
    wait_for(lambda: len(_last(blocks, "HIGH_RATE")) >= 240 and _last(blocks, "HOUSEKEEPING"))
    high, house = _last(blocks, "HIGH_RATE")[-1], _last(blocks, "HOUSEKEEPING")[-1]
    client.command("DISCONNECT")
    device.run_ticks(1200)                                  # a second with nobody listening
    seen = len(blocks)
    client.connect()
    device.run_ticks(240)
    wait_for(lambda: len(_last(blocks[seen:], "HIGH_RATE")) >= 240
             and _last(blocks[seen:], "HOUSEKEEPING"))
    assert _last(blocks[seen:], "HIGH_RATE")[0] == high + 1
    assert _last(blocks[seen:], "HOUSEKEEPING")[0] == house + 1
