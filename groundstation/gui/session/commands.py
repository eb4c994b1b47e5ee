"""The order in which the GUI's Session sends operator commands (no Qt here).

Each command blocks its sender until the device has answered, so it runs off the GUI
thread.  One thread per command would let a later command overtake an earlier one (an
ARM sent before its SET_MODE is refused); one sender for all of them keeps the
operator's order.  ABORT does not wait in line: the caller sends it at once on a thread
of its own after `drop_waiting()`, so nothing queued before an Esc - an ARM, a current
- reaches the device after the ABORT.
"""

from __future__ import annotations

import threading
from collections import deque
from typing import Callable

#: runs `target` on a new worker thread named `name` (the Session's `_worker`, which
#: shutdown() joins)
StartThread = Callable[[Callable[[], None], str], None]


class CommandQueue:
    """Commands waiting for the one sender thread, in the order given."""

    def __init__(self, start_thread: StartThread):
        self._start_thread = start_thread
        self._waiting: deque[tuple[str, Callable[[], None]]] = deque()
        self._lock = threading.Lock()
        self._sending = False

    def submit(self, name: str, send: Callable[[], None]) -> None:
        """Queue `send` (which sends command `name` and waits for its end)."""
        with self._lock:
            self._waiting.append((name, send))
            if self._sending:
                return                  # the running sender takes it in turn
            self._sending = True
        self._start_thread(self._send_all, "gs-commands")

    def drop_waiting(self) -> list[str]:
        """Forget what has not been sent yet; returns those commands' names, in order.
        The one being sent, if any, goes on to its end."""
        with self._lock:
            dropped = [name for name, _ in self._waiting]
            self._waiting.clear()
        return dropped

    def _send_all(self) -> None:
        while True:
            with self._lock:
                if not self._waiting:
                    self._sending = False
                    return
                _, send = self._waiting.popleft()
            send()


__all__ = ["CommandQueue"]
