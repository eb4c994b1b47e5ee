"""`Station`: one session with a testbed (or its simulation), without Qt.

It owns what a session is made of - the device link, the simulator (a child process, or
in this process with a script-driven clock), the function generator, the recording and
its journal, the parameter history - and offers the verbs every front end uses: the
CLI's commands call them directly, a script or notebook uses them through
`from groundstation import Testbed`, the window's Session runs them on worker threads.

    from groundstation import Testbed           # Testbed is Station

    with Testbed("sim", testbed="profiles/testbeds/relative_2dof.toml", fast=True) as tb:
        tb.upload_design("profiles/controllers/relative_design2.toml")
        tb.set_mode("RELATIVE")
        tb.arm()
        tb.start_recording("step", notes="Design #2, 1 mrad step")
        tb.set_reference(1e-3)
        tb.dwell(2.0)
        tb.stop_recording()

Safety lives here, not in the callers:
* a parameter table is uploaded only with a Clearance (params/clearance.py): validated
  against its design, or sent on an explicit override whose reason is recorded in the
  history and the log; the table commands cannot be sent around it (`command` refuses
  them);
* whatever ends the session - an exception, Ctrl-C, a lost link - `make_safe` leaves
  the rig safe: ABORT (motors off, disarmed), the generator's outputs off, the recording
  closed with everything received so far and the reason it closed.

`device="sim"` starts the simulated testbed: with `fast=True` its clock is driven by the
session (a 60 s dwell takes about a second), the device in this process (where a script
can reach it); `fast=FastSimOptions(where="process")` runs it in a child process of its
own instead (faster: it does not share this interpreter with the receiver), and the
same options tune the stepped clock (station/options.py).  Without `fast`, the simulator
is a real-time child process, exactly as `make run` does.  Any other value is a rig's
address.  `publishing=ConsolePublishing(endpoint)` publishes the link for read-only
consoles.

The parameter table goes through params/upload_path.py (design -> table -> gate ->
upload -> verify), the function generator through a GeneratorDesk
(station/generator_desk.py); the verbs here hand the work to them.
"""

from __future__ import annotations

import logging
import threading
import time
from pathlib import Path
from typing import Any, Callable, Mapping

from .clock import ScriptAborted, SteppedClock, WallClock
from ..core.contracts import BaseMotionInstrument, DeviceLink
from ..core.dictionary import Dictionary, load_dictionary
from ..core.errors import GroundStationError
from ..core.kinds import SIMULATED_DEVICE, BetweenSteps, LinkState, wants_simulated_generator
from ..params.upload import MemoryHistory, ParameterHistory, ParameterLoader
from ..plant.testbed import load_testbed
from .generator_desk import GeneratorDesk
from .options import ConsolePublishing, FastSimOptions
from .recording import RecordingSlot, device_record
from .rig import LocalSimulator, named_generator, open_link, open_testbed_generator, start_simulator
from .settling import settle_rig
from .start_state import StartCriteria
from .tracker import DeviceStateTracker

log = logging.getLogger(__name__)


#: the commands that change the parameter table: only ParameterLoader sends them, and
#: only for a cleared table (Station.command refuses them)
TABLE_COMMANDS = frozenset({"PARAM_BEGIN", "PARAM_WRITE", "PARAM_COMMIT"})


class ScriptError(GroundStationError):
    """A step of a script or campaign could not be done (the message says which and why)."""


