"""How a script's time passes: on a real device, wall time; on the simulated testbed in
fast mode, as fast as the simulator, the link and the recorder can go.

`WallClock.advance(seconds)` sleeps (in short steps, so an abort or a lost link ends the
wait at once).  `SteppedClock` drives a manually paced SimulatedDevice (in this process, or in a child
process through sim/stepped_process.SteppedSimulatorProcess):

- advance() runs the device in chunks of 0.75 s as fast as it can, with flow control by
  credits: at most `FastPacing.in_flight` chunks whose frames the host has not yet all
  received, and nothing new while the recorder's queue to its writer is more than a
  quarter full - so nothing is dropped and the recorder never discards a block, while
  the simulator, the receiver and the writer work at the same time.  HIGH_RATE frames
  travel many to a datagram.  advance() returns when every frame it caused is received.
- heartbeats in device time: after every chunk the device counts the host as heard at
  the chunk's last tick (what a HEARTBEAT sent then would do); the host's own heartbeat
  thread runs in wall time, far too rarely for a fast clock.
- between steps (`between_steps="held"`, the default) device time stands still, except
  that a command runs the control period it takes effect in (its state then reaches the
  host in HIGH_RATE), a commit confirmed in HOUSEKEEPING runs to the end of the
  housekeeping period (at most 0.1 s), and a recording opens with one period.  Keep-alives,
  reads and the blocks of a transfer, answered in full, run nothing.  Device time then depends only on what
  the script does, never on how fast the host does it: a fast run is tick-repeatable.
  `between_steps="realtime"` is the older behaviour: an idle thread runs the device at
  the real-time rate while the script is not in advance().
- fast_forward() (a profile playing to its end while the script waits on the device):
  held, the device runs chunks flat out while a profile plays; realtime, as long as
  the block lasts.
- `until` (a host-side predicate on telemetry) is evaluated on whole chunks, each fully
  received first; `stop_on_fault` ends an advance after the chunk in which the device
  latched a fault, judged on the device - both at the same tick however fast it runs.
- a device in another process (SteppedSimulatorProcess, which has `step_ahead`) is sent
  a dwell's chunks without the clock waiting for each to run: it always has the next one
  queued, within the same credits; each step is made conditional on no fault latched,
  so the chunks requested ahead end exactly where a fault was seen.
"""

from __future__ import annotations

import contextlib
import threading
import time
from collections import deque
from dataclasses import dataclass
from typing import Callable, Iterator

from ..core.contracts import DeviceLink
from ..core.kinds import BetweenSteps, LinkState
from ..core.errors import GroundStationError, LinkLostError

#: device periods per chunk of a fast advance: 0.75 s, inside the 1 s watchdog even
#: counting the HEARTBEAT's own round trip
CHUNK_TICKS = 900
#: how long the host may make no progress on a chunk's frames (or the recorder on its
#: queue) before the link is declared stalled
FLOW_TIMEOUT_S = 10.0
#: the recorder's queue to its writer may be this full before the clock waits for it
RECORDER_QUEUE_LIMIT = 0.25


@dataclass(frozen=True)
class FastPacing:
    """How a SteppedClock paces the device against the host.

    in_flight        chunks whose frames the host has not all received yet, at most (1:
                     each chunk waits for the previous one's frames - the pacing before
                     issue 19)
    datagram_bytes   HIGH_RATE frames per datagram up to this size (0: one frame each,
                     as a rig sends them)
    """

    in_flight: int = 4
    datagram_bytes: int = 32768

    def __post_init__(self) -> None:
        if self.in_flight < 1:
            raise ValueError(f"in_flight must be >= 1, not {self.in_flight!r}")
        if self.datagram_bytes < 0:
            raise ValueError(f"datagram_bytes must be >= 0, not {self.datagram_bytes!r}")


#: the pacing before issue 19: one chunk in flight, one frame per datagram
ONE_CHUNK_IN_FLIGHT = FastPacing(in_flight=1, datagram_bytes=0)


class ScriptAborted(GroundStationError):
    """The operator (or a failure elsewhere) aborted the script."""


