"""A raw host connection to a device: our own frames out, every frame in, judged.

Not the ground station's DeviceClient: that one retries, checks ranges, hides framing
errors and keeps one session.  A Host here sends exactly the COMMAND frames it is told
to (bad ones included), keeps every frame the device sends (in arrival order, with the
path it came by) and counts what fails SPEC §2/§4 instead of dropping it silently.
"""

from __future__ import annotations

import random
import threading
import time
from dataclasses import dataclass, field
from typing import Any, Callable

import numpy as np

from ..codec.frames import decode_items
from ..core.dictionary import Dictionary
from ..core.errors import LinkError, LinkLostError
from ..link.address import DeviceAddress
from ..link.transports import SerialStream, TcpStream, UdpReceiver
from .frames import FrameJudge, FramingReport, RawFrame, command_frame

STAGE_NAMES = {1: "ACCEPTED", 2: "REJECTED", 3: "COMPLETED", 4: "FAILED"}


class NoAnswer(LinkError):
    """The device did not answer a command within the time the SPEC allows."""


@dataclass
class Stage:
    stage: int
    reason: int
    data: bytes
    tick: int
    arrival: int

    @property
    def name(self) -> str:
        return STAGE_NAMES.get(self.stage, f"stage {self.stage}")


@dataclass
class Exchange:
    """One COMMAND and the RESPONSE stages that came back for it."""

    name: str
    sequence: int
    frame: bytes
    stages: list[Stage] = field(default_factory=list)

    @property
    def final(self) -> Stage | None:
        return self.stages[-1] if self.stages else None

    def outcome(self, errors: dict[int, str]) -> str:
        """'ACCEPTED, COMPLETED' or 'REJECTED OUT_OF_RANGE' - for evidence lines."""
        return ", ".join(s.name + (f" {errors.get(s.reason, s.reason)}" if s.reason else "")
                         for s in self.stages) or "no answer"


def pack_arguments(items, values: dict[str, Any]) -> bytes:
    """Pack argument values as §3 says, without any range check (the device must do it)."""
    out = bytearray()
    for item in items:
        value = values[item.name]
        if item.is_variable:
            out += value.encode() if isinstance(value, str) else bytes(value)
            continue
        dt = item.wire_dtype.newbyteorder(">")
        if item.has_conversion:
            value = item.to_raw(value)
        out += np.asarray(value).astype(dt).tobytes()
    return bytes(out)


