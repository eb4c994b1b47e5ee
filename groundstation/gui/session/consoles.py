"""The session's many-consoles verbs (fanout/, docs/consoles.md): watch a publishing
station read-only, or publish this window's device link.  A mixin of gui/session.Session,
kept apart because it is a job of its own: it uses the session's store, limits, workers
and signals and adds none."""

from __future__ import annotations

from ...core.errors import GroundStationError


class ConsoleMixin:
    def watch(self, endpoint: str, curve_keys: str | None = None, key_name: str = "viewer") -> None:
        """A read-only console on the station publishing at `endpoint`: the same charts,
        status, recording and analysis; commands refused but ABORT, which goes straight
        to the device (fanout/viewer.py).  ZeroMQ reconnects by itself: no back-off here."""
        from ...fanout.viewer import WatchClient

        self.close_replay()
        self.disconnect_link()
        try:
            viewer = WatchClient(self.d, endpoint, curve_keys=curve_keys, key_name=key_name)
        except GroundStationError as exc:
            self.sig_link_state.emit("failed", str(exc))
            self.sig_event.emit("ERROR", "watch", str(exc))
            return
        self.address = self.watching = viewer.endpoint
        self.store.clear()
        for cb in (self.store, self.limits, self._on_block):
            viewer.subscribe(cb)
        viewer.add_link_listener(lambda s, m: self.sig_link_state.emit(s, m))
        viewer.add_command_listener(self._on_command_done)
        viewer.add_remote_listener(lambda s, m: self.sig_event.emit(
            "INFO" if s == "up" else "WARNING", "commander", f"the commanding station's link "
            f"{s}" + (f": {m}" if m else "")))
        self.client = viewer
        self.sig_source.emit("watch", viewer.endpoint)

        def start() -> None:
            try:
                viewer.start().wait_up(timeout=10.0)
            except GroundStationError as exc:     # keeps listening: up when one publishes
                self.sig_event.emit("WARNING", "watch", str(exc))
                return
            device = (viewer.device or {}).get("address", "?")
            self.sig_event.emit("INFO", "watch", f"watching {viewer.endpoint} read-only: "
                                                 f"device {device}")
        self._worker(start, "gs-watch")

    def start_publishing(self, endpoint: str, curve_keys: str | None = None) -> bool:
        """Publish what this window's device link receives (now and after reconnects)."""
        from ...fanout.publisher import Publisher

        try:
            self.publisher = Publisher(endpoint, curve_keys=curve_keys)
        except GroundStationError as exc:
            self.sig_event.emit("ERROR", "publish", str(exc))
            return False
        if self.client is not None and self.watching is None:
            self.publisher.attach(self.client, self.address)
        self.sig_event.emit("INFO", "publish", f"publishing on {self.publisher.endpoint}: "
                                               f"groundstation gui --watch {self.publisher.endpoint}")
        return True