class Station:
    """One session with a testbed (or its simulation); see the module docstring."""

    __test__ = False        # `Testbed` is this class: a name pytest must not collect

    def __init__(self, device: str = "sim", *, testbed: str | Path | None = None,
                 fast: bool | FastSimOptions = False,
                 generator: str | None = "auto", log_folder: str | Path = "logs", seed: int = 0,
                 history: str | Path | ParameterHistory | MemoryHistory | None = None,
                 take_over: bool = False, speed: float = 1.0,
                 dictionary: Dictionary | None = None,
                 operator: Callable[[str], bool] | None = None,
                 echo: Callable[[str], None] | None = None,
                 publishing: ConsolePublishing | None = None,
                 sim_listen: tuple[str, int] | None = None):
        """`device`: "sim" (the simulated testbed) or a rig's address.  `fast`: True runs the
        simulated testbed on the script's clock (FastSimOptions: how).  `publishing`: the link
        published for read-only consoles.  `sim_listen`: (host, port) of the real-time sim."""
        if not isinstance(fast, (bool, FastSimOptions)):
            raise TypeError(f"fast must be True, False or a FastSimOptions, not {fast!r}")
        if publishing is not None and not isinstance(publishing, ConsolePublishing):
            raise TypeError(f"publishing must be a ConsolePublishing, not {publishing!r}")
        self.device_spec = device
        self.fast = fast is not False
        #: fast only: where the simulated device runs and how its clock is paced
        self.fast_sim = fast if isinstance(fast, FastSimOptions) else FastSimOptions()
        #: where the link is published for read-only consoles (fanout/, docs/consoles.md)
        self.publishing, self.publisher, self.sim_listen = publishing, None, sim_listen
        self.testbed_path = Path(testbed) if testbed else None
        self.generator_spec = generator
        self.log_folder = Path(log_folder)
        self.seed = seed
        self.speed = speed
        self.history = (history if isinstance(history, (ParameterHistory, MemoryHistory))
                        else ParameterHistory(history) if history else None)
        self.take_over = take_over
        #: asked at a pause step; True goes on, False aborts (None: refuse pauses)
        self.operator = operator
        self.echo = echo or (lambda text: log.info("%s", text))
        self.d = dictionary or load_dictionary()
        self.testbed = load_testbed(self.testbed_path)
        self.abort_event = threading.Event()
        self.state = DeviceStateTracker()
        #: the device link: a CommandChannel and a TelemetrySource (core/contracts.py)
        self.client: DeviceLink | None = None
        self.address = ""
        self.clock: WallClock | SteppedClock | None = None
        self.generator: BaseMotionInstrument | None = None
        self.recording = RecordingSlot(self.echo)
        #: the function generator's verbs (the instrument itself is `self.generator`)
        self.generator_desk = GeneratorDesk(lambda: self.generator, self.testbed, self.recording,
                                            self.echo)
        self.last_upload = None
        #: the simulated testbed this session started (station/rig.py), if any
        self._local: LocalSimulator | None = None
        #: attach(): the client belongs to someone else (the GUI's session) - close() leaves
        #: it open; likewise a generator driver passed in is not ours to close
        self._attached = False
        self._owns_generator = True
        self._owner_journal: Callable[[str, dict, bytes], None] | None = None
        # abort() runs make_safe on the caller's thread while the script's own thread may
        # be making safe after its step failed: one at a time, or both would close the
        # same recording
        self._safe_lock = threading.RLock()

    # ------------------------------------------------------------------ session
    @classmethod
    def attach(cls, client: DeviceLink, *, testbed: str | Path | None = None,
               generator: str | BaseMotionInstrument | None = None,
               log_folder: str | Path = "logs", history=None,
               journal: Callable[[str, dict, bytes], None] | None = None,
               operator: Callable[[str], bool] | None = None,
               echo: Callable[[str], None] | None = None) -> "Station":
        """A session on a connection that is already open and owned by someone else (the
        GUI's, whose charts then show the script live).  `client` is a connected
        DeviceClient; time is wall time (a real-time device).  `generator` is None, a
        VISA resource (opened here, closed by close()) or an open FunctionGenerator4050
        (used, never closed here).  `history` a folder or a ParameterHistory.  `journal`
        (kind, record, blob) receives what the session's verbs journal (uploads, profiles)
        when the owner keeps its own recording (the window's); by default it goes to this
        session's recording.

        make_safe()/abort() act as always (ABORT on the shared link, generator outputs
        off, this session's recording closed); close() closes only what the session
        opened itself - the client stays open, with this session's subscriptions removed."""
        if client is None or client.link_state != LinkState.UP:
            raise ScriptError("attach: the link is not up - connect to the device first")
        st = cls("attached", testbed=testbed, generator=None, log_folder=log_folder,
                 history=history, dictionary=client.dictionary, operator=operator, echo=echo)
        st._attached = True
        st._owner_journal = journal
        st.client = client
        st.address = getattr(client, "address", "")
        client.subscribe(st.state)
        st.clock = WallClock(client, st.abort_event)
        if isinstance(generator, str):
            try:
                st.generator = open_testbed_generator(generator, st.testbed)
            except BaseException:
                client.unsubscribe(st.state)
                raise
        elif generator is not None:
            st.generator, st._owns_generator = generator, False
        st.echo("attached to the open link" + (f", generator {st.generator.resource_name}"
                                                 if st.generator is not None else ""))
        return st

    @property
    def attached(self) -> bool:
        return self._attached

    @property
    def simulated(self) -> bool:
        """True when this session started the simulated testbed it talks to."""
        return self._local is not None

    @property
    def simulator(self):
        """The fast simulated device this session steps (a SimulatedDevice in this process,
        whose firmware a script may inspect, or a SteppedSimulatorProcess), else None."""
        return self._local.stepped if self._local is not None else None

    @property
    def recorder(self):
        return self.recording.recorder

    @property
    def recordings(self) -> list[dict[str, Any]]:
        return self.recording.entries

    def __enter__(self) -> "Station":
        self.open()
        return self

    def __exit__(self, exc_type, exc, tb) -> None:
        try:
            if exc_type is not None and issubclass(exc_type, KeyboardInterrupt):
                reason = "interrupted by the operator (Ctrl-C)"
            else:
                reason = f"{exc_type.__name__}: {exc}" if exc_type else "end of script"
            self.make_safe(reason=reason)
        finally:
            self.close()

    def open(self) -> None:
        if self._attached:                 # attach() did the opening
            return
        try:
            self._open()
        except BaseException:
            self.close()                   # a simulator started for a failed connect
            raise

    def _open(self) -> None:
        resource = named_generator(self.generator_spec)
        if self.device_spec == SIMULATED_DEVICE:
            self._local = start_simulator(
                self.testbed.path, dictionary=self.d, fast=self.fast, fast_sim=self.fast_sim.where,
                seed=self.seed, speed=self.speed, listen=self.sim_listen,
                generator=wants_simulated_generator(self.generator_spec, inertial=self.testbed.inertial))
            address, resource = self._local.address, self._local.fg_resource
        else:
            address = self.device_spec
        self.address = address
        self.echo(f"device {address}" + (f", generator {resource}" if resource else ""))
        stepped = self.simulator
        # held between steps, the fast device's time passes only when the stepped clock
        # runs it, and the clock counts the host as heard after every run (device-time
        # heartbeats): a wall-time heartbeat would only land at random ticks
        held = stepped is not None and self.fast_sim.between_steps == BetweenSteps.HELD
        self.client = open_link(self.d, address, local=self._local, heartbeat=not held)
        self.client.subscribe(self.state)
        if self.publishing is not None:    # before CONNECT: viewers see the session begin
            from ..fanout.publisher import Publisher
            self.publisher = Publisher(self.publishing.endpoint, curve_keys=self.publishing.curve_keys)
            self.publisher.attach(self.client, address)
            self.echo(f"publishing on {self.publisher.endpoint}")
        self.client.connect(take_over=self.take_over)
        self.clock = (SteppedClock(stepped, self.client, self.abort_event, pacing=self.fast_sim.pacing,
                                   between_steps=self.fast_sim.between_steps,
                                   recorder_backlog=self.recording.backlog)
                      if stepped is not None else WallClock(self.client, self.abort_event))
        if resource:
            self.generator = open_testbed_generator(resource, self.testbed)

    def close(self) -> None:
        """Close everything this session opened (after make_safe)."""
        for step in (self.recording.close, self.recording.close_standby, self._close_generator,
                     self._close_clock, self._close_client, self._stop_sim,
                     self.recording.finish_compression):
            try:
                step()
            except Exception:                          # closing must reach every step
                log.exception("closing the session: %s failed", getattr(step, "__name__", step))

    def make_safe(self, reason: str = "") -> None:
        """ABORT the device, generator outputs off, recording closed.  Never raises."""
        with self._safe_lock:
            self._make_safe(reason)

    def _make_safe(self, reason: str) -> None:
        if self.client is not None and self.client.link_state == LinkState.UP:
            try:
                self.client.command("ABORT")
            except GroundStationError as exc:
                log.error("ABORT failed: %s", exc)
        if self.generator is not None:
            try:
                self.generator.abort()
            except Exception as exc:                   # the driver logs and retries itself
                log.error("generator off failed: %s", exc)
        if self.recording.active:
            try:
                self.mark(f"stopped: {reason}" if reason else "stopped")
            except GroundStationError:
                pass
        self.recording.close(reason)

    def recover(self, reason: str = "", settle_s: float = 3.0) -> None:
        """After a failed run: make safe, let the rig come to rest for `settle_s` (a
        lightly damped base stage rings on after its generator stops), then acknowledge
        the latched fault (DISARM) and wait until the telemetry shows it cleared, so the
        next run can arm again."""
        self.make_safe(reason)
        self.clock.advance(settle_s)
        self.client.command("DISARM")
        deadline = time.monotonic() + 5.0
        tick = self.state.tick
        while (self.state.fault or self.state.tick == tick) and time.monotonic() < deadline:
            time.sleep(0.01)
        if self.state.fault:
            raise ScriptError("the device still reports a fault after DISARM")

    def abort(self) -> None:
        """From any thread: stop the script at its next wait, and make the rig safe now."""
        self.abort_event.set()
        self.make_safe("abort")

    # ------------------------------------------------------------------ device verbs
    def command(self, name: str, **args: Any):
        if name in TABLE_COMMANDS:
            raise ScriptError(f"{name}: the parameter table changes only through "
                              f"upload_design/upload_table (validated, verified, recorded)")
        self._check_running()
        return self.client.command(name, **args)

    def set_mode(self, mode: str) -> None:
        self.command("SET_MODE", mode=mode)

    def arm(self) -> None:
        self.command("ARM")

    def disarm(self) -> None:
        self.command("DISARM")

    def friction_comp(self, on: bool) -> None:
        self.command("FRICTION_COMP", enable=int(bool(on)))

    def set_reference(self, angle_rad: float) -> None:
        self.command("SET_REFERENCE", reference=float(angle_rad))

    def set_currents(self, coarse_a: float = 0.0, fine_a: float = 0.0) -> None:
        self.command("SET_CURRENTS", current_coarse=float(coarse_a), current_fine=float(fine_a))

    # ------------------------------------------------------------------ parameter table
    def parameter_loader(self) -> ParameterLoader:
        """The loader on this session's link, journaling into its recording."""
        if self.client is None:
            raise ScriptError("the session is not open")
        if self.history is None:
            self.history = MemoryHistory()
        return ParameterLoader(self.client, self.d, self.history, journal=self._journal,
                               active_table_seen=lambda: self.state.active_table,
                               reports_between_steps=self.clock.time_flows_between_steps)

    def read_params(self, progress: Callable[[str, float], None] | None = None):
        """The device's active table (ActiveTable: bytes, CRC, values)."""
        return self.parameter_loader().read_active(progress)

    def upload_design(self, path, accept_risk: str | None = None,
                      progress: Callable[[str, float], None] | None = None, *,
                      on_report: Callable[[Any], None] | None = None):
        """Validate a controller design against this testbed's model and upload it,
        verified.  `path` is a design file (or a ControllerDesign already loaded).  The
        table is the design's over the device's active one, and that very table is
        validated.  A design the validation refuses is not sent, unless `accept_risk`
        gives the reason an engineer accepts it (recorded in the history and the log);
        the device still applies its own checks.  `on_report` receives the validation's
        report before anything is sent.  Returns the UploadRecord."""
        from ..params.upload_path import source_of, upload_design

        self._check_running()
        chosen = self.testbed if self.testbed_path is not None else None
        return self._uploaded(source_of(path), lambda loader: upload_design(
            loader, path, accept_risk=accept_risk, progress=progress, on_report=on_report,
            warn=self.echo, testbed=chosen))

    def upload_table(self, values: Mapping[str, Any], source: str, *, design=None,
                     accept_risk: str | None = None,
                     progress: Callable[[str, float], None] | None = None,
                     on_report: Callable[[Any], None] | None = None):
        """Upload a complete table, verified.  With `design` it is validated against it;
        without one the closed loop cannot be checked, so it is sent only with
        `accept_risk` (the override, recorded).  `on_report` receives the validation's
        report (passed or refused) before anything is sent.  Returns the UploadRecord."""
        from ..params.upload_path import upload_table

        self._check_running()
        return self._uploaded(source, lambda loader: upload_table(
            loader, values, source, design=design, accept_risk=accept_risk, progress=progress,
            on_report=on_report, warn=self.echo))

    def _uploaded(self, source: str, upload):
        """Run one upload of params/upload_path.py on this session's loader: a refusal
        by the gate becomes the ScriptError a script sees; a verified upload is said and
        kept as `last_upload`."""
        from ..params.clearance import ValidationRefused

        try:
            outcome = upload(self.parameter_loader())
        except ValidationRefused as exc:
            raise ScriptError(f"{source}: {exc}") from exc
        self.last_upload = outcome.record
        self.echo(f"parameter table {outcome.record.crc:08x} verified ({outcome.source})")
        return outcome.record

    def rollback_params(self, progress: Callable[[str, float], None] | None = None):
        """Re-activate the table that was active before the upload that made the active one."""
        self._check_running()
        record = self.parameter_loader().rollback(progress=progress)
        self.echo(f"rolled back: table {record.crc:08x} active again (was {record.previous_crc:08x})")
        return record

    # ------------------------------------------------------------------ profiles
    def play_profile(self, profile, mode: str | None = None, *, timeout: float | None = None,
                     gyro_range: float | None = None,
                     progress: Callable[[int, int], None] | None = None,
                     upload_progress: Callable[[str, float], None] | None = None,
                     on_step: Callable[[str], None] | None = None, player_out: list | None = None):
        """Upload a profile (verified), set the mode, arm, play it sample-exact to its end,
        disarm; on anything else the player makes the device safe.  Returns the
        PlaybackResult whether or not it completed.  `player_out` receives the player
        (what it made safe, its upload record) for a caller that must report it."""
        from ..profiles.upload import ProfilePlayer

        self._check_running()
        kwargs = {} if gyro_range is None else {"gyro_range": gyro_range}
        player = ProfilePlayer(self.client, self.d, journal=self._journal, **kwargs)
        if player_out is not None:
            player_out.append(player)
        try:
            with self.clock.fast_forward():
                return player.play(profile, mode, timeout=timeout, progress=progress,
                                   upload_progress=upload_progress, on_step=on_step)
        finally:
            player.close()

    def play(self, profile, mode: str | None = None, *, max_seconds: float | None = None,
             progress: Callable[[float], None] | None = None):
        """Play a command profile (a file or a Profile) to its end; on the fast simulator
        the device clock runs flat out meanwhile.  `max_seconds` shortens a longer profile
        (trial runs, tests) with a smooth return to rest over its last 0.2 s.  Returns the
        PlaybackResult; raises when playback did not complete."""
        from ..profiles.profile import load_profile
        from ..profiles.samples import Profile

        prof = profile if isinstance(profile, Profile) else load_profile(profile, self.d)
        if max_seconds is not None and prof.duration > max_seconds:
            prof = _shortened(prof, max_seconds)
        result = self.play_profile(
            prof, mode, on_step=lambda text: self.echo(f"{prof.name}: {text}"),
            progress=(lambda done, total: progress(done / max(total, 1))) if progress else None)
        if not result.completed:
            if self.abort_event.is_set():          # ended by our own abort: say so
                raise ScriptAborted(f"profile {prof.name}: aborted ({result.text()})")
            raise ScriptError(f"profile {prof.name}: {result.text()}")
        self.echo(f"profile {prof.name}: {prof.sample_count} samples played")
        return result

    # ------------------------------------------------------------------ time
    def dwell(self, seconds: float, progress: Callable[[float], None] | None = None) -> None:
        """Let `seconds` of device time pass (fast on the fast simulator)."""
        self._check_running()
        # a fault ends the wait at once: the log then ends near the fault, not a minute on
        if isinstance(self.clock, SteppedClock):
            # judged on the device after each chunk: the same tick however fast it runs
            self.clock.advance(seconds, progress, stop_on_fault=True)
        else:
            self.clock.advance(seconds, progress, until=lambda: self.state.fault)
        self._check_running()

    def settle(self, max_seconds: float = 30.0, criteria: StartCriteria | None = None,
               progress: Callable[[float], None] | None = None, *,
               recentre: str | Path | None = None, recentre_seconds: float = 20.0) -> dict[str, float]:
        """Wait (device time) until the rig is at rest, in range and unfaulted; with
        `recentre` (a RELATIVE-mode design) bring it back first when only out of range.
        The measured start state, marked in the log; ScriptError with every unmet
        criterion otherwise (station/settling.py)."""
        if self.clock is None:
            raise ScriptError("settle: the session is not open")
        return settle_rig(self, max_seconds, criteria or StartCriteria(), progress,
                          None if recentre is None else Path(recentre), recentre_seconds)

    def _note(self, text: str) -> None:
        """A line for the operator, and a mark in the log when one is recording."""
        if self.recording.active:
            self.mark(text)
        else:
            self.echo(text)

    def pause(self, prompt: str) -> None:
        """Wait for the operator; refused when nobody can answer (a non-interactive run)."""
        if self.operator is None:
            raise ScriptError(f"pause '{prompt}': no operator to answer in this run")
        self.echo(f"PAUSE: {prompt}")
        if not self.operator(prompt):
            raise ScriptAborted(f"the operator stopped at '{prompt}'")

    # ------------------------------------------------------------------ recording
    def start_recording(self, name: str, notes: str = "") -> Path:
        if self.recording.active:
            raise ScriptError(f"start_recording '{name}': '{self.recorder.test_name}' is still recording")
        fast = isinstance(self.clock, SteppedClock)
        path = self.recording.start(self.client, self.d, self.testbed, self.log_folder, name, notes,
                                    fast=fast)
        if self.device_spec != "attached":     # (attached: the window's recording says it)
            self.recording.journal("testbed", device_record(
                self.device_spec == SIMULATED_DEVICE, address=self.address, seed=self.seed, fast=fast,
                speed=self.speed))
        if fast:
            self.clock.tick_over()          # held device time: the log opens with telemetry
        return path

    def stop_recording(self) -> dict[str, Any]:
        if not self.recording.active:
            raise ScriptError("stop_recording: nothing is recording")
        name = self.recording.recorder.test_name
        entry, status = self.recording.stop(self.client)
        if status.state != "stopped":
            raise ScriptError(f"recording '{name}' ended badly: {status.state} {status.error}")
        return entry

    def mark(self, text: str) -> None:
        """An event in the current log (and the script's output)."""
        self.echo(f"mark: {text}")
        self.recording.mark("script", text)

    # ------------------------------------------------------------------ generator
    # the work is the GeneratorDesk's; these are the script verbs (campaign actions too)
    def generator_set(self, channel: int = 1, *, waveform: str = "SINE", frequency_hz: float | None = None,
                      amplitude_vpp: float | None = None, offset_v: float = 0.0,
                      phase_deg: float = 0.0, output: bool = True) -> None:
        """Configure one channel of the generator and switch its output on (or off)."""
        self.generator_desk.set(channel, waveform=waveform, frequency_hz=frequency_hz,
                                amplitude_vpp=amplitude_vpp, offset_v=offset_v,
                                phase_deg=phase_deg, output=output)

    def generator_off(self) -> None:
        """Every generator output off (nothing to do without a generator)."""
        self.generator_desk.off()

    def play_base_motion(self, psd_file: str | Path, *, duration_s: float = 60.0, seed: int = 0,
                         rms_rad: float | None = None, channel: int = 1):
        """Synthesise a base-motion profile from a PSD table, play it on the generator
        and return the profile (GeneratorDesk.play_base_motion)."""
        return self.generator_desk.play_base_motion(psd_file, duration_s=duration_s, seed=seed,
                                                    rms_rad=rms_rad, channel=channel)

    # ------------------------------------------------------------------ helpers
    def _journal(self, kind: str, record: dict, blob: bytes = b"") -> None:
        """Journal entries of the verbs: the owner's recording (attach(journal=...)), else ours."""
        (self._owner_journal or self.recording.journal)(kind, record, blob)

    def _check_running(self) -> None:
        if self.abort_event.is_set():
            raise ScriptAborted("aborted")
        if self.client is None:
            raise ScriptError("the session is not open")
        if self.state.fault:
            raise ScriptError("the device reports a fault (see its EVENTs); it has disarmed - "
                              "send DISARM to acknowledge it, then try again")

    def _close_generator(self) -> None:
        gen, self.generator = self.generator, None
        if gen is not None and self._owns_generator:
            gen.close()

    def _close_clock(self) -> None:
        if self.clock is not None:
            self.clock.close()

    def _close_client(self) -> None:
        client, self.client = self.client, None
        if client is not None and self._attached:
            client.unsubscribe(self.state)     # the owner's link goes on without us
        elif client is not None:
            client.close()
        publisher, self.publisher = self.publisher, None
        if publisher is not None:              # after the close: viewers hear it end
            publisher.close()

    def _stop_sim(self) -> None:
        local, self._local = self._local, None
        if local is not None:
            local.stop()


def _shortened(profile, seconds: float):
    """The first `seconds` of a profile, brought back to rest (0) over its last 0.2 s."""
    import dataclasses

    import numpy as np

    n = max(4, int(seconds * profile.rate))
    k = max(2, min(int(0.2 * profile.rate), n // 2))
    samples = np.array(profile.samples[:n], dtype=np.float64)
    fade = 0.5 + 0.5 * np.cos(np.pi * np.arange(1, k + 1) / k)      # 1 -> 0 with zero slope
    samples[-k:] *= fade
    return dataclasses.replace(profile, samples=samples, name=f"{profile.name} (first {seconds:g} s)")
