"""The CLI's one way to open a session for a command: `--device` (and its companions)
as a Station, so that `params` and `profile` run the same verbs as scripts, campaigns
and the window.  A simulator started here goes with the command."""

from __future__ import annotations

from contextlib import contextmanager
from typing import Iterator


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


@contextmanager
def command_station(args, dictionary, testbed: str | None = None) -> Iterator:
    """An open Station for one CLI command: no function generator, the parameter history
    from --history (if the command has one), closed (not made safe: a command that moved
    the rig makes it safe itself) on the way out."""
    from .params.upload import ParameterHistory
    from .station.station import Station

    history = None
    if hasattr(args, "history"):
        history = ParameterHistory(args.history or ParameterHistory.default_folder())
    station = Station(args.device, testbed=args.testbed or testbed, generator=None,
                      history=history, take_over=args.take_over, dictionary=dictionary,
                      echo=lambda text: None)
    try:
        station.open()
        if station.simulated:
            print(f"started the simulated testbed on {station.address}", flush=True)
        yield station
    finally:
        station.close()
