"""DeviceClient.commands: several commands in flight, each followed as command() would
(answered in order, retried when lost, reported to the listeners in the order given),
and the first refusal raised only after everything sent has been answered.  The
profile upload uses it for its PROFILE_WRITE blocks."""

from __future__ import annotations

import numpy as np
import pytest

from groundstation.core.errors import CommandRejected
from groundstation.link import DeviceClient
from groundstation.link.transports import TcpStream


def _blocks(n: int, per_block: int = 4, start: float = 0.0) -> list[tuple[str, dict]]:
    samples = (start + np.arange(n * per_block, dtype=">f4") * 1e-3).astype(">f4")
    return [("PROFILE_WRITE", {"offset": i * per_block,
                               "samples": samples[i * per_block:(i + 1) * per_block].tobytes()})
            for i in range(n)]


def test_pipelined_commands_answer_and_report_in_order(client, device, dictionary):
    client.connect()
    client.command("PROFILE_BEGIN", profile_id=7, target=2, sample_count=200)
    seen = []
    client.add_command_listener(lambda r: seen.append(r.arguments.get("offset")))
    calls = _blocks(50)
    results = client.commands(calls, window=8)
    assert [r.arguments["offset"] for r in results] == [a["offset"] for _, a in calls]
    assert seen == [a["offset"] for _, a in calls]            # the journal's order
    assert all([s.stage for s in r.stages] == ["SENT", "ACCEPTED", "COMPLETED"] for r in results)
    staged = bytes(device.firmware._staging["profile"].buffer)
    assert staged == b"".join(a["samples"] for _, a in calls)


def test_a_refusal_is_raised_after_the_commands_in_flight_are_answered(client, device):
    client.connect()
    client.command("PROFILE_BEGIN", profile_id=7, target=2, sample_count=40)
    calls = _blocks(20)                     # blocks 10.. lie beyond the 40 staged samples
    seen = []
    client.add_command_listener(lambda r: seen.append((r.arguments["offset"], r.final_stage)))
    with pytest.raises(CommandRejected, match="OUT_OF_RANGE"):
        client.commands(calls, window=4)
    # the first ten completed, the eleventh was refused; what was in flight with it was
    # answered and reported too, and nothing was sent after the refusal was seen
    assert seen[:10] == [(4 * i, "COMPLETED") for i in range(10)]
    assert seen[10] == (40, "REJECTED")
    assert 11 <= len(seen) <= 10 + 4
    assert not client._pending


class _DropWrites(TcpStream):
    """TCP client that loses the writes whose numbers are in `lost`."""

    def __init__(self, host, port, lost):
        super().__init__(host, port)
        self.lost, self.n = set(lost), 0

    def _write(self, data):
        self.n += 1
        if self.n in self.lost:
            return
        super()._write(data)


def test_a_lost_command_in_flight_is_resent_and_executed_once(dictionary, device):
    # write 1: CONNECT, 2: PROFILE_BEGIN, then the blocks: the third block is lost once
    client = DeviceClient(dictionary, _DropWrites("127.0.0.1", device.tcp_port, {5}),
                          heartbeat=False)
    client.start()
    try:
        client.connect()
        client.command("PROFILE_BEGIN", profile_id=7, target=2, sample_count=40)
        accepted = device.firmware.accepted
        calls = _blocks(10)
        results = client.commands(calls, window=6)
        assert [r.retries for r in results] == [0, 0, 1] + [0] * 7
        assert [s.stage for s in results[2].stages] == ["SENT", "RETRY", "ACCEPTED", "COMPLETED"]
        assert device.firmware.accepted == accepted + 10
        staged = bytes(device.firmware._staging["profile"].buffer)
        assert staged == b"".join(a["samples"] for _, a in calls)
    finally:
        client.close()


def test_the_journal_record_of_a_command_is_asdict_of_it(client):
    from dataclasses import asdict

    from groundstation.logs.live import command_record
    client.connect()
    results = [client.command("GET_INFO")]
    client.command("PROFILE_BEGIN", profile_id=7, target=2, sample_count=8)
    results += client.commands(_blocks(2))
    for result in results:
        assert result.stages and command_record(result) == asdict(result)
        assert list(command_record(result)) == list(asdict(result))
