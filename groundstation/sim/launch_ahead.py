"""A fast simulator's child process launched ahead of the session that will use it.

`campaign run --device sim --fast` first checks the whole campaign - every design is
discretised, every profile and base motion read, which imports scipy.signal - and only
then opens the session, whose first act is to start the simulator's child process: its
interpreter, its imports and numba's cache, about half a second of another core's time
that the check could have overlapped.  So the command launches the child as soon as it
knows which simulator the campaign will ask for (the campaign file's testbed, the seed,
whether the simulated generator is wanted), and the session's start takes that child
instead of launching one (`take`).

It is a guess, never a decision: the session takes a child launched ahead only when it
asks for exactly that simulator (the same command line and dictionary); otherwise it
starts its own as always.  A child nobody took is ended (`discard`, which the command
calls on its way out whatever happened, and at exit) - and a child ends by itself when
its parent's end of the channel closes.
"""

from __future__ import annotations

import atexit
import threading

from .stepped_process import SteppedSimulatorProcess

_lock = threading.Lock()
_waiting: list[SteppedSimulatorProcess] = []


def launch_ahead(*, testbed, seed: int = 0, generator: bool = False) -> None:
    """Launch the child of this simulator now, for the next session that asks for it.
    No dictionary is needed yet (the child loads its own), so a command can launch it
    before it has imported numpy; the session that takes it gives it its own."""
    device = SteppedSimulatorProcess(None, testbed=testbed, seed=seed, generator=generator)
    device.launch()
    with _lock:
        _waiting.append(device)


def take(wanted: SteppedSimulatorProcess) -> SteppedSimulatorProcess:
    """A child launched ahead with `wanted`'s command line (which is all that makes one
    child differ from another), now with `wanted`'s dictionary; else `wanted` itself
    (not launched)."""
    with _lock:
        for device in _waiting:
            if device.args == wanted.args:
                _waiting.remove(device)
                device.dictionary = wanted.dictionary
                return device
    return wanted


def discard() -> None:
    """End every child launched ahead that no session took."""
    with _lock:
        left = list(_waiting)
        _waiting.clear()
    for device in left:
        device.stop()


atexit.register(discard)          # a child launched ahead never outlives the command
