"""The simulated device's protocol endpoint: TCP command server, UDP telemetry sender,
optional serial stream, and the 1200 Hz tick loop (paced to the wall clock, as fast as
possible, or stepped by hand from a test).

Binds to 127.0.0.1 unless told otherwise.  All firmware access is under one lock, so a
command is executed between two control periods, never in the middle of one.
"""

from __future__ import annotations

import itertools
import logging
import socket
import struct
import threading
import time
from typing import Any, Callable, Iterable

import numpy as np

from ..core.kinds import SimPacing
from ..codec import FrameCodec, StreamDeframer
from ..core.dictionary import Dictionary, load_dictionary
from ..core.errors import LinkLostError, PortInUseError
from ..link.transports import StreamTransport, TcpStream, listening_socket
from . import core
from .deviations import Deviations
from .firmware import REJECTED, Firmware
from .telemetry_batch import FrameRun, TelemetryBatcher
from ..plant.testbed import Testbed

log = logging.getLogger(__name__)


def housekeeping_divider(dictionary: Dictionary) -> int:
    """Control periods per HOUSEKEEPING frame: the dictionary's control rate over the
    packet's rate_hz (1200 Hz / 10 Hz = 120)."""
    rate = dictionary.packet("HOUSEKEEPING").rate_hz
    ratio = dictionary.control_rate_hz / rate if rate else 0.0
    divider = round(ratio)
    if divider < 1 or abs(ratio - divider) > 1e-9:
        raise ValueError(f"HOUSEKEEPING rate_hz = {rate!r} does not divide the control rate "
                         f"{dictionary.control_rate_hz:g} Hz into whole control periods")
    return divider


#: realtime pacing without a session: control periods run per wake-up of the tick loop
#: (0.1 s at 1200 Hz; well below _catch_up's half second, beyond which periods are skipped)
IDLE_PERIODS = 120

#: commands whose whole result is in their RESPONSE (keep-alive, identity, the blocks of
#: a transfer, read-backs): executing one asks for no device time to confirm it
ANSWERED_IN_FULL = frozenset({"HEARTBEAT", "GET_INFO", "PARAM_BEGIN", "PARAM_WRITE", "PARAM_READ",
                              "PROFILE_BEGIN", "PROFILE_WRITE"})


#: commands the device confirms in HOUSEKEEPING (the active table's CRC, the active
#: profile): their confirmation needs the rest of the housekeeping period
CONFIRMED_IN_HOUSEKEEPING = frozenset({"PARAM_COMMIT", "PROFILE_COMMIT"})


def _response_struct(dictionary: Dictionary) -> tuple[int, struct.Struct] | None:
    """(packet id, struct of the fixed items) of RESPONSE when its items are the ones the
    device fills in - command_sequence, opcode, stage, reason as plain integers, then the
    variable data - so a frame can be packed without the general encoder; None (use the
    encoder) for any other layout a dictionary may give it."""
    pkt = dictionary.packet("RESPONSE")
    items = pkt.items
    names = [item.name for item in items]
    if names != ["command_sequence", "opcode", "stage", "reason", "data"] or not items[-1].is_variable:
        return None
    codes = []
    for item in items[:-1]:
        dt = item.wire_dtype
        if item.has_conversion or dt.kind not in "iu":
            return None
        codes.append(dt.newbyteorder(">").char)
    fixed = struct.Struct(">" + "".join(codes))
    if fixed.size != pkt.fixed_payload_size:
        return None
    return pkt.id, fixed


def _packed(frames: list[bytes], datagram_bytes: int) -> list[bytes]:
    """Whole frames (of any lengths, in order) joined into datagrams of at most
    `datagram_bytes` (a longer frame alone in its own)."""
    out: list[bytes] = []
    start, size = 0, 0
    for i, frame in enumerate(frames):
        if size and size + len(frame) > datagram_bytes:
            out.append(b"".join(frames[start:i]))
            start, size = i, 0
        size += len(frame)
    if size:
        out.append(b"".join(frames[start:]))
    return out


