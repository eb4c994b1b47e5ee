"""Why a watching console hears nothing although a station publishes: its ZeroMQ
handshakes, as the SUB socket's monitor reports them.

Without this a console whose security does not match the publisher's heard nothing and
was told "no station publishes" - ZeroMQ retries a failed handshake silently.  The
monitor sees each attempt: a publisher that requires CURVE keys and a console without
them (or the reverse) fail on the ZMTP mechanism (HANDSHAKE_FAILED_PROTOCOL with
PROTOCOL_ERROR_ZMTP_MECHANISM_MISMATCH); a key the publisher has not authorised fails
its ZAP check (HANDSHAKE_FAILED_AUTH, status 400); a wrong publisher.public fails the
CURVE exchange itself (HANDSHAKE_FAILED_NO_DETAIL).  Each becomes one sentence saying
what is the case and which option changes it.

A mismatch does not always show as one: the publisher may close the connection while
this side still writes its greeting, and then the monitor says only NO_DETAIL (EPIPE).
For such an answer probe_mechanism asks the publisher itself, over a plain TCP
connection, which security mechanism it speaks.
"""

from __future__ import annotations

import contextlib
import socket
import time
from urllib.parse import urlsplit

KEYS_DOC = "docs/consoles.md, 'Beyond this computer: CURVE keys'"
#: ZMTP 3 greeting (RFC 23): signature (10 bytes) and major version; the peer answers
#: with its whole greeting, the mechanism's name in bytes 12..31
_GREETING_START = b"\xff" + b"\0" * 8 + b"\x7f" + b"\x03"
_GREETING_SIZE = 64
PROBE_TIMEOUT_S = 1.0


def probe_mechanism(endpoint: str, timeout: float = PROBE_TIMEOUT_S) -> str | None:
    """The ZMTP security mechanism ("NULL", "CURVE", ...) the ZeroMQ socket bound at
    `endpoint` (tcp://HOST:PORT) speaks; None when nothing answers like one.

    Only the start of this side's greeting is sent: the publisher answers with its own
    whole greeting as soon as it sees our version, and never learns our mechanism, so
    it has nothing to refuse (it drops the half-open connection when we close)."""
    parts = urlsplit(endpoint)
    try:
        host, port = parts.hostname, parts.port
    except ValueError:
        return None
    if parts.scheme != "tcp" or not host or not port:
        return None
    deadline = time.monotonic() + timeout
    try:
        with socket.create_connection((host, port), timeout=timeout) as sock:
            sock.sendall(_GREETING_START)
            greeting = b""
            while len(greeting) < _GREETING_SIZE:
                left = deadline - time.monotonic()
                if left <= 0:
                    return None
                sock.settimeout(left)
                data = sock.recv(_GREETING_SIZE - len(greeting))
                if not data:
                    return None
                greeting += data
    except OSError:
        return None
    if greeting[0] != 0xFF or greeting[9] != 0x7F or greeting[10] < 3:
        return None                          # not ZMTP 3: not a station's publisher
    return greeting[12:32].rstrip(b"\0").decode("ascii", "replace") or None


