"""The VISA session to the generator and its fail-safe link.

One job: getting bytes to and from the instrument, and getting its outputs off whatever
happens.  Opening a resource on any pyvisa backend, one transaction at a time (a lock),
every backend failure turned into one `InstrumentLinkError` line that says what to check,
and the outputs switched off at the end - on the session, or on a fresh one if the
session died.  What the commands mean is the driver's business (`fg4050`).

pyvisa is imported only when a resource manager is made, so importing the station does
not need it.
"""

from __future__ import annotations

import atexit
import logging
import re
import socket
import threading
import warnings
from dataclasses import dataclass

import numpy as np

from . import spec4050 as spec
from .fg_errors import InstrumentError, InstrumentLinkError

log = logging.getLogger(__name__)

DEFAULT_BACKEND = "@py"
SHUTDOWN_TIMEOUT_MS = 1000          # closing must not hang on a dead link


@dataclass(frozen=True)
class ResourceListing:
    backend: str
    resources: tuple[str, ...]
    notes: tuple[str, ...]       # why a backend could not list, backend warnings


def normalise_backend(backend: str | None) -> str:
    """None -> '@py'; 'tests/fg.yaml' -> 'tests/fg.yaml@sim'."""
    if not backend:
        return DEFAULT_BACKEND
    if backend.endswith((".yaml", ".yml")):
        return backend + "@sim"
    return backend


def resource_manager(backend: str):
    import pyvisa

    try:
        return pyvisa.ResourceManager(backend)
    except (OSError, ValueError, ImportError, pyvisa.errors.Error) as exc:
        hint = (" (install a vendor VISA library, or use @py)" if backend == "@ivi"
                else "")
        raise InstrumentLinkError(f"VISA backend {backend!r} is not available: "
                                  f"{_brief(exc)}{hint}") from None


def _brief(exc: BaseException, limit: int = 300) -> str:
    """One readable line from a backend's exception (pyvisa-sim puts whole tracebacks
    into its messages): the last 'SomethingError: ...' line if there is one."""
    lines = [ln.strip().strip("'\\n") for ln in str(exc).replace("\\n", "\n").splitlines()]
    lines = [ln for ln in lines if ln]
    if not lines:
        return type(exc).__name__
    errors = [ln for ln in lines if re.match(r"^[A-Za-z_.]*(Error|Exception): ", ln)]
    text = errors[-1] if errors else lines[0]
    return text if len(text) <= limit else text[:limit] + "..."


def list_resources(backend: str | None = None, query: str = "?*::INSTR") -> ResourceListing:
    """The VISA resources a backend can see; never raises.

    pyvisa-py reports the limits of its discovery (no psutil, no zeroconf, no USB
    library) as warnings: they are returned as notes for the user (and logged) instead
    of being printed by the warnings machinery."""
    backend = normalise_backend(backend)
    notes: list[str] = []
    found: tuple[str, ...] = ()
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        try:
            rm = resource_manager(backend)
        except InstrumentLinkError as exc:
            notes.append(str(exc))
        else:
            try:
                found = tuple(rm.list_resources(query))
            except Exception as exc:      # any backend failure means "nothing found here"
                notes.append(f"listing {query} on {backend} failed: {exc}")
            finally:
                release_manager(rm)
    for w in caught:
        if issubclass(w.category, ResourceWarning):   # the backend's own leak, not news
            log.debug("%s: %s", backend, w.message)
        else:
            notes.append(str(w.message))
    for note in notes:
        log.info("VISA listing: %s", note)
    return ResourceListing(backend, found, tuple(notes))


def release_manager(rm) -> None:
    """Close a resource manager unless sessions are still open through it.

    pyvisa hands out one ResourceManager per VISA library (ResourceManager("@py") twice
    is the same object), and closing it closes every session opened through it: listing
    the resources, or closing one generator, must not cut another generator off."""
    try:
        if rm.list_opened_resources():
            return
        rm.close()
    except Exception as exc:
        log.debug("closing the resource manager: %s", exc)


def _is_timeout(exc: BaseException) -> bool:
    import pyvisa

    return (isinstance(exc, pyvisa.errors.VisaIOError)
            and exc.error_code == pyvisa.constants.StatusCode.error_timeout)


