"""A link kept open for a command-line session: connect, and reconnect with back-off.

The window reconnects on its own after a lost link (gui/session/session.py, with the same
delays); `record` and `monitor` use this.  For `--device sim` the keeper also owns the
simulator child, and starts a fresh one if the old one died.  A session *taken over*
by another station is not reconnected: that is a decision for the operator.
"""

from __future__ import annotations

import logging
import threading
from dataclasses import dataclass
from typing import Callable

from ..core.dictionary import Dictionary
from ..core.errors import GroundStationError
from ..core.kinds import LinkState, SIMULATED_DEVICE
from ..core.contracts import DeviceLink
from .rig import LocalSimulator, open_link, start_simulator

log = logging.getLogger(__name__)

#: seconds between reconnect attempts: quick at first, then every 10 s
RECONNECT_DELAYS_S = (1.0, 2.0, 4.0, 8.0, 10.0)

#: how a command-line session ends (its exit status): as asked, failed (recording failed
#: or link lost without reconnecting), could not start, taken over by another station
EXIT_OK, EXIT_FAILED, EXIT_REFUSED, EXIT_TAKEN_OVER = 0, 1, 2, 3


@dataclass(frozen=True)
class Ending:
    """Why a kept link's session is over: the exit status and the reason to report."""
    status: int
    reason: str


class LinkKeeper:
    """Owns the device address (and the simulator child for 'sim') and the live client.

    on_client(client) runs for every new client before it connects, so that a recorder
    can be attached in time to journal the CONNECT; it returns the function that
    detaches it again, called before that client is closed."""

    def __init__(self, dictionary: Dictionary, device: str, testbed: str | None = None, *,
                 take_over: bool = False,
                 on_client: Callable[[DeviceLink], Callable[[], None]] | None = None,
                 say: Callable[[str], None] = print, sim_listen: tuple[str, int] | None = None):
        self.dictionary = dictionary
        #: (host, port) the simulator started for `device` "sim" serves on (None: any port)
        self.sim_listen = sim_listen
        self.device = device
        self.testbed = testbed
        self.take_over = take_over
        self.on_client = on_client
        self.say = say
        self.client: DeviceLink | None = None
        self.sim: LocalSimulator | None = None
        self.address = ""
        self.reconnects = 0
        self._detach: Callable[[], None] | None = None

    def open(self) -> DeviceLink:
        """Start the simulator if asked for, open the link and connect; raises
        GroundStationError (with the device's reason) if that fails."""
        if self.device == SIMULATED_DEVICE:
            if self.sim is None or self.sim.gone():
                if self.sim is not None:
                    self.sim.stop()
                self.sim = start_simulator(self.testbed, listen=self.sim_listen)
                self.address = self.sim.address
                self.say(f"started the simulated testbed on {self.address}")
        else:
            self.address = self.device
        client = open_link(self.dictionary, self.address,
                           local=self.sim if self.device == SIMULATED_DEVICE else None)
        self.client = client
        if self.on_client is not None:
            self._detach = self.on_client(client)
        client.connect(take_over=self.take_over)
        return client

    def reopen(self, stop: threading.Event) -> DeviceLink | None:
        """After a lost link: close the old client and try again, waiting the back-off
        delays in between, until connected (returns the client) or `stop` is set (None)."""
        attempt = 0
        while not stop.is_set():
            self._close_client()
            delay = RECONNECT_DELAYS_S[min(attempt, len(RECONNECT_DELAYS_S) - 1)]
            attempt += 1
            self.say(f"reconnecting in {delay:g} s (attempt {attempt})")
            if stop.wait(delay):
                return None
            try:
                client = self.open()
            except GroundStationError as exc:
                self.say(f"reconnect failed: {exc}")
                continue
            self.reconnects += 1
            self.say(f"reconnected to {self.address}")
            return client
        return None

    def keep_up(self, stop: threading.Event, *, reconnect: bool = True,
                on_event: Callable[[str, str], None] | None = None) -> Ending | None:
        """One check of the link, the policy `record` and `monitor` share: None while
        the session goes on (after a reconnect if the link was lost: `self.client` is
        the new client), else the Ending.  A session taken over is never reconnected;
        a lost link is reopened with back-off unless `reconnect` is off.  on_event(state,
        message) hears "reconnecting" and "reconnected" (a recording journals them)."""
        client = self.client
        if client is None:
            return Ending(EXIT_FAILED, "no link")
        if client.link_state == LinkState.UP:
            return None
        if client.link_state == LinkState.ENDED:             # another station took the session over
            self.say(f"error: {client.link_error}")
            return Ending(EXIT_TAKEN_OVER, client.link_error)
        lost = f"link {client.link_state}: {client.link_error}"
        self.say(lost)
        if not reconnect:
            return Ending(EXIT_FAILED, lost)
        if on_event is not None:
            on_event("reconnecting", lost)
        if self.reopen(stop) is None:                # stopped while waiting to reconnect
            return Ending(EXIT_OK, "")
        if on_event is not None:
            on_event("reconnected", f"reconnected to {self.address}")
        return None

    def _close_client(self) -> None:
        # close first, detach after: the recorder journals the DISCONNECT and the close
        if self.client is not None:
            self.client.close()
            self.client = None
        if self._detach is not None:
            self._detach()
            self._detach = None

    def close(self) -> None:
        """Disconnect (the device disarms) and stop the simulator child, if any."""
        try:
            self._close_client()
        finally:
            if self.sim is not None:
                self.sim.stop()
                self.sim = None
