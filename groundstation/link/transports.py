"""Byte transports: TCP and serial streams, UDP datagrams.

Each transport turns OS-level failures into a specific LinkError with a message that
names the endpoint and says what to check.  Public read()/write() count bytes and call
the backend's _read()/_write(), so byte accounting and logging live in one place.
"""

from __future__ import annotations

import contextlib
import errno
import logging
import select
import socket
import struct
import sys
import time

import serial

from ..core.errors import DeviceUnreachableError, LinkError, LinkLostError, PortInUseError

log = logging.getLogger(__name__)

UDP_RECEIVE_BUFFER = 8 * 1024 * 1024   # ~4 s of HIGH_RATE at 1200 Hz: rides out GC pauses
# Kernel receive timestamps (Linux): a datagram's arrival time no longer depends on when
# the reader thread got round to it, so the receiver can batch without adding latency.
# Python does not export the constant; 35 is Linux's asm-generic value (x86, ARM).  A
# kernel that does not send it back just leaves arrival times to time.time() (_recv).
_SO_TIMESTAMPNS = getattr(socket, "SO_TIMESTAMPNS", 35 if sys.platform.startswith("linux") else None)
_TIMESPEC = struct.Struct("@qq")


def listening_socket(host: str, port: int, what_to_do: str) -> socket.socket:
    """A TCP server socket bound to host:port (0: any free port), listening, with a 0.1 s
    accept timeout so its accept loop can notice a stop.  A port in use raises
    PortInUseError ending with `what_to_do` (which option to change)."""
    lst = socket.socket(socket.AF_INET, socket.SOCK_STREAM)
    lst.setsockopt(socket.SOL_SOCKET, socket.SO_REUSEADDR, 1)
    try:
        lst.bind((host, port))
    except OSError as exc:
        lst.close()
        if exc.errno == errno.EADDRINUSE:
            raise PortInUseError(f"TCP port {port} on {host} is already in use - {what_to_do}") from None
        raise LinkError(f"cannot listen on {host}:{port} ({exc.strerror or exc})") from None
    lst.listen(4)
    lst.settimeout(0.1)
    return lst


class StreamTransport:
    """A bidirectional byte stream (template: subclasses implement _read/_write/_close)."""

    name = "stream"

    def __init__(self) -> None:
        self.bytes_read = 0
        self.bytes_written = 0
        self.closed = False

    def write(self, data: bytes) -> None:
        if self.closed:
            raise LinkLostError(f"{self.name}: write on a closed link")
        self._write(data)
        self.bytes_written += len(data)

    def read(self, timeout: float) -> bytes:
        """Bytes available within `timeout` s (b'' if none); LinkLostError if the peer went away."""
        if self.closed:
            raise LinkLostError(f"{self.name}: read on a closed link")
        data = self._read(timeout)
        self.bytes_read += len(data)
        return data

    def close(self) -> None:
        if not self.closed:
            self.closed = True
            self._close()

    def _write(self, data: bytes) -> None:
        raise NotImplementedError

    def _read(self, timeout: float) -> bytes:
        raise NotImplementedError

    def _close(self) -> None:
        raise NotImplementedError


class TcpStream(StreamTransport):
    """TCP client connection to the device's command port."""

    def __init__(self, host: str, port: int, connect_timeout: float = 3.0,
                 sock: socket.socket | None = None):
        super().__init__()
        self.name = f"tcp://{host}:{port}"
        if sock is None:
            try:
                sock = socket.create_connection((host, port), timeout=connect_timeout)
            except ConnectionRefusedError:
                raise DeviceUnreachableError(f"{self.name}: connection refused - is the controller (or "
                                f"`groundstation sim`) running and listening on port {port}?") from None
            except socket.timeout:
                raise DeviceUnreachableError(f"{self.name}: no answer within {connect_timeout} s - check "
                                f"the address, cable and firewall") from None
            except OSError as exc:
                raise DeviceUnreachableError(f"{self.name}: cannot connect ({exc.strerror or exc})") from None
        sock.setsockopt(socket.IPPROTO_TCP, socket.TCP_NODELAY, 1)
        self._sock = sock
        try:    # the device's address as the socket sees it: telemetry must come from it
            self.peer: tuple[str, int] | None = tuple(sock.getpeername()[:2])
        except OSError:
            self.peer = None

    def _write(self, data: bytes) -> None:
        try:
            self._sock.sendall(data)
        except OSError as exc:
            raise LinkLostError(f"{self.name}: link lost while sending ({exc.strerror or exc})") from None

    def _read(self, timeout: float) -> bytes:
        try:
            self._sock.settimeout(timeout)
            data = self._sock.recv(65536)
        except socket.timeout:
            return b""
        except OSError as exc:
            raise LinkLostError(f"{self.name}: link lost ({exc.strerror or exc})") from None
        if not data:
            raise LinkLostError(f"{self.name}: the device closed the connection")
        return data

    def _close(self) -> None:
        try:
            self._sock.shutdown(socket.SHUT_RDWR)
        except OSError:
            pass
        self._sock.close()