def io_failure(exc: BaseException, *, reading: bool, timeout_ms: int | None, backend: str) -> str:
    """Why one VISA transaction failed, in one line that says what to do about it.

    Anything a backend raises while a message goes out or a reply comes back is an I/O
    failure to the driver: VISA errors, dropped sockets, and also a reply that is not text
    (UnicodeDecodeError from pyvisa's decoding) or a message a backend could not take
    (pyvisa-sim decodes every message it receives as UTF-8)."""
    if _is_timeout(exc):
        t = f"{timeout_ms / 1000:g} s" if timeout_ms else "the VISA timeout"
        return (f"no answer within {t} (VISA timeout): check that the generator is on and "
                f"connected and that this is its address (a slow instrument needs a longer "
                f"--timeout)")
    if isinstance(exc, UnicodeDecodeError):
        bad = exc.object[exc.start:exc.start + 8]
        if reading:
            return (f"the reply is not text (byte {bad[:1]!r} at position {exc.start} cannot be "
                    f"decoded as {exc.encoding}): the link is corrupting data, or another "
                    f"program is talking to the instrument - check the cable and close other "
                    f"VISA programs")
        hint = (" - pyvisa-sim cannot carry binary data" if backend.endswith("@sim") else "")
        return (f"the VISA backend {backend} could not take the message (it decodes it as "
                f"{exc.encoding} and byte {bad[:1]!r} at position {exc.start} is not text){hint}")
    if isinstance(exc, UnicodeEncodeError):
        return f"the message is not ASCII text ({exc.reason} at position {exc.start})"
    text = _brief(exc)
    name = type(exc).__name__
    return text if text.startswith(name) else f"{name}: {text}"


def shorten(command: str, n: int = 120) -> str:
    """A command as quoted in a message (an upload header can be long)."""
    return command if len(command) <= n else command[:n] + "..."


