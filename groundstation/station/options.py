"""The rarer choices of a Station, grouped by what they are about.

A script passes them only to tune something specific; the everyday keywords (device,
testbed, fast, generator, log folder, seed, history, ...) stay on the Station itself:

    from groundstation import Testbed
    from groundstation.station.options import ConsolePublishing, FastSimOptions

    Testbed("sim", fast=FastSimOptions(where="process"))       # the simulator in a child
    Testbed("tcp://192.168.1.20:5020", publishing=ConsolePublishing("tcp://127.0.0.1:5600"))

Words may be given as plain strings ("process", "held"): each is checked against its
vocabulary (core/kinds.py) when the options are made.
"""

from __future__ import annotations

from dataclasses import dataclass

from ..core.kinds import BetweenSteps, FastSim
from .clock import FastPacing


@dataclass(frozen=True)
class FastSimOptions:
    """How the fast (script-clocked) simulated testbed runs.

    where          in this process (inline: a script may reach the device) or in a child
                   process of its own (process: faster, it does not share the interpreter
                   with the receiver)
    pacing         how the stepped clock paces the device against the host (clock.py);
                   None: the clock's default
    between_steps  what device time does while the script is not advancing it: held
                   (stands still, a run repeats tick for tick) or realtime
    """

    where: FastSim = FastSim.INLINE
    pacing: FastPacing | None = None
    between_steps: BetweenSteps = BetweenSteps.HELD

    def __post_init__(self) -> None:
        # frozen: the checked words are set through object.__setattr__
        try:
            object.__setattr__(self, "where", FastSim(self.where))
        except ValueError:
            raise ValueError(f"FastSimOptions.where must be one of {', '.join(FastSim)}, "
                             f"not {self.where!r}") from None
        try:
            object.__setattr__(self, "between_steps", BetweenSteps(self.between_steps))
        except ValueError:
            raise ValueError(f"FastSimOptions.between_steps must be one of {', '.join(BetweenSteps)}, "
                             f"not {self.between_steps!r}") from None
        if self.pacing is not None and not isinstance(self.pacing, FastPacing):
            raise TypeError(f"pacing must be a FastPacing (station/clock.py), not {self.pacing!r}")


@dataclass(frozen=True)
class ConsolePublishing:
    """Publish the session's link for read-only consoles (fanout/, docs/consoles.md).

    endpoint    where viewers connect, e.g. "tcp://127.0.0.1:5600" ("*" for any port)
    curve_keys  a folder of CurveZMQ keys: viewers must hold an authorised key
    """

    endpoint: str
    curve_keys: str | None = None

    def __post_init__(self) -> None:
        if not isinstance(self.endpoint, str) or not self.endpoint:
            raise ValueError(f"publishing needs an endpoint, e.g. 'tcp://127.0.0.1:5600', "
                             f"not {self.endpoint!r}")


__all__ = ["FastSimOptions", "ConsolePublishing"]
