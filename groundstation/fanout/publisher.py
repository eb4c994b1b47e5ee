"""The commander's side: what its device link receives, published on a PUB socket.

The device link calls the publisher on its receiving thread with the bytes exactly as
received (DeviceClient.add_raw_tap), so a publish must cost next to nothing and must
never block or raise into the link:

* sends are non-blocking (zmq.NOBLOCK) and a PUB socket drops a slow subscriber's
  messages, whole, once its queue holds SNDHWM messages; the device link and the other
  viewers never wait for it.  The viewer sees the hole in the message sequence;
* every send is guarded: an error is counted and logged once, never raised;
* one lock serialises the threads that publish (telemetry reader, command threads, the
  hello timer), since a ZeroMQ socket is not thread-safe; a send takes microseconds.

Besides the frames, the publisher sends the commander's command journal (each command
with its stages, as the recorder journals it; HEARTBEATs left out), its link state
changes, and twice a second a hello: the device's address and transport (so a viewer
can send ABORT straight to the device, SPEC §7), the protocol and dictionary hash, and
the commander's link health.  The session token is never published.
"""

from __future__ import annotations

import logging
import os
import threading
import time
from dataclasses import asdict
from typing import Any, Callable

from ..core.contracts import DeviceLink
from ..core.kinds import SIMULATED_DEVICE
from . import wire
from .endpoints import FanoutError, check_bind

log = logging.getLogger(__name__)

#: messages queued per viewer before the PUB socket drops that viewer's messages: 100
#: frames messages a second at 1200 Hz (10 ms batches), so ~10 s of a steady stream
SNDHWM = 1000
HELLO_PERIOD_S = 0.5
UNPUBLISHED_COMMANDS = {"HEARTBEAT"}


def device_description(client: DeviceLink, address: str = "") -> dict[str, Any]:
    """The device as a viewer needs it for ABORT: kind (tcp or serial), host and port."""
    from ..link.address import parse_address

    if address and address != SIMULATED_DEVICE:
        try:
            addr = parse_address(address)
        except Exception:           # a name only the commander understands: use the peer
            addr = None
        if addr is not None and addr.kind == "serial":
            return {"kind": "serial", "port": addr.serial_port, "address": str(addr)}
        if addr is not None:
            return {"kind": "tcp", "host": addr.host, "port": addr.port, "address": str(addr)}
    peer = getattr(getattr(client, "command_link", None), "peer", None)
    if peer:
        return {"kind": "tcp", "host": peer[0], "port": int(peer[1]),
                "address": f"tcp://{peer[0]}:{peer[1]}"}
    return {"kind": "serial", "port": getattr(getattr(client, "command_link", None), "name", "?"),
            "address": address or "serial"}


