"""The contracts between the parts of the station, as `typing.Protocol`s.

Code that only needs one side of a contract is written against it, not against a class,
so that another implementation can stand in without an adapter:

- `TelemetrySource`: decoded telemetry blocks and the state of where they come from.
  The live link (link.client.DeviceClient) and a log replay (logs.replay.ReplaySource)
  both are one, which is why the charts, the limits and the recorder run unchanged on
  a replay;
- `CommandChannel`: commands with their stages, as the device link carries them
  (DeviceClient; the Station, the parameter loader and the profile player use it);
- `DeviceLink`: both of those at once plus the session, the counters and the listeners'
  removal - the whole face of a connection to a device (DeviceClient).  Whatever holds a
  device connection (the station, the recorder, the uploads, the publisher, the clock)
  takes one of these three, never the class; tests/test_architecture.py checks that;
- `BaseMotionInstrument`: the base-disturbance function generator as a session drives
  it (instruments.fg4050.FunctionGenerator4050).

tests/core/test_contracts.py checks that each implementation satisfies its contract, method
names and call signatures alike.  Nothing here imports beyond the standard library.
"""

from __future__ import annotations

from typing import Any, Callable, Iterable, Protocol, runtime_checkable

#: a decoded block of one packet (codec.frames.TelemetryBlock)
Block = Any
#: link states a source reports: 'up', 'lost', 'closed', 'ended' (live); a replay adds
#: 'finished'
LinkListener = Callable[[str, str], None]


@runtime_checkable
class TelemetrySource(Protocol):
    """Where decoded telemetry comes from (live link or replay)."""

    def subscribe(self, callback: Callable[[Block], None], *, after_others: bool = False) -> None:
        """Call `callback(block)` for every decoded block, on the source's own thread.
        `after_others`: call it after every other subscriber, even those subscribed
        later - a consumer that treats its call as "everyone has the block" (the fast
        clock, whose "received" lets a dwell end and the recording stop) needs this."""

    def unsubscribe(self, callback: Callable[[Block], None]) -> None:
        """Stop calling `callback` (no error if it was not subscribed)."""

    def add_link_listener(self, callback: LinkListener) -> None:
        """Call `callback(state, message)` when the source's state changes."""

    def close(self) -> None:
        """Stop delivering and release what the source holds."""


@runtime_checkable
class CommandChannel(Protocol):
    """Commands to the device, each followed to its final stage."""

    dictionary: Any
    link_state: str

    def command(self, name: str, *, on_stage: Callable[[Any], None] | None = None,
                **args: Any) -> Any:
        """Send `name` with `args`; return the CommandResult once it completed, raise a
        GroundStationError (refused, failed, timed out, link down) otherwise."""

    def add_command_listener(self, callback: Callable[[Any], None]) -> None:
        """Call `callback(result)` when any command ends (for the journal)."""

    def abort(self) -> Any:
        """ABORT: motors off, disarmed, whatever the state."""


@runtime_checkable
class DeviceLink(TelemetrySource, CommandChannel, Protocol):
    """A connection to one device: telemetry, commands, its session and its counters."""

    #: what went wrong last ('' while up): shown with a 'lost' state
    link_error: str
    #: the CONNECT answer (session token, testbed description, ...); {} before connect
    device_info: dict[str, Any]
    #: the link counters (link.stats.LinkStatistics: snapshot(), rates, losses)
    stats: Any
    #: how long the reader gathers telemetry into one block before delivering it (s)
    telemetry_batch_s: float

    def connect(self, take_over: bool = False) -> Any:
        """Open a session (version and dictionary check, token, heartbeat)."""

    def disconnect(self) -> None:
        """End the session cleanly (the device disarms)."""

    def commands(self, calls: Iterable[tuple[str, dict[str, Any]]], *,
                 window: int = 16) -> list[Any]:
        """Commands pipelined `window` at a time, waited for and checked in order."""

    def remove_link_listener(self, callback: LinkListener) -> None:
        """Stop calling `callback` on state changes."""

    def remove_command_listener(self, callback: Callable[[Any], None]) -> None:
        """Stop calling `callback` when a command ends."""

    def add_raw_tap(self, callback: Callable[[str, list[bytes], list[float]], None]) -> None:
        """Call `callback(path, chunks, host_times)` with telemetry as received."""

    def remove_raw_tap(self, callback: Callable[[str, list[bytes], list[float]], None]) -> None:
        """Stop the raw tap `callback`."""


@runtime_checkable
class BaseMotionInstrument(Protocol):
    """The function generator that drives the base-motion stage."""

    resource_name: str

    def configure(self, channel: int, *, waveform: str | None = None,
                  frequency_hz: float | None = None, amplitude_vpp: float | None = None,
                  offset_v: float | None = None, phase_deg: float | None = None,
                  load: str | int | None = None) -> Any:
        """Check the whole setting against the limits, then send it."""

    def set_output(self, channel: int, on: bool) -> None:
        """Switch a channel's output."""

    def upload_arbitrary(self, channel: int, volts: Iterable[float], *, name: str,
                         frequency_hz: float, select: bool = True) -> Any:
        """Store one period of a waveform (volts) and, with `select`, play it."""

    def describe(self, channel: int) -> str:
        """The channel's state read back from the instrument, in one line."""

    def abort(self) -> None:
        """Every output off now (fail safe; never raises for a lost link)."""

    def close(self) -> None:
        """Outputs off and the session closed."""
