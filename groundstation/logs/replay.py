"""Replay of a recorded log through the same interface as the live link.

`ReplaySource` looks to its consumers like a `DeviceClient`: `subscribe(cb)` receives
`TelemetryBlock`s in a worker thread, `add_link_listener(cb(state, message))`,
`stats` (a `LinkStatistics` fed with every block before the subscribers see it),
`link_state`, `close()` and use as a context manager.  The blocks, their order and the
device-time timeline come from blocks.py (`BlockMerger`, also behind `iter_blocks`);
this module adds the worker thread, the controls and the pacing.

Timing
    Playback is paced by *device* time: at speed s, a frame is delivered at wall time
    t0 + (T - T0) / s, where T is the merged timeline's device time (its running
    maximum along the arrival order).  The worker wakes at most ~60 times a second and
    delivers what is due, in blocks of at most 1/60 s of device time; with speed None
    ("max") it delivers whole runs as fast as the subscribers take them.

Times given to `seek` and reported by `position`, `start_time` and `end_time` are
device times in seconds as recorded in `/telemetry/<PACKET>/device_time` (unwrapped
device tick / tick rate).
"""

from __future__ import annotations

import logging
import math
import threading
import time
from collections import deque
from pathlib import Path
from typing import Any, Callable

import numpy as np

from ..core.callbacks import TelemetryOutlet
from ..core.kinds import LinkState
from ..codec import TelemetryBlock
from ..core.dictionary import Dictionary
from ..core.errors import GroundStationError
from ..link.stats import LinkStatistics
# ReplayError, ReplayDamagedError, iter_blocks and MAIN_PACKET were defined here before
# the split; callers and tests still import them from this module
from .blocks import BlockMerger, _Window

log = logging.getLogger(__name__)

MIN_SPEED = 0.1
MAX_SPEED = 50.0
DELIVERY_PERIOD_S = 1.0 / 60.0     # worker wake-up period and device time per paced block


def _check_speed(speed: Any) -> float | None:
    if speed is None or (isinstance(speed, str) and speed.lower() == "max"):
        return None
    if isinstance(speed, bool) or not isinstance(speed, (int, float, np.integer, np.floating)):
        raise ValueError(f"replay speed must be a number from {MIN_SPEED} to {MAX_SPEED} "
                         f"or None/'max', not {speed!r}")
    s = float(speed)
    if not MIN_SPEED <= s <= MAX_SPEED:     # NaN fails this too
        raise ValueError(f"replay speed {speed} is outside {MIN_SPEED}..{MAX_SPEED} "
                         f"(use None or 'max' for as fast as possible)")
    return s


