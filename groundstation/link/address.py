"""Device addresses as an operator types them, and opening a client for one.

    tcp://HOST:PORT            command channel over TCP, telemetry over UDP (default)
    HOST:PORT                  same as tcp://
    tcp://HOST:PORT?telemetry=stream   telemetry on the TCP stream (no UDP)
    serial:///dev/ttyUSB0?baud=2000000  everything over one serial port
    serial://loop://           pyserial URLs work too (loop://, socket://...)
"""

from __future__ import annotations

from dataclasses import dataclass
from urllib.parse import parse_qs, urlsplit

from ..core.dictionary import Dictionary
from ..core.errors import LinkError
from .client import DeviceClient
from .transports import SerialStream, TcpStream, UdpReceiver

# 2 Mbaud: full-rate HIGH_RATE needs 78 B x 1200/s = 93.6 kB/s, more than 921600 8N1 carries
DEFAULT_BAUD = 2_000_000


@dataclass(frozen=True)
class DeviceAddress:
    kind: str                    # "tcp" or "serial"
    host: str = "127.0.0.1"
    port: int = 0
    serial_port: str = ""
    baud: int = DEFAULT_BAUD
    telemetry: str = "udp"       # "udp" or "stream"
    telemetry_port: int = 0      # local UDP port (0: any free port)

    def __str__(self) -> str:
        if self.kind == "serial":
            return f"serial://{self.serial_port}?baud={self.baud}"
        return f"tcp://{self.host}:{self.port}" + ("?telemetry=stream" if self.telemetry == "stream" else "")


def parse_address(text: str) -> DeviceAddress:
    text = text.strip()
    if text.startswith("serial://"):
        rest = text[len("serial://"):]
        port, _, query = rest.partition("?")
        q = parse_qs(query)
        if not port:
            raise LinkError(f"'{text}': no serial port given (e.g. serial:///dev/ttyUSB0?baud=2000000)")
        try:
            baud = int(q.get("baud", [DEFAULT_BAUD])[0])
        except ValueError:
            raise LinkError(f"'{text}': baud must be an integer") from None
        return DeviceAddress("serial", serial_port=port, baud=baud, telemetry="stream")
    if "://" not in text:
        text = "tcp://" + text
    parts = urlsplit(text)
    if parts.scheme != "tcp":
        raise LinkError(f"'{text}': unknown scheme '{parts.scheme}' (use tcp:// or serial://)")
    try:
        port = parts.port
    except ValueError:
        port = None
    if not parts.hostname or not port:
        raise LinkError(f"'{text}': expected HOST:PORT, e.g. tcp://192.168.1.20:5020")
    q = parse_qs(parts.query)
    telemetry = q.get("telemetry", ["udp"])[0]
    if telemetry not in ("udp", "stream"):
        raise LinkError(f"'{text}': telemetry must be udp or stream")
    try:
        tport = int(q.get("telemetry_port", ["0"])[0])
    except ValueError:
        raise LinkError(f"'{text}': telemetry_port must be an integer") from None
    return DeviceAddress("tcp", host=parts.hostname, port=port, telemetry=telemetry,
                         telemetry_port=tport)


def open_client(dictionary: Dictionary, address: DeviceAddress | str, *,
                heartbeat: bool = True, bind_host: str | None = None) -> DeviceClient:
    """Open the transports for an address and return a started (not connected) client."""
    addr = parse_address(address) if isinstance(address, str) else address
    if addr.kind == "serial":
        return _started(DeviceClient(dictionary, SerialStream(addr.serial_port, addr.baud),
                                     heartbeat=heartbeat))
    udp = None
    if addr.telemetry == "udp":
        # listen where the device can reach us: loopback for a local device, else all
        local = bind_host or ("127.0.0.1" if addr.host in ("127.0.0.1", "localhost") else "0.0.0.0")
        udp = UdpReceiver(local, addr.telemetry_port)
    try:
        stream = TcpStream(addr.host, addr.port)
    except LinkError:
        if udp is not None:
            udp.close()
        raise
    return _started(DeviceClient(dictionary, stream, udp, heartbeat=heartbeat))


def open_command_link(dictionary: Dictionary, host: str, port: int, *,
                      connect_timeout: float = 2.0) -> DeviceClient:
    """A started client on a command connection of its own, without telemetry and without
    a heartbeat: for one command that needs no session (a console's ABORT)."""
    return _started(DeviceClient(dictionary, TcpStream(host, port, connect_timeout=connect_timeout),
                                 None, heartbeat=False))


def _started(client: DeviceClient) -> DeviceClient:
    client.start()
    return client
