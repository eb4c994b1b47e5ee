"""How a script's time passes: on a real device, wall time; on the simulated testbed in
fast mode, as fast as the simulator, the link and the recorder can go.

`WallClock.advance(seconds)` sleeps (in short steps, so an abort or a lost link ends the
wait at once).  `SteppedClock` drives a manually paced SimulatedDevice:

- while a script is *not* in advance() (sending commands, uploading a table, waiting
  for an instrument) an idle thread runs the device at the real-time rate, so
  HOUSEKEEPING, heartbeats and the watchdog behave exactly as on a rig;
- advance() runs the device in chunks as fast as it can, and after each chunk waits
  until the host has received the chunk's last frame (flow control: nothing is dropped
  and a recording keeps up) and sends a HEARTBEAT (the watchdog counts device time, and
  the host's own heartbeat thread runs in wall time, far too rarely for a fast clock).
"""

from __future__ import annotations

import contextlib
import threading
import time
from typing import Callable, Iterator

from .errors import GroundStationError, LinkLostError

#: device periods per chunk of a fast advance: 0.75 s, inside the 1 s watchdog even
#: counting the HEARTBEAT's own round trip
CHUNK_TICKS = 900
#: how long one chunk's frames may take to arrive before the link is declared stalled
FLOW_TIMEOUT_S = 10.0


class ScriptAborted(GroundStationError):
    """The operator (or a failure elsewhere) aborted the script."""


class WallClock:
    """Real time: the device runs by itself."""

    fast = False

    def __init__(self, client, abort: threading.Event):
        self.client = client
        self.abort = abort

    def advance(self, seconds: float, progress: Callable[[float], None] | None = None,
                until: Callable[[], bool] | None = None) -> None:
        """Wait `seconds` (or until `until()` is true); raise on abort or a lost link."""
        end = time.monotonic() + seconds
        while True:
            now = time.monotonic()
            if self.abort.is_set():
                raise ScriptAborted("aborted")
            if self.client.link_state != "up":
                raise LinkLostError(f"link {self.client.link_state}: {self.client.link_error}")
            if until is not None and until():
                return
            if now >= end:
                return
            if progress is not None:
                progress(1.0 - (end - now) / seconds if seconds > 0 else 1.0)
            time.sleep(min(0.05, end - now))

    @contextlib.contextmanager
    def fast_forward(self) -> Iterator[None]:
        """Real time cannot be hurried."""
        yield

    def close(self) -> None:
        pass


class SteppedClock:
    """Device time driven by the script (a SimulatedDevice with pacing='manual')."""

    fast = True

    def __init__(self, device, client, abort: threading.Event):
        self.device = device
        self.client = client
        self.abort = abort
        self.rate = device.dictionary.control_rate_hz
        # a chunk's frames arrive all at once: the receiver need not wait for more to gather
        client.telemetry_batch_s = 0.001
        self._last_tick = -1
        self._seen = threading.Condition()
        client.subscribe(self._on_block)
        self._lock = threading.Lock()          # one of idle / advance runs the device
        self._stop = threading.Event()
        self._fast = threading.Event()         # fast_forward(): the idle thread runs flat out
        self.error: BaseException | None = None
        self._idle = threading.Thread(target=self._idle_loop, name="gs-sim-idle-clock", daemon=True)
        self._idle.start()

    def _on_block(self, block) -> None:
        if block.name == "HIGH_RATE" and len(block):
            with self._seen:
                self._last_tick = int(block["tick"][-1])
                self._seen.notify_all()

    def _idle_loop(self) -> None:
        period = 0.01
        step = max(1, int(round(self.rate * period)))
        while not self._stop.is_set():
            if self._fast.is_set():
                with self._lock:
                    try:
                        self._chunk(CHUNK_TICKS)
                    except BaseException as exc:          # seen by the script at fast_forward's end
                        self.error = exc
                        self._fast.clear()
                continue
            if self._stop.wait(period):
                return
            with self._lock:
                if self._stop.is_set():
                    return
                self.device.run_ticks(step)

    def _chunk(self, n: int) -> None:
        """n periods, their frames received, and a HEARTBEAT (the watchdog counts ticks)."""
        self.device.run_ticks(n)
        # the heartbeat's round trip overlaps the frames' way through the receiver
        self.client.command("HEARTBEAT")
        self._wait_for(self.device.firmware.tick & 0xFFFFFFFF)

    @contextlib.contextmanager
    def fast_forward(self) -> Iterator[None]:
        """While inside, device time runs as fast as the link allows even though the
        script is not in advance() - for steps that wait on the device themselves (a
        profile playing to its end)."""
        self.error = None
        self._fast.set()
        try:
            yield
        finally:
            self._fast.clear()
            with self._lock:                          # the chunk under way has finished
                pass
        if self.error is not None:
            raise self.error

    def _wait_for(self, tick: int) -> None:
        deadline = time.monotonic() + FLOW_TIMEOUT_S
        with self._seen:
            while self._last_tick < tick:
                left = deadline - time.monotonic()
                if left <= 0 or self.client.link_state != "up":
                    raise LinkLostError(f"telemetry stalled: tick {self._last_tick} received, "
                                        f"{tick} sent")
                self._seen.wait(min(left, 0.1))

    def advance(self, seconds: float, progress: Callable[[float], None] | None = None,
                until: Callable[[], bool] | None = None) -> None:
        total = int(round(seconds * self.rate))
        done = 0
        with self._lock:
            while done < total:
                if self.abort.is_set():
                    raise ScriptAborted("aborted")
                n = min(CHUNK_TICKS, total - done)
                self._chunk(n)
                done += n
                if progress is not None:
                    progress(done / total)
                if until is not None and until():
                    return

    def close(self) -> None:
        self._stop.set()
        self._fast.clear()
        self._idle.join(timeout=15)
        self.client.unsubscribe(self._on_block)
