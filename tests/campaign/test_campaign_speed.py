"""Issue 19: the fast clock's pipelining changes nothing but speed.

The same session is run on the fast simulator with the pacing of before (one chunk in
flight, one frame per datagram) and with the pipelined one (several chunks in flight,
many frames per datagram), and the two logs must hold the same frames - every packet,
every column, every byte - and the same journal apart from host times.  With device
time held between steps, a fast run is tick-repeatable: commands execute at the same
device tick in both runs, and a dwell that a fault ends stops at the same tick.

Nothing here depends on how fast the machine is; `benchmarks/bench_campaign.py`
measures the speed."""

from __future__ import annotations

import threading
from pathlib import Path

import numpy as np
import pytest

from groundstation import Testbed
from groundstation.station.clock import ONE_CHUNK_IN_FLIGHT, FastPacing, SteppedClock
from groundstation.station.options import FastSimOptions
from groundstation.link import open_client
from groundstation.logs.reader import LogReader
from groundstation.plant.testbed import TESTBEDS_DIR
from groundstation.sim import SimulatedDevice
from groundstation.station.station import ScriptError

ROOT = Path(__file__).resolve().parents[2]
DESIGN = ROOT / "profiles" / "controllers" / "relative_design2.toml"
PROFILE = ROOT / "profiles" / "waveforms" / "sysid_coarse_noise_0p02A.toml"
#: more chunks in flight than any dwell below has chunks, and datagrams of ~200 frames
PIPELINED = FastPacing(in_flight=6, datagram_bytes=32768)


def _session(folder: Path, pacing: FastPacing, fast_sim: str = "inline") -> tuple[Path, dict]:
    """Closed loop, a step, a profile played, a mark, then open loop driven into a
    fault that ends a dwell early - all recorded."""
    with Testbed("sim", testbed=TESTBEDS_DIR / "relative_2dof.toml",
                 fast=FastSimOptions(where=fast_sim, pacing=pacing), log_folder=folder) as tb:
        tb.upload_design(DESIGN)
        tb.start_recording("speed")
        tb.set_mode("RELATIVE")
        tb.arm()
        tb.set_reference(1e-3)
        tb.dwell(2.5)                       # 3 whole chunks and a part
        tb.disarm()
        tb.play(PROFILE, mode="OPEN_LOOP", max_seconds=1.5)
        tb.mark("profile played")
        tb.dwell(1.0)
        tb.set_mode("OPEN_LOOP")
        tb.arm()
        tb.set_currents(2.5, 0.0)           # runs into its travel limit: a fault
        with pytest.raises(ScriptError, match="fault"):
            tb.dwell(30.0)
        faulted_at = tb.state.tick
        entry = tb.stop_recording()
    return Path(entry["files"][0]), {**entry, "faulted_at": faulted_at}


def _content(path: Path) -> dict:
    """Everything in a log that does not depend on the host's clock or its random
    command sequence numbers."""
    out: dict = {}
    with LogReader(path) as log:
        for packet in log.packets():
            cols = log.read(packet, raw=True)
            cols.pop("host_time", None)
            out[packet] = cols
            frames = log.frames(packet)
            out[f"{packet} frames"] = (frames if isinstance(frames, list)
                                       else [bytes(row) for row in np.asarray(frames)])
        journal = []
        for rec in log.journal():
            if rec.kind == "link":             # link statistics once a wall second
                continue
            data = dict(rec.data)
            if rec.kind == "command":
                data = {"name": data["name"], "arguments": data["arguments"],
                        "final_stage": data["final_stage"],
                        "stages": [(s["stage"], s["reason"], s["device_tick"])
                                   for s in data["stages"]]}
            journal.append((rec.kind, _without_times(data), rec.blob))
        out["journal"] = journal
    return out


def _without_times(data):
    if isinstance(data, dict):
        return {k: _without_times(v) for k, v in data.items()
                if k not in ("host_time", "upload_s", "time", "wall_seconds", "file")}
    if isinstance(data, list):
        return [_without_times(v) for v in data]
    return data


def _assert_same(a: dict, b: dict) -> None:
    assert a.keys() == b.keys()
    for key in a:
        if key == "journal":
            assert a[key] == b[key]
        elif key.endswith("frames"):
            assert len(a[key]) == len(b[key]), key
            assert a[key] == b[key], key
        else:
            assert a[key].keys() == b[key].keys(), key
            for col in a[key]:
                x, y = np.asarray(a[key][col]), np.asarray(b[key][col])
                assert x.shape == y.shape, (key, col)
                assert (x == y).all() or (x.dtype.kind == "f" and np.array_equal(x, y, equal_nan=True)), \
                    (key, col)


@pytest.fixture(scope="module")
def two_runs(tmp_path_factory):
    old = _session(tmp_path_factory.mktemp("one_chunk"), ONE_CHUNK_IN_FLIGHT)
    new = _session(tmp_path_factory.mktemp("pipelined"), PIPELINED)
    return old, new