class HandshakeWatch:
    """The monitor of one SUB socket; `drain()` in the socket's thread, `problem` after.

    `problem` is the newest failed handshake in words, "" when none failed or when one
    succeeded since (a publisher restarted with other settings); `certain` when it names
    a cause that retrying cannot cure (keys on one side only, a key refused, the wrong
    publisher key) - not so a handshake cut short by a publisher that was stopping."""

    def __init__(self, sock, endpoint: str, curve_keys: str | None, key_name: str):
        import zmq

        self.endpoint, self.curve_keys, self.key_name = endpoint, curve_keys, key_name
        self.problem = ""
        self.certain = False
        events = (zmq.EVENT_HANDSHAKE_FAILED_PROTOCOL | zmq.EVENT_HANDSHAKE_FAILED_NO_DETAIL
                  | zmq.EVENT_HANDSHAKE_FAILED_AUTH | zmq.EVENT_HANDSHAKE_SUCCEEDED)
        self._sock = sock
        self.monitor = sock.get_monitor_socket(events)

    def drain(self) -> bool:
        """Read the events waiting; True when `problem` changed."""
        import zmq
        from zmq.utils.monitor import recv_monitor_message

        before = self.problem
        unclear = False
        for _ in range(100):                 # bounded: a reconnect loop makes a few a second
            try:
                event = recv_monitor_message(self.monitor, zmq.NOBLOCK)
            except zmq.Again:
                break
            kind, value = int(event["event"]), int(event["value"])
            if kind == zmq.EVENT_HANDSHAKE_SUCCEEDED:
                self.problem, self.certain, unclear = "", False, False
            elif kind == zmq.EVENT_HANDSHAKE_FAILED_PROTOCOL \
                    and value == zmq.PROTOCOL_ERROR_ZMTP_MECHANISM_MISMATCH:
                self.problem, self.certain, unclear = self.mismatch(), True, False
            elif kind == zmq.EVENT_HANDSHAKE_FAILED_AUTH:
                self.problem, self.certain, unclear = self.refused(value), True, False
            elif not self.problem:
                unclear = (kind, value)
        if unclear:
            # asked once per failure seen, not at each of ZeroMQ's reconnects
            self.problem, self.certain = self.explain_unclear(*unclear,
                                                              probe_mechanism(self.endpoint))
        return self.problem != before

    def mismatch(self) -> str:
        """The publisher's mechanism is not this console's: keys on one side only."""
        where, keyed = self.endpoint, self.curve_keys is not None
        if not keyed:
            return (f"a station publishes on {where} but requires CURVE keys, and this "
                    f"console has none: watch with --curve-keys DIR --key-name NAME (DIR "
                    f"holding the lab's publisher.public and your NAME.public and "
                    f"NAME.secret, made by `groundstation fanout keys DIR --name NAME`; "
                    f"{KEYS_DOC})")
        return (f"a station publishes on {where} without CURVE keys, and this console "
                f"was given --curve-keys {self.curve_keys}: watch it without --curve-keys")

    def refused(self, value: int) -> str:
        where = self.endpoint
        return (f"the station publishing on {where} refused this console's CURVE key "
                f"{self.key_name}.public (status {value}): it is not in the publisher's "
                f"authorized/ folder - copy {self.curve_keys}/{self.key_name}.public into "
                f"authorized/ of the publisher's keys folder, or use a key that is there "
                f"(--key-name)")

    def explain_unclear(self, event: int, value: int, mechanism: str | None) -> tuple[str, bool]:
        """(problem, certain) of a failure the monitor gives no reason for, with the
        publisher's mechanism as probe_mechanism found it (None: nothing answered like
        a ZeroMQ socket)."""
        where, keyed = self.endpoint, self.curve_keys is not None
        if (mechanism == "CURVE") != keyed and mechanism in ("CURVE", "NULL"):
            return self.mismatch(), True
        if mechanism == "CURVE":
            # both sides speak CURVE and the publisher's ZAP check did not refuse us: the
            # exchange failed on the publisher's key this console trusts
            return (f"the CURVE handshake with the station publishing on {where} failed: "
                    f"{self.curve_keys}/publisher.public is not that publisher's key - copy "
                    f"its publisher.public again"), True
        return (f"a program answers on {where} but the ZeroMQ handshake with it failed "
                f"(monitor event {event}, value {value:#x}; it speaks "
                f"{mechanism or 'no ZeroMQ greeting'}): is it a station's publisher?"), False

    def close(self) -> None:
        # the socket may already be closing: then there is no monitor left to stop
        with contextlib.suppress(Exception):
            self._sock.disable_monitor()
        self.monitor.close(linger=0)


__all__ = ["HandshakeWatch", "KEYS_DOC"]
