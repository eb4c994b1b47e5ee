"""The real-time simulated device idles cheaply: with no session open its tick loop wakes
once per IDLE_PERIODS control periods instead of once per period, the device clock
still counts every period, and a session opening brings the loop back to one wake-up
per period at once (SPEC §5.5's timing for a connected host unchanged).

The tick loop runs on a clock of the test's (SimulatedDevice.monotonic / .wait): device
time passes only when the test lets it, so the counts are exact whatever the machine's
load; nothing here measures wall time.
"""

from __future__ import annotations

import threading

import pytest

from conftest import wait_for
from groundstation.link import open_client
from groundstation.sim import SimulatedDevice
from groundstation.sim.device import IDLE_PERIODS


class DeviceClock:
    """Time for the tick loop: a wait passes its timeout at once while that stays within
    `limit`, else it holds (the loop is then `held`) until the limit is raised or the
    device's wake event is set (then it returns early, no time passing, as Event.wait)."""

    def __init__(self, wake: threading.Event):
        self.t = 0.0
        self.limit = 0.0
        self.wake = wake
        self.held = False
        self.cond = threading.Condition()

    def now(self) -> float:
        return self.t

    def wait(self, timeout: float) -> bool:
        with self.cond:
            # the bounded poll notices the wake event, which is set from other threads
            while not self.wake.is_set() and self.t + timeout > self.limit:
                self.held = True
                self.cond.wait(0.005)
            self.held = False
            if self.wake.is_set():
                return True
            self.t += timeout
            return False

    def run_to(self, limit: float) -> None:
        """Let device time run to `limit`; back when the loop is held there."""
        with self.cond:
            self.limit, self.held = limit, False
        wait_for(lambda: self.held and self.t + 1e-9 >= limit - 1 / 1200, timeout=60)


@pytest.fixture
def device(dictionary):
    dev = SimulatedDevice(dictionary, pacing="realtime", seed=1)
    clock = DeviceClock(dev._wake)
    dev.monotonic, dev.wait = clock.now, clock.wait
    dev.start()
    yield dev, clock
    dev.stop()


def test_an_idle_device_wakes_once_per_idle_batch_and_keeps_its_clock(device):
    dev, clock = device
    clock.run_to(2.0)                                  # two device seconds, nobody connected
    ticks = dev.firmware.tick
    assert 2400 - IDLE_PERIODS <= ticks <= 2400        # every period was run
    # one wake-up per batch, 10 per device second (a rounding of the clock may add a
    # short one); it was one per period, 1200 per second
    per_second = dev.loop_wakeups / (ticks / 1200)
    assert per_second <= 2 * 1200 / IDLE_PERIODS + 1 and IDLE_PERIODS >= 60, per_second


def test_a_slowed_device_idles_without_overruns(dictionary):
    """At speed 0.1 (120 periods per wall second) an idle batch of 120 periods would be
    a whole second late for _catch_up, which skips what is over half a second as
    overruns: the batch is smaller there."""
    dev = SimulatedDevice(dictionary, pacing="realtime", seed=1, speed=0.1)
    clock = DeviceClock(dev._wake)
    dev.monotonic, dev.wait = clock.now, clock.wait
    dev.start()
    try:
        clock.run_to(20.0)                             # 2400 periods at 120 per second
        assert dev.firmware.tick >= 2400 - 30 and dev.firmware.overruns == 0
        assert dev.loop_wakeups <= 2 * dev.firmware.tick / 30 + 2
    finally:
        dev.stop()


def test_a_session_brings_the_loop_back_to_every_period(device, dictionary):
    dev, clock = device
    clock.run_to(1.0)
    client = open_client(dictionary, f"tcp://127.0.0.1:{dev.tcp_port}", heartbeat=False)
    try:
        client.connect()
        # the CONNECT ran the periods due first: the host finds the clock where it was
        assert dev.firmware.tick == pytest.approx(1200, abs=IDLE_PERIODS)
        # the session woke the loop out of its idle wait: held now on the next period
        wait_for(lambda: clock.held and not dev._idling, timeout=10)
        ticks, wakeups = dev.firmware.tick, dev.loop_wakeups
        clock.run_to(clock.t + 0.25)
        ran = dev.firmware.tick - ticks
        assert ran >= 295
        # one wake-up per period from the first one on (a lost wake would have run the
        # first IDLE_PERIODS in one batch)
        assert dev.loop_wakeups - wakeups >= ran - 1, (dev.loop_wakeups - wakeups, ran)
    finally:
        client.close()