class VisaLink:
    """The VISA session and what it takes to switch the outputs off at the end.

    Holds no reference to the driver, so a weakref finaliser and an atexit handler can
    use it after the driver is gone."""

    def __init__(self, rm, resource_name: str, backend: str, timeout_ms: int):
        self.rm = rm
        self.resource_name = resource_name
        self.backend = backend
        self.timeout_ms = timeout_ms
        self.lock = threading.RLock()
        self.inst = None
        self.closed = False
        #: set once *IDN? named a 4050-series generator: only then does shutdown send
        #: output commands (never to an instrument of unknown kind, nor to nothing)
        self.is_generator = False

    def open_session(self, timeout_ms: int | None = None):
        inst = self.rm.open_resource(self.resource_name, read_termination="\n",
                                     write_termination="\n",
                                     timeout=timeout_ms or self.timeout_ms)
        _no_delay(inst, self.resource_name)
        return inst

    @staticmethod
    def _off(inst) -> None:
        """Both outputs off, confirmed by *OPC? (a write alone may vanish into a dead socket)."""
        for ch in spec.CHANNELS:
            inst.write(f"C{ch}:OUTP OFF")
        if inst.query("*OPC?").strip() not in ("1", "+1"):
            raise InstrumentError("the generator did not confirm switching its outputs off")

    def outputs_off(self, *, reopen: bool = True) -> None:
        """Switch both outputs off on the session or, if it is dead, on a new one."""
        with self.lock:
            first: Exception | None = None
            if self.inst is not None:
                try:
                    self._off(self.inst)
                    return
                except Exception as exc:       # dead link: try again on a fresh session
                    first = exc
            if not reopen:
                raise InstrumentLinkError(f"could not switch the outputs of {self.resource_name} "
                                          f"off: {first}")
            try:
                inst = self.open_session(SHUTDOWN_TIMEOUT_MS)
            except Exception as exc:
                raise InstrumentLinkError(
                    f"could not switch the outputs of {self.resource_name} off: {first or exc}; "
                    f"re-opening failed: {exc}") from None
            try:
                self._off(inst)
            except Exception as exc:
                self._close_quietly(inst)
                raise InstrumentLinkError(f"could not switch the outputs of {self.resource_name} "
                                          f"off: {exc}") from None
            self._close_quietly(self.inst)
            inst.timeout = self.timeout_ms
            self.inst = inst
            log.warning("%s: the session had failed (%s); outputs switched off on a new one",
                        self.resource_name, first)

    @staticmethod
    def _close_quietly(obj) -> None:
        if obj is None:
            return
        try:
            obj.close()
        except Exception as exc:
            log.debug("closing %r: %s", obj, exc)

    def shutdown(self) -> None:
        """Outputs off, session and resource manager closed.  Idempotent; never raises."""
        with self.lock:
            if self.closed:
                return
            self.closed = True
            atexit.unregister(self.shutdown)        # never raises, registered or not
            if self.is_generator:
                try:
                    if self.inst is not None:
                        self.inst.timeout = SHUTDOWN_TIMEOUT_MS
                    self.outputs_off()
                except Exception as exc:
                    log.error("%s: outputs may still be ON: %s", self.resource_name, exc)
            self._close_quietly(self.inst)
            self.inst = None
            release_manager(self.rm)


    # ------------------------------------------------------------------ transactions
    def require_open(self) -> None:
        if self.closed:
            raise InstrumentLinkError(f"{self.resource_name} is closed")

    def io_error(self, what: str, exc: BaseException, *, reading: bool = False
                 ) -> InstrumentLinkError:
        # the backend's traceback is for a developer (debug log), the line for the user
        log.debug("%s: %s failed", self.resource_name, what, exc_info=exc)
        why = io_failure(exc, reading=reading, timeout_ms=self.timeout_ms, backend=self.backend)
        return InstrumentLinkError(f"{self.resource_name}: {what} failed: {why}")

    def query(self, command: str) -> str:
        """Send a query and return the reply line.  Any failure of the exchange (VISA
        error, timeout, dropped link, a reply that is not text) raises InstrumentLinkError
        naming the query and what to check."""
        self.require_open()
        with self.lock:
            try:
                return self.inst.query(command).strip()
            except Exception as exc:          # whatever the backend raised: an I/O failure
                raise self.io_error(f"query {command!r}", exc, reading=True) from None

    def write(self, command: str, binary: np.ndarray | None = None) -> None:
        """Send a command, with `binary` int16 samples appended (little-endian, no block
        header: the command's own LENGTH frames them)."""
        self.require_open()
        with self.lock:
            try:
                if binary is None:
                    self.inst.write(command)
                else:
                    self.inst.write_binary_values(command, binary, datatype="h",
                                                  is_big_endian=False, header_fmt="empty")
            except Exception as exc:          # whatever the backend raised: an I/O failure
                what = (f"sending {shorten(command)!r}" if binary is None else
                        f"sending {shorten(command)!r} with {2 * len(binary)} bytes of samples")
                raise self.io_error(what, exc) from None


__all__ = ["DEFAULT_BACKEND", "ResourceListing", "VisaLink", "io_failure", "list_resources",
           "normalise_backend", "resource_manager", "shorten"]


def _no_delay(inst, resource_name: str) -> None:
    """Small writes sent at once on a raw TCP socket (TCP_NODELAY).  A checked setting is
    the command, then `*ESR?`: two small writes in a row.  With Nagle's algorithm the
    second waits until the instrument acknowledges the first, and an instrument with
    nothing to answer to a setting delays that acknowledgement (about 40 ms on Linux):
    44 ms per checked setting, 0.18 s per base-motion upload, measured on the simulated
    generator.  VISA names this VI_ATTR_TCPIP_NODELAY, but pyvisa-py (0.8) does not
    accept it on a SOCKET resource, so the option is set on its socket.  Other
    resources (USB, VXI-11, pyvisa-sim, another backend) are left as they are."""
    if not resource_name.upper().endswith("::SOCKET"):
        return
    session = getattr(getattr(inst, "visalib", None), "sessions", {}).get(getattr(inst, "session", None))
    sock = getattr(session, "interface", None)
    if not isinstance(sock, socket.socket):
        log.debug("%s: TCP_NODELAY not set (no socket of pyvisa-py's); small writes may wait "
                  "for an acknowledgement", resource_name)
        return
    try:
        sock.setsockopt(socket.IPPROTO_TCP, socket.TCP_NODELAY, 1)
    except OSError as exc:
        log.debug("%s: TCP_NODELAY not set (%s)", resource_name, exc)
