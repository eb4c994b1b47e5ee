"""`Testbed.attach`: the verbs on a link someone else opened (the GUI's).  Leaving the
block makes the rig safe exactly as an own session does, but the borrowed link - and a
borrowed generator driver - stay open; a generator opened from a resource is closed."""

from __future__ import annotations

from pathlib import Path

import pytest

from groundstation.instruments import open_generator
from groundstation.link import open_client
from groundstation.logs import LogReader
from groundstation import ScriptError, Testbed
from groundstation.sim import SimulatedDevice
from groundstation.sim.scpi_server import attach_generator
from groundstation.plant.testbed import load_testbed

from conftest import wait_for

ROOT = Path(__file__).resolve().parents[2]
INERTIAL = ROOT / "profiles" / "testbeds" / "inertial_2dof.toml"


def test_attach_borrows_the_link_and_leaves_it_open(dictionary, tmp_path):
    testbed = load_testbed(INERTIAL)
    dev = SimulatedDevice(dictionary, pacing="realtime", testbed=testbed).start()
    server = attach_generator(dev)
    client = open_client(dictionary, f"127.0.0.1:{dev.tcp_port}")
    borrowed = None
    try:
        client.connect()
        # a driver the owner (the GUI's generator panel) holds open
        borrowed = open_generator(server.resource, testbed=testbed)
        with Testbed.attach(client, testbed=INERTIAL, generator=borrowed, log_folder=tmp_path,
                            history=tmp_path / "history") as tb:
            assert tb.attached and tb.client is client
            tb.set_mode("OPEN_LOOP")
            tb.arm()
            tb.set_currents(coarse_a=0.05)
            tb.generator_set(1, waveform="SINE", frequency_hz=2.0, amplitude_vpp=0.3)
            path = tb.start_recording("attached", notes="on a borrowed link")
            tb.dwell(0.5)
            assert dev.firmware.armed and borrowed.get_output(1)
        # safe as any session leaves it ...
        assert not dev.firmware.armed and dev.firmware.mode == 0
        assert borrowed.get_output(1) is False
        # ... but what was borrowed is still open, and the session's subscription is gone
        assert not borrowed.closed
        assert client.link_state == "up" and tb.client is None
        assert tb.state not in client._subscribers
        seen = []
        client.subscribe(seen.append)
        wait_for(lambda: len(seen) > 10, timeout=5.0)          # telemetry still flows
        assert client.command("SET_MODE", mode="OPEN_LOOP").final_stage == "COMPLETED"
        with LogReader(path) as log:
            assert log.n_frames("HIGH_RATE") >= 300
            texts = [e.data.get("text", "") for e in log.journal("event")]
        assert any("end of script" in t for t in texts)

        # a generator given as a resource is the session's own: closed with it (outputs off)
        tb = Testbed.attach(client, testbed=INERTIAL, generator=server.resource, log_folder=tmp_path)
        own = tb.generator
        assert own is not None and not own.closed
        tb.close()
        assert own.closed and client.link_state == "up"
    finally:
        client.close()
        if borrowed is not None:
            borrowed.close()
        server.stop()
        dev.stop()


def test_attach_needs_a_link_that_is_up(dictionary, device, client):
    with pytest.raises(ScriptError, match="link is not up"):
        Testbed.attach(None)
    client.close()
    with pytest.raises(ScriptError, match="link is not up"):
        Testbed.attach(client)
