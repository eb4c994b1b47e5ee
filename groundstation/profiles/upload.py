"""Putting a profile on the device, playing it, and following it from the telemetry.

Upload (SPEC.md §11.2): check the samples here (range, count, finiteness, start at rest),
PROFILE_BEGIN(profile_id, target, sample_count), the big-endian f32 samples in
PROFILE_WRITE blocks as large as a frame allows (253 samples), PROFILE_COMMIT with the
CRC-32 of all sample bytes (the device checks the CRC over what it received and validates
the samples again), then wait for HOUSEKEEPING.active_profile to name the new profile.
There is no read-back command for profiles: the device's CRC check over its own buffer
is the read-back.  The profile id is derived from the CRC, so HOUSEKEEPING names the
content that was committed.

Playback: PROFILE_START; the device plays sample k-1 in the k-th period after the start
and reports HIGH_RATE.profile_index = k (1-based, 0 when nothing was played in that
period).  Progress and the end come from that telemetry and from the EVENTs
(PROFILE_FINISHED, PROFILE_STOPPED, or the cause of a disarm).

`ProfilePlayer.play` is the whole safe sequence (upload, mode, arm, start, wait, disarm);
any error or Ctrl-C on the way sends PROFILE_STOP and ABORT, so the device is left safe.

No Qt here: the CLI, the GUI and campaigns use the same classes.
"""

from __future__ import annotations

import logging
import threading
import time
import zlib
from collections import deque
from dataclasses import asdict, dataclass, field
from typing import Any, Callable

import numpy as np

from ..core.contracts import DeviceLink
from ..core.kinds import LinkState, ProfileOrigin
from ..core.dictionary import Dictionary
from ..core.errors import CommandFailed, CommandRejected, GroundStationError, LinkLostError
from .samples import DEFAULT_GYRO_RANGE, TARGETS, Profile
from .checks import check_profile
from .samples import ProfileError, ProfileRefused

log = logging.getLogger(__name__)

#: how long HOUSEKEEPING (10 Hz) may take to name the committed profile
HOUSEKEEPING_WAIT_S = 3.0
#: how long HIGH_RATE may take to show the armed state (the held reference)
TELEMETRY_WAIT_S = 3.0
#: PROFILE_WRITE blocks sent ahead of their answers (DeviceClient.commands)
WRITE_WINDOW = 16
#: largest jump from the held position to an absolute REFERENCE profile's first sample
MAX_START_JUMP_RAD = 1e-5

_REASON_ADVICE = {
    "INVALID_STATE": "not allowed in the device's present state (armed while the mode is "
                     "changed, a profile playing, or a mode that does not play this target)",
    "CRC_MISMATCH": "the samples arrived corrupted (CRC mismatch); the previously loaded "
                    "profile stays loaded - upload again",
    "VALIDATION_FAILED": "the device refused the samples (range or finiteness); the "
                         "previously loaded profile stays loaded",
    "OUT_OF_RANGE": "the device refused an argument (sample count, or a block beyond the "
                    "staged size) - are host and device on the same protocol?",
    "NOTHING_STAGED": "the device has no staged or loaded profile (another upload or a "
                      "reboot?) - upload again",
    "NOT_ARMED": "the drives are not armed - ARM first",
    "FAULT_LATCHED": "a fault is latched - acknowledge it with DISARM first",
}

#: events that end playback, and the reason reported for them
_END_EVENTS = {"PROFILE_FINISHED": "finished", "PROFILE_STOPPED": "stopped",
               "DISARMED": "disarmed", "ABORTED": "aborted",
               "WATCHDOG_EXPIRED": "watchdog expired", "FAULT": "fault"}
#: which of several ending events in one period names the cause (first wins)
_END_PRIORITY = ("FAULT", "WATCHDOG_EXPIRED", "ABORTED", "PROFILE_STOPPED", "DISARMED",
                 "PROFILE_FINISHED")


class ProfileUploadError(ProfileError):
    """An upload did not end with the profile loaded and confirmed on the device."""


class PlaybackError(ProfileError):
    """Playback could not be started or followed (the device was made safe)."""


def default_mode(target: str) -> str:
    """The mode a target is played in unless told otherwise."""
    return TARGETS[target].modes[0]


def profile_id_for(crc: int) -> int:
    """A profile id (1 … 65535) derived from the sample CRC: HOUSEKEEPING then names the content."""
    return 1 + crc % 65535


