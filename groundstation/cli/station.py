"""The CLI's one way to open a session for a command: `--device` (and its companions)
as a Station, so that `params` and `profile` run the same verbs as scripts, campaigns
and the window.  A simulator started here goes with the command."""

from __future__ import annotations

import sys
from contextlib import contextmanager
from typing import Iterator

#: the exit status of a command that refused or failed (the device was left safe)
EXIT_REFUSED = 1
#: ... and of one that could not start: bad input, or the device not reachable at all
EXIT_CANNOT_START = 2


def fail(text: str, code: int = EXIT_REFUSED) -> int:
    """Say why a command stops, on stderr, and return its exit status."""
    print(f"error: {text}", file=sys.stderr)
    return code


def status_for(exc: BaseException) -> int:
    """The exit status for an error that stopped a device command: 2 when the device could
    not be reached at all, or a port to listen on (the simulator's) was taken (nothing was
    sent: as `monitor` and `record` say it), 1 when it refused or failed on the way."""
    from ..core.errors import DeviceUnreachableError, PortInUseError

    cannot_start = isinstance(exc, (DeviceUnreachableError, PortInUseError))
    return EXIT_CANNOT_START if cannot_start else EXIT_REFUSED


def print_progress(step: str, fraction: float) -> None:
    """A transfer's progress: a live percentage on a terminal, one line in a log."""
    if sys.stderr.isatty():
        print(f"\r{step}: {100 * fraction:5.1f} %", end="", file=sys.stderr, flush=True)
        if fraction >= 1.0:
            print("", file=sys.stderr, flush=True)
    elif fraction >= 1.0:
        print(f"{step}: done", file=sys.stderr, flush=True)


def add_device_options(s, *, history: bool = False) -> None:
    s.add_argument("--device", default="sim",
                   help="sim (a simulated testbed started for this command) | tcp://HOST:PORT | "
                        "HOST:PORT | serial://PORT?baud=N")
    s.add_argument("--testbed", default=None,
                   help="testbed file for --device sim (default: the design's testbed, else the "
                        "default testbed)")
    if history:
        s.add_argument("--history", default=None,
                       help="folder of verified uploads, for rollback (default: "
                            "$XDG_DATA_HOME/groundstation/parameter_history)")
    s.add_argument("--take-over", action="store_true", help="end another host's session")
    add_sim_port_option(s)


def add_sim_port_option(s) -> None:
    from .arguments import listen_address
    s.add_argument("--sim-port", type=listen_address, default=None, metavar="[HOST:]PORT",
                   help="--device sim: the port the simulated testbed serves on, so that other "
                        "programs can reach it (127.0.0.1 unless a host is given; default: a "
                        "free port the system picks)")


@contextmanager
def command_station(args, dictionary, testbed: str | None = None) -> Iterator:
    """An open Station for one CLI command: no function generator, the parameter history
    from --history (if the command has one), closed (not made safe: a command that moved
    the rig makes it safe itself) on the way out."""
    from ..params.upload import ParameterHistory
    from ..station.station import Station

    history = None
    if hasattr(args, "history"):
        history = ParameterHistory(args.history or ParameterHistory.default_folder())
    station = Station(args.device, testbed=args.testbed or testbed, generator=None,
                      history=history, take_over=args.take_over, dictionary=dictionary,
                      echo=lambda text: None, sim_listen=getattr(args, "sim_port", None))
    try:
        station.open()
        if station.simulated:
            print(f"started the simulated testbed on {station.address}", flush=True)
        yield station
    finally:
        station.close()
