"""A list of callbacks that a source of events calls in turn.

The live link, a log replay and a read-only console each deliver telemetry blocks, link
states and finished commands to whoever subscribed: the charts, the recorder, the
journal, a script.  They share one rule, kept here: a callback that raises is logged
and counted and the others are still called, because a broken chart must not take the
link (or the replay, or the console) down with it.  Adding and removing may happen on
any thread while the source calls: each call walks a copy of the list.
"""

from __future__ import annotations

import logging
from typing import Any, Callable


class Callbacks:
    """Callbacks called in the order they were added, those added `last` after all the
    others; `failures` counts the raises."""

    def __init__(self, what: str, logger: logging.Logger) -> None:
        #: what a callback is, for the log line of a failure ("telemetry subscriber")
        self.what = what
        self.failures = 0
        self._log = logger
        self._callbacks: list[Callable[..., Any]] = []
        self._last: list[Callable[..., Any]] = []

    def add(self, callback: Callable[..., Any], last: bool = False) -> None:
        """`last`: called after every callback not added `last`, whenever those were
        added - for an observer whose "it arrived" must mean "everyone has it"."""
        (self._last if last else self._callbacks).append(callback)

    def remove(self, callback: Callable[..., Any]) -> None:
        """Stop calling `callback`; no error if it was never added (or already removed)."""
        for callbacks in (self._callbacks, self._last):
            if callback in callbacks:
                callbacks.remove(callback)
                return

    def __call__(self, *args: Any) -> None:
        for callback in self._callbacks + self._last:
            try:
                callback(*args)
            except Exception:
                self.failures += 1
                self._log.exception("%s %r failed", self.what, callback)

    def __len__(self) -> int:
        return len(self._callbacks) + len(self._last)

    def __contains__(self, callback: object) -> bool:
        return callback in self._callbacks or callback in self._last


class TelemetryOutlet:
    """The subscriber side of a telemetry source - the TelemetrySource contract's
    subscribe/unsubscribe and link listeners - for the live link, a log replay and a
    read-only console alike.  The source calls `self._subscribers(block)` for each
    block it delivers and `self._link_listeners(state, message)` when its state changes
    (each source's class says which states it reports)."""

    def __init__(self, what: str, logger: logging.Logger) -> None:
        self._subscribers = Callbacks(f"{what} subscriber", logger)
        self._link_listeners = Callbacks(f"{what} link listener", logger)

    @property
    def subscriber_errors(self) -> int:
        """How many times a subscriber raised (each is logged, the others still called)."""
        return self._subscribers.failures

    def subscribe(self, callback: Callable[[Any], None], *, after_others: bool = False) -> None:
        """Call `callback(block)` for every block delivered, on the source's own thread.
        `after_others`: after every other subscriber, even those subscribed later (the
        fast clock's "received": a recorder subscribed after it must have the block too)."""
        self._subscribers.add(callback, last=after_others)

    def unsubscribe(self, callback: Callable[[Any], None]) -> None:
        """Stop calling `callback` (no error if it was not subscribed)."""
        self._subscribers.remove(callback)

    def add_link_listener(self, callback: Callable[[str, str], None]) -> None:
        """Call `callback(state, message)` when the source's state changes."""
        self._link_listeners.add(callback)

    def remove_link_listener(self, callback: Callable[[str, str], None]) -> None:
        self._link_listeners.remove(callback)