@dataclass
class ProfileRecord:
    """One verified upload (what the journal keeps, with the sample bytes as its blob)."""

    time: float                      # s since the epoch, when confirmed
    name: str
    target: str
    units: str
    origin: str
    offset: float                    # added to a relative profile's samples (0 otherwise)
    profile_id: int
    crc: int
    sample_count: int
    duration_s: float
    source: str
    description: str = ""
    generator: dict[str, Any] = field(default_factory=dict)
    committed_tick: int = 0
    upload_s: float = 0.0            # wall time from PROFILE_BEGIN to the confirmation
    device: str = ""
    warnings: list[str] = field(default_factory=list)


@dataclass
class PlaybackResult:
    completed: bool                  # every sample was played
    samples_played: int              # the last profile_index seen (or the count, if completed)
    sample_count: int
    start_tick: int                  # the tick of PROFILE_START; sample 0 plays at start_tick + 1
    end_tick: int | None             # first period without a sample (None: not seen)
    reason: str                      # finished, stopped, disarmed, aborted, watchdog expired, fault, timeout

    def text(self) -> str:
        if self.completed:
            return f"played all {self.sample_count} samples (ticks {self.start_tick + 1} … " \
                   f"{self.start_tick + self.sample_count})"
        return f"ended early ({self.reason}) after {self.samples_played} of {self.sample_count} samples"


class _Monitor:
    """Telemetry the loader and the player need, kept from the reader thread."""

    def __init__(self, client: DeviceLink):
        self.client = client
        self.cond = threading.Condition()
        self.hr_tick = -1
        self.hr_reference = 0.0
        self.hr_armed = False
        self.hk_tick = -1
        self.hk_active = 0
        self.since = None                # playback: the start tick, None when not following
        self.max_index = 0
        self.last_index_tick = -1
        self.end_tick: int | None = None
        self.events: list[tuple[int, str]] = []
        #: the last HIGH_RATE blocks as (ticks, profile_index), for follow()
        self.recent: deque[tuple[np.ndarray, np.ndarray]] = deque(maxlen=64)
        #: the predicates wait() is waiting on: a block wakes the waiter only when one holds
        self._waiting: list[Callable[[], bool]] = []
        client.subscribe(self)

    def __call__(self, block) -> None:
        n = len(block)
        if not n:
            return
        with self.cond:
            if block.name == "HIGH_RATE":
                ticks = block["tick"]
                self.hr_tick = int(ticks[-1])
                self.hr_reference = float(block["reference"][-1])
                self.hr_armed = bool(block["armed"][-1])
                pair = (ticks.astype(np.int64), np.asarray(block["profile_index"], dtype=np.int64))
                self.recent.append(pair)
                self._scan(*pair)
            elif block.name == "HOUSEKEEPING":
                self.hk_tick = int(block["tick"][-1])
                self.hk_active = int(block["active_profile"][-1])
            elif block.name == "EVENT":
                name = self.client.dictionary.event_name
                for tick, code in zip(block["tick"], block["code"]):
                    self.events.append((int(tick), name(int(code))))
                del self.events[:-256]
            else:
                return
            # not on every block: a waiter that wakes for nothing takes the interpreter
            # from the thread running the device (fast simulator, same process) every time
            if any(predicate() for predicate in self._waiting):
                self.cond.notify_all()

    def _scan(self, ticks: np.ndarray, idx: np.ndarray) -> None:
        if self.since is None:
            return
        after = ticks > self.since
        played = after & (idx > 0)
        if played.any():
            self.max_index = max(self.max_index, int(idx[played].max()))
            self.last_index_tick = max(self.last_index_tick, int(ticks[played].max()))
        idle = after & (idx == 0)
        if idle.any():
            first = int(ticks[idle].min())
            self.end_tick = first if self.end_tick is None else min(self.end_tick, first)

    def follow(self, start_tick: int) -> None:
        """Follow playback started at start_tick, including frames already received (the
        reader may have seen the first played periods before PROFILE_START returned)."""
        with self.cond:
            self.since = start_tick
            self.max_index = 0
            self.last_index_tick = -1
            self.end_tick = None
            for pair in self.recent:
                self._scan(*pair)

    def end_event(self) -> str | None:
        """The playback-ending event at or after the start tick: the first one's tick,
        and of the events of that tick the most telling.  An ABORT disarms, and the device
        reports DISARMED before ABORTED in the same period; the operator's abort is the
        cause, the disarm its consequence."""
        if self.since is None:
            return None
        ending = [(tick, name) for tick, name in self.events
                  if tick >= self.since and name in _END_EVENTS]
        if not ending:
            return None
        first = ending[0][0]
        same_tick = [name for tick, name in ending if tick == first]
        return min(same_tick, key=_END_PRIORITY.index)

    def wait(self, predicate: Callable[[], bool], timeout: float) -> bool:
        deadline = time.monotonic() + timeout
        with self.cond:
            self._waiting.append(predicate)
            try:
                while not predicate():
                    left = deadline - time.monotonic()
                    if left <= 0:
                        return False
                    self.cond.wait(min(left, 0.1))
                return True
            finally:
                self._waiting.remove(predicate)

    def close(self) -> None:
        unsubscribe = getattr(self.client, "unsubscribe", None)
        if unsubscribe is not None:
            unsubscribe(self)


