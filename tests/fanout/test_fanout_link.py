"""Many consoles on one rig (issue 18): a commander publishes what its link receives,
read-only viewers decode it with their own dictionaries.  Loopback only, ports from the
system (tcp://127.0.0.1:*), the simulated device driven tick by tick."""

from __future__ import annotations

import threading

import numpy as np
import pytest

from groundstation.core.errors import GroundStationError
from groundstation.fanout.endpoints import FanoutError, ReadOnlyConsole
from groundstation.fanout.publisher import Publisher
from groundstation.fanout.viewer import WatchClient
from groundstation.link import open_client
from groundstation.sim import SimulatedDevice

from conftest import wait_for


def high_rate(blocks):
    return sum(len(b) for b in blocks if b.name == "HIGH_RATE")


def last_high_rate_sequence(blocks) -> int | None:
    """The sequence number of the newest HIGH_RATE frame among `blocks` (None: none)."""
    for b in reversed(blocks):
        if b.name == "HIGH_RATE" and len(b):
            return int(b["sequence"][-1])
    return None


def columns(blocks, packet):
    """Every column and the arrival times of a packet's blocks, concatenated."""
    mine = [b for b in blocks if b.name == packet]
    out = {"host_time": np.concatenate([np.broadcast_to(b.host_time, (len(b),)) for b in mine])}
    for name in mine[0].columns:
        out[name] = np.concatenate([b[name] for b in mine])
    return out