class Host:
    """One host's connection: command stream, telemetry (UDP, or on the stream)."""

    def __init__(self, dictionary: Dictionary, address: DeviceAddress, *, udp: bool = True,
                 counter: "_Counter | None" = None):
        self.d = dictionary
        self.address = address
        self.report = FramingReport()
        limits = {}
        for p in dictionary.packets:
            fixed = p.fixed_payload_size
            limits[p.id] = (fixed, dictionary.max_payload if p.variable_item else fixed)
        self._judge_stream = FrameJudge(dictionary.version_major, limits, self.report)
        self._judge_udp = FrameJudge(dictionary.version_major, limits, self.report)
        self.frames: list[RawFrame] = []
        self.foreign_datagrams = 0
        self.datagram_sources: set[tuple[str, int]] = set()
        self._cond = threading.Condition()
        self._arrivals = counter or _Counter()
        self._stop = threading.Event()
        self._sequence = random.SystemRandom().randrange(1, 1 << 32)
        self.token = 0
        self.lost = ""
        self._heartbeat_paused = threading.Event()
        self._heartbeat_lock = threading.Lock()      # a pause and a heartbeat exclude
        self._send_lock = threading.Lock()
        self.udp: UdpReceiver | None = None
        if address.kind == "serial":
            self.stream = SerialStream(address.serial_port, address.baud)
        else:
            if udp:
                local = "127.0.0.1" if address.host in ("127.0.0.1", "localhost") else "0.0.0.0"
                self.udp = UdpReceiver(local, 0)
            try:
                self.stream = TcpStream(address.host, address.port)
            except LinkError:
                if self.udp is not None:
                    self.udp.close()
                raise
        self.peer = getattr(self.stream, "peer", None)
        self._threads = [threading.Thread(target=self._read_stream, daemon=True,
                                          name="conformance-stream")]
        if self.udp is not None:
            self._threads.append(threading.Thread(target=self._read_udp, daemon=True,
                                                  name="conformance-udp"))
        self._threads.append(threading.Thread(target=self._heartbeat, daemon=True,
                                              name="conformance-heartbeat"))
        for t in self._threads:
            t.start()

    @property
    def telemetry_port(self) -> int:
        return self.udp.port if self.udp is not None else 0

    # ------------------------------------------------------------------ receiving
    def _keep(self, found, path: str) -> None:
        if not found:
            return
        with self._cond:
            for pid, seq, tick, payload, raw in found:
                self.frames.append(RawFrame(pid, seq, tick, payload, raw, path,
                                            self._arrivals.next()))
            self._cond.notify_all()

    def _read_stream(self) -> None:
        while not self._stop.is_set():
            try:
                data = self.stream.read(0.05)
            except LinkLostError as exc:
                self.lost = str(exc)
                with self._cond:
                    self._cond.notify_all()
                return
            if data:
                self._keep(self._judge_stream.feed_stream(data), "stream")

    def _read_udp(self) -> None:
        assert self.udp is not None
        device = (self.peer[0], self.peer[1]) if self.peer else None
        while not self._stop.is_set():
            try:
                datagrams, _, sources = self.udp.receive_from(0.05)
            except LinkLostError:
                return
            for data, source in zip(datagrams, sources):
                self.datagram_sources.add(tuple(source[:2]))
                if device is not None and tuple(source[:2]) != device:
                    self.foreign_datagrams += 1     # §1.1: telemetry only from the device
                    continue
                self._keep(self._judge_udp.feed_datagram(data), "datagram")

    # ------------------------------------------------------------------ waiting
    def mark(self) -> int:
        """An arrival index: frames after it are 'new' for since()/wait_frame()."""
        return self._arrivals.now()

    def since(self, mark: int, packet_id: int | None = None) -> list[RawFrame]:
        with self._cond:
            return [f for f in self.frames if f.arrival > mark
                    and (packet_id is None or f.packet_id == packet_id)]

    def wait_frame(self, match: Callable[[RawFrame], bool], mark: int, timeout: float
                   ) -> RawFrame | None:
        """The first frame after `mark` that matches, waiting at most `timeout` s."""
        deadline = time.monotonic() + timeout
        seen = 0
        with self._cond:
            while True:
                new = [f for f in self.frames[seen:] if f.arrival > mark]
                seen = len(self.frames)
                for f in new:
                    if match(f):
                        return f
                left = deadline - time.monotonic()
                if left <= 0 or self.lost:
                    return None
                self._cond.wait(min(left, 0.05))

    # ------------------------------------------------------------------ sending
    def next_sequence(self) -> int:
        self._sequence = (self._sequence + 1) & 0xFFFFFFFF or 1
        return self._sequence

    def build(self, command: str | int, values: dict[str, Any] | None = None, *,
              arguments: bytes | None = None, token: int | None = None,
              sequence: int | None = None) -> tuple[str, int, bytes]:
        """(name, sequence, frame) for a command, arguments packed raw unless given."""
        if isinstance(command, int):
            name, opcode = f"opcode 0x{command:04X}", command
            args = arguments or b""
        else:
            cmd = self.d.command(command)
            name, opcode = cmd.name, cmd.opcode
            args = arguments if arguments is not None else pack_arguments(cmd.args, values or {})
        seq = self.next_sequence() if sequence is None else sequence
        tok = self.token if token is None else token
        frame = command_frame(self.d.version_major, self.d.packet("COMMAND").id, seq, tok,
                              opcode, args)
        return name, seq, frame

    def send(self, frame: bytes) -> None:
        with self._send_lock:         # the heartbeat thread writes too: whole frames only
            self.stream.write(frame)

    def exchange(self, command: str | int, values: dict[str, Any] | None = None, *,
                 timeout: float | None = None, frame: tuple[str, int, bytes] | None = None,
                 resend: bool = True, **build) -> Exchange:
        """Send a command and collect its stages until REJECTED/COMPLETED/FAILED.

        The wait per stage is the dictionary's accept timeout, resending the identical
        frame up to `retries` times (§6.4), then the command's own timeout."""
        name, seq, raw = frame or self.build(command, values, **build)
        ex = Exchange(name, seq, raw)
        if name in ("CONNECT", "DISCONNECT"):
            # a session may begin or end from here on: the new owner's telemetry can
            # arrive before this answer does, so the break is marked before sending too
            self.session_changed()
        mark = self.mark()
        self.send(raw)
        defaults = self.d.command_defaults
        # four times the host's accept timeout per try: the suite judges answers, not
        # speed, and a loaded machine may be slow to run a simulated device
        accept = float(defaults.get("accept_timeout_s", 0.25)) * 4
        retries = int(defaults.get("retries", 3)) if resend else 0
        if not resend:                   # one frame only: give it all the retries' time
            accept *= 1 + int(defaults.get("retries", 3))
        done = float(timeout if timeout is not None else self._timeout_of(command)) + accept
        response = self.d.packet("RESPONSE")
        seen = mark
        limit = time.monotonic() + accept
        tries = 0
        while True:
            f = self.wait_frame(lambda f: f.packet_id == response.id
                                and int.from_bytes(f.payload[:4], "big") == seq,
                                seen, max(0.0, limit - time.monotonic()))
            if f is None:
                if not ex.stages and tries < retries:
                    tries += 1
                    self.send(raw)
                    limit = time.monotonic() + accept
                    continue
                return ex
            seen = f.arrival
            v = decode_items(response.items, f.payload, "RESPONSE")
            ex.stages.append(Stage(v["stage"], v["reason"], v["data"], f.tick, f.arrival))
            if v["stage"] != 1:
                return ex
            limit = time.monotonic() + done

    def _timeout_of(self, command) -> float:
        if isinstance(command, str):
            t = self.d.command(command).timeout_s
            if t:
                return float(t)
        return float(self.d.command_defaults.get("timeout_s", 1.0))

    def reply(self, ex: Exchange, command: str) -> dict[str, Any]:
        return decode_items(self.d.command(command).reply, ex.final.data, f"{command} reply")

    # ------------------------------------------------------------------ session
    def connect(self, *, take_over: bool = False, dictionary_hash: int | None = None,
                telemetry_port: int | None = None) -> Exchange:
        ex = self.exchange("CONNECT", {
            "protocol_major": self.d.version_major, "protocol_minor": self.d.version_minor,
            "dictionary_hash": self.d.hash if dictionary_hash is None else dictionary_hash,
            "telemetry_port": self.telemetry_port if telemetry_port is None else telemetry_port,
            "take_over": int(take_over)}, token=0)
        if ex.final is not None and ex.final.stage == 3:
            self.token = self.reply(ex, "CONNECT")["session_token"]
            self.session_changed()
        return ex

    def session_changed(self) -> None:
        """Mark where a session began or ended: telemetry may pause there (§1.3), so
        rates are not judged across it."""
        self._arrivals.breaks.append(self._arrivals.now())

    @property
    def session_breaks(self) -> list[int]:
        return list(self._arrivals.breaks)

    def pause_heartbeat(self, paused: bool = True) -> None:
        """Pause (or resume) the heartbeat.  Once a pause returns no heartbeat is sent
        any more: the thread checks and sends under the same lock.  One sent just before
        may still be on its way; a command exchanged after the pause has passed it (one
        ordered stream)."""
        with self._heartbeat_lock:
            if paused:
                self._heartbeat_paused.set()
            else:
                self._heartbeat_paused.clear()

    def _heartbeat(self) -> None:
        period = float(self.d.command_defaults.get("heartbeat_period_s", 0.2))
        while not self._stop.wait(period):
            with self._heartbeat_lock:
                if not self.token or self._heartbeat_paused.is_set() or self.lost:
                    continue
                try:
                    self.send(self.build("HEARTBEAT", {})[2])
                except LinkError:
                    return

    def close(self) -> None:
        self._stop.set()
        self.stream.close()
        if self.udp is not None:
            self.udp.close()
        for t in self._threads:
            t.join(timeout=1.0)


class _Counter:
    """Arrival numbers shared by the hosts of one run (thread-safe)."""

    def __init__(self) -> None:
        self._n = 0
        self._lock = threading.Lock()
        #: arrival numbers at which a session began or ended (Host.session_changed)
        self.breaks: list[int] = []

    def next(self) -> int:
        with self._lock:
            self._n += 1
            return self._n

    def now(self) -> int:
        with self._lock:
            return self._n