class _Connection:
    def __init__(self, conn_id: int, transport: StreamTransport, peer_ip: str | None):
        self.id = conn_id
        self.transport = transport
        self.peer_ip = peer_ip
        self.lock = threading.Lock()
        self.thread: threading.Thread | None = None

    def send(self, data: bytes) -> None:
        """Write to the host; a host that went away is noticed (and the connection
        ended) by this connection's reader, so a sender need not care."""
        with self.lock:
            try:
                self.transport.write(data)
            except LinkLostError:
                pass


class SimulatedDevice:
    """A testbed controller on loopback (or a serial stream) speaking the real protocol."""

    def __init__(self, dictionary: Dictionary | None = None, *, host: str = "127.0.0.1",
                 tcp_port: int = 0, pacing: str = "realtime", seed: int = 0,
                 frames_per_datagram: int = 1, firmware: Firmware | None = None,
                 testbed: Testbed | None = None, speed: float = 1.0,
                 deviations: Deviations | None = None):
        if pacing not in (SimPacing.REALTIME, SimPacing.FAST, SimPacing.MANUAL):
            raise ValueError(f"pacing must be realtime, fast or manual, not {pacing!r}")
        if not speed > 0 or speed == float("inf"):
            raise ValueError(f"speed must be a finite number > 0, not {speed!r}")
        self.dictionary = dictionary or load_dictionary()
        self.codec = FrameCodec(self.dictionary)
        self.firmware = firmware or Firmware(self.dictionary, seed=seed, testbed=testbed)
        if deviations:                  # test only: a device that breaks the SPEC on purpose
            self.firmware.deviations = deviations
            self.firmware.fw[core.FW_WD_TICKS] *= deviations.watchdog_factor
        #: control periods per HOUSEKEEPING frame (the dictionary's rates)
        self.housekeeping_divider = housekeeping_divider(self.dictionary)
        self.host = host
        self.pacing = pacing
        #: realtime pacing only: control periods per 1/1200 s of wall time (10: a 10x
        #: burst, 12 000 frames/s).  Ticks stay exact; only the wall clock is scaled, so
        #: tick-based timeouts (the watchdog) also run `speed` times sooner in wall time.
        self.speed = float(speed)
        self.frames_per_datagram = max(1, frames_per_datagram)
        self._requested_port = tcp_port
        self._lock = threading.RLock()
        self._stop = threading.Event()
        self._connections: dict[int, _Connection] = {}
        self._ids = itertools.count(1)
        self._seq = {p.name: 0 for p in self.dictionary.packets}
        self._listener: socket.socket | None = None
        self._udp: socket.socket | None = None
        self._threads: list[threading.Thread] = []
        #: test hook: called with each telemetry datagram; return None to drop it
        self.datagram_filter: Callable[[bytes], bytes | None] | None = None
        #: function generator output: (first_tick, n) -> n volts, one per period (None: 0 V)
        self.base_drive: Callable[[int, int], np.ndarray] | None = None
        #: receives (first_tick, truth array) of every batch: true angles for analysis/tests
        self.truth_sink: Callable[[int, np.ndarray], None] | None = None
        #: manual pacing: called as after_commands(housekeeping) (device lock held) after a
        #: block of commands holding any command not ANSWERED_IN_FULL was executed, before
        #: their answers are sent - the stepped clock's hook for "a command's confirmation
        #: needs device time"; `housekeeping`: one of them is CONFIRMED_IN_HOUSEKEEPING
        self.after_commands: Callable[[bool], None] | None = None
        self._answered_in_full = frozenset(self.dictionary.command(name).opcode
                                           for name in ANSWERED_IN_FULL)
        self._confirmed_in_hk = frozenset(self.dictionary.command(name).opcode
                                          for name in CONFIRMED_IN_HOUSEKEEPING)
        self._response_layout = _response_struct(self.dictionary)
        self._batcher = TelemetryBatcher(self.codec, self.housekeeping_divider)
        self.tcp_port: int | None = None
        self._t0: float | None = None
        self._ticks_done = 0
        self.datagrams_sent = 0
        #: realtime pacing: wake-ups of the tick loop (one per control period in a
        #: session, one per IDLE_PERIODS without one)
        self.loop_wakeups = 0
        #: set to wake the tick loop early: a session opened, or the device stops
        self._wake = threading.Event()
        self._idling = False
        #: the tick loop's clock and wait (test hook: a test runs it on a clock of its own)
        self.monotonic: Callable[[], float] = time.monotonic
        self.wait: Callable[[float], Any] = self._wake.wait

    # ------------------------------------------------------------------ lifecycle
    def start(self) -> "SimulatedDevice":
        # Telemetry leaves from the command port's number (SPEC §1.1): the host accepts
        # datagrams only from there.  With any free port asked for (0), a TCP port whose
        # UDP twin is taken is given back and another one tried.
        for attempt in range(20):
            lst = listening_socket(self.host, self._requested_port,
                                   "another simulator running? choose --tcp-port")
            port = lst.getsockname()[1]
            udp = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
            try:
                udp.bind((self.host, port))
                break
            except OSError as exc:
                udp.close()
                lst.close()
                if self._requested_port or attempt == 19:
                    raise PortInUseError(
                        f"UDP port {port} on {self.host} is in use ({exc.strerror or exc}); the "
                        f"simulated testbed sends telemetry from its command port's number - "
                        f"choose another --tcp-port") from None
        self._udp = udp
        self._listener = lst
        self.tcp_port = port
        self._spawn(self._accept_loop, "sim-accept")
        if self.pacing != SimPacing.MANUAL:
            self._spawn(self._tick_loop, "sim-ticks")
        log.info("simulated device listening on tcp://%s:%d", self.host, self.tcp_port)
        return self

    def _spawn(self, target, name) -> threading.Thread:
        t = threading.Thread(target=target, name=name, daemon=True)
        self._threads.append(t)
        t.start()
        return t

    def gone(self) -> str:
        """Why the device can no longer answer ("" while it runs; it lives in this
        process, so only a stop ends it): DeviceClient.device_gone."""
        return "stopped" if self._stop.is_set() else ""

    def stop(self) -> None:
        self._stop.set()
        self._wake.set()
        if self._listener is not None:
            self._listener.close()
        for conn in list(self._connections.values()):
            conn.transport.close()
        for t in self._threads:
            t.join(timeout=2.0)
        if self._udp is not None:
            self._udp.close()

    def __enter__(self) -> "SimulatedDevice":
        return self.start()

    def __exit__(self, *exc) -> None:
        self.stop()

    # ------------------------------------------------------------------ connections
    def _accept_loop(self) -> None:
        assert self._listener is not None
        while not self._stop.is_set():
            try:
                sock, addr = self._listener.accept()
            except socket.timeout:
                continue
            except OSError:
                return
            self.attach_stream(TcpStream(addr[0], addr[1], sock=sock), peer_ip=addr[0])

    def attach_stream(self, transport: StreamTransport, peer_ip: str | None = None) -> int:
        """Serve commands (and telemetry, if the host asks for it there) on a stream."""
        conn = _Connection(next(self._ids), transport, peer_ip)
        peer = getattr(transport, "peer", None)
        with self._lock:
            self._connections[conn.id] = conn
            # how the firmware names this host to others (e.g. after a take-over)
            self.firmware.peer_names[conn.id] = (f"{peer[0]}:{peer[1]}" if peer
                                                 else f"{transport.name} link")
        conn.thread = self._spawn(lambda: self._serve(conn), f"sim-conn-{conn.id}")
        return conn.id

    def _serve(self, conn: _Connection) -> None:
        deframer = StreamDeframer(self.codec)
        try:
            while not self._stop.is_set():
                data = conn.transport.read(0.1)
                if not data:
                    continue
                version_errors = deframer.counters.version_errors
                for block in deframer.feed(data, time.time()):
                    if block.name == "COMMAND":
                        self._on_commands(conn, block)
                if deframer.counters.version_errors != version_errors:
                    self._answer_other_version_connect(conn, data)
        except LinkLostError as exc:
            log.info("connection %d closed: %s", conn.id, exc)
        finally:
            with self._lock:
                self._connections.pop(conn.id, None)
                if self.firmware.session_peer == conn.id:
                    self.firmware.end_session("command connection closed")
                self.firmware.peer_names.pop(conn.id, None)
            conn.transport.close()

    def _on_commands(self, conn: _Connection, block) -> None:
        out = []
        with self._lock:
            if self.pacing == SimPacing.REALTIME and self._t0 is not None:
                self._catch_up()          # execute at the control-cycle boundary of "now"
            confirm = housekeeping = False
            for i in range(len(block)):
                seq = int(block["sequence"][i])
                token = int(block["session_token"][i])
                opcode = int(block["opcode"][i])
                stages = self.firmware.handle_command(seq, token, opcode, block["arguments"][i],
                                                      peer=conn.id)
                confirm = confirm or opcode not in self._answered_in_full
                housekeeping = housekeeping or opcode in self._confirmed_in_hk
                for st in stages:
                    out.append(self._response(seq, opcode, st))
            self._flush_events()
            if confirm and self.pacing == SimPacing.MANUAL and self.after_commands is not None:
                self.after_commands(housekeeping)
            if self._idling and self.firmware.session_token is not None:
                self._wake.set()          # an idle tick loop goes back to every period
        conn.send(b"".join(out))

    def _answer_other_version_connect(self, conn: _Connection, data: bytes) -> None:
        """SPEC §7: a CONNECT in another protocol major version is answered REJECTED
        DICTIONARY_MISMATCH, in this device's own version, so the host can name both
        versions instead of waiting for an answer that never comes.  (Header: sync 2,
        version 1, packet id 1, length 2, sequence 4, tick 4; COMMAND payload: token 4,
        opcode 2.)  A frame split across two reads is missed; the host's retry comes
        whole."""
        command_id = self.dictionary.packet("COMMAND").id
        connect = self.dictionary.command("CONNECT").opcode
        out = []
        at = data.find(b"\xEB\x90")
        while at >= 0 and at + 20 <= len(data):
            if (data[at + 2] != self.dictionary.version_major and data[at + 3] == command_id
                    and int.from_bytes(data[at + 18:at + 20], "big") == connect):
                seq = int.from_bytes(data[at + 6:at + 10], "big")
                with self._lock:
                    out.append(self._frame("RESPONSE", {
                        "command_sequence": seq, "opcode": connect, "stage": REJECTED,
                        "reason": self.dictionary.error_codes["DICTIONARY_MISMATCH"],
                        "data": self.firmware._connect_reply(0)}))
            at = data.find(b"\xEB\x90", at + 2)
        if out:
            conn.send(b"".join(out))

    def _response(self, seq: int, opcode: int, st) -> bytes:
        """One RESPONSE frame.  Its fixed items are packed with a struct made from the
        dictionary once (see _response_struct): the general encoder checks every item
        of every frame, and a profile upload answers hundreds of blocks twice each."""
        if self._response_layout is None:
            return self._frame("RESPONSE", {"command_sequence": seq, "opcode": opcode,
                                            "stage": st.stage, "reason": st.reason,
                                            "data": st.data})
        packet_id, fixed = self._response_layout
        frame_seq = self._next_seq("RESPONSE")
        return self.codec.frame(packet_id, fixed.pack(seq, opcode, st.stage, st.reason)
                                + bytes(st.data), frame_seq, self.firmware.tick)

    def _frame(self, packet: str, values: dict[str, Any], tick: int | None = None) -> bytes:
        seq = self._seq[packet]
        self._seq[packet] = (seq + 1) & 0xFFFFFFFF
        return self.codec.encode_variable(packet, values, seq,
                                          self.firmware.tick if tick is None else tick)

    # ------------------------------------------------------------------ telemetry
    def _telemetry_target(self) -> tuple[Any, ...] | None:
        fw = self.firmware
        if fw.session_token is None:
            return None
        conn = self._connections.get(fw.session_peer)
        if conn is None:
            return None
        port = getattr(fw, "telemetry_port", 0)
        if port and conn.peer_ip:
            return ("udp", (conn.peer_ip, port))
        return ("stream", conn)

    def _send_telemetry(self, frames: list[bytes] | FrameRun, frame_groups: bool,
                        group: int | None = None) -> None:
        target = self._telemetry_target()
        if target is None or not len(frames):
            return
        frames = self.firmware.deviations.outgoing(frames)
        if target[0] == "stream":
            target[1].send(frames.data if isinstance(frames, FrameRun) else b"".join(frames))
            return
        step = (group or self.frames_per_datagram) if frame_groups else 1
        if isinstance(frames, FrameRun):
            self._send_datagrams(target[1], frames.groups(step))
            return
        self._send_datagrams(target[1], (b"".join(frames[i:i + step])
                                         for i in range(0, len(frames), step)))

    def _send_datagrams(self, address: tuple, datagrams: Iterable[bytes]) -> None:
        for datagram in datagrams:
            if self.datagram_filter is not None:
                datagram = self.datagram_filter(datagram)
                if datagram is None:
                    continue
            try:
                self._udp.sendto(datagram, address)
                self.datagrams_sent += 1
            except OSError as exc:       # host gone or buffer full: a real rig drops too
                self.firmware.overruns += 1
                log.debug("telemetry send failed: %s", exc)

    def _event_frames(self) -> list[bytes]:
        fw = self.firmware
        frames = []
        while fw.events:
            level, code, text, tick = fw.events.popleft()
            frames.append(self._frame("EVENT", {"level": level, "code": code, "text": text[:900]}, tick))
        return frames

    def _flush_events(self) -> None:
        if self._telemetry_target() is None:
            # sent to nobody: not numbered either (SPEC §2: a frame not sent does not use
            # up a sequence number)
            self.firmware.events.clear()
            return
        self._send_telemetry(self._event_frames(), frame_groups=False)

    def run_ticks(self, n: int) -> None:
        """Advance the device by n control periods and send their telemetry."""
        with self._lock:
            sending = self._telemetry_target() is not None
            frames, hk_frames = self._simulate(n, encode=sending)
            if sending:
                self._send_telemetry(frames, frame_groups=True)
                self._send_telemetry(hk_frames, frame_groups=False)
            self._flush_events()

    def step(self, n: int, *, datagram_bytes: int = 0, only_while_playing: bool = False,
             unless_faulted: bool = False) -> int | None:
        """The stepped clock's advance (manual pacing): n control periods and their
        telemetry, HIGH_RATE frames packed `datagram_bytes` to a datagram (0: as
        `frames_per_datagram` says) and sent after the others.  At the end the host counts as heard at the last tick:
        the clock that calls this is the host, and it runs the device only while it keeps
        up with the telemetry (a device-time heartbeat, the same value a HEARTBEAT sent
        after the periods would leave).  With `only_while_playing`, nothing runs unless a
        profile is playing (checked under the device lock, so no command can come between);
        with `unless_faulted`, nothing once the firmware has latched a fault (a dwell's
        chunks requested ahead end where the fault was seen).
        Returns the tick of the last period run, or None when nothing ran."""
        with self._lock:
            if only_while_playing and not self.firmware.profile_active:
                return None
            if unless_faulted and self.firmware.fault:
                return None
            target = self._telemetry_target()
            frames, hk_frames = self._simulate(n, encode=target is not None)
            # EVENTs and HOUSEKEEPING first, HIGH_RATE last: the arrival of the last
            # HIGH_RATE frame then tells the clock that all of it has arrived (one socket to
            # one socket keeps the datagrams' order)
            if target is None:
                self.firmware.events.clear()     # to nobody: not numbered (SPEC §2)
            events = self._event_frames()
            if target is not None and target[0] == "udp" and datagram_bytes:
                # these packed too: every datagram is a send here and a receive in the
                # host, and each of those lets another thread take the interpreter
                self._send_datagrams(target[1], _packed(events + hk_frames.frames(), datagram_bytes))
                group = max(1, datagram_bytes // frames.size) if len(frames) else 1
                self._send_telemetry(frames, frame_groups=True, group=group)
            elif target is not None:
                self._send_telemetry(events, frame_groups=False)
                self._send_telemetry(hk_frames, frame_groups=False)
                self._send_telemetry(frames, frame_groups=True)
            self.host_heard()
            return self.firmware.tick & 0xFFFFFFFF

    def hold_between_steps(self, on_ran: Callable[[int], None] | None, *,
                           datagram_bytes: int = 0) -> None:
        """Manual pacing with device time held between the clock's steps: after a block
        of commands one of which needs device time to be confirmed, run the control
        period it takes effect in (for one confirmed in HOUSEKEEPING, to the end of the
        housekeeping period), so its state reaches the host, then `on_ran(last_tick)` -
        all before the commands' answers leave.  None: commands run no periods."""
        if on_ran is None:
            self.after_commands = None
            return

        def confirm(housekeeping: bool) -> None:
            every = self.housekeeping_divider
            n = every - self.firmware.tick % every if housekeeping else 1
            on_ran(self.step(n, datagram_bytes=datagram_bytes))
        self.after_commands = confirm

    def sync(self) -> None:
        """Every confirmation period run so far has been reported (in this process,
        on_ran is called before step returns: nothing to wait for)."""

    @property
    def faulted(self) -> bool:
        """Whether the firmware has latched a fault."""
        return bool(self.firmware.fault)

    def host_heard(self) -> None:
        """Manual pacing: the session's host was heard now (what any session command does
        on the firmware); nothing without a session."""
        with self._lock:
            fw = self.firmware
            if fw.session_token is not None:
                fw.fw[core.FW_LAST_HEARD] = fw.tick

    def _simulate(self, n: int, encode: bool = True) -> tuple[FrameRun, FrameRun]:
        """n periods -> HIGH_RATE frames (one per period) and HOUSEKEEPING frames (10 Hz),
        each encoded in one pass (telemetry_batch.py); batch sizes never change what is
        sent.  With `encode` False (nobody to send them to) the periods run but no frame
        is made: nothing is encoded for nobody, and no sequence number is used up (SPEC §2)."""
        return self._batcher.run(self.firmware, n, self._seq, encode=encode,
                                 base_drive=self.base_drive, truth_sink=self.truth_sink)

    def run_fast(self, seconds: float, consumer: Callable[[bytes], None],
                 batch: int | None = None) -> int:
        """Run `seconds` of simulated time as fast as possible, handing the frames (the
        exact bytes paced mode would stream, in order) to `consumer`, `batch` control
        periods at a time (None: one second's worth); returns periods run."""
        total = int(round(seconds * self.dictionary.control_rate_hz))
        if batch is None:
            batch = max(1, int(round(self.dictionary.control_rate_hz)))
        done = 0
        while done < total:
            n = min(batch, total - done)
            with self._lock:
                frames, hk_frames = self._simulate(n)
                events = self._event_frames()
            consumer(frames.data + hk_frames.data + b"".join(events))
            done += n
        return done

    def _next_seq(self, packet: str) -> int:
        seq = self._seq[packet]
        self._seq[packet] = (seq + 1) & 0xFFFFFFFF
        return seq

    def _catch_up(self) -> None:
        """Realtime pacing: run the control periods that are due by the wall clock."""
        rate = self.dictionary.control_rate_hz * self.speed     # periods per wall second
        with self._lock:
            due = int((self.monotonic() - self._t0) * rate) - self._ticks_done
            max_batch = int(rate // 2)
            if due > max_batch:          # we fell behind (machine busy): skip, and say so
                self.firmware.overruns += due - max_batch
                self._ticks_done += due - max_batch
                due = max_batch
            if due > 0:
                self.run_ticks(due)
                self._ticks_done += due

    def _tick_loop(self) -> None:
        self._t0 = self.monotonic()
        self._ticks_done = 0
        period = 1.0 / (self.dictionary.control_rate_hz * self.speed)     # wall seconds
        # an idle batch stays well inside _catch_up's half second of wall time (a slowed
        # device, speed < 1, has fewer periods in it), so no idle period counts as overrun
        idle_batch = max(1, min(IDLE_PERIODS, int(0.25 / period)))
        while not self._stop.is_set():
            if self.pacing == SimPacing.FAST:
                self.run_ticks(self.housekeeping_divider)    # one housekeeping period
                continue
            self._wake.clear()            # before the session is looked at
            self._catch_up()
            self.loop_wakeups += 1
            # in a session, wake at the next control period's start, so frames leave on
            # time (SPEC §5.5); without one nothing is sent (§1.3), so the plant runs IDLE_PERIODS
            # at a time - a command runs the periods due first (_on_commands), so the
            # device clock a connecting host finds is the same
            with self._lock:              # as _on_commands looks at it: no wake is lost
                self._idling = self.firmware.session_token is None
            ahead = idle_batch if self._idling else 1
            next_due = self._t0 + (self._ticks_done + ahead) * period
            self.wait(max(0.0002, next_due - self.monotonic()))