class SerialStream(StreamTransport):
    """A serial port (or any pyserial URL: loop://, socket://host:port, spy://...)."""

    def __init__(self, port: str, baudrate: int = 2_000_000, port_factory=None):
        super().__init__()
        self.name = f"serial:{port}@{baudrate}"
        try:
            if port_factory is not None:
                self._ser = port_factory()
            else:
                self._ser = serial.serial_for_url(port, baudrate=baudrate, timeout=0.1,
                                                  write_timeout=1.0)
        except serial.SerialException as exc:
            raise DeviceUnreachableError(f"{self.name}: cannot open ({exc}) - is the adapter "
                                         f"plugged in and do you have permission (group "
                                         f"'dialout')?") from None

    def _write(self, data: bytes) -> None:
        try:
            self._ser.write(data)
        except (serial.SerialException, OSError) as exc:
            raise LinkLostError(f"{self.name}: serial device vanished while sending ({exc})") from None

    def _read(self, timeout: float) -> bytes:
        try:
            self._ser.timeout = timeout
            first = self._ser.read(1)
            if not first:
                return b""
            waiting = self._ser.in_waiting
            return first + (self._ser.read(waiting) if waiting else b"")
        except (serial.SerialException, OSError, TypeError) as exc:
            # pyserial raises TypeError from inside read() when the fd is gone
            raise LinkLostError(f"{self.name}: serial device vanished ({exc})") from None

    def _close(self) -> None:
        try:
            self._ser.close()
        except (serial.SerialException, OSError):
            pass


