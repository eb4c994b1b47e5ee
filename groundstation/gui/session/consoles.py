"""The session's part in the many-consoles fan-out (fanout/, docs/consoles.md): the
Publisher that passes this window's device link on to read-only consoles, and the watch
client that makes this window such a console.

`Consoles` is owned by the Session (`session.consoles`).  It holds the fan-out objects;
the Session decides what its link is and tells it when a device link comes up or goes
(`link_up`, `link_down`), and installs a watch client as its link (`Session.watch`)."""

from __future__ import annotations

from typing import TYPE_CHECKING

from ...core.contracts import DeviceLink
from ...core.dictionary import Dictionary
from ...core.errors import GroundStationError
from ...core.kinds import LinkState
from .commands import StartThread
from .events import EventSink

if TYPE_CHECKING:
    from ...fanout.publisher import Publisher
    from ...fanout.viewer import WatchClient

#: how long a new watch waits for the publishing station before saying it still waits
WATCH_UP_TIMEOUT_S = 10.0


class Consoles:
    """The Publisher of this window's device link (or None) and the endpoint it watches
    read-only (or None)."""

    def __init__(self, dictionary: Dictionary, report: EventSink, start_thread: StartThread):
        self.d = dictionary
        self._report = report
        self._start_thread = start_thread
        #: what this window's device link receives, published for read-only consoles
        self.publisher: Publisher | None = None
        #: the endpoint of the station this window watches read-only, or None
        self.watching: str | None = None

    # ------------------------------------------------------------------ publishing
    def start_publishing(self, endpoint: str, curve_keys: str | None = None,
                         client: DeviceLink | None = None, address: str = "") -> bool:
        """Publish on `endpoint` what this window's device link receives, now (`client`,
        opened on `address`, when one is up) and after every `link_up`."""
        # imported here: ZeroMQ is loaded only by a window that uses the fan-out
        from ...fanout.publisher import Publisher

        try:
            self.publisher = Publisher(endpoint, curve_keys=curve_keys)
        except GroundStationError as exc:
            self._report("ERROR", "publish", str(exc))
            return False
        if client is not None:
            self.publisher.attach(client, address)
        self._report("INFO", "publish", f"publishing on {self.publisher.endpoint}: "
                                        f"groundstation gui --watch {self.publisher.endpoint}")
        return True

    def link_up(self, client: DeviceLink, address: str) -> None:
        """A device link of this window came up (a reconnect's too): published, if we
        publish."""
        if self.publisher is not None:
            self.publisher.attach(client, address)

    def link_down(self) -> None:
        """The session's link was closed: nothing more is published, nothing watched."""
        self.watching = None
        if self.publisher is not None:
            self.publisher.detach()

    def close(self) -> None:
        if self.publisher is not None:
            self.publisher.close()
            self.publisher = None

    # ------------------------------------------------------------------ watching
    def open_watch(self, endpoint: str, curve_keys: str | None = None,
                   key_name: str = "viewer") -> WatchClient:
        """A read-only console's link to the station publishing at `endpoint`, not
        started yet (`start_watch`); raises GroundStationError when it cannot be opened.
        What the commanding station's own link does goes into the event log."""
        from ...fanout.viewer import WatchClient

        viewer = WatchClient(self.d, endpoint, curve_keys=curve_keys, key_name=key_name)
        viewer.add_remote_listener(lambda s, m: self._report(
            "INFO" if s == LinkState.UP else "WARNING", "commander",
            f"the commanding station's link {s}" + (f": {m}" if m else "")))
        self.watching = viewer.endpoint
        return viewer

    def start_watch(self, viewer: WatchClient) -> None:
        """Start listening (worker thread) and say when the publishing station answers.
        ZeroMQ reconnects by itself, so a station that is not there yet is only a
        warning: the watch comes up when one publishes."""
        def start() -> None:
            try:
                viewer.start().wait_up(timeout=WATCH_UP_TIMEOUT_S)
            except GroundStationError as exc:
                self._report("WARNING", "watch", str(exc))
                return
            device = (viewer.device or {}).get("address", "?")
            self._report("INFO", "watch", f"watching {viewer.endpoint} read-only: device {device}")
        self._start_thread(start, "gs-watch")


__all__ = ["Consoles", "WATCH_UP_TIMEOUT_S"]
