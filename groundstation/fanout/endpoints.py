"""Which ZeroMQ endpoints a publisher may bind and a viewer may watch, and the errors.

A publisher binds loopback unless told otherwise: the raw telemetry of a rig is lab
data, and a PUB socket has no notion of who subscribes.  A wider bind (a LAN address,
0.0.0.0, *) is refused unless CURVE keys are given, so that only the holders of a key
the lab authorised can subscribe (keys.py).  Standard library only.
"""

from __future__ import annotations

import ipaddress
from dataclasses import dataclass

from ..core.errors import CommandError, GroundStationError

LOOPBACK_NAMES = {"localhost", "127.0.0.1", "::1"}
#: a read-only console's answer to any command but ABORT (the GUI's tooltips say it too)
READ_ONLY = "read-only console watching {endpoint}: commands are sent by the station that holds the session"


class FanoutError(GroundStationError):
    """A publisher or viewer cannot start as asked (the message says why and what to do)."""


class ReadOnlyConsole(CommandError):
    """A command other than ABORT asked of a watching console (nothing was sent)."""


@dataclass(frozen=True)
class Endpoint:
    text: str
    host: str
    port: str            # a number, or "*" (bind: any free port)

    @property
    def loopback(self) -> bool:
        if self.host in LOOPBACK_NAMES:
            return True
        try:
            return ipaddress.ip_address(self.host).is_loopback
        except ValueError:                 # "*", an interface name, a host name
            return False


def parse_endpoint(text: str, *, for_bind: bool) -> Endpoint:
    """tcp://HOST:PORT (a bind may use PORT "*", the test's way to get a free port)."""
    text = text.strip()
    if not text.startswith("tcp://"):
        raise FanoutError(f"'{text}': a console endpoint is tcp://HOST:PORT, e.g. "
                          f"tcp://127.0.0.1:5600")
    rest = text[len("tcp://"):]
    host, sep, port = rest.rpartition(":")
    host = host.strip("[]")
    if not sep or not host or not (port.isdigit() or (for_bind and port == "*")):
        raise FanoutError(f"'{text}': expected tcp://HOST:PORT, e.g. tcp://127.0.0.1:5600")
    return Endpoint(text, host, port)


def check_bind(text: str, have_keys: bool) -> Endpoint:
    """The endpoint to publish on, refused beyond loopback without CURVE keys."""
    ep = parse_endpoint(text, for_bind=True)
    if not ep.loopback and not have_keys:
        raise FanoutError(
            f"--publish {text} would let anyone on the network subscribe to the rig's "
            f"telemetry: publish on tcp://127.0.0.1:PORT, or give --curve-keys DIR "
            f"(create it with `groundstation fanout keys DIR`) so that only viewers "
            f"holding a lab key can subscribe")
    return ep


def read_only_message(endpoint: str) -> str:
    return READ_ONLY.format(endpoint=endpoint)
