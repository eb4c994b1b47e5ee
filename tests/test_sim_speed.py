"""The paced simulator's speed factor: `speed` control periods per 1/1200 s of wall time,
ticks still one per period; the default (1.0) leaves everything as it was."""

from __future__ import annotations

import math
import threading
import time

import numpy as np
import pytest

from groundstation.cli import build_parser
from groundstation.link import open_client
from groundstation.sim import SimulatedDevice
from groundstation.sim.process import SimulatorProcess

RATE = 1200.0


def _tick_rate(dev: SimulatedDevice, warmup: float = 0.2, span: float = 0.8) -> float:
    """Device ticks per wall second, measured after a short warm-up."""
    time.sleep(warmup)
    t0, k0 = time.monotonic(), dev.firmware.tick
    time.sleep(span)
    t1, k1 = time.monotonic(), dev.firmware.tick
    return (k1 - k0) / (t1 - t0)


def test_default_speed_is_one(dictionary):
    dev = SimulatedDevice(dictionary, pacing="manual")
    assert dev.speed == 1.0


@pytest.mark.parametrize("bad", [0.0, -1.0, math.nan, math.inf])
def test_speed_must_be_finite_and_positive(dictionary, bad):
    with pytest.raises(ValueError, match="speed"):
        SimulatedDevice(dictionary, speed=bad)


def test_speed_five_runs_five_times_the_control_rate(dictionary):
    with SimulatedDevice(dictionary, pacing="realtime", speed=5.0) as dev:
        rate = _tick_rate(dev)
        overruns = dev.firmware.overruns
    assert 0.85 * 5 * RATE < rate < 1.1 * 5 * RATE, rate
    assert overruns == 0


def test_speed_one_keeps_the_control_rate(dictionary):
    with SimulatedDevice(dictionary, pacing="realtime") as dev:
        rate = _tick_rate(dev, span=0.5)
    assert 0.85 * RATE < rate < 1.1 * RATE, rate


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
    """End to end: `groundstation sim --speed 5` streams one HIGH_RATE frame per tick,
    5 x 1200 ticks per wall second."""
    ticks: list[np.ndarray] = []
    hosts: list[float] = []
    lock = threading.Lock()

    def on_block(block):
        if block.name == "HIGH_RATE":
            with lock:
                ticks.append(np.asarray(block["tick"], dtype=np.int64))
                hosts.append(float(np.max(block.host_time)))

    with SimulatorProcess(speed=5.0) as address:
        client = open_client(dictionary, address)
        try:
            client.subscribe(on_block)
            client.connect()
            time.sleep(1.2)
        finally:
            client.close()
    with lock:
        k = np.concatenate(ticks)
        h = np.array(hosts)
    assert len(k) > 3000, len(k)
    steps = np.diff(k)
    assert (steps >= 1).all()                  # in order, never repeated
    assert np.mean(steps == 1) > 0.99          # one frame per tick (loopback UDP: ~no loss)
    # the device clock against the host's, over the last second of arrivals
    keep = h >= h[-1] - 1.0
    first = int(np.argmax(keep))
    sizes = np.cumsum([len(t) for t in ticks])
    k_first = k[sizes[first] - 1]
    rate = (k[-1] - k_first) / (h[-1] - h[first])
    assert 0.8 * 5 * RATE < rate < 1.2 * 5 * RATE, rate
