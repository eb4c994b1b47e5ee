"""A pseudo-terminal pair for serving the simulated device on a "serial port".

The device keeps the master side; the ground station opens the slave's name
(/dev/pts/N) with pyserial exactly as it would open /dev/ttyUSB0.  Both sides are put in
raw mode so no byte is translated.
"""

from __future__ import annotations

import os
import select
import tty

from ..core.errors import LinkLostError
from ..link.transports import StreamTransport


class PtyMasterStream(StreamTransport):
    def __init__(self) -> None:
        super().__init__()
        self._master, self._slave = os.openpty()
        tty.setraw(self._master)
        tty.setraw(self._slave)
        self.slave_name = os.ttyname(self._slave)
        self.name = f"pty-master({self.slave_name})"

    def _write(self, data: bytes) -> None:
        view = memoryview(data)
        while view:
            try:
                n = os.write(self._master, view)
            except OSError as exc:
                raise LinkLostError(f"{self.name}: write failed ({exc.strerror})") from None
            view = view[n:]

    def _read(self, timeout: float) -> bytes:
        try:
            ready, _, _ = select.select([self._master], [], [], timeout)
            if not ready:
                return b""
            return os.read(self._master, 65536)
        except OSError as exc:
            raise LinkLostError(f"{self.name}: read failed ({exc.strerror})") from None

    def _close(self) -> None:
        for fd in (self._master, self._slave):
            try:
                os.close(fd)
            except OSError:
                pass
