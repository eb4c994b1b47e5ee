"""The device client: session, verified commands, heartbeat, telemetry fan-out.

Threads: one reader per link (the command stream; the UDP telemetry socket when there
is one) and a heartbeat thread while a session is open.  Telemetry blocks go to the
link statistics and then to every subscriber, in the reader thread: subscribers must be
quick (the recorder and GUI put blocks on their own queues).  Commands are sent from
the caller's thread and wait for their verification stages (SPEC.md, "Commands").
"""

from __future__ import annotations

import ipaddress
import logging
import random
import re
import threading
import time
from collections import deque
from dataclasses import dataclass, field
from datetime import datetime
from typing import Any, Callable, Iterable

from ..core.callbacks import Callbacks, TelemetryOutlet
from ..core.kinds import LinkState
from ..codec import DatagramDecoder, FrameCodec, StreamDeframer, TelemetryBlock
from ..codec.frames import decode_items, encode_items
from ..core.dictionary import Dictionary
from ..core.errors import (CommandArgumentError, CommandFailed, CommandRejected, CommandTimeout,
                           DictionaryMismatchError, EncodeError, GroundStationError, LinkLostError,
                           NotConnectedError, ProtocolVersionError, SessionEndedError)
from .intake import TelemetryIntake
from .stats import LinkStatistics
from .transports import StreamTransport, UdpReceiver

log = logging.getLogger(__name__)

#: a device on this machine that is still there (DeviceClient.device_gone) is waited
#: for this long before a command counts as unanswered: the hung-child criterion of the
#: fast simulator's own control channel (sim/stepped_process.REPLY_TIMEOUT_S)
LOCAL_DEVICE_PATIENCE_S = 30.0
#: resends to such a device grow from the dictionary's accept timeout to at most this
LOCAL_RETRY_MAX_S = 2.0

STAGES = {1: "ACCEPTED", 2: "REJECTED", 3: "COMPLETED", 4: "FAILED"}


@dataclass
class StageRecord:
    stage: str            # SENT, RETRY, ACCEPTED, REJECTED, COMPLETED, FAILED, TIMEOUT
    reason: str = "OK"
    host_time: float = 0.0
    device_tick: int | None = None


@dataclass
class CommandResult:
    name: str
    sequence: int
    arguments: dict[str, Any]
    stages: list[StageRecord] = field(default_factory=list)
    reply: dict[str, Any] = field(default_factory=dict)
    retries: int = 0

    @property
    def final_stage(self) -> str:
        return self.stages[-1].stage if self.stages else "UNSENT"

class _Pending:
    def __init__(self, result: CommandResult):
        self.result = result
        self.answered = threading.Event()   # ACCEPTED or REJECTED seen
        self.finished = threading.Event()   # COMPLETED, FAILED or REJECTED seen
        self.reply_bytes = b""
        self.last_send = 0.0               # host time of the last send (the link's clock)
        self.sent_at = 0.0                 # monotonic time of the last send (its timeout)
        self.error: Exception | None = None
        self.on_stage: Callable[[StageRecord], None] | None = None


