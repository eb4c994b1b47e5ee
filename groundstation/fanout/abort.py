"""ABORT from a read-only console, straight to the device (SPEC §7: any host, no token).

The viewer learns the device's address from the publisher's hello and opens a command
connection of its own for the one command; the device answers on that connection and
the commander's session is untouched (a non-owner connection closing ends nothing).

Where the device is:
* tcp (UDP or stream telemetry): ABORT goes over TCP to the device's command port, the
  one transport a host sends on (the host sends nothing over UDP, SPEC §1.1).  A device
  the commander reached on loopback is reached at the publisher's host instead when the
  viewer watches from another machine (the commander and the device then share a host);
* serial: not possible.  The serial line is held by the commanding station and carries
  one host; the viewer says so and names the station to press Abort on.  Relaying it
  through the publisher was not done on purpose: it would turn the read-only PUB socket
  into a way for a subscriber to put commands on the commander's link.
"""

from __future__ import annotations

from typing import Any

from ..core.errors import LinkError
from .endpoints import LOOPBACK_NAMES, parse_endpoint


class AbortUnreachable(LinkError):
    """A viewer cannot reach the device to ABORT (the message says why and what to do)."""


def abort_target(device: dict[str, Any] | None, watching: str) -> tuple[str, int]:
    """(host, port) of the device's command channel, or AbortUnreachable."""
    if not device:
        raise AbortUnreachable(
            f"ABORT from this console: the publisher at {watching} has not said where the "
            f"device is yet (no hello received) - press Abort (Esc) on the commanding station")
    if device.get("kind") != "tcp":
        raise AbortUnreachable(
            f"ABORT from this console is impossible: the device is on a serial line "
            f"({device.get('address', device.get('port', '?'))}) held by the commanding "
            f"station, and a serial line carries one host - press Abort (Esc) on that station")
    host, port = str(device["host"]), int(device["port"])
    watched = parse_endpoint(watching, for_bind=False)
    if host in LOOPBACK_NAMES and watched.host not in LOOPBACK_NAMES:
        host = watched.host            # the device is beside the commander, not beside us
    return host, port


def send_abort(dictionary, device: dict[str, Any] | None, watching: str, *,
               on_result=None, connect_timeout: float = 2.0):
    """ABORT on a connection of this console's own; returns the CommandResult.
    `on_result(result)` hears how it ended, refused or timed out too (for the journal)."""
    from ..link.address import open_command_link

    host, port = abort_target(device, watching)
    try:
        client = open_command_link(dictionary, host, port, connect_timeout=connect_timeout)
    except LinkError as exc:
        raise AbortUnreachable(f"ABORT: cannot reach the device at {host}:{port} from this "
                               f"console ({exc}) - press Abort (Esc) on the commanding "
                               f"station") from None
    if on_result is not None:
        client.add_command_listener(on_result)
    try:
        return client.command("ABORT")
    finally:
        client.close()
