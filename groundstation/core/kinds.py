"""The closed vocabularies of the ground station, as StrEnums.

Each is a set of words that the files, the command line, the logs and the wire already
use; a member *is* its word (`LinkState.UP == "up"`, `str(Setup.INERTIAL) == "inertial"`),
so a value read from a TOML file, an argument or an old log compares and serialises as
before, while the code names the vocabulary instead of spelling a string, and a typo is an
AttributeError at import instead of a comparison that is silently never true.
"""

from __future__ import annotations

from enum import StrEnum


class LinkState(StrEnum):
    """The device link's state (link/client.py; the window adds CONNECTING and FAILED)."""

    CONNECTING = "connecting"     # the window is opening the link
    UP = "up"                     # connected, frames flowing
    LOST = "lost"                 # the transport failed (link_error says how)
    ENDED = "ended"               # the device ended our session (taken over)
    FAILED = "failed"             # a connect attempt failed (the window)
    CLOSED = "closed"             # closed by us


class Setup(StrEnum):
    """Which rig a testbed file describes (testbed.setup, reference chapter 2)."""

    RELATIVE = "relative"         # the stage fixed: encoders measure the pointing
    INERTIAL = "inertial"         # the base moves: gyro and autocollimator measure it


class FastSim(StrEnum):
    """Where a fast (stepped) simulated testbed runs."""

    INLINE = "inline"             # in this process, where a script can reach it
    PROCESS = "process"           # in a child process of its own (faster)


class BetweenSteps(StrEnum):
    """What the fast device's clock does while a script is not advancing it."""

    HELD = "held"                 # stands still (a run is tick-repeatable)
    REALTIME = "realtime"         # runs at the real-time rate (the older behaviour)


class GeneratorChoice(StrEnum):
    """The words a session accepts for its base-motion generator; anything else is a VISA
    resource string."""

    AUTO = "auto"                 # the simulator's own on an inertial simulated rig, else none
    NONE = "none"
    SIM = "sim"                   # the simulated generator


def wants_simulated_generator(choice: str | None, *, inertial: bool) -> bool:
    """Whether a session on the simulated testbed starts the simulator's generator:
    asked for ("sim"), or "auto" on an inertial rig (the base moves only there)."""
    return choice == GeneratorChoice.SIM or (choice == GeneratorChoice.AUTO and inertial)


#: the device word that starts the simulated testbed (anything else is an address)
SIMULATED_DEVICE = "sim"


class ProfileOrigin(StrEnum):
    """What a command profile's samples are measured from (profile files' `origin`)."""

    ABSOLUTE = "absolute"         # the target itself
    RELATIVE = "relative"         # offsets from the position held when the profile starts


class SimPacing(StrEnum):
    """How the simulated device's control periods are paced (sim/device.py)."""

    REALTIME = "realtime"         # 1200 periods per wall second (times `speed`)
    FAST = "fast"                 # as fast as possible, frames to a consumer
    MANUAL = "manual"             # stepped by a script's clock (the fast simulated testbed)