def run(device, client_blocks, ticks: int, chunk: int = 600) -> None:
    """Advance the device in chunks the commander's UDP socket holds, each received."""
    for _ in range(ticks // chunk):
        target = high_rate(client_blocks) + chunk
        device.run_ticks(chunk)
        wait_for(lambda: high_rate(client_blocks) >= target)


@pytest.fixture
def commander(dictionary, device, client):
    """The station that holds the session, publishing on a free loopback port."""
    client.connect()
    pub = Publisher("tcp://127.0.0.1:*", sndhwm=10, sndbuf=16384)
    pub.attach(client, f"127.0.0.1:{device.tcp_port}")
    yield pub
    pub.close()


def test_three_viewers_one_stalled_decode_what_the_commander_decodes(dictionary, device, client,
                                                                     commander):
    viewers = [WatchClient(dictionary, commander.endpoint).start() for _ in range(2)]
    # the third one stops reading: its queues are kept tiny so its messages drop soon
    stalled = WatchClient(dictionary, commander.endpoint, rcvhwm=2, rcvbuf=4096).start()
    try:
        for v in viewers + [stalled]:
            v.wait_up(timeout=30.0)
        gate = threading.Event()
        stalled.subscribe(lambda block: gate.wait(30.0))
        mine = []
        client.subscribe(mine.append)
        seen = [[] for _ in viewers]
        for v, blocks in zip(viewers, seen):
            v.subscribe(blocks.append)
        late = []
        stalled.subscribe(late.append)

        run(device, mine, 36000)                 # 30 s of telemetry while one viewer is stalled
        for blocks in seen:
            wait_for(lambda: high_rate(blocks) == high_rate(mine))
        # the stall slowed no one: the commander lost nothing, nor did the others
        assert client.stats.snapshot().dropped == 0
        for v in viewers:
            assert v.stats.snapshot().dropped == 0 and v.counters.missed_messages == 0
        # and the viewers decoded exactly what the commander decoded, arrival times too
        for packet in ("HIGH_RATE", "HOUSEKEEPING"):
            ref = columns(mine, packet)
            for blocks in seen:
                got = columns(blocks, packet)
                assert got.keys() == ref.keys()
                for name in ref:
                    np.testing.assert_array_equal(got[name], ref[name], err_msg=f"{packet}.{name}")

        gate.set()                               # the stalled viewer reads again ...
        # ... and catches up.  What the publisher sends while that viewer's tiny queue is
        # still full is dropped for it (PUB/SUB), the newest message too: a stressed run
        # lost the last one of a 600-tick burst and never "reached the last sequence".
        # So the device steps on, one message's worth at a time, until the viewer has
        # handed its subscribers the commander's newest frame.
        def caught_up() -> bool:
            if last_high_rate_sequence(late) == last_high_rate_sequence(mine):
                return True
            run(device, mine, 12, chunk=12)
            return False

        wait_for(caught_up)
        # ... and counts its own gaps: frames from sequence numbers, messages from the
        # publisher's message sequence
        snap = stalled.stats.snapshot()
        assert snap.dropped > 0 and stalled.counters.missed_messages > 0
        assert high_rate(late) + snap.packets["HIGH_RATE"].dropped == high_rate(mine)
    finally:
        for v in viewers + [stalled]:
            v.close()


def test_a_viewer_cannot_command_but_its_abort_stops_the_device(dictionary, device, client,
                                                                 commander):
    with WatchClient(dictionary, commander.endpoint) as viewer:
        viewer.wait_up(timeout=30.0)
        journal = []
        viewer.add_command_listener(journal.append)
        client.command("SET_MODE", mode="OPEN_LOOP")
        client.command("ARM")
        device.run_ticks(10)
        assert device.firmware.armed
        for name, args in (("ARM", {}), ("DISARM", {}), ("SET_MODE", {"mode": "IDLE"}),
                           ("CONNECT", {})):
            with pytest.raises(ReadOnlyConsole, match="read-only console watching tcp://127.0.0.1:"):
                viewer.command(name, **args)
        with pytest.raises(ReadOnlyConsole, match="commands are sent by the station that holds"):
            viewer.connect(take_over=True)
        assert viewer.session_token is None and device.firmware.armed
        # the commander's commands reach the viewer's journal (for its recording)
        wait_for(lambda: [r.name for r in journal][-2:] == ["SET_MODE", "ARM"])
        assert journal[-1].final_stage == "COMPLETED"

        result = viewer.abort()                  # straight to the device, no token
        assert result.final_stage == "COMPLETED"
        assert not device.firmware.armed and device.firmware.mode == 0
        assert journal[-1].name == "ABORT" and journal[-1].final_stage == "COMPLETED"
        # ABORT is no take-over: the commander still holds its session
        assert client.command("SET_MODE", mode="OPEN_LOOP").final_stage == "COMPLETED"
        assert viewer.command("ABORT").final_stage == "COMPLETED"


def test_a_stream_link_is_published_without_its_responses(dictionary):
    """Telemetry on the TCP stream: the frames are published, the RESPONSE frames (the
    CONNECT answer holds the session token) are not."""
    dev = SimulatedDevice(dictionary, pacing="manual", seed=2).start()
    client = open_client(dictionary, f"tcp://127.0.0.1:{dev.tcp_port}?telemetry=stream",
                         heartbeat=False)
    pub = Publisher("tcp://127.0.0.1:*")
    viewer = WatchClient(dictionary, pub.endpoint)
    try:
        client.connect()
        pub.attach(client, f"tcp://127.0.0.1:{dev.tcp_port}?telemetry=stream")
        chunks = []
        client.add_raw_tap(lambda path, c, t: chunks.extend(c))
        viewer.start().wait_up(timeout=30.0)
        assert viewer.hello["device"] == {"kind": "tcp", "host": "127.0.0.1", "port": dev.tcp_port,
                                          "address": f"tcp://127.0.0.1:{dev.tcp_port}?telemetry=stream"}
        mine, seen = [], []
        client.subscribe(mine.append)
        viewer.subscribe(seen.append)
        run(dev, mine, 1200)
        client.command("GET_INFO")
        wait_for(lambda: high_rate(seen) == high_rate(mine))
        np.testing.assert_array_equal(columns(seen, "HIGH_RATE")["tick"],
                                      columns(mine, "HIGH_RATE")["tick"])
        token = client.session_token.to_bytes(4, "big")
        assert not any(token in c for c in chunks)
        assert not any(b.name == "RESPONSE" for b in seen)
        assert viewer.abort().final_stage == "COMPLETED"
    finally:
        viewer.close()
        pub.close()
        client.close()
        dev.stop()


def test_a_serial_device_cannot_be_aborted_from_a_viewer(dictionary):
    from groundstation.fanout.abort import AbortUnreachable, abort_target

    with pytest.raises(AbortUnreachable, match="serial line .* press Abort"):
        abort_target({"kind": "serial", "address": "serial:///dev/ttyUSB0"}, "tcp://127.0.0.1:5600")
    with pytest.raises(AbortUnreachable, match="no hello"):
        abort_target(None, "tcp://127.0.0.1:5600")
    # a device beside the commander is reached at the commander's host
    assert abort_target({"kind": "tcp", "host": "127.0.0.1", "port": 5020},
                        "tcp://192.168.1.7:5600") == ("192.168.1.7", 5020)
    assert issubclass(AbortUnreachable, GroundStationError)    # the GUI shows its message


def test_no_publisher_is_said_plainly(dictionary):
    with WatchClient(dictionary, "tcp://127.0.0.1:9") as viewer:
        with pytest.raises(FanoutError, match="no station publishes on tcp://127.0.0.1:9.*--publish"):
            viewer.wait_up(timeout=0.3)
        with pytest.raises(Exception, match="no hello"):
            viewer.abort()


def test_a_watch_client_is_a_telemetry_source(dictionary):
    """The recorder, the charts and monitor consume it as they consume the live link."""
    import inspect

    from groundstation.core.contracts import TelemetrySource
    from groundstation.link.client import DeviceClient

    viewer = WatchClient(dictionary, "tcp://127.0.0.1:9")
    assert isinstance(viewer, TelemetrySource)
    for name in ("subscribe", "unsubscribe", "add_link_listener", "remove_link_listener",
                 "add_command_listener", "remove_command_listener", "abort", "close"):
        assert (list(inspect.signature(getattr(WatchClient, name)).parameters)
                == list(inspect.signature(getattr(DeviceClient, name)).parameters)), name
    viewer.close()


def test_an_abort_asked_before_the_first_hello_waits_for_it(dictionary):
    """A console that has just started watching can show telemetry before the
    publisher's first hello (which says where the device is) has come: an ABORT asked
    then waits for the hello instead of failing with "no hello"."""
    dev = SimulatedDevice(dictionary, pacing="manual", seed=3).start()
    client = open_client(dictionary, f"tcp://127.0.0.1:{dev.tcp_port}?telemetry=stream",
                         heartbeat=False)
    pub = Publisher("tcp://127.0.0.1:*", hello_period_s=0.2)
    viewer = WatchClient(dictionary, pub.endpoint)
    try:
        client.connect()
        pub.attach(client, f"tcp://127.0.0.1:{dev.tcp_port}?telemetry=stream")
        viewer.start()
        assert not viewer.hello                    # nothing heard yet
        assert viewer.abort().final_stage == "COMPLETED"
        assert viewer.hello["device"]["port"] == dev.tcp_port
    finally:
        viewer.close()
        pub.close()
        client.close()
        dev.stop()
