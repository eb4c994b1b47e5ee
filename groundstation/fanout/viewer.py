"""`WatchClient`: a read-only console's telemetry source, over a ZeroMQ SUB socket.

It satisfies the TelemetrySource contract as the live DeviceClient and the replay do,
and has the parts of the client that the recorder, `monitor` and the window read
(`stats`, `link_state`, command and link listeners, `command`, `abort`), so they run on
it unchanged.  It decodes the published frames with this console's own dictionary and
DatagramDecoder, exactly as the commander decodes them, and keeps its own LinkStatistics:
its drops are its own (frames missing from the packets' sequence numbers, whatever
lost them: the device link, or this viewer being too slow for the publisher's
high-water mark).  Messages it missed are counted too (`missed_messages`).

Everything it receives is untrusted (on loopback without keys, any local process can
bind the address it watches): wire.parse checks sizes, nesting and each kind's schema
(schema.py); a message failing a check is counted (`bad_messages`) with its reason and
ignored.  A jump of the message sequence beyond MAX_SEQUENCE_GAP is counted as a
resynchronisation (`message_resyncs`), not as missed messages.

It never holds a session token.  `command` refuses everything but ABORT with
ReadOnlyConsole; ABORT goes straight to the device (abort.py).  Link states: 'up' while
valid messages arrive; 'lost' after `silence_s` without a valid one, or after
BAD_IN_A_ROW bad messages in a row (ZeroMQ keeps reconnecting by itself: 'up' again at
the next valid message); 'failed' if the reader thread meets an unexpected error - it
then stops, with the reason in `failure` (never silently); 'closed'.  What the
commander's own link does arrives as 'remote' events (add_remote_listener) and in `hello`.
"""

from __future__ import annotations

import logging
import threading
import time
from collections import deque
from dataclasses import dataclass, field
from typing import Any, Callable

from ..core.callbacks import Callbacks, TelemetryOutlet
from ..core.kinds import LinkState
from ..codec import DatagramDecoder, FrameCodec
from ..link.client import CommandResult, StageRecord
from ..link.intake import TelemetryIntake
from ..link.stats import LinkStatistics
from . import schema, wire
from .abort import send_abort
from .handshake import HandshakeWatch
from .publisher import HELLO_PERIOD_S
from .endpoints import FanoutError, ReadOnlyConsole, parse_endpoint, read_only_message

log = logging.getLogger(__name__)

RCVHWM = 10000
#: bad messages in a row after which the watch is 'lost': the stream no longer makes
#: sense (a genuine publisher sends none; a hello alone comes twice a second)
BAD_IN_A_ROW = 20
#: the largest jump of the message sequence counted as missed messages: ~2.5 h of a
#: publisher's ~110 messages a second.  A viewer misses messages only while it is
#: stalled (the publisher drops them at its high-water mark), never that many; a larger
#: jump (or one backwards: a restarted publisher) is a resynchronisation.
MAX_SEQUENCE_GAP = 1_000_000
#: how long an ABORT asked before the publisher's first hello waits for it: four of the
#: publisher's hello periods (2 s).  After that the console says to press Abort on the
#: commanding station
ABORT_WAITS_FOR_HELLO_S = 4 * HELLO_PERIOD_S
#: messages handled before the reader looks at its clock again, so that a flood of
#: messages cannot keep the watchdog from running
DRAIN_BATCH = 1000


@dataclass
class FanoutCounters:
    """Counted like the deframer's counters, so the link statistics show them."""
    messages: int = 0
    missed_messages: int = 0
    bad_messages: int = 0
    message_resyncs: int = 0
    recent_errors: deque = field(default_factory=lambda: deque(maxlen=16))

    def as_dict(self) -> dict[str, int]:
        return {k: v for k, v in self.__dict__.items() if k != "recent_errors"}