class Publisher:
    """One PUB socket; attach() it to the commander's device link."""

    def __init__(self, endpoint: str, *, curve_keys: str | None = None, sndhwm: int = SNDHWM,
                 hello_period_s: float = HELLO_PERIOD_S, sndbuf: int | None = None):
        """`sndhwm`: messages queued per viewer before its messages are dropped; `sndbuf`:
        the kernel's send buffer per viewer connection in bytes (None: the system's; the
        tests shrink it so that a stalled viewer's drops begin within a second)."""
        import zmq

        check_bind(endpoint, curve_keys is not None)
        self._zmq = zmq
        self._ctx = zmq.Context()
        self._sock = self._ctx.socket(zmq.PUB)
        self._sock.sndhwm = sndhwm
        self._sock.linger = 0
        if sndbuf is not None:
            self._sock.sndbuf = sndbuf
        self._auth = None
        try:
            if curve_keys is not None:
                from .keys import secure_publisher
                self._auth = secure_publisher(self._ctx, self._sock, curve_keys)
            self._sock.bind(endpoint)
        except zmq.ZMQError as exc:
            self._close_socket()
            raise FanoutError(f"cannot publish on {endpoint}: {exc} - is another station "
                              f"publishing there? choose another port") from None
        except BaseException:
            self._close_socket()
            raise
        #: the bound endpoint (tcp://127.0.0.1:PORT when the port was "*")
        self.endpoint = self._sock.last_endpoint.decode()
        self.instance = os.urandom(4).hex()
        self.sent = 0
        self.send_errors = 0
        self.bytes_sent = 0
        self._seq = 0
        self._lock = threading.Lock()
        self._client = None
        self._device: dict[str, Any] = {}
        self._dictionary = None
        self._detach: Callable[[], None] | None = None
        self._stop = threading.Event()
        self._hello_period = hello_period_s
        self._hello = threading.Thread(target=self._hello_loop, name="gs-fanout-hello",
                                       daemon=True)
        self._hello.start()

    # ------------------------------------------------------------------ feeding
    def attach(self, client: DeviceLink, address: str = "") -> None:
        """Publish what `client` (a DeviceClient) receives, its commands and link states;
        `address` is the device address the commander opened (told to viewers for
        ABORT).  A later attach (a reconnect's new client) replaces the earlier one."""
        self.detach()
        self._client, self._dictionary = client, client.dictionary
        self._device = device_description(client, address)

        def on_link(state: str, message: str) -> None:
            # a link closed as asked has no error text: viewers print what they get
            self._send_json(wire.TOPIC_LINK, {"state": state, "message": message or
                                              f"the commanding station's device link is {state}"})

        client.add_raw_tap(self.publish_frames)
        client.add_command_listener(self.publish_command)
        client.add_link_listener(on_link)

        def detach() -> None:
            client.remove_raw_tap(self.publish_frames)
            client.remove_command_listener(self.publish_command)
            client.remove_link_listener(on_link)
        self._detach = detach
        self._send_json(wire.TOPIC_LINK, {"state": client.link_state, "message": client.link_error})

    def detach(self) -> None:
        detach, self._detach = self._detach, None
        if detach is not None:
            detach()
        self._client = None

    def publish_frames(self, path: str, chunks: list[bytes], times: list[float]) -> None:
        """The device link's raw tap (its receiving thread): never blocks, never raises."""
        if not chunks:
            return
        try:
            with self._lock:
                self._send(wire.frames_message(self._seq, chunks, times))
        except Exception:                 # building the message failed: a bug, not the link's
            self._failed()

    def publish_command(self, result) -> None:
        if result.name in UNPUBLISHED_COMMANDS:
            return
        record = asdict(result)
        record["final_stage"] = result.final_stage
        self._send_json(wire.TOPIC_COMMAND, record)

    # ------------------------------------------------------------------ sending
    def _send_json(self, topic: bytes, record: Any) -> None:
        try:
            with self._lock:
                self._send(wire.json_message(topic, self._seq, time.time(), record))
        except Exception:
            self._failed()

    def _send(self, parts: list[bytes]) -> None:
        """Under the lock.  PUB drops at the high-water mark rather than block; NOBLOCK
        keeps even an unforeseen blocking case from reaching the link's thread."""
        if self._stop.is_set():
            return
        self._seq += 1                  # a sequence number is used once, sent or not
        try:
            self._sock.send_multipart(parts, flags=self._zmq.NOBLOCK)
        except self._zmq.ZMQError:
            self._failed()
            return
        self.sent += 1
        self.bytes_sent += sum(len(p) for p in parts)

    def _failed(self) -> None:
        self.send_errors += 1
        if self.send_errors == 1:
            log.exception("publishing on %s failed (counted, not raised; later failures "
                          "are only counted)", self.endpoint)

    def hello(self) -> dict[str, Any]:
        """What viewers learn twice a second: the device, the protocol, the link's health."""
        client, d = self._client, self._dictionary
        record: dict[str, Any] = {"publisher": self.endpoint, "instance": self.instance,
                                  "device": self._device, "sent": self.sent,
                                  "send_errors": self.send_errors}
        if d is not None:
            record.update(protocol=d.version, dictionary_hash=f"{d.hash:08x}")
        if client is not None:
            from ..link.stats import format_snapshot
            snap = client.stats.snapshot()
            record.update(link_state=client.link_state, link_error=client.link_error,
                          health=format_snapshot(snap), dropped=snap.dropped)
        return record

    def _hello_loop(self) -> None:
        while not self._stop.wait(self._hello_period):
            try:
                record = self.hello()
            except Exception:
                self._failed()
                continue
            self._send_json(wire.TOPIC_HELLO, record)

    # ------------------------------------------------------------------ closing
    def close(self) -> None:
        """Stop publishing (the device link goes on); safe to call twice.  Viewers are told
        (best effort: a viewer that misses it says 'lost' after its silence time)."""
        was_attached = self._detach is not None
        self.detach()
        if was_attached and not self._stop.is_set():
            self._send_json(wire.TOPIC_LINK, {"state": "closed", "message":
                                              "the commanding station stopped publishing"})
        self._stop.set()
        if self._hello.is_alive() and self._hello is not threading.current_thread():
            self._hello.join(timeout=2.0)
        with self._lock:
            self._close_socket()

    def _close_socket(self) -> None:
        if not self._sock.closed:
            self._sock.close(linger=0)
        if self._auth is not None:
            self._auth.stop()
            self._auth = None
        if not self._ctx.closed:
            self._ctx.term()

    def __enter__(self) -> "Publisher":
        return self

    def __exit__(self, *exc) -> None:
        self.close()
