"""Thesis designs uploaded through the real path (client -> simulated device over loopback)
and run in closed loop on the simulated rig: read-back bit for bit, relative Design #2
tracks a step, inertial Design #2 holds the line of sight and settles a small step."""

from __future__ import annotations

import threading
import time
from pathlib import Path

import numpy as np
import pytest

from groundstation.link import open_client
from groundstation.params import table as ptable
from groundstation.params.design_file import load_design, table_values
from groundstation.params.loop import validate
from groundstation.params.clearance import override_table
from groundstation.params.upload import ParameterLoader
from groundstation.sim import SimulatedDevice
from groundstation.sim.firmware import Firmware
from groundstation.plant.testbed import TESTBEDS_DIR, load_testbed
from groundstation.live.display_buffers import TelemetryStore

CONTROLLERS = Path(__file__).resolve().parents[2] / "profiles" / "controllers"
RATE = 1200


class Rig:
    """A manually clocked simulated device: the test decides how much time passes, so the
    closed-loop results are the same on any machine."""

    def __init__(self, dictionary, testbed: str):
        fw = Firmware(dictionary, seed=5, testbed=load_testbed(TESTBEDS_DIR / testbed))
        self.device = SimulatedDevice(dictionary, pacing="manual", firmware=fw).start()
        self.client = open_client(dictionary, f"127.0.0.1:{self.device.tcp_port}", heartbeat=False)
        self.client.connect()
        self.store = TelemetryStore(dictionary, seconds=30.0)
        self.client.subscribe(self.store)
        self.d = dictionary

    def upload(self, values) -> None:
        """Upload while a clock thread keeps ticks (and so HOUSEKEEPING) coming."""
        stop = threading.Event()

        def clock():
            while not stop.wait(0.005):
                self.device.run_ticks(12)
        t = threading.Thread(target=clock, daemon=True)
        t.start()
        try:
            loader = ParameterLoader(self.client, self.d)
            # a test rig's table: cleared by the recorded override (the designs are
            # validated by the tests that call this)
            record = loader.upload(values, "test", clearance=override_table(
                values, self.d, "closed-loop test rig"))
            assert loader.read_active().blob == ptable.pack(self.d, values)     # bit for bit
            assert record.crc == self.device.firmware.param_crc
        finally:
            stop.set()
            t.join()

    def run(self, seconds: float) -> dict[str, np.ndarray]:
        """Advance `seconds` of device time (heartbeats in between); the HIGH_RATE of that time."""
        ring = self.store.ring("HIGH_RATE")
        n = int(round(seconds * RATE))
        for _ in range(n // 300):
            self.device.run_ticks(300)
            self.client.command("HEARTBEAT")
        self.device.run_ticks(n % 300)
        newest = self.device.firmware.tick
        end = time.monotonic() + 10
        while ring.latest("tick") != newest and time.monotonic() < end:
            time.sleep(0.005)
        assert ring.latest("tick") == newest, "telemetry lost on loopback"
        snap = ring.snapshot(["encoder_inner", "los_estimate", "gyro_rate", "reference", "status",
                              "torque_coarse_cmd", "torque_fine_cmd", "mode"], seconds=(n - 1) / RATE)
        return snap.values

    def close(self) -> None:
        self.client.close()
        self.device.stop()


@pytest.fixture
def rig_factory(dictionary):
    rigs = []

    def make(testbed):
        rigs.append(Rig(dictionary, testbed))
        return rigs[-1]
    yield make
    for r in rigs:
        r.close()


def armed(status: np.ndarray) -> np.ndarray:
    return (status.astype(int) & 1) == 1


def test_relative_design_2_tracks_a_step(rig_factory, dictionary):
    design = load_design(CONTROLLERS / "relative_design2.toml")
    rig = rig_factory("relative_2dof.toml")
    rig.upload(table_values(design, dictionary=dictionary))
    rig.client.command("SET_MODE", mode="RELATIVE")
    rig.client.command("ARM")
    rig.run(0.5)
    step = 1e-3                                               # 1 mrad: well inside the flexure's 15
    rig.client.command("SET_REFERENCE", reference=step)
    out = rig.run(2.0)
    assert armed(out["status"]).all(), "the loop faulted or disarmed"
    phi2 = out["encoder_inner"]
    late = phi2[-RATE // 2:]                                  # the last 0.5 s
    assert abs(late.mean() - step) < 0.02 * step              # tracks within 2 %
    assert late.std() < 0.01 * step                           # and has settled
    # the design's 35 deg phase margin gives about 50 % overshoot; more would mean the
    # discretised controller is not the designed one
    assert np.abs(phi2).max() < 1.65 * step


def test_inertial_design_2_holds_the_line_of_sight(rig_factory, dictionary):
    """The reference's inertial designs with K_p = 25 are marginally unstable on the
    reference's own model (largest closed-loop |z| = 1.0004 at 22.8 Hz, see
    docs/controllers.md), so the host refuses them.  Sent anyway (the device only checks
    the controller's own poles), the simulated rig's friction bounds the oscillation: the
    line of sight is held and a step settles on its mean, with a residual limit cycle."""
    design = load_design(CONTROLLERS / "inertial_design2.toml")
    values = table_values(design, dictionary=dictionary)
    report = validate(design, values, dictionary)
    assert not report.ok and "unstable" in " ".join(report.problems)
    rig = rig_factory("inertial_2dof.toml")
    rig.upload(values)
    rig.client.command("SET_MODE", mode="INERTIAL")
    rig.client.command("ARM")
    hold = rig.run(3.0)
    assert armed(hold["status"]).all(), "the loop faulted or disarmed"
    assert not saturated(hold["status"]).any()
    rate = hold["gyro_rate"][RATE:]                           # after the first second
    assert np.abs(rate).max() < 0.03                          # rad/s: bounded, not diverging
    assert rate[-RATE:].std() < 1.5 * rate[:RATE].std()       # and not growing
    step = 1e-3                                               # 1 mrad
    start = rig.store.ring("HIGH_RATE").latest("los_estimate")
    rig.client.command("SET_REFERENCE", reference=start + step)
    out = rig.run(3.0)
    assert armed(out["status"]).all()
    late = out["los_estimate"][-RATE:] - start
    assert abs(late.mean() - step) < 0.02 * step              # settles on the new angle (mean)
    assert late.std() < 0.2 * step                            # around it: the limit cycle


def saturated(status: np.ndarray) -> np.ndarray:
    return (status.astype(int) & 0b110) != 0
