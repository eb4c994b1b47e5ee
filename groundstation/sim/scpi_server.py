"""The TCP side of the simulated function generator: a raw SCPI socket
(`TCPIP0::127.0.0.1::PORT::SOCKET` through pyvisa-py, "\\n" terminated) serving a
`fg_instrument.SimulatedGenerator`: the listening socket, one thread per connection, the
framing of SCPI text lines and of WVDT binary blocks (framed by their LENGTH, so the data
may contain the terminator byte), and the fault-injection hook: for tests,
`ScpiServer.inject_reply(command, data)` makes the server answer a query with raw bytes (a
reply that is not text, not a number) or not at all (a hung instrument).
`attach_generator` gives a SimulatedDevice a served generator driving its base stage.
"""

from __future__ import annotations

import logging
import re
import socket
import threading

from ..link.transports import listening_socket
from ..instruments import spec4050 as spec
from .fg_instrument import ScpiError, SimulatedGenerator, parse_length

log = logging.getLogger(__name__)

MAX_LINE_BYTES = 64 * 1024                     # a text line longer than this is garbage
MAX_UPLOAD_BYTES = 4 * 2 * spec.ARB_POINTS_MAX  # framing refuses (and drops) anything larger


class _Conn:
    def __init__(self, sock: socket.socket):
        self.sock = sock
        self.buf = bytearray()


class ScpiServer:
    """Serves a SimulatedGenerator on TCP (raw SCPI socket; one thread per connection)."""

    def __init__(self, generator: SimulatedGenerator, *, host: str = "127.0.0.1", port: int = 0):
        self.generator = generator
        self.host = host
        self._requested_port = port
        self.port: int | None = None
        self._stop = threading.Event()
        self._listener: socket.socket | None = None
        self._threads: list[threading.Thread] = []
        self._conns: set[_Conn] = set()
        self._lock = threading.Lock()
        #: injected reply faults (a test hook): command line (upper case) -> the bytes sent
        #: instead of its reply (None: no reply at all, as a hung instrument)
        self._reply_faults: dict[str, bytes | None] = {}

    def inject_reply(self, command: str, reply: bytes | None) -> None:
        """Answer the query line `command` with `reply` (raw bytes, e.g. not valid text;
        None: never answer) from now on; the command is still executed."""
        with self._lock:
            self._reply_faults[command.strip().upper()] = reply

    def clear_faults(self) -> None:
        with self._lock:
            self._reply_faults.clear()

    @property
    def resource(self) -> str:
        """The VISA address pyvisa-py opens (with read/write termination '\\n')."""
        return f"TCPIP0::{self.host}::{self.port}::SOCKET"

    def start(self) -> "ScpiServer":
        lst = listening_socket(self.host, self._requested_port,
                               "choose another --fg-port (0: any free port)")
        self._listener = lst
        self.port = lst.getsockname()[1]
        self._spawn(self._accept_loop, "fg-accept")
        log.info("simulated function generator on %s", self.resource)
        return self

    def _spawn(self, target, name: str) -> None:
        t = threading.Thread(target=target, name=name, daemon=True)
        self._threads.append(t)
        t.start()

    def stop(self) -> None:
        self._stop.set()
        if self._listener is not None:
            self._listener.close()
        self.drop_connections()
        for t in self._threads:
            t.join(timeout=2.0)

    def __enter__(self) -> "ScpiServer":
        return self.start()

    def __exit__(self, *exc) -> None:
        self.stop()

    def drop_connections(self) -> None:
        """Close every client connection (a pulled cable; also a test hook)."""
        with self._lock:
            conns = list(self._conns)
        for conn in conns:
            try:
                conn.sock.shutdown(socket.SHUT_RDWR)
            except OSError:
                pass

    def _accept_loop(self) -> None:
        assert self._listener is not None
        while not self._stop.is_set():
            try:
                sock, _ = self._listener.accept()
            except socket.timeout:
                continue
            except OSError:
                return
            sock.settimeout(0.1)
            conn = _Conn(sock)
            with self._lock:
                self._conns.add(conn)
            self._spawn(lambda: self._serve(conn), "fg-conn")

    def _serve(self, conn: _Conn) -> None:
        try:
            while not self._stop.is_set():
                try:
                    data = conn.sock.recv(65536)
                except socket.timeout:
                    continue
                except OSError:
                    return
                if not data:
                    return
                conn.buf += data
                while self._next_message(conn):
                    pass
        finally:
            with self._lock:
                self._conns.discard(conn)
            conn.sock.close()

    def _next_message(self, conn: _Conn) -> bool:
        """Handle one complete message from the buffer; False when more bytes are needed."""
        buf = conn.buf
        nl = buf.find(b"\n")
        wd = buf.find(b"WAVEDATA,")
        if wd != -1 and (nl == -1 or wd < nl):
            # binary upload: the header says how many bytes follow, the data may hold "\n"
            header = bytes(buf[:wd]).decode("ascii", "replace")
            m = re.search(r"LENGTH\s*,\s*([^,]*)", header, re.IGNORECASE)
            try:
                n = parse_length(m.group(1)) if m else None
            except ScpiError:
                n = None
            if n is None or n > MAX_UPLOAD_BYTES:
                # unframeable: report it and drop the connection (the rest is garbage)
                with self.generator.lock:
                    self.generator.command_log.append(header.strip() + "WAVEDATA,<unframed>")
                    self.generator._push_error(-109 if n is None else -223,
                                               "Missing parameter; LENGTH" if n is None
                                               else "Too much data")
                conn.buf.clear()
                conn.sock.shutdown(socket.SHUT_RDWR)
                return False
            end = wd + len(b"WAVEDATA,") + n
            if len(buf) < end:
                return False
            self.generator.handle_upload(header, bytes(buf[wd + len(b"WAVEDATA,"):end]))
            if buf[end:end + 1] == b"\n":
                end += 1
            del buf[:end]
            return True
        if nl == -1:
            if len(buf) > MAX_LINE_BYTES:
                with self.generator.lock:
                    self.generator._push_error(-223, "Too much data; line too long")
                buf.clear()
            return False
        line = bytes(buf[:nl]).decode("ascii", "replace").rstrip("\r")
        del buf[:nl + 1]
        replies = self.generator.handle_line(line)
        with self._lock:
            faulty = line.strip().upper() in self._reply_faults
            fault = self._reply_faults.get(line.strip().upper())
        data = (fault or b"") if faulty else "".join(r + "\n" for r in replies).encode("ascii")
        if data:
            try:
                conn.sock.sendall(data)
            except OSError:
                pass
        return True


def attach_generator(device, *, host: str = "127.0.0.1", port: int = 0,
                     base_channel: int = 1) -> ScpiServer:
    """Give a SimulatedDevice a function generator: its base stage is driven by channel
    `base_channel`, its clock is the device's tick.  Returns the started server (stop it
    before the device)."""
    fw_rate = device.dictionary.control_rate_hz
    gen = SimulatedGenerator(tick_source=lambda: device.firmware.tick, control_rate_hz=fw_rate,
                             base_channel=base_channel)
    server = ScpiServer(gen, host=host, port=port).start()
    device.base_drive = gen.base_drive
    return server
