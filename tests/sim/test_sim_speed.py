"""The paced simulator's speed factor: `speed` control periods per 1/1200 s of wall time,
ticks still one per period; the default (1.0) leaves everything as it was.

These tests do not depend on how fast the machine is: the pacing law is checked against
a controlled clock, and the process test checks what is streamed, not how quickly.  The
achieved tick rate against the wall clock is measured by `benchmarks/bench_sim.py`
("speed factor"), which prints it beside its tolerance."""

from __future__ import annotations

import math
import threading

import numpy as np
import pytest

from groundstation.cli.main import build_parser
from groundstation.link import open_client
from groundstation.sim import SimulatedDevice
from groundstation.sim.process import SimulatorProcess

RATE = 1200.0


def test_default_speed_is_one(dictionary):
    dev = SimulatedDevice(dictionary, pacing="manual")
    assert dev.speed == 1.0


@pytest.mark.parametrize("bad", [0.0, -1.0, math.nan, math.inf])
def test_speed_must_be_finite_and_positive(dictionary, bad):
    with pytest.raises(ValueError, match="speed"):
        SimulatedDevice(dictionary, speed=bad)


class FakeClock:
    """time.monotonic for the device module: moves only when the test says so."""

    def __init__(self) -> None:
        self.now = 1000.0

    def __call__(self) -> float:
        return self.now


@pytest.mark.parametrize("speed", [1.0, 5.0, 0.5])
def test_pacing_runs_speed_periods_per_period_of_wall_time(dictionary, monkeypatch, speed):
    """The pacing law itself, on a controlled clock: after t seconds of wall time the
    device has run exactly floor(t * 1200 * speed) control periods, one tick each, with
    no overrun."""
    from groundstation.sim import device as device_module

    clock = FakeClock()
    monkeypatch.setattr(device_module.time, "monotonic", clock)
    dev = SimulatedDevice(dictionary, pacing="realtime", speed=speed)
    dev._t0, dev._ticks_done = clock.now, 0              # what the tick loop does at start
    tick0 = dev.firmware.tick
    for step_s in (0.01, 0.1, 0.0005, 0.25, 0.05):
        clock.now += step_s
        dev._catch_up()
        elapsed = clock.now - dev._t0
        expected = int(elapsed * RATE * speed)
        assert dev.firmware.tick - tick0 == expected == dev._ticks_done, (elapsed, speed)
    assert dev.firmware.overruns == 0


def test_pacing_that_falls_behind_skips_and_counts_overruns(dictionary, monkeypatch):
    """A machine too busy to keep up: at most half a second of periods runs at once, the
    rest is skipped and counted as overruns (ticks still one per period run)."""
    from groundstation.sim import device as device_module

    clock = FakeClock()
    monkeypatch.setattr(device_module.time, "monotonic", clock)
    dev = SimulatedDevice(dictionary, pacing="realtime", speed=5.0)
    dev._t0, dev._ticks_done = clock.now, 0
    tick0 = dev.firmware.tick
    clock.now += 2.0                                     # 12 000 periods due at once
    dev._catch_up()
    assert dev.firmware.tick - tick0 == int(RATE * 5.0 // 2)
    assert dev.firmware.overruns == 12000 - int(RATE * 5.0 // 2)


def test_cli_and_process_pass_the_speed_through():
    assert build_parser().parse_args(["sim"]).speed == 1.0
    assert build_parser().parse_args(["sim", "--speed", "10"]).speed == 10.0
    for bad in ("0", "-2", "nan", "fast"):
        with pytest.raises(SystemExit):
            build_parser().parse_args(["sim", "--speed", bad])
    assert "--speed" not in SimulatorProcess().args           # default: command line as before
    args = SimulatorProcess(speed=10).args
    assert args[args.index("--speed") + 1] == "10.0"


def test_simulator_process_streams_exact_ticks_at_speed(dictionary):
    """End to end: `groundstation sim --speed 5` streams one HIGH_RATE frame per tick:
    ticks and sequence numbers advance together (a frame lost on the link skips both
    alike), in order, never repeated.  How many ticks per wall second it achieves is
    bench_sim.py's to measure."""
    wanted = 3000
    ticks: list[np.ndarray] = []
    seqs: list[np.ndarray] = []
    lock = threading.Lock()
    enough = threading.Event()

    def on_block(block):
        if block.name == "HIGH_RATE":
            with lock:
                ticks.append(np.asarray(block["tick"], dtype=np.int64))
                seqs.append(np.asarray(block["sequence"], dtype=np.int64))
                if sum(len(t) for t in ticks) >= wanted:
                    enough.set()

    with SimulatorProcess(speed=5.0) as address:
        client = open_client(dictionary, address)
        try:
            client.subscribe(on_block)
            client.connect()
            # a deadline only against a hung simulator: at speed 5 this takes ~0.5 s
            assert enough.wait(120.0), "the simulator streamed fewer than 3000 frames in 120 s"
        finally:
            client.close()
    with lock:
        k = np.concatenate(ticks)
        q = np.concatenate(seqs)
    assert len(k) >= wanted
    assert (np.diff(k) >= 1).all()                       # in order, never repeated
    assert (np.diff(k) == np.diff(q)).all()              # one frame per tick