class WatchClient(TelemetryOutlet):
    """Watches a publishing station: see the module docstring."""

    def __init__(self, dictionary, endpoint: str, *, curve_keys: str | None = None,
                 key_name: str = "viewer", rcvhwm: int = RCVHWM, silence_s: float = 3.0,
                 rcvbuf: int | None = None):
        self.dictionary = dictionary
        self.endpoint = parse_endpoint(endpoint, for_bind=False).text
        self.address = self.endpoint
        self.curve_keys, self.key_name = curve_keys, key_name
        self.rcvhwm, self.rcvbuf = rcvhwm, rcvbuf
        self.silence_s = silence_s
        self.session_token = None               # never: a viewer commands nothing
        self.stats = LinkStatistics(dictionary.control_rate_hz)
        self._decoder = DatagramDecoder(FrameCodec(dictionary))
        self.intake = TelemetryIntake(dictionary, None)
        self.counters = FanoutCounters()
        for source in (self._decoder.counters, self.intake.counters, self.counters):
            self.stats.add_framing_source(source)
        self.link_state = LinkState.CLOSED
        self.link_error = ""
        #: the publisher's newest hello (device, protocol, the commander's link health)
        self.hello: dict[str, Any] = {}
        super().__init__("telemetry", log)
        self._command_listeners = Callbacks("command listener", log)
        self._remote_listeners = Callbacks("remote link listener", log)
        self._expected: int | None = None
        self._instance: str | None = None
        self._stop = threading.Event()
        self._thread: threading.Thread | None = None
        self._thread_lock = threading.Lock()     # start() and close() on different threads
        self._last_valid = 0.0
        self._bad_in_a_row = 0
        #: why the reader thread stopped on its own (None while it runs or stopped as asked)
        self.failure: str | None = None
        #: set at the first hello, at a failed handshake and when the reader ends:
        #: wait_up waits on it
        self._wake = threading.Event()
        #: this console's ZeroMQ handshakes with the publisher (handshake.py): why it
        #: hears nothing when a station is there (keys required, key refused ...)
        self.handshake: HandshakeWatch | None = None

    # ------------------------------------------------------------------ contract
    def add_command_listener(self, callback: Callable[[CommandResult], None]) -> None:
        """Hears the commander's commands (from the publisher) and this console's ABORTs."""
        self._command_listeners.add(callback)

    def remove_command_listener(self, callback: Callable[[CommandResult], None]) -> None:
        self._command_listeners.remove(callback)

    def add_remote_listener(self, callback: Callable[[str, str], None]) -> None:
        """`callback(state, message)` when the commander's device link changes state."""
        self._remote_listeners.add(callback)

    @property
    def device(self) -> dict[str, Any] | None:
        return self.hello.get("device")

    # ------------------------------------------------------------------ commands
    def command(self, name: str, *, on_stage=None, **args: Any) -> CommandResult:
        """ABORT goes to the device; anything else is refused, nothing is sent."""
        if name == "ABORT":
            return self.abort()
        raise ReadOnlyConsole(f"{name}: {read_only_message(self.endpoint)}")

    def abort(self) -> CommandResult:
        """ABORT straight to the device.  Asked before the publisher's first hello has
        arrived - it says where the device is, twice a second, and a console that has
        just started watching can already show the rig's telemetry - it waits for that
        hello (at most ABORT_WAITS_FOR_HELLO_S) instead of failing at once."""
        if not self.hello and self._thread is not None and not self.ended:
            self._wake.wait(ABORT_WAITS_FOR_HELLO_S)
        return send_abort(self.dictionary, self.device, self.endpoint,
                          on_result=self._notify_command)

    def connect(self, take_over: bool = False) -> None:
        raise ReadOnlyConsole(f"CONNECT: {read_only_message(self.endpoint)}")

    # ------------------------------------------------------------------ running
    def start(self) -> "WatchClient":
        """Connect the SUB socket and start the reader thread (ZeroMQ connects lazily:
        nothing fails here when no one publishes yet - see wait_up)."""
        if self._thread is not None:
            return self
        import zmq

        ctx = zmq.Context()
        sock = ctx.socket(zmq.SUB)
        sock.rcvhwm = self.rcvhwm
        sock.linger = 0
        # a part larger than this is never buffered: ZeroMQ drops that connection
        sock.maxmsgsize = schema.ZMQ_MAX_PART_BYTES
        if self.rcvbuf is not None:          # the kernel's buffer (tests: a small one)
            sock.rcvbuf = self.rcvbuf
        try:
            if self.curve_keys is not None:
                from .keys import secure_viewer
                secure_viewer(sock, self.curve_keys, self.key_name)
            sock.subscribe(b"")
            # before connect: the first handshake is the one a mismatch fails
            self.handshake = HandshakeWatch(sock, self.endpoint, self.curve_keys, self.key_name)
            sock.connect(self.endpoint)
        except BaseException:
            if self.handshake is not None:
                self.handshake.close()
            sock.close(linger=0)
            ctx.term()
            raise
        self._set_state(LinkState.CONNECTING, self.endpoint)
        reader = threading.Thread(target=self._read, args=(ctx, sock), name="gs-fanout-viewer",
                                  daemon=True)
        # started before it is published: a close() on another thread (the window's
        # disconnect worker) that saw it unstarted failed to join it ("cannot join thread
        # before it is started", a CI run).  A close() that comes before the assignment
        # finds none to join; the reader sees _stop and ends by itself.
        with self._thread_lock:
            reader.start()
            self._thread = reader
        return self

    @property
    def ended(self) -> bool:
        """The reader thread has stopped (closed, or failed: see `failure`)."""
        return self._thread is not None and not self._thread.is_alive()

    def wait_up(self, timeout: float = 5.0) -> "WatchClient":
        """Wait until the publisher's first valid hello (its device address) has arrived."""
        self._wake.wait(timeout)
        if self.failure is not None:
            raise FanoutError(f"stopped watching {self.endpoint}: {self.failure}")
        if not self.hello and self.problem:
            raise FanoutError(self.problem)
        if not self.hello:
            keys = (" with these CURVE keys (is this console's public key in the "
                    "publisher's authorized/ folder?)" if self.curve_keys else "")
            bad = self.counters.bad_messages
            junk = (f" ({bad} message(s) arrived that this console refused, the last: "
                    f"{self.counters.recent_errors[-1]} - is another program bound there?)"
                    if bad and self.counters.recent_errors else "")
            raise FanoutError(f"no station publishes on {self.endpoint}{keys} within "
                              f"{timeout:g} s{junk} - start the commanding station with "
                              f"--publish {self.endpoint}")
        return self

    @property
    def problem(self) -> str:
        """Why the handshakes with the publisher fail, "" when they do not."""
        return self.handshake.problem if self.handshake is not None else ""

    def _read(self, ctx, sock) -> None:
        import zmq

        poller = zmq.Poller()
        poller.register(sock, zmq.POLLIN)
        poller.register(self.handshake.monitor, zmq.POLLIN)
        try:
            while not self._stop.is_set():
                ready = dict(poller.poll(100))
                if ready.get(sock):
                    for _ in range(DRAIN_BATCH):     # what is queued, a bounded number
                        try:
                            parts = sock.recv_multipart(zmq.NOBLOCK)
                        except zmq.Again:
                            break
                        self._on_parts(parts)
                if ready.get(self.handshake.monitor) and self.handshake.drain():
                    self._on_handshake()
                self._watchdog()
        except BaseException as exc:     # noqa: BLE001 - the watch must never end silently
            self._fail(exc)
        finally:
            self.handshake.close()
            sock.close(linger=0)
            ctx.term()
            self._wake.set()

    def _on_handshake(self) -> None:
        """A new handshake failure (or the first success after one): said once, not at
        each of ZeroMQ's reconnects; wait_up need not wait out its timeout for it."""
        if self.problem:
            log.warning("watching %s: %s", self.endpoint, self.problem)
            if self.handshake.certain:
                self._wake.set()
            if self.link_state != LinkState.UP:
                self._set_state(self.link_state, self.problem)

    def _watchdog(self) -> None:
        """'lost' when nothing valid arrived for silence_s (whatever else did)."""
        if self.link_state == LinkState.UP and time.monotonic() - self._last_valid > self.silence_s:
            bad = f" ({self._bad_in_a_row} refused meanwhile)" if self._bad_in_a_row else ""
            why = f": {self.problem}" if self.problem else ""
            self._set_state(LinkState.LOST, f"nothing valid from the publisher at {self.endpoint} for "
                                    f"{self.silence_s:g} s{bad} - still listening{why}")

    def _fail(self, exc: BaseException) -> None:
        """The reader thread stops on an error nothing foresaw: said, never silent."""
        self.failure = f"the reader stopped on {type(exc).__name__}: {str(exc)[:200]}"
        log.error("watching %s: %s", self.endpoint, self.failure)
        log.debug("watching %s: the reader's error", self.endpoint, exc_info=True)
        self._set_state(LinkState.FAILED, f"{self.failure} - this console no longer watches "
                                  f"{self.endpoint}; start it again")

    def _bad(self, reason: str) -> None:
        """A message refused: counted, its reason kept; too many in a row is 'lost'."""
        self.counters.bad_messages += 1
        self.counters.recent_errors.append(FanoutError(f"refused a message: {reason}"))
        self._bad_in_a_row += 1
        if self._bad_in_a_row == BAD_IN_A_ROW and self.link_state in (LinkState.UP, LinkState.CONNECTING):
            self._set_state(LinkState.LOST, f"{BAD_IN_A_ROW} messages in a row from {self.endpoint} "
                                    f"that this console refused (the last: {reason}) - is "
                                    f"another program bound there? still listening")

    def _on_parts(self, parts: list[bytes]) -> None:
        try:
            msg = wire.parse(parts)
        except wire.WireError as exc:
            self._bad(str(exc))
            return
        except Exception as exc:           # noqa: BLE001 - parse should raise WireError only
            log.debug("parsing a fan-out message", exc_info=True)
            self._bad(f"{type(exc).__name__}: {str(exc)[:200]}")
            return
        try:
            if msg.topic == wire.TOPIC_FRAMES:
                self._on_frames(msg)
            elif msg.topic == wire.TOPIC_HELLO:
                self._on_hello(msg.record)
            elif msg.topic == wire.TOPIC_COMMAND:
                self._on_command(msg.record)
            elif msg.topic == wire.TOPIC_LINK:
                self._remote(msg.record["state"], msg.record["message"])
        except Exception as exc:           # noqa: BLE001 - checked, yet not decodable here
            log.debug("handling a %s message", msg.topic.decode(), exc_info=True)
            self._bad(f"a {msg.topic.decode()} message this console could not handle: "
                      f"{type(exc).__name__}: {str(exc)[:200]}")
            return
        self._sequence(msg.sequence)
        self.counters.messages += 1
        self._bad_in_a_row = 0
        self._last_valid = time.monotonic()
        if self.link_state != LinkState.UP:
            self._set_state(LinkState.UP, self.endpoint)

    def _sequence(self, seq: int) -> None:
        """Missed messages from the gaps of the message sequence, within reason."""
        expected, self._expected = self._expected, seq + 1
        if expected is None or seq == expected:
            return
        if expected < seq <= expected + MAX_SEQUENCE_GAP:
            self.counters.missed_messages += seq - expected
            return
        self.counters.message_resyncs += 1
        how = (f"jumped by {seq - expected}, more than the {MAX_SEQUENCE_GAP} a stall can "
               f"miss" if seq > expected else "went back (a restarted publisher?)")
        self.counters.recent_errors.append(FanoutError(
            f"the message sequence {how}: {expected} expected, {seq} received - counted as a "
            f"resynchronisation, not as missed messages"))

    def _on_frames(self, msg: wire.Message) -> None:
        blocks = self.intake.blocks(self._decoder.decode(msg.chunks, msg.times), "stream")
        for block in blocks:
            if block.name == "RESPONSE":
                continue
            self.stats.update(block)
            self._subscribers(block)

    def _on_hello(self, record: dict[str, Any]) -> None:
        first = not self.hello
        if first and record.get("dictionary_hash") not in (None, f"{self.dictionary.hash:08x}"):
            text = (f"the commanding station decodes with dictionary {record['dictionary_hash']}"
                    f", this console with {self.dictionary.hash:08x}: the frames are decoded "
                    f"here with this console's dictionary (logs keep the raw frames)")
            self.counters.recent_errors.append(FanoutError(text))
            log.warning("%s", text)
        if record["instance"] != self._instance and self._instance is not None:
            self._remote("restarted", "the commanding station started publishing again")
        self._instance = record["instance"]
        self.hello = record
        self._wake.set()

    def _on_command(self, record: dict[str, Any]) -> None:
        """`record` as schema.command checked it."""
        stages = [StageRecord(**s) for s in record["stages"]]
        result = CommandResult(record["name"], record["sequence"], record["arguments"], stages,
                               record["reply"], record["retries"])
        self._notify_command(result)

    def _notify_command(self, result: CommandResult) -> None:
        self._command_listeners(result)

    def _remote(self, state: str, message: str) -> None:
        self._remote_listeners(state, message)

    def _set_state(self, state: str, message: str) -> None:
        self.link_state, self.link_error = state, message
        self._link_listeners(state, message)

    def close(self) -> None:
        """Stop watching; safe to call twice."""
        self._stop.set()
        with self._thread_lock:
            reader, self._thread = self._thread, None
        if reader is not None:
            reader.join(timeout=2.0)
        if self.link_state != LinkState.CLOSED:
            self._set_state(LinkState.CLOSED, "this console stopped watching")

    def __enter__(self) -> "WatchClient":
        return self.start()

    def __exit__(self, *exc) -> None:
        self.close()