class WallClock:
    """Real time: the device runs by itself."""

    fast = False
    #: device time passes between the script's steps: periodic reports (HOUSEKEEPING)
    #: keep coming, so waiting for the next one is waiting for something
    time_flows_between_steps = True

    def __init__(self, client: DeviceLink, abort: threading.Event):
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
            if self.client.link_state != LinkState.UP:
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

    def __init__(self, device, client: DeviceLink, abort: threading.Event, *,
                 pacing: FastPacing | None = None, between_steps: str = "held",
                 recorder_backlog: Callable[[], float] | None = None):
        if between_steps not in (BetweenSteps.HELD, BetweenSteps.REALTIME):
            raise ValueError(f"between_steps must be held or realtime, not {between_steps!r}")
        self.device = device
        self.client = client
        self.abort = abort
        self.pacing = pacing or FastPacing()
        self.between_steps = between_steps
        self.time_flows_between_steps = between_steps != BetweenSteps.HELD
        #: the recorder's queue fill (0..1), or None when nothing records
        self.recorder_backlog = recorder_backlog
        self.rate = device.dictionary.control_rate_hz
        # a chunk's frames arrive all at once: the receiver need not wait for more to gather
        client.telemetry_batch_s = 0.001
        self._last_tick = -1
        self._seen = threading.Condition()
        self._in_flight: deque[int] = deque()   # last ticks of chunks not yet all received
        self._requested = 0                      # chunks asked for ahead, not yet run
        self._ahead_error: str | None = None     # why a chunk asked for ahead failed
        # after every other subscriber: a block counts as received once the recorder has
        # it too.  Called first, it let drain() return, and the script stop the
        # recording, before the recorder had the last block - a stressed run lost the
        # last 900 frames of a dwell that a fault ended (tests/campaign/test_campaign_speed.py)
        client.subscribe(self._on_block, after_others=True)
        self._lock = threading.Lock()          # one of idle / advance runs the device
        self._stop = threading.Event()
        self._fast = threading.Event()         # fast_forward(): the idle thread runs flat out
        # held: a command ran (a profile may have started), fast_forward() began or close()
        self._commanded = threading.Event()
        self.error: BaseException | None = None
        #: wall seconds the clock spent waiting for credits (receiver, recorder): for the
        #: benchmark's profile
        self.waited_s = 0.0
        if between_steps == BetweenSteps.HELD:
            device.hold_between_steps(self._ran, datagram_bytes=self.pacing.datagram_bytes)
        self._idle = threading.Thread(target=self._idle_loop, name="gs-sim-idle-clock", daemon=True)
        self._idle.start()

    def _on_block(self, block) -> None:
        if block.name == "HIGH_RATE" and len(block):
            with self._seen:
                self._last_tick = int(block["tick"][-1])
                self._seen.notify_all()

    # ------------------------------------------------------------------ running the device
    def _idle_loop(self) -> None:
        period = 0.01
        step = max(1, int(round(self.rate * period)))
        held = self.between_steps == BetweenSteps.HELD
        while not self._stop.is_set():
            if self._fast.is_set():
                with self._lock:
                    try:
                        ran = self._run(CHUNK_TICKS, self.pacing.in_flight, only_while_playing=held)
                    except BaseException as exc:          # seen by the script at fast_forward's end
                        self.error = exc
                        self._fast.clear()
                        continue
                if ran is not None or not held:
                    continue
            if held:
                # nothing plays yet (or any more): sleep until a command, fast_forward() or
                # close() says otherwise.  No polling: a thread that woke up every 10 ms
                # took the interpreter from the one running the device a hundred times a
                # wall second, each time a thread switch on a busy machine.
                self._commanded.wait()
                self._commanded.clear()
                continue
            if self._stop.wait(period):
                return
            with self._lock:
                if self._stop.is_set():
                    return
                self.device.run_ticks(step)

    def _run(self, n: int, in_flight: int, only_while_playing: bool = False,
             unless_faulted: bool = False) -> int | None:
        """n periods once fewer than `in_flight` chunks are unreceived and the recorder
        keeps up; returns the last tick run (None: nothing ran, no profile playing or a
        fault latched)."""
        self._wait_for_credit(in_flight - 1)
        last = self.device.step(n, datagram_bytes=self.pacing.datagram_bytes,
                                only_while_playing=only_while_playing,
                                unless_faulted=unless_faulted)
        if last is not None:
            with self._seen:
                self._in_flight.append(last)
        return last

    def _run_ahead(self, n: int, in_flight: int) -> None:
        """_run for a device in another process, without waiting for the chunk to run."""
        self._wait_for_credit(in_flight - 1)
        with self._seen:
            self._requested += 1
        try:
            self.device.step_ahead(n, self._stepped, datagram_bytes=self.pacing.datagram_bytes,
                                   unless_faulted=True)
        except BaseException:
            with self._seen:
                self._requested -= 1
            raise

    def _stepped(self, last: int | None, error: str | None) -> None:
        """A chunk asked for ahead has run (on the device handle's reader thread)."""
        with self._seen:
            self._requested -= 1
            if error is not None:
                self._ahead_error = error
            elif last is not None:
                self._in_flight.append(last)
            self._seen.notify_all()

    def _ran(self, last: int) -> None:
        """Held between steps: the device ran a command's confirmation period(s) itself
        (SimulatedDevice.hold_between_steps), ending at tick `last`."""
        with self._seen:
            self._in_flight.append(last)
        self._commanded.set()

    def _wait_for_credit(self, allowed: int) -> None:
        """Until at most `allowed` chunks are unreceived and the recorder's queue is below
        its limit; LinkLostError when nothing moves for FLOW_TIMEOUT_S."""
        t0 = time.monotonic()
        deadline = t0 + FLOW_TIMEOUT_S
        progress = self._last_tick
        with self._seen:
            while True:
                if self._ahead_error is not None:
                    error, self._ahead_error = self._ahead_error, None
                    raise LinkLostError(error)
                while self._in_flight and self._in_flight[0] <= self._last_tick:
                    self._in_flight.popleft()
                unreceived = len(self._in_flight) + self._requested
                backlog = self.recorder_backlog() if self.recorder_backlog is not None else 0.0
                if unreceived <= allowed and backlog <= RECORDER_QUEUE_LIMIT:
                    break
                if self._last_tick != progress:
                    progress, deadline = self._last_tick, time.monotonic() + FLOW_TIMEOUT_S
                left = deadline - time.monotonic()
                if left <= 0 or self.client.link_state != LinkState.UP:
                    what = (f"tick {self._last_tick} received, "
                            f"{self._in_flight[-1] if self._in_flight else 'more'} sent"
                            f"{f', {self._requested} chunks not yet run' if self._requested else ''}"
                            if unreceived > allowed else
                            f"the recorder's queue stays {backlog:.0%} full")
                    raise LinkLostError(f"telemetry stalled: {what}")
                # frames and chunks run wake us; the recorder's writer drains in another
                # process: look again soon
                self._seen.wait(min(left, 0.1 if unreceived > allowed else 0.002))
        self.waited_s += time.monotonic() - t0

    def drain(self) -> None:
        """Until the host has received every frame the device sent."""
        self.device.sync()          # a device in another process: its periods all counted
        self._wait_for_credit(0)

    def tick_over(self) -> None:
        """Held between steps: one control period, received (a recording that starts then
        opens with the device's state, as on a rig whose stream flows anyway)."""
        if self.between_steps != BetweenSteps.HELD:
            return
        with self._lock:
            self._run(1, 1)
            self.drain()

    # ------------------------------------------------------------------ the script's verbs
    @contextlib.contextmanager
    def fast_forward(self) -> Iterator[None]:
        """While inside, device time runs as fast as the link allows even though the
        script is not in advance() - for steps that wait on the device themselves (a
        profile playing to its end; held between steps: only while a profile plays)."""
        self.error = None
        self._fast.set()
        self._commanded.set()
        try:
            yield
        finally:
            self._fast.clear()
            with self._lock:                          # the chunk under way has finished
                pass
        if self.error is not None:
            raise self.error

    def advance(self, seconds: float, progress: Callable[[float], None] | None = None,
                until: Callable[[], bool] | None = None, stop_on_fault: bool = False) -> None:
        """`seconds` of device time in chunks, pipelined; `until()` (on the host's
        telemetry) ends it after a chunk, judged with that chunk fully received (so with
        one chunk in flight); `stop_on_fault` after the chunk in which the device latched
        a fault (judged on the device).  Returns once every frame has been received."""
        total = int(round(seconds * self.rate))
        in_flight = 1 if until is not None else self.pacing.in_flight
        # a device in another process gets the chunks queued ahead (not with `until`,
        # which needs each chunk received before the next is decided)
        ahead = until is None and hasattr(self.device, "step_ahead")
        done = 0
        with self._lock:
            while done < total:
                if self.abort.is_set():
                    raise ScriptAborted("aborted")
                n = min(CHUNK_TICKS, total - done)
                if ahead:
                    self._run_ahead(n, in_flight)
                elif self._run(n, in_flight, unless_faulted=stop_on_fault) is None:
                    break                                    # a fault latched before it
                done += n
                if progress is not None:
                    progress(done / total)
                if until is not None:
                    self.drain()
                    if until():
                        return
                # ahead, the fault seen may be a chunk or two late: the chunks asked for
                # since then ran nothing (unless_faulted), so where it ends is exact
                if stop_on_fault and self.device.faulted:
                    break
            self.drain()

    def close(self) -> None:
        self._stop.set()
        self._fast.clear()
        self._commanded.set()
        self._idle.join(timeout=15)
        if self.between_steps == BetweenSteps.HELD:
            # a device process already gone holds nothing
            with contextlib.suppress(LinkLostError):
                self.device.hold_between_steps(None)
        self.client.unsubscribe(self._on_block)