class ReplaySource(TelemetryOutlet):
    """A recorded log played back through the live link's consumer interface.

    Starts paused at the beginning; `play()`, `pause()`, `step(n)`, `seek(t)`,
    `seek_fraction(x)` and `speed` may be used from any thread (they only post a request
    to the worker, which does all the file I/O and calls the subscribers).  Listeners
    get ('finished', '') at the end, ('up', '') when a seek or play leaves the end, ('lost',
    message) if the file fails while playing, and ('closed', '') on close().

    `stats` is fed every block before the subscribers, so the sequence gaps recorded
    live count as the same drops and gap events (with their recorded arrival times).  A
    seek resets it (a jump is not a drop).  play() at the end looks
    for rows a recorder appended since; to play again from the start, seek first.
    """

    def __init__(self, path: str | Path, *, dictionary: Dictionary | None = None,
                 speed: float | str | None = 1.0, main_packet: str | None = None,
                 chunk_seconds: float = 4.0):
        self._speed = _check_speed(speed)
        self._reader = BlockMerger(path, dictionary, main_packet, chunk_seconds)
        self.path = self._reader.path
        self.dictionary = self._reader.dictionary
        self.codec = self._reader.codec
        self.attrs = self._reader.attrs
        self.main_packet = self._reader.main_track.pkt.name
        self.stats = LinkStatistics(self.dictionary.control_rate_hz)
        self.link_state = LinkState.UP
        self.link_error = ""
        self.error: Exception | None = None     # what stopped the replay ('lost'), if anything
        self.frames_delivered = 0
        super().__init__("replay", log)
        rng = self._reader.time_range()
        self._start_time, self._end_time = rng if rng else (0.0, 0.0)
        self._position: float | None = None
        self._cv = threading.Condition()
        self._ops: deque[tuple[str, Any]] = deque()
        self._playing = False
        self._closed = False
        self._idle = True
        self._reanchor = True
        self._finished = threading.Event()
        self._window: _Window | None = None
        self._thread = threading.Thread(target=self._run, name="gs-replay", daemon=True)
        self._thread.start()

    # --------------------------------------------------------------- consumer interface
    def _notify(self, state: str, message: str = "") -> None:
        self._link_listeners(state, message)

    # --------------------------------------------------------------- controls
    def play(self) -> None:
        """Play from the current position at `speed` (at the end: look for new rows)."""
        with self._cv:
            if self._finished.is_set():
                self._ops.append(("resume", None))
            self._playing = True
            self._reanchor = True
            self._idle = False
            self._cv.notify_all()

    def pause(self) -> None:
        """Stop after the block being delivered; the position is kept."""
        with self._cv:
            self._playing = False
            self._cv.notify_all()

    def step(self, n: int = 1) -> None:
        """Pause, then deliver the next n frames of the main packet together with the
        other packets' frames that arrived before them."""
        n = int(n)
        if n < 1:
            raise ValueError(f"step count must be at least 1, not {n}")
        with self._cv:
            self._playing = False
            self._ops.append(("step", n))
            self._cv.notify_all()

    def seek(self, device_time_s: float) -> None:
        """Continue (playing or paused) from the first main-packet frame at or after
        `device_time_s`; sequence statistics start afresh (see `stats`)."""
        t = float(device_time_s)
        if math.isnan(t):
            raise ValueError("cannot seek to NaN")
        with self._cv:
            self._ops.append(("seek", t))
            self._reanchor = True
            self._cv.notify_all()

    def seek_fraction(self, fraction: float) -> None:
        """Seek to a fraction 0..1 of the duration."""
        x = float(fraction)
        if not 0.0 <= x <= 1.0:
            raise ValueError(f"seek fraction {fraction} is outside 0..1")
        self.seek(self._start_time + x * (self._end_time - self._start_time))

    @property
    def speed(self) -> float | None:
        """Playback speed 0.1..50, or None for as fast as possible."""
        return self._speed

    @speed.setter
    def speed(self, value: float | str | None) -> None:
        s = _check_speed(value)
        with self._cv:
            self._speed = s
            self._reanchor = True
            self._cv.notify_all()

    @property
    def playing(self) -> bool:
        return self._playing and not self._finished.is_set()

    @property
    def position(self) -> float | None:
        """Device time (s) of the last delivered frame; after a seek, of the frame it
        landed on until the next delivery; None before anything was delivered."""
        return self._position

    @property
    def start_time(self) -> float:
        """Device time (s) of the first main-packet frame."""
        return self._start_time

    @property
    def end_time(self) -> float:
        return self._end_time

    @property
    def duration(self) -> float:
        """Device time (s) from the first to the last main-packet frame known so far."""
        return self._end_time - self._start_time

    @property
    def finished(self) -> bool:
        return self._finished.is_set()

    @property
    def finished_event(self) -> threading.Event:
        return self._finished

    def wait_finished(self, timeout: float | None = None) -> bool:
        return self._finished.wait(timeout)

    def wait_idle(self, timeout: float | None = None) -> bool:
        """Wait until every posted step/seek is done and nothing is playing (paused or at
        the end); True if so within the timeout."""
        deadline = None if timeout is None else time.monotonic() + timeout
        with self._cv:
            while not self._closed and not (self._idle and not self._ops):
                left = None if deadline is None else deadline - time.monotonic()
                if left is not None and left <= 0:
                    return False
                self._cv.wait(left)
            return True

    def close(self) -> None:
        """Stop the worker and close the file; safe to call twice, from any thread."""
        with self._cv:
            if self._closed:
                return
            self._closed = True
            self._cv.notify_all()
        if threading.current_thread() is not self._thread:
            self._thread.join(timeout=5.0)
        self.link_state = LinkState.CLOSED
        self._notify("closed", "")

    def __enter__(self) -> "ReplaySource":
        return self

    def __exit__(self, *exc) -> None:
        self.close()

    # --------------------------------------------------------------- worker
    def _run(self) -> None:
        try:
            self._loop()
        except Exception as exc:  # a damaged or vanished file: say so, keep the app running
            self.error = exc
            if isinstance(exc, GroundStationError):
                # says what and where, and the consumer gets it (`error`, the 'lost'
                # listener): no traceback, and nothing on a terminal beside its report
                msg = f"replay of {self.path.name} stopped: {exc}"
                log.info(msg)
            else:
                msg = f"replay of {self.path.name} stopped: {type(exc).__name__}: {exc}"
                log.exception(msg)
            self.link_error = msg
            self.link_state = LinkState.LOST
            with self._cv:
                self._idle = True
                self._ops.clear()
                self._cv.notify_all()
            self._finished.set()
            self._notify("lost", msg)
        finally:
            self._reader.close()

    def _loop(self) -> None:
        anchor_wall = anchor_t = 0.0
        last_wake = -math.inf
        while True:
            with self._cv:
                while not self._closed and not self._ops and not (
                        self._playing and not self._finished.is_set()):
                    self._idle = True
                    self._cv.notify_all()
                    self._cv.wait()
                if self._closed:
                    return
                self._idle = False
                op = self._ops.popleft() if self._ops else None
                speed = self._speed
                reanchor = False
                if op is None:          # a seek's re-anchoring waits for the seek to be done
                    reanchor, self._reanchor = self._reanchor, False
            if op is not None:
                self._operation(*op)
                continue
            w = self._current()
            if w is None:
                continue
            if speed is None:
                self._deliver(w, len(w), self._interrupted)
                continue
            now = time.monotonic()
            if reanchor:
                anchor_wall = now
                anchor_t = self._position if self._position is not None else float(w.timeline[w.k])
                anchor_t = min(anchor_t, float(w.timeline[w.k]))
            limit = anchor_t + (now - anchor_wall) * speed
            due = int(np.searchsorted(w.timeline, limit, side="right"))
            k = w.k
            while k < due:      # blocks of at most DELIVERY_PERIOD_S of device time
                k_end = max(k + 1, int(np.searchsorted(w.timeline, w.timeline[k] + DELIVERY_PERIOD_S,
                                                       side="left")))
                k = self._deliver(w, min(k_end, due), self._interrupted)
                if self._interrupted():
                    break
            if k < len(w) and k >= due:
                last_wake = now
                next_due = anchor_wall + (float(w.timeline[k]) - anchor_t) / speed
                wake = max(next_due, last_wake + DELIVERY_PERIOD_S)
                with self._cv:
                    if not self._closed and not self._ops and not self._reanchor and self._playing:
                        self._cv.wait(max(0.0, wake - time.monotonic()))

    def _closing(self) -> bool:
        return self._closed

    def _interrupted(self) -> bool:
        with self._cv:
            return self._closed or bool(self._ops) or self._reanchor or not self._playing

    def _current(self) -> _Window | None:
        """The window being delivered; the next one when it is used up; None at the end."""
        w = self._window
        if w is not None and w.k < len(w):
            return w
        w = self._window = self._reader.next_window()
        if w is None:
            self._set_finished()
        else:
            rng = self._reader.time_range()
            if rng:
                self._start_time, self._end_time = rng
        return w

    def _set_finished(self) -> None:
        rng = self._reader.time_range()
        if rng:
            self._start_time, self._end_time = rng
        if not self._finished.is_set():
            self._finished.set()
            self._notify("finished", "")

    def _clear_finished(self) -> None:
        if self._finished.is_set():
            self._finished.clear()
            self._notify("up", "")

    def _deliver(self, w: _Window, k_end: int, stop: Callable[[], bool] | None = None) -> int:
        """Deliver merged frames w.k .. k_end block by block: stats first, then the
        subscribers; `stop()` is asked after each block.  Returns the index reached."""
        for k, block in self._reader.runs(w, w.k, k_end):
            self.stats.update(block)
            self._subscribers(block)
            self.frames_delivered += k - w.k
            self._position = float(w.timeline[k - 1])
            w.k = k
            if stop is not None and k < k_end and stop():
                break
        return w.k

    def _operation(self, kind: str, arg: Any) -> None:
        if kind == "seek":
            rows, landed = self._reader.locate(arg)
            self._reader.reset(rows)
            self._window = None
            self.stats.reset()
            rng = self._reader.time_range()
            if rng:
                self._start_time, self._end_time = rng
            if landed is not None:
                self._position = landed
                self._clear_finished()
            else:
                self._position = self._end_time if rng else None
                self._set_finished()
        elif kind == "resume":
            w = self._window
            if (w is not None and w.k < len(w)) or self._reader.refresh():
                self._clear_finished()
        elif kind == "step":
            remaining = arg
            while remaining > 0:
                with self._cv:
                    if self._closed:
                        return
                w = self._current()
                if w is None:
                    return
                main = np.flatnonzero(w.track[w.k:] == self._reader.main)[:remaining]
                if len(main) == remaining:
                    self._deliver(w, w.k + int(main[-1]) + 1, self._closing)
                    return
                remaining -= len(main)
                self._deliver(w, len(w), self._closing)


__all__ = ["DELIVERY_PERIOD_S", "MAX_SPEED", "MIN_SPEED", "ReplaySource"]