class UdpReceiver:
    """Bound UDP socket for telemetry datagrams, with an enlarged receive buffer."""

    def __init__(self, host: str = "127.0.0.1", port: int = 0,
                 buffer_bytes: int = UDP_RECEIVE_BUFFER):
        self._sock = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
        self._sock.setsockopt(socket.SOL_SOCKET, socket.SO_RCVBUF, buffer_bytes)
        try:
            self._sock.bind((host, port))
        except OSError as exc:
            self._sock.close()
            if exc.errno == errno.EADDRINUSE:
                raise PortInUseError(f"UDP port {port} on {host} is already in use by another "
                                     f"program - choose another telemetry port or stop it") from None
            raise LinkError(f"cannot listen for telemetry on udp://{host}:{port} "
                            f"({exc.strerror or exc})") from None
        self.host, self.port = self._sock.getsockname()
        self.receive_buffer = self._sock.getsockopt(socket.SOL_SOCKET, socket.SO_RCVBUF)
        if self.receive_buffer < buffer_bytes // 2:      # Linux reports twice what it grants
            log.warning("UDP receive buffer is %d bytes, %d requested: raise the limit with "
                        "'sysctl -w net.core.rmem_max=%d' to ride out pauses without drops",
                        self.receive_buffer, buffer_bytes, buffer_bytes)
        self.kernel_timestamps = False
        if _SO_TIMESTAMPNS is not None:
            try:
                self._sock.setsockopt(socket.SOL_SOCKET, _SO_TIMESTAMPNS, 1)
                self.kernel_timestamps = True
            except OSError:
                pass                    # not supported here: host times come from time.time()
        self.datagrams = 0
        self.bytes_read = 0
        self.closed = False
        #: the last receive_from() stopped at max_datagrams: more were waiting
        self.backlog = False
        # wake(): a socket pair the wait watches beside the telemetry socket, because
        # closing a socket from another thread does not end a recv already waiting on
        # it (the reader would sleep out its timeout, at every session's close)
        self._sock.setblocking(False)          # reads follow _wait(), which does the waiting
        self._wake_r, self._wake_w = socket.socketpair()
        self._wake_r.setblocking(False)
        self._wake_w.setblocking(False)
        self._poll = select.poll()
        self._poll.register(self._sock, select.POLLIN)
        self._poll.register(self._wake_r, select.POLLIN)

    def _recv(self) -> tuple[bytes, float, tuple[str, int]]:
        if not self.kernel_timestamps:
            data, addr = self._sock.recvfrom(65536)
            return data, time.time(), addr
        data, ancillary, _flags, addr = self._sock.recvmsg(65536, 64)
        for level, kind, raw in ancillary:
            if level == socket.SOL_SOCKET and kind == _SO_TIMESTAMPNS and len(raw) >= _TIMESPEC.size:
                sec, nsec = _TIMESPEC.unpack_from(raw)
                return data, sec + nsec * 1e-9, addr
        return data, time.time(), addr

    def receive(self, timeout: float, max_datagrams: int = 512,
                coalesce_s: float = 0.0) -> tuple[list[bytes], list[float]]:
        """receive_from() without the senders' addresses."""
        datagrams, times, _ = self.receive_from(timeout, max_datagrams, coalesce_s)
        return datagrams, times

    def receive_from(self, timeout: float, max_datagrams: int = 512, coalesce_s: float = 0.0
                     ) -> tuple[list[bytes], list[float], list[tuple[str, int]]]:
        """Wait up to `timeout` s for one datagram, then drain what else is queued.

        coalesce_s > 0 waits that long after the first datagram before draining, so a
        1200 Hz stream is handled in batches of about 1200*coalesce_s frames: each wake-up
        of the reader costs the same interpreter time whatever it carries, and in the
        GUI process that time is taken from the event loop.  Arrival times are the
        kernel's, so batching does not change the measured latency.  After a call that
        stopped at max_datagrams (more were waiting: a backlog) the next one does not
        wait: with the wait, a stream faster than max_datagrams / coalesce_s (512 per
        25 ms, less whatever handing them on takes) could never be caught up with and
        would overflow the socket's buffer."""
        out: list[bytes] = []
        times: list[float] = []
        sources: list[tuple[str, int]] = []
        if not self._wait(timeout):
            return out, times, sources
        try:
            data, when, addr = self._recv()
        except BlockingIOError:                       # woken, nothing queued
            return out, times, sources
        except OSError as exc:
            if self.closed:
                return out, times, sources
            raise LinkLostError(f"udp://{self.host}:{self.port}: receive failed ({exc})") from None
        out.append(data)
        times.append(when)
        sources.append(addr)
        if coalesce_s > 0 and not self.backlog:
            time.sleep(coalesce_s)
        try:
            while len(out) < max_datagrams:
                data, when, addr = self._recv()
                out.append(data)
                times.append(when)
                sources.append(addr)
        except (BlockingIOError, OSError):
            pass                        # drained (or closed meanwhile: the next call says so)
        self.backlog = len(out) >= max_datagrams
        self.datagrams += len(out)
        self.bytes_read += sum(len(d) for d in out)
        return out, times, sources

    def _wait(self, timeout: float) -> bool:
        """Up to `timeout` s for a datagram or a wake(); False when neither came (or the
        receiver is closed)."""
        if self.closed:
            return False
        try:
            ready = self._poll.poll(max(0.0, timeout) * 1000.0)
        except (OSError, ValueError):                 # closed meanwhile
            return False
        if any(fd == self._wake_r.fileno() for fd, _ in ready):
            with contextlib.suppress(OSError):    # a byte per wake(), a handful at most
                self._wake_r.recv(4096)
        return bool(ready) and not self.closed

    def wake(self) -> None:
        """End a receive_from() waiting now (or the next one) at once, with whatever is
        queued: what a reader needs to drain the socket, or to stop, without waiting out
        its timeout."""
        with contextlib.suppress(OSError):            # a full pair is woken already
            self._wake_w.send(b"\0")

    def close(self) -> None:
        self.closed = True
        self.wake()
        self._sock.close()
        self._wake_r.close()
        self._wake_w.close()
