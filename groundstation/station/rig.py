"""The one place that builds a rig for a session: the simulated testbed (started here,
in one of its three forms), the device link and the base-motion generator.

A script's Station, the station keeper, the window's session and the `fg` commands all
start what they need through here, so a simulator is started, watched and stopped the
same way everywhere, a link to a local simulator always knows the device's liveness
(DeviceClient.device_gone), and a generator is always opened with the testbed's safety
limits.

The simulated testbed's forms:
- real time, in a child process (`groundstation sim`, SimulatorProcess): what an operator
  sees; its own interpreter, paced to the wall clock (optionally `speed` times faster);
- fast and inline: a manually paced SimulatedDevice in this process, driven by the
  script's SteppedClock (a script can reach into it);
- fast, in a child process (SteppedSimulatorProcess): the same device with an interpreter
  and a core of its own, stepped over a private control channel.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from ..core.dictionary import Dictionary
from ..core.errors import GroundStationError
from ..core.kinds import FastSim, GeneratorChoice
from ..link import DeviceClient, open_client


@dataclass
class LocalSimulator:
    """A simulated testbed this process started, and stops."""

    address: str                       # host:port of its command link
    fg_resource: str | None            # its function generator's VISA resource, if asked for
    seed: int = 0                      # its random seed (sensor noise, disturbances)
    #: the manually paced device a SteppedClock drives (fast forms), None in real time
    stepped: Any | None = None
    #: what was started here, stopped in reverse order (each has gone() and stop())
    parts: list = field(default_factory=list)

    def gone(self) -> str:
        """Why the simulator can no longer answer ("" while it runs)."""
        for part in self.parts:
            why = part.gone() if hasattr(part, "gone") else ""
            if why:
                return why
        return ""

    @property
    def process(self):
        """The child process (subprocess.Popen) the simulator runs in; None in this process."""
        return next((part.proc for part in self.parts if getattr(part, "proc", None)), None)

    def stop(self) -> None:
        for part in reversed(self.parts):
            part.stop()
        self.parts.clear()


def start_simulator(testbed: str | Path | None, *, dictionary: Dictionary | None = None,
                    fast: bool = False, fast_sim: FastSim | str = FastSim.INLINE, seed: int = 0,
                    speed: float = 1.0, generator: bool = False,
                    listen: tuple[str, int] | None = None) -> LocalSimulator:
    """Start the simulated testbed of `testbed` (a testbed file; None: the simulator's
    default) in the form asked for, with its function generator when `generator`.  The
    fast forms speak `dictionary` (the one the host's link uses).  `listen`: the (host,
    port) the real-time simulator serves on (None: 127.0.0.1, a port the system picks);
    a fast one is the script's own, on a link nobody else joins."""
    if fast and dictionary is None:
        raise ValueError("a fast simulated testbed needs the dictionary the link speaks")
    if fast and listen is not None:
        raise GroundStationError("a chosen simulator port (--sim-port) is for the real-time "
                                 "simulator: with --fast the simulator is this run's own, on a "
                                 "private link - leave out one or the other")
    if not fast:
        from ..sim.process import SimulatorProcess

        host, port = listen if listen is not None else ("127.0.0.1", 0)
        sim = SimulatorProcess(pacing="realtime", seed=seed, host=host, tcp_port=port,
                               testbed=str(testbed) if testbed else None, speed=speed,
                               fg_port=0 if generator else None)
        address = sim.start()
        local = LocalSimulator(address, sim.fg_resource, seed, parts=[sim])
    elif FastSim(fast_sim) is FastSim.PROCESS:
        from ..sim.launch_ahead import take
        from ..sim.stepped_process import SteppedSimulatorProcess

        # one launched ahead for exactly this simulator, if any (sim/launch_ahead.py)
        device = take(SteppedSimulatorProcess(dictionary, testbed=_testbed_path(testbed), seed=seed,
                                              generator=generator)).start()
        local = LocalSimulator(f"127.0.0.1:{device.tcp_port}", device.fg_resource, seed,
                               stepped=device, parts=[device])
    else:
        from ..plant.testbed import load_testbed
        from ..sim.device import SimulatedDevice
        from ..sim.firmware import Firmware
        from ..sim.scpi_server import attach_generator

        fw = Firmware(dictionary, seed=seed, testbed=load_testbed(_testbed_path(testbed)))
        device = SimulatedDevice(dictionary, pacing="manual", firmware=fw).start()
        local = LocalSimulator(f"127.0.0.1:{device.tcp_port}", None, seed, stepped=device,
                               parts=[device])
        if generator:
            try:
                server = attach_generator(device)
            except BaseException:
                local.stop()
                raise
            local.parts.append(server)
            local.fg_resource = server.resource
    if generator and not local.fg_resource:
        local.stop()
        raise GroundStationError("the simulated testbed did not announce its function generator")
    return local


def _testbed_path(testbed: str | Path | None) -> Path:
    from ..plant.testbed import DEFAULT_TESTBED

    return Path(testbed) if testbed else Path(DEFAULT_TESTBED)


def open_link(dictionary: Dictionary, address: str, *, local: LocalSimulator | None = None,
              heartbeat: bool = True) -> DeviceClient:
    """A started (not yet connected) client for the device at `address`; for a simulator
    started here (`local`), one that waits for it while it is there instead of giving up
    after the dictionary's retries (docs/testing.md)."""
    client = open_client(dictionary, address, heartbeat=heartbeat)
    if local is not None:
        client.device_gone = local.gone
    return client


def named_generator(choice: str | None) -> str | None:
    """The VISA resource of a real generator the user named, or None for the words
    (auto, none, sim) and for no choice."""
    if choice is None or choice in set(GeneratorChoice):
        return None
    return choice


def open_testbed_generator(resource: str, testbed=None, *, limits=None,
                           backend: str | None = None, timeout_s: float = 5.0):
    """The base-motion generator at `resource`, bound by safety limits: `limits`, or the
    testbed's (its [limits]); every setting is checked against them before it is sent.
    A generator is never opened without limits."""
    from ..instruments import SafetyLimits, open_generator

    if limits is None:
        if testbed is None:
            raise ValueError("a generator opens with safety limits: give a testbed or limits")
        limits = SafetyLimits.from_testbed(testbed)
    return open_generator(resource, backend=backend, limits=limits, timeout_s=timeout_s)