def _explained(client: DeviceLink, error: type[ProfileError], name: str, args: dict[str, Any]):
    """client.command(name, **args); a refusal or failure becomes `error` with what the
    device's reason means for the operator."""
    try:
        return client.command(name, **args)
    except (CommandRejected, CommandFailed) as exc:
        raise _with_advice(error, exc) from exc


def _with_advice(error: type[ProfileError], exc: CommandRejected | CommandFailed) -> ProfileError:
    advice = _REASON_ADVICE.get(getattr(exc, "reason", ""), "")
    return error(f"{exc}" + (f": {advice}" if advice else ""))


class ProfileLoader:
    """Uploads profiles through a DeviceClient and confirms them on the device."""

    def __init__(self, client: DeviceLink, dictionary: Dictionary,
                 journal: Callable[[str, dict, bytes], None] | None = None, *,
                 gyro_range: float = DEFAULT_GYRO_RANGE, monitor: _Monitor | None = None):
        self.client = client
        self.d = dictionary
        #: called with ("profile", record, sample bytes) after each confirmed upload
        self.journal = journal
        self.gyro_range = gyro_range
        self._own_monitor = monitor is None
        self.monitor = monitor or _Monitor(client)
        # PROFILE_WRITE payload: token u32, opcode u16, offset u32, then whole samples
        self.block_samples = (dictionary.max_payload - 10) // 4
        self.last_uploaded: ProfileRecord | None = None

    def close(self) -> None:
        if self._own_monitor:
            self.monitor.close()

    def upload(self, profile: Profile, *, offset: float = 0.0, profile_id: int | None = None,
               progress: Callable[[str, float], None] | None = None,
               verify_housekeeping: bool = True) -> ProfileRecord:
        """Send a profile and confirm it; raise ProfileRefused (nothing sent) for samples the
        device must not get, ProfileUploadError for anything short of confirmed."""
        check = check_profile(profile, self.d, offset=offset, gyro_range=self.gyro_range)
        check.raise_if_refused()
        for w in check.warnings:
            log.warning("%s: %s", profile.name, w)
        data = profile.wire_bytes(offset)
        crc = zlib.crc32(data)
        pid = profile_id if profile_id is not None else profile_id_for(crc)
        count = profile.sample_count
        target_code = self.d.command("PROFILE_BEGIN").args[1].states[profile.target]
        t0 = time.monotonic()
        self._command("PROFILE_BEGIN", profile_id=pid, target=target_code, sample_count=count)
        step = self.block_samples
        blocks = [("PROFILE_WRITE", {"offset": first, "samples": data[4 * first:4 * (first + step)]})
                  for first in range(0, count, step)]
        # PROFILE_WRITE needs no device time and blocks commute (each names its offset),
        # so they go pipelined, a window ahead of their answers: a 60 s profile is 285
        # blocks, and one round trip each was most of an upload's time.  Only a client
        # that pipelines by itself is asked to: a wrapper that forwards other attributes
        # to a client gets every block through its own command().
        pipelined = getattr(type(self.client), "commands", None) is not None
        per_call = WRITE_WINDOW * 4 if pipelined else 1
        for i in range(0, len(blocks), per_call):
            group = blocks[i:i + per_call]
            if pipelined:
                self._commands(group)
            else:
                name, args = group[0]
                self._command(name, **args)
            if progress:
                progress("upload", min(1.0, (i + len(group)) * step / count))
        result = self._command("PROFILE_COMMIT", profile_crc=crc)
        committed = next((s.device_tick for s in result.stages if s.stage == "COMPLETED"), None) or 0
        if verify_housekeeping:
            m = self.monitor
            seen = m.wait(lambda: m.hk_tick >= committed and m.hk_active == pid, HOUSEKEEPING_WAIT_S)
            if not seen:
                got = "no HOUSEKEEPING" if m.hk_tick < committed else f"active_profile {m.hk_active}"
                raise ProfileUploadError(
                    f"{profile.name}: committed, but {got} {HOUSEKEEPING_WAIT_S:g} s later "
                    f"(expected active_profile {pid}) - is telemetry arriving?")
        record = ProfileRecord(
            time=time.time(), name=profile.name, target=profile.target, units=profile.units,
            origin=profile.origin, offset=float(offset) if profile.origin == ProfileOrigin.RELATIVE else 0.0,
            profile_id=pid, crc=crc, sample_count=count, duration_s=profile.duration,
            source=profile.source, description=profile.description,
            generator=dict(profile.generator), committed_tick=int(committed),
            upload_s=time.monotonic() - t0,
            device=str(getattr(self.client, "device_info", {}).get("description", "")),
            warnings=list(check.warnings))
        self.last_uploaded = record
        if self.journal is not None:
            self.journal("profile", {"action": "uploaded", **asdict(record)}, data)
        return record

    def _command(self, name: str, **args: Any):
        return _explained(self.client, ProfileUploadError, name, args)

    def _commands(self, calls: list[tuple[str, dict[str, Any]]]):
        try:
            return self.client.commands(calls, window=WRITE_WINDOW)
        except (CommandRejected, CommandFailed) as exc:
            raise _with_advice(ProfileUploadError, exc) from exc