def test_pipelined_log_is_the_one_chunk_log(two_runs):
    (old_path, old), (new_path, new) = two_runs
    for entry in (old, new):
        assert entry["dropped"] == 0 and entry["discarded_blocks"] == 0
    a, b = _content(old_path), _content(new_path)
    assert len(a["HIGH_RATE"]["tick"]) > 6000         # the session above, recorded
    _assert_same(a, b)


def test_fast_runs_are_tick_repeatable(two_runs):
    """Held between steps, device time depends only on the script: every command ran at
    the same tick, and the fault ended the dwell after the same chunk."""
    (old_path, old), (new_path, new) = two_runs
    ticks = []
    for path in (old_path, new_path):
        with LogReader(path) as log:
            ticks.append([(r.data["name"], [s["device_tick"] for s in r.data["stages"]])
                          for r in log.journal("command")])
            hr = log.read("HIGH_RATE", ["tick", "fault"], raw=True)
            first_fault = int(hr["tick"][np.argmax(hr["fault"] != 0)])
            assert hr["fault"].any()
            # the dwell stopped at the end of the chunk the fault happened in
            assert 0 <= old["faulted_at"] - first_fault < 900
    assert ticks[0] == ticks[1]
    assert any(name == "PROFILE_START" for name, _ in ticks[0])
    assert old["faulted_at"] == new["faulted_at"]


@pytest.fixture(scope="module")
def process_run(tmp_path_factory):
    return _session(tmp_path_factory.mktemp("process"), PIPELINED, fast_sim="process")


def test_a_simulator_in_its_own_process_writes_the_same_log(two_runs, process_run):
    """The fast device in a child process (sim/stepped_process.py): the same frames,
    the same journal, commands at the same ticks, the fault's dwell ended at the same
    tick as the in-process device with the pacing of before."""
    (old_path, old), _ = two_runs
    new_path, new = process_run
    assert new["dropped"] == 0 and new["discarded_blocks"] == 0
    _assert_same(_content(old_path), _content(new_path))
    assert old["faulted_at"] == new["faulted_at"]


def test_pacing_is_checked():
    with pytest.raises(ValueError, match="in_flight"):
        FastPacing(in_flight=0)
    with pytest.raises(ValueError, match="datagram_bytes"):
        FastPacing(datagram_bytes=-1)


def test_clock_waits_for_the_recorder_instead_of_discarding(dictionary):
    """While the recorder's queue is above its limit no chunk runs; the advance goes on
    when it drains.  (The queue is a stand-in callable here: what is checked is that the
    device's tick stands still for as long as it says full.)"""
    dev = SimulatedDevice(dictionary, pacing="manual").start()
    client = open_client(dictionary, f"127.0.0.1:{dev.tcp_port}")
    seen: list[tuple[float, int]] = []
    fill = iter([1.0, 1.0, 0.9, 0.5, 0.3])        # then 0.0: drained

    def backlog() -> float:
        value = next(fill, 0.0)
        seen.append((value, dev.firmware.tick))
        return value

    clock = None
    try:
        client.connect()
        clock = SteppedClock(dev, client, threading.Event(), recorder_backlog=backlog)
        tick0 = dev.firmware.tick
        clock.advance(3.0)
        assert dev.firmware.tick - tick0 == 3600
        full = [tick for value, tick in seen if value > 0.25]
        assert len(full) == 5 and set(full) == {tick0}   # nothing ran while it was full
    finally:
        if clock is not None:
            clock.close()
        client.close()
        dev.stop()


def test_a_block_counts_as_received_only_once_every_subscriber_has_it(dictionary):
    """The clock subscribes before a recording starts, yet its "received" (which lets a
    dwell return and the script stop the recording) must wait for subscribers added after
    it: a stressed run lost the last 900 frames of a dwell this way.  The later subscriber
    holds the chunk's last block and looks whether advance() has returned meanwhile: it
    never may (the wait is the bound in which a wrong order shows; the right one waits
    it out)."""
    dev = SimulatedDevice(dictionary, pacing="manual").start()
    client = open_client(dictionary, f"127.0.0.1:{dev.tcp_port}")
    clock = None
    advanced = threading.Event()
    early: list[bool] = []
    try:
        client.connect()
        clock = SteppedClock(dev, client, threading.Event())
        target = dev.firmware.tick + 900

        def recorder_like(block) -> None:       # subscribed after the clock, as a recorder is
            if block.name == "HIGH_RATE" and len(block) and int(block["tick"][-1]) >= target:
                early.append(advanced.wait(3.0))

        client.subscribe(recorder_like)
        runner = threading.Thread(target=lambda: (clock.advance(0.75), advanced.set()))
        runner.start()
        runner.join(60)
        assert not runner.is_alive() and advanced.is_set()
        assert early and not any(early)
    finally:
        if clock is not None:
            clock.close()
        client.close()
        dev.stop()