class DeviceClient(TelemetryOutlet):
    """Talks to one device (the rig's controller or the simulated testbed).

    Link listeners hear 'up', 'lost', 'closed', or 'ended' (the device ended this host's
    session: another host took it over; the message says who and when)."""

    def __init__(self, dictionary: Dictionary, command_link: StreamTransport,
                 telemetry: UdpReceiver | None = None, *, heartbeat: bool = True):
        self.dictionary = dictionary
        self.codec = FrameCodec(dictionary)
        self.command_link = command_link
        self.telemetry = telemetry
        self.stats = LinkStatistics(dictionary.control_rate_hz)
        self._stream = StreamDeframer(self.codec)
        self.stats.add_framing_source(self._stream.counters)
        self._datagrams = DatagramDecoder(self.codec) if telemetry is not None else None
        if self._datagrams is not None:
            self.stats.add_framing_source(self._datagrams.counters)
        # telemetry only from the device at the other end of the command link (SPEC §1.1)
        self.intake = TelemetryIntake(dictionary, getattr(command_link, "peer", None)
                                      if telemetry is not None else None)
        self.stats.add_framing_source(self.intake.counters)
        super().__init__("telemetry", log)
        self._command_listeners = Callbacks("command listener", log)
        #: called with the bytes as received (fanout/publisher.py), on the reader thread
        self._raw_taps: list[Callable[[str, list[bytes], list[float]], None]] = []
        self._pending: dict[int, _Pending] = {}
        self._lock = threading.Lock()
        self._send_lock = threading.Lock()
        self._sequence = random.SystemRandom().randrange(1, 1 << 32)
        self._stop = threading.Event()
        self._threads: list[threading.Thread] = []
        self._heartbeat_enabled = heartbeat
        self._heartbeat_thread: threading.Thread | None = None
        self._session_stop = threading.Event()
        self._draining = threading.Event()
        self._drained = threading.Event()
        #: the quiet time that ends the drain at close: a datagram sent before the
        #: DISCONNECT's answer may still be on the wire behind it.  On loopback the
        #: kernel usually queues it within the sender's call, but on a busy machine it
        #: may hand a burst's rest to its softirq thread, which waits for a core like
        #: any other: 20 ms covers that, at a fifth of a network's 0.1 s
        self.drain_quiet_s = 0.02 if _on_loopback(getattr(command_link, "peer", None)) else 0.1
        self.session_token: int | None = None
        self.device_info: dict[str, Any] = {}
        self.link_state = LinkState.CLOSED
        self.link_error: str = ""
        #: how long the telemetry reader lets datagrams gather after waking (UdpReceiver.receive):
        #: 10 ms batches a 1200 Hz stream 12 frames at a time, at no cost in latency
        #: (arrival times are the kernel's) and a tenth of the per-wake-up interpreter time.
        self.telemetry_batch_s = 0.010
        #: Set by whoever started the device on this machine and watches it (the
        #: simulated testbed: its process or its threads): returns why the device can no
        #: longer answer, "" while it runs.  With it, an unanswered command is not given up
        #: after the dictionary's retries - those stand for a device that lost the frame or
        #: died, and a local device neither loses frames (TCP on loopback) nor dies unseen;
        #: a late answer there means a busy machine (a starved child on 2 cores at load 10
        #: took over a second).  It is resent at growing intervals and given up only when
        #: the device is gone or LOCAL_DEVICE_PATIENCE_S have passed (hung).
        self.device_gone: Callable[[], str] | None = None
        self.heartbeat_failures = 0
        self.unmatched_responses = 0

    # ------------------------------------------------------------------ plumbing
    def remove_command_listener(self, callback: Callable[[CommandResult], None]) -> None:
        self._command_listeners.remove(callback)

    def add_command_listener(self, callback: Callable[["CommandResult"], None]) -> None:
        """Call `callback(result)` when any command ends (completed, refused, failed or
        timed out), e.g. to journal it in the log."""
        self._command_listeners.add(callback)

    def add_raw_tap(self, callback: Callable[[str, list[bytes], list[float]], None]) -> None:
        """Call `callback(path, chunks, times)` with the device's telemetry as received, on
        the reader thread: each chunk is a UDP datagram from the device (path 'datagram')
        or, on a stream link, the frames of one decoded block (path 'stream'; RESPONSE
        frames are never tapped: the CONNECT answer holds the session token).  The
        callback must not block; an exception is logged and the link goes on."""
        self._raw_taps.append(callback)

    def remove_raw_tap(self, callback: Callable[[str, list[bytes], list[float]], None]) -> None:
        if callback in self._raw_taps:
            self._raw_taps.remove(callback)

    def _tap(self, path: str, chunks: list[bytes], times: list[float]) -> None:
        for cb in list(self._raw_taps):
            try:
                cb(path, chunks, times)
            except Exception:
                log.exception("raw telemetry tap %r failed", cb)

    def _tap_stream(self, blocks: list[TelemetryBlock]) -> None:
        """A stream's telemetry frames, one chunk per block, as they were received."""
        chunks, times = [], []
        allowed = self.intake.allowed["stream"]       # the intake counts the others
        for b in blocks:
            if b.name == "RESPONSE" or b.name not in allowed or not len(b):
                continue
            chunks.append(b.raw.tobytes() if b.raw is not None else b"".join(b.frames))
            times.append(float(b.host_time[0]))
        if chunks:
            self._tap("stream", chunks, times)

    def start(self) -> None:
        """Start the reader threads (no I/O before this)."""
        if self._threads:
            return
        self._set_state(LinkState.UP, "")
        self._threads.append(threading.Thread(target=self._read_stream, name="gs-cmd-reader",
                                              daemon=True))
        if self.telemetry is not None:
            self._threads.append(threading.Thread(target=self._read_datagrams,
                                                  name="gs-udp-reader", daemon=True))
        for t in self._threads:
            t.start()

    def _set_state(self, state: str, message: str) -> None:
        self.link_state = state
        self.link_error = message
        self._link_listeners(state, message)

    def _dispatch(self, blocks: list[TelemetryBlock], path: str) -> None:
        for block in self.intake.blocks(blocks, path):
            self.stats.update(block)
            if block.name == "RESPONSE":
                self._on_responses(block)
                continue
            if block.name == "EVENT":
                for level, code, text in zip(block["level"], block["code"], block["text"]):
                    log.info("device event %s %s: %s", level, self.dictionary.event_name(int(code)), text)
            self._subscribers(block)

    def _read_stream(self) -> None:
        while not self._stop.is_set():
            try:
                data = self.command_link.read(0.1)
            except LinkLostError as exc:
                if not self._stop.is_set():
                    self._lost(str(exc))
                return
            if data:
                blocks = self._stream.feed(data, time.time())
                if self._raw_taps:
                    self._tap_stream(blocks)
                self._dispatch(blocks, "stream")

    def _read_datagrams(self) -> None:
        assert self.telemetry is not None and self._datagrams is not None
        while not self._stop.is_set():
            draining = self._draining.is_set()    # then until quiet (drain_quiet_s)
            try:
                datagrams, times, sources = self.telemetry.receive_from(
                    self.drain_quiet_s if draining else 0.1,
                    coalesce_s=0.0 if draining else self.telemetry_batch_s)
            except LinkLostError as exc:
                if not self._stop.is_set():
                    self._lost(str(exc))
                return
            datagrams, times = self.intake.datagrams(datagrams, times, sources)
            if datagrams and self._raw_taps:
                self._tap("datagram", datagrams, times)
            if datagrams:
                self._dispatch(self._datagrams.decode(datagrams, times), "datagram")
            elif draining:
                self._drained.set()         # nothing left in the socket after the session ended

    def _lost(self, message: str) -> None:
        log.error("link lost: %s", message)
        self._session_stop.set()
        with self._lock:
            pending = list(self._pending.values())
        for p in pending:
            p.error = LinkLostError(message)
            p.answered.set()
            p.finished.set()
        self._set_state(LinkState.LOST, message)

    # ------------------------------------------------------------------ commands
    def _on_responses(self, block: TelemetryBlock) -> None:
        now = time.time()
        for i in range(len(block)):
            seq = int(block["command_sequence"][i])
            stage = STAGES.get(int(block["stage"][i]), f"STAGE_{int(block['stage'][i])}")
            reason = self.dictionary.error_name(int(block["reason"][i]))
            tick = int(block["tick"][i])
            with self._lock:
                p = self._pending.get(seq)
            if p is None or int(block["opcode"][i]) != self.dictionary.command(p.result.name).opcode:
                self.unmatched_responses += 1
                continue
            if any(s.stage == stage for s in p.result.stages):
                continue                     # a re-sent answer to a retried command
            record = StageRecord(stage, reason, now, tick)
            p.result.stages.append(record)
            self._notify(p.on_stage, record)
            if stage in ("ACCEPTED", "REJECTED"):
                self.stats.clock.observe(p.last_send, now, tick)
                p.answered.set()
            if stage in ("COMPLETED", "FAILED", "REJECTED"):
                p.reply_bytes = block["data"][i]
                p.finished.set()

    def command(self, name: str, *, on_stage: Callable[[StageRecord], None] | None = None,
                **arguments: Any) -> CommandResult:
        """Send a command and wait until it is COMPLETED; raise on REJECTED/FAILED/timeout.

        Arguments are checked against commands.toml before anything is sent.  An
        unanswered command is resent with the same sequence number (the device
        executes it at most once)."""
        return self._await(self._send_new(name, on_stage, arguments))

    def commands(self, calls: Iterable[tuple[str, dict[str, Any]]], *,
                 window: int = 16) -> list[CommandResult]:
        """Commands pipelined: up to `window` are sent before the oldest one's answer is
        waited for, so a transfer of many blocks costs about one round trip per window
        instead of one per block.  Each is then waited for, retried, checked and handed
        to the command listeners in the order given, as command() does.  After a refusal,
        failure or timeout nothing more is sent; the commands already sent are waited
        for, then the first error is raised.  `calls`: (name, arguments) pairs.  The
        window stays well inside the device's memory of answered commands (64, SPEC
        §6.4), so a retry is always recognised as one."""
        window = max(1, min(int(window), 32))
        sent: deque[tuple] = deque()
        results: list[CommandResult] = []
        error: BaseException | None = None
        todo = iter(calls)
        try:
            while True:
                while error is None and len(sent) < window:
                    call = next(todo, None)
                    if call is None:
                        break
                    try:
                        sent.append(self._send_new(call[0], None, dict(call[1])))
                    except GroundStationError as exc:
                        error = exc
                if not sent:
                    break
                try:
                    results.append(self._await(sent.popleft()))
                except GroundStationError as exc:
                    error = error or exc
        finally:
            while sent:                  # interrupted: forget what will not be waited for
                self._finished(sent.popleft()[1])
        if error is not None:
            raise error
        return results

    def _send_new(self, name: str, on_stage: Callable[[StageRecord], None] | None,
                  arguments: dict[str, Any]) -> tuple:
        """Check, encode and send a new command once; what _await() needs to follow it."""
        cmd = self.dictionary.command(name)
        if cmd.needs_session and self.session_token is None:
            raise NotConnectedError(f"{name}: no session - connect first")
        # after the device ended our session the link still carries the commands anyone
        # may send (ABORT, GET_INFO, CONNECT to take the session back)
        usable = self.link_state == LinkState.UP or (self.link_state == LinkState.ENDED and not cmd.needs_session)
        if not usable:
            raise LinkLostError(f"{name}: link is {self.link_state}"
                                + (f" ({self.link_error})" if self.link_error else ""))
        try:
            args = encode_items(cmd.args, arguments, name)
        except EncodeError as exc:
            raise CommandArgumentError(str(exc)) from None
        token = self.session_token or 0
        with self._lock:
            seq = self._sequence
            self._sequence = (self._sequence + 1) & 0xFFFFFFFF or 1
        payload = token.to_bytes(4, "big") + cmd.opcode.to_bytes(2, "big") + args
        frame = self.codec.frame(self.dictionary.packet("COMMAND").id, payload, seq, 0)
        result = CommandResult(name, seq, dict(arguments))
        p = _Pending(result)
        p.on_stage = on_stage
        with self._lock:
            self._pending[seq] = p
        try:
            self._transmit(p, frame, "SENT")
        except BaseException:
            self._finished(p)
            raise
        return cmd, p, frame, token

    def _transmit(self, p: _Pending, frame: bytes, stage_name: str) -> None:
        p.last_send = time.time()
        p.sent_at = time.monotonic()
        stage = StageRecord(stage_name, "OK", p.last_send)
        p.result.stages.append(stage)
        self._notify(p.on_stage, stage)
        with self._send_lock:
            self.command_link.write(frame)

    def _finished(self, p: _Pending) -> None:
        """The command is no longer followed: forget it, tell the listeners."""
        with self._lock:
            self._pending.pop(p.result.sequence, None)
        self._command_listeners(p.result)

    def _await(self, sent: tuple) -> CommandResult:
        """Wait for a sent command's answer (resending it unanswered) and its end."""
        cmd, p, frame, token = sent
        result = p.result
        name, seq, on_stage = result.name, result.sequence, p.on_stage
        defaults = self.dictionary.command_defaults
        accept_timeout = float(defaults["accept_timeout_s"])
        first_sent = p.sent_at
        interval = accept_timeout
        try:
            while not p.answered.wait(max(0.0, p.sent_at + interval - time.monotonic())):
                if result.retries >= int(defaults["retries"]) and self._patient(first_sent):
                    interval = min(2.0 * interval, LOCAL_RETRY_MAX_S)
                elif result.retries >= int(defaults["retries"]):
                    result.stages.append(StageRecord("TIMEOUT", "NO_ANSWER", time.time()))
                    self._notify(on_stage, result.stages[-1])
                    versions = [e for e in self.stats.recent_errors()
                                if isinstance(e, ProtocolVersionError)]
                    if versions:       # the device answers, but in another protocol version
                        theirs = getattr(versions[-1], "version", "?")
                        ours = self.dictionary.version_major
                        advice = ("update the ground station" if isinstance(theirs, int) and theirs > ours
                                  else "update the firmware, or use the protocol/*.toml it was "
                                       "built with (--protocol-dir)")
                        raise DictionaryMismatchError(
                            f"{name}: protocol version mismatch - the device answers in protocol "
                            f"version {theirs}, this ground station speaks version {self.dictionary.version} "
                            f"(dictionary hash {self.dictionary.hash:08x}); frames of the other "
                            f"version cannot be read - {advice}", "DICTIONARY_MISMATCH")
                    gone = self.device_gone() if self.device_gone is not None else ""
                    raise CommandTimeout(
                        f"{name} (seq {seq}): no answer from the device after {result.retries} "
                        f"retries" + (f" in {time.monotonic() - first_sent:.0f} s - the device "
                                      f"{'is gone: ' + gone if gone else 'hangs'}"
                                      if self.device_gone is not None else
                                      f" of {accept_timeout} s - is the link up?"))
                result.retries += 1
                self._transmit(p, frame, "RETRY")
            started = time.monotonic()
            completed = p.finished.wait(cmd.timeout_s)
            while not completed and self._patient(started):
                completed = p.finished.wait(cmd.timeout_s)
            if not completed:
                result.stages.append(StageRecord("TIMEOUT", "NOT_COMPLETED", time.time()))
                self._notify(on_stage, result.stages[-1])
                raise CommandTimeout(f"{name} (seq {seq}): accepted but not completed "
                                     f"within {cmd.timeout_s} s")
            if p.error is not None:
                raise p.error
            last = result.stages[-1]
            if last.stage == "REJECTED":
                if (last.reason == "NOT_SESSION_OWNER" and cmd.needs_session and token
                        and token == self.session_token):
                    raise self._session_taken(name, p.reply_bytes)
                raise self._rejection(cmd.name, seq, last.reason, p.reply_bytes)
            if last.stage == "FAILED":
                raise CommandFailed(f"{name} (seq {seq}) failed on the device: {last.reason}",
                                    last.reason)
            if cmd.reply:
                result.reply = decode_items(cmd.reply, p.reply_bytes, f"{name} reply")
            return result
        finally:
            self._finished(p)

    def _patient(self, since: float) -> bool:
        """Wait longer than the dictionary says for an answer: the device runs on this
        machine, is still there, and has not yet been silent for LOCAL_DEVICE_PATIENCE_S."""
        if self.device_gone is None or self.link_state not in (LinkState.UP, LinkState.ENDED):
            return False
        return not self.device_gone() and time.monotonic() - since < LOCAL_DEVICE_PATIENCE_S

    def _session_taken(self, name: str, data: bytes) -> SessionEndedError:
        """Our token stopped working: another host took the session over (SPEC §7).  The
        rejection's data names the new owner and the tick its session began."""
        text = data.decode("utf-8", "replace").strip()
        match = re.fullmatch(r"owner (\S+) since tick (\d+)", text)
        if match:
            who, tick = match.group(1), int(match.group(2))
            offset = self.stats.clock.offset
            when = (datetime.fromtimestamp(tick / self.dictionary.control_rate_hz + offset)
                    .strftime("%H:%M:%S") if offset is not None else "?")
            what = f"taken over by {who} at {when} (device tick {tick})"
        elif text == "no session open":
            what = "closed on the device (no session open any more)"
        else:
            what = f"ended by the device ({text or 'no details given'})"
        message = (f"session {what}: this station no longer controls the rig; connect with "
                   f"take-over to take it back")
        self.session_token = None
        self._session_stop.set()
        if self.link_state == LinkState.UP:
            log.error("%s", message)
            self._set_state(LinkState.ENDED, message)
        return SessionEndedError(f"{name}: {message}", "NOT_SESSION_OWNER", data)

    def _rejection(self, name: str, seq: int, reason: str, data: bytes) -> CommandRejected:
        if reason == "DICTIONARY_MISMATCH" and name == "CONNECT":
            dev = {}
            try:
                dev = decode_items(self.dictionary.command("CONNECT").reply, data, "CONNECT reply")
            except GroundStationError:
                pass
            return DictionaryMismatchError(
                f"protocol dictionary mismatch: ground station speaks protocol "
                f"{self.dictionary.version} (dictionary hash {self.dictionary.hash:08x}), the "
                f"firmware speaks {dev.get('protocol_major', '?')}.{dev.get('protocol_minor', '?')} "
                f"(hash {dev.get('dictionary_hash', 0):08x}) - use the protocol/*.toml the "
                f"firmware was built with", reason, data)
        return CommandRejected(f"{name} (seq {seq}) rejected by the device: {reason}", reason, data)

    @staticmethod
    def _notify(cb, stage: StageRecord) -> None:
        """Report a stage as it happens (caller's thread for SENT/RETRY/TIMEOUT, the
        reader thread for the device's stages); a failing callback is only logged."""
        if cb is not None:
            try:
                cb(stage)
            except Exception:
                log.exception("command stage callback failed")

    # ------------------------------------------------------------------ session
    def connect(self, take_over: bool = False) -> CommandResult:
        """Open a session: version/dictionary check, token, telemetry port, heartbeat."""
        self.start()
        result = self.command(
            "CONNECT", protocol_major=self.dictionary.version_major,
            protocol_minor=self.dictionary.version_minor,
            dictionary_hash=self.dictionary.hash,
            telemetry_port=self.telemetry.port if self.telemetry is not None else 0,
            take_over=int(take_over))
        self.session_token = int(result.reply["session_token"])
        self.device_info = dict(result.reply)
        if self._heartbeat_enabled:
            self._session_stop.clear()
            self._heartbeat_thread = threading.Thread(target=self._heartbeat, name="gs-heartbeat",
                                                      daemon=True)
            self._heartbeat_thread.start()
        return result

    def _heartbeat(self) -> None:
        period = float(self.dictionary.command_defaults["heartbeat_period_s"])
        while not self._session_stop.wait(period):
            try:
                self.command("HEARTBEAT")
                self.heartbeat_failures = 0
            except NotConnectedError:
                return
            except GroundStationError as exc:
                self.heartbeat_failures += 1
                log.warning("heartbeat failed (%d in a row): %s", self.heartbeat_failures, exc)
                if self.link_state != LinkState.UP:
                    return

    def disconnect(self) -> None:
        """End the session cleanly (the device disarms)."""
        self._session_stop.set()
        if self._heartbeat_thread is not None:
            self._heartbeat_thread.join(timeout=2.0)
            self._heartbeat_thread = None
        if self.session_token is not None and self.link_state == LinkState.UP:
            try:
                self.command("DISCONNECT")
            finally:
                self.session_token = None
        self.session_token = None

    def abort(self) -> CommandResult:
        """ABORT: accepted from anyone, in every state."""
        return self.command("ABORT")

    def close(self) -> None:
        """Disconnect if needed and stop all threads; safe to call twice."""
        try:
            if self.session_token is not None and self.link_state == LinkState.UP:
                self.disconnect()
        except GroundStationError as exc:
            log.warning("disconnect on close failed: %s", exc)
        self._session_stop.set()
        if self.telemetry is not None and self._threads and self.link_state == LinkState.UP:
            # the device stopped its telemetry at DISCONNECT; what it sent before is still
            # in the socket: let the reader hand it on before the socket closes
            self._draining.set()
            self.telemetry.wake()           # a reader waiting for more stops waiting
            self._drained.wait(0.5)
        self._stop.set()
        self.command_link.close()
        if self.telemetry is not None:
            self.telemetry.close()
        for t in self._threads:
            t.join(timeout=2.0)
        self._threads.clear()
        if self.link_state not in (LinkState.LOST, LinkState.ENDED):     # keep the reason it ended
            self._set_state(LinkState.CLOSED, "")

    def __enter__(self) -> "DeviceClient":
        return self

    def __exit__(self, *exc) -> None:
        self.close()


def _on_loopback(peer) -> bool:
    try:
        return peer is not None and ipaddress.ip_address(peer[0]).is_loopback
    except ValueError:
        return False