class ProfilePlayer:
    """Loads, starts, follows and stops profiles on one device."""

    def __init__(self, client: DeviceLink, dictionary: Dictionary,
                 journal: Callable[[str, dict, bytes], None] | None = None, *,
                 gyro_range: float = DEFAULT_GYRO_RANGE):
        self.client = client
        self.d = dictionary
        self.journal = journal
        self.monitor = _Monitor(client)
        self.loader = ProfileLoader(client, dictionary, journal, gyro_range=gyro_range,
                                    monitor=self.monitor)
        self.record: ProfileRecord | None = None
        self.start_tick: int | None = None
        #: what play() could not do when it made the device safe (empty: PROFILE_STOP and
        #: ABORT both completed)
        self.safe_failures: list[str] = []
        self.made_safe = False               # make_safe() ran

    def close(self) -> None:
        self.monitor.close()

    def __enter__(self) -> "ProfilePlayer":
        return self

    def __exit__(self, *exc) -> None:
        self.close()

    # ------------------------------------------------------------------ steps
    def load(self, profile: Profile, *, offset: float = 0.0,
             progress: Callable[[str, float], None] | None = None) -> ProfileRecord:
        self.record = self.loader.upload(profile, offset=offset, progress=progress)
        return self.record

    def held_reference(self, since_tick: int, timeout: float = TELEMETRY_WAIT_S) -> float:
        """The reference the device holds, from the first armed HIGH_RATE frame after
        `since_tick` (ARM sets it to the position the mode controls)."""
        m = self.monitor
        if not m.wait(lambda: m.hr_tick > since_tick and m.hr_armed, timeout):
            raise PlaybackError(f"no armed HIGH_RATE frame within {timeout:g} s after the ARM - "
                                f"is telemetry arriving?")
        with m.cond:
            return m.hr_reference

    def start(self) -> int:
        """PROFILE_START; returns its tick (sample 0 plays in the next period)."""
        result = self._command("PROFILE_START")
        tick = next((s.device_tick for s in result.stages if s.stage == "COMPLETED"), None)
        if tick is None:
            raise PlaybackError("PROFILE_START completed without a device tick")
        self.start_tick = int(tick)
        self.monitor.follow(self.start_tick)
        return self.start_tick

    def stop(self) -> None:
        self._command("PROFILE_STOP")

    @property
    def index(self) -> int:
        """The last profile_index seen since the start (samples played)."""
        return self.monitor.max_index

    def wait_finished(self, timeout: float,
                      progress: Callable[[int, int], None] | None = None) -> PlaybackResult:
        """Wait until playback ends (the last sample played, or a period without a sample);
        `progress(index, count)` is called from this thread about 10 times a second.
        On timeout the result's reason is 'timeout' (playback may still be running)."""
        if self.start_tick is None or self.record is None:
            raise PlaybackError("nothing was started")
        m = self.monitor
        count = self.record.sample_count
        deadline = time.monotonic() + timeout
        ended = False
        while True:
            ended = m.wait(lambda: m.max_index >= count or m.end_tick is not None, 0.1)
            if progress is not None:
                progress(m.max_index, count)
            if ended or time.monotonic() >= deadline:
                break
            if getattr(self.client, "link_state", "up") != LinkState.UP:
                raise LinkLostError(f"link {self.client.link_state} during playback: the "
                                    f"device's watchdog will stop the motors")
        if ended and m.max_index < count:
            # the EVENT naming the cause is sent after the batch of frames that shows the
            # end: give it a moment to arrive
            m.wait(lambda: m.end_event() is not None, 0.5)
        with m.cond:
            event = m.end_event()
            completed = m.max_index >= count or event == "PROFILE_FINISHED"
            reason = "finished" if completed else (_END_EVENTS.get(event or "", "") or
                                                   ("timeout" if not ended else "ended"))
            result = PlaybackResult(completed=completed,
                                    samples_played=count if completed else m.max_index,
                                    sample_count=count, start_tick=self.start_tick,
                                    end_tick=m.end_tick if m.end_tick is not None else
                                    (self.start_tick + count + 1 if completed else None),
                                    reason=reason)
        if self.journal is not None and ended:
            self.journal("profile", {"action": "played", "name": self.record.name,
                                     "profile_id": self.record.profile_id, "crc": self.record.crc,
                                     **asdict(result)}, b"")
        return result

    def make_safe(self) -> list[str]:
        """PROFILE_STOP, then ABORT (motors to zero, disarmed, IDLE); each is tried even if
        the other fails.  Returns what could not be done (empty: the device is safe)."""
        self.made_safe = True
        failures = []
        for name in ("PROFILE_STOP", "ABORT"):
            try:
                self.client.command(name)
            except GroundStationError as exc:
                failures.append(f"{name}: {exc}")
                log.error("making the device safe: %s failed: %s", name, exc)
        return failures

    # ------------------------------------------------------------------ the sequence
    def play(self, profile: Profile, mode: str | None = None, *, timeout: float | None = None,
             progress: Callable[[int, int], None] | None = None,
             upload_progress: Callable[[str, float], None] | None = None,
             on_step: Callable[[str], None] | None = None,
             max_start_jump: float = MAX_START_JUMP_RAD) -> PlaybackResult:
        """Upload (verified), set the mode, arm, start, follow to the end, disarm.

        A relative REFERENCE profile is uploaded after arming, offset by the reference the
        device then holds, so it starts exactly where the axis is.  An absolute one is
        refused (after arming, before starting) if its first sample is more than
        max_start_jump from the held reference.  Any error or KeyboardInterrupt on the way:
        PROFILE_STOP and ABORT, then the exception goes on."""
        info = TARGETS[profile.target]
        mode = mode or default_mode(profile.target)
        if mode not in info.modes:
            raise ProfileRefused(f"{profile.name}: a {profile.target} profile plays in "
                                 f"{' or '.join(info.modes)}, not {mode}")
        check_profile(profile, self.d, gyro_range=self.loader.gyro_range).raise_if_refused()
        say = on_step or (lambda text: None)
        relative = profile.origin == ProfileOrigin.RELATIVE
        try:
            if not relative:
                say("uploading")
                self.load(profile, progress=upload_progress)
            say(f"mode {mode}")
            self._command("SET_MODE", mode=mode)
            arm = self._command("ARM")
            arm_tick = next((s.device_tick for s in arm.stages if s.stage == "COMPLETED"), 0) or 0
            if profile.target == "REFERENCE":
                held = self.held_reference(arm_tick)
                if relative:
                    say(f"uploading (offset by the held reference {held:.9g} rad)")
                    self.load(profile, offset=held, progress=upload_progress)
                else:
                    jump = abs(float(profile.samples[0]) - held)
                    if jump > max_start_jump:
                        raise ProfileRefused(
                            f"{profile.name}: the absolute profile starts at "
                            f"{float(profile.samples[0]):.6g} rad but the axis holds {held:.6g} rad "
                            f"- a jump of {jump:.3g} rad; make it origin = 'relative' or move "
                            f"the axis there first")
            say("playing")
            self.start()
            assert self.record is not None
            wait = timeout if timeout is not None else self.record.duration_s + 10.0
            result = self.wait_finished(wait, progress)
            if result.reason == "timeout":
                raise PlaybackError(f"{profile.name}: playback not finished {wait:g} s after the "
                                    f"start ({result.samples_played} of {result.sample_count} "
                                    f"samples seen)")
            if result.completed:
                say("disarming")
                self._command("DISARM")
            else:
                # stopped, aborted or faulted on the device: leave any latched fault for
                # the operator to see (DISARM would acknowledge it), just make sure
                self.safe_failures = self.make_safe()
            return result
        except BaseException:
            self.safe_failures = self.make_safe()
            raise

    def _command(self, name: str, **args: Any):
        return _explained(self.client, PlaybackError, name, args)
