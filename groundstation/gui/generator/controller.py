"""The GUI's function-generator controller: the one owner of the 4050-series driver.

No widgets here.  Every VISA transaction runs on one worker thread, one job at a time, in
the order asked: a VISA session is not thread-safe, and the instrument must see settings
in the order the operator gave them.  Results come back as Qt signals, always with the
state read back from the instrument (waveform, frequency, amplitude, offset, phase,
output, load), never with what was asked for.

Safety:
* a setting is checked against the instrument's and the testbed's limits on the
  caller's thread before it is queued (the driver's `check` is pure, no I/O), so a panel
  can refuse it at once with the reason; the driver checks again, against what the
  instrument holds, before sending;
* `abort()` jumps the queue: jobs not started yet are dropped (an "output on" queued
  before an abort must never run after it), a job under way stops before its next
  step, and both outputs go off as soon as the transaction in progress has finished;
* `shutdown()` (the window closes, the simulator stops) switches the outputs off and
  closes the session, bounded in time; the driver's own atexit/finaliser is the last net.

What was done is journaled in the recording (kind "function_generator"), so a log says
which waveform moved the base and when.

The parts without Qt live in modules of their own, and every name is still importable
from here: `fg_jobs` (the worker thread and its queue), `fg_records` (what the controller
reports), `fg_limits_text` (the allowed ranges as the panel shows them) and
`fg_motion_check` (the achieved base motion against its target, from the telemetry).
"""

from __future__ import annotations

import logging
import threading
from dataclasses import asdict
from pathlib import Path
from typing import Callable

from PySide6.QtCore import QObject, Signal

from ...basemotion import BaseMotionProfile, BaseStageModel, PsdTable, load_psd, make_profile
from ...core.errors import GroundStationError
from ...instruments import (BasicWave, FunctionGenerator4050, InstrumentLinkError, SafetyLimits,
                            SettingRefusedError, list_resources)
from ...instruments.generator_journal import JOURNAL_KIND, GeneratorJournalRecord
from ...instruments.spec4050 import arb_name_for
from ...plant.testbed import DEFAULT_TESTBED, Testbed, load_testbed
from ...station.rig import open_testbed_generator
from .jobs import JobQueue
from .motion_check import check_uploaded_motion, newest_device_time
from .records import (DEFAULT_TOLERANCE, SIMULATOR, CheckResult, GeneratorState,
                      ResourceChoice, UploadedProfile)

log = logging.getLogger(__name__)

SHUTDOWN_TIMEOUT_S = 10.0


class GeneratorController(QObject):
    #: the resources found: list[ResourceChoice], notes (tuple[str]) from the VISA backend
    sig_resources = Signal(object, object)
    sig_opened = Signal(str, str)            # resource, identity
    sig_closed = Signal(str)                 # resource
    sig_state = Signal(object)               # GeneratorState, read back after every change
    sig_uploaded = Signal(object)            # UploadedProfile
    sig_failed = Signal(str, str)            # action, message (the instrument or the link failed)
    #: a setting refused before sending: the setting's name ("amplitude", ...) and why
    sig_refused = Signal(str, str)
    sig_info = Signal(str)                   # something done that a status line should say
    sig_busy = Signal(str)                   # the job under way ("" when idle)

    def __init__(self, session, journal: Callable[[str, dict, bytes], None] | None = None,
                 parent: QObject | None = None):
        """`session`: anything with `testbed` (path or None), `fg_resource` (the
        simulator's generator or None), `store` (TelemetryStore) and `d` (Dictionary)."""
        super().__init__(parent)
        self.session = session
        self._journal = journal
        self.backend: str | None = None      # pyvisa backend for listing/opening (None: @py)
        self.timeout_s = 5.0
        self.fg: FunctionGenerator4050 | None = None
        self.resource: str = ""
        self.limits: SafetyLimits | None = None
        self.state: GeneratorState | None = None
        self.uploaded: UploadedProfile | None = None
        #: device times (s) where the base motion last (re)started and stopped
        self.motion_start_s: float | None = None
        self.motion_end_s: float | None = None
        #: whether the motion since motion_start_s is the uploaded profile playing
        self.motion_plays_upload = False
        self._testbeds: dict[str, Testbed] = {}
        self._jobs = JobQueue(busy=lambda action: self.sig_busy.emit(action),
                              info=lambda text: self.sig_info.emit(text),
                              failed=lambda action, text: self.sig_failed.emit(action, text))
        self._lock = self._jobs.lock          # the resource listing's state too
        self._lister: threading.Thread | None = None
        self._relist = False

    # ------------------------------------------------------------------ testbed and limits
    def testbed(self) -> Testbed:
        """The session's testbed (the simulator's default when none is chosen)."""
        path = str(self.session.testbed or DEFAULT_TESTBED)
        if path not in self._testbeds:
            self._testbeds[path] = load_testbed(path)
        return self._testbeds[path]

    def safety_limits(self) -> SafetyLimits:
        return SafetyLimits.from_testbed(self.testbed())

    def stage(self) -> BaseStageModel:
        return BaseStageModel.from_testbed(self.testbed())

    # ------------------------------------------------------------------ profiles (no I/O)
    @staticmethod
    def load_psd(path: str | Path) -> PsdTable:
        return load_psd(path)

    def make_profile(self, path: str | Path, *, duration_s: float, seed: int,
                     target_rms_mrad: float | None, precompensate: bool) -> BaseMotionProfile:
        """A profile for this testbed's stage; BaseMotionError / PsdFileError say why not."""
        return make_profile(load_psd(path), self.stage(), duration_s=duration_s, seed=seed,
                            target_rms_rad=None if target_rms_mrad is None else target_rms_mrad / 1e3,
                            precompensate=precompensate)

    # ------------------------------------------------------------------ resources
    def simulator_resource(self) -> str | None:
        return getattr(self.session, "fg_resource", None)

    def refresh_resources(self) -> None:
        """List the VISA resources on a thread of its own (pyvisa-py's discovery takes
        about a second, and uses its own resource manager, never the open session), plus
        the simulator's generator when the session's simulator serves one.

        One listing at a time: `list_resources` catches the backend's warnings with
        warnings.catch_warnings, which is process-wide state - two at once would restore
        each other's filters.  A request during a listing makes it list once more."""
        with self._lock:
            self._relist = True
            if self._lister is not None and self._lister.is_alive():
                return
            self._lister = threading.Thread(target=self._list_work, name="gs-fg-list", daemon=True)
            self._lister.start()

    def _list_work(self) -> None:
        while True:
            with self._lock:
                if not self._relist or self._jobs.closing:
                    self._lister = None
                    return
                self._relist = False
            listing = list_resources(self.backend)
            choices = []
            sim = self.simulator_resource()
            if sim:
                choices.append(ResourceChoice(sim, f"{SIMULATOR} - {sim}", True))
            choices += [ResourceChoice(r, r) for r in listing.resources if r != sim]
            self.sig_resources.emit(choices, listing.notes)

    def resolve(self, resource: str) -> str:
        """'simulator' (or its label) -> the simulator's VISA address."""
        text = resource.strip()
        if text == SIMULATOR or text.startswith(SIMULATOR + " - "):
            sim = self.simulator_resource()
            if not sim:
                raise InstrumentLinkError("the simulated testbed is not running (or serves no "
                                          "generator): connect to the simulated testbed first")
            return sim
        return text

    # ------------------------------------------------------------------ the worker (fg_jobs)
    def idle(self) -> bool:
        """Nothing queued and nothing under way (for scripts and tests)."""
        return self._jobs.idle()

    def _require(self) -> FunctionGenerator4050:
        fg = self.fg
        if fg is None or fg.closed:
            raise InstrumentLinkError("no function generator is open: pick a resource and Connect")
        return fg

    def _record(self, action: str, data: dict, blob: bytes = b"") -> None:
        if self._journal is not None:
            try:
                record = GeneratorJournalRecord(action=action, resource=self.resource, **data)
                self._journal(JOURNAL_KIND, record.to_record(), blob)
            except Exception as exc:       # the journal must never stop the instrument
                log.warning("journal: %s", exc)

    # ------------------------------------------------------------------ state read-back
    def _newest_device_time(self) -> float | None:
        return newest_device_time(self.session)

    def _read_state(self, channel: int, *, motion_changed: bool = False,
                    before: float | None = None) -> GeneratorState:
        """Read the channel back, note where the base motion started/stopped, emit.

        `before`: the newest telemetry time taken just before the command.  A stop is
        dated then - the telemetry lags the device, so that moment had the output still
        on for sure, and a check's window ending there holds no free decay; a start is
        dated after the read-back, which only lengthens the settling allowed for."""
        fg = self._require()
        wave = fg.basic_wave(channel)
        out = fg.output_state(channel)
        arb = fg.arb_selection(channel) if wave.waveform == "ARB" else None
        try:
            fg.check(channel, wave, out.load)
            refusal = ""
        except SettingRefusedError as exc:
            refusal = str(exc).replace("; nothing was sent", "")
        state = GeneratorState(self.resource, channel, wave, out, arb, refusal)
        previous, self.state = self.state, state
        was_on = previous is not None and previous.channel == channel and previous.output.on
        now = self._newest_device_time()
        up = self.uploaded
        plays_upload = (up is not None and up.channel == channel and wave.waveform == "ARB"
                        and arb is not None and arb.name == up.upload.name)
        if out.on and (not was_on or motion_changed):
            self.motion_start_s, self.motion_end_s = now, None
            self.motion_plays_upload = plays_upload
        elif was_on and not out.on:
            self.motion_end_s = before if before is not None else now
        if out.on and not plays_upload:        # changed at the front panel, say
            self.motion_plays_upload = False
        self.sig_state.emit(state)
        return state

    # ------------------------------------------------------------------ open / close
    def open(self, resource: str) -> None:
        """Open a generator (closing any other first: its outputs go off)."""
        try:
            address = self.resolve(resource)
            self._testbeds.clear()            # the limits as the file says now, not as cached
            limits = self.safety_limits()
        except GroundStationError as exc:
            self.sig_failed.emit("open", str(exc))
            return

        def job(epoch):
            self._close_now()
            fg = open_testbed_generator(address, limits=limits, backend=self.backend,
                                        timeout_s=self.timeout_s)
            self.fg, self.resource, self.limits = fg, address, limits
            self.state = None
            self._record("open", {"identity": str(fg.identity), "limits": asdict(limits)})
            self.sig_opened.emit(address, str(fg.identity))
            self._read_state(1)
        self._jobs.submit("open", job)

    def _close_now(self) -> None:
        fg, self.fg = self.fg, None
        if fg is not None:
            resource = self.resource
            before = self._newest_device_time()
            fg.close()                        # outputs off; never raises
            self._record("close", {"device_time": before})
            if self.state is not None and self.state.output.on:
                self.motion_end_s = before
            self.state = None
            self.sig_closed.emit(resource)

    def close(self) -> None:
        """Outputs off and the session closed (queued: after what was asked before)."""
        self._jobs.submit("close", lambda epoch: self._close_now())

    @property
    def is_open(self) -> bool:
        return self.fg is not None and not self.fg.closed

    # ------------------------------------------------------------------ settings
    def _precheck(self, channel: int, wave: BasicWave, load: str | None) -> str | None:
        """The driver's own check, before anything is queued; the reason if refused
        (also emitted as sig_refused with the setting's name)."""
        fg = self.fg
        if fg is None or fg.closed:
            reason = "no function generator is open: pick a resource and Connect"
            self.sig_refused.emit("", reason)
            return reason
        try:
            fg.check(channel, wave, load)
        except SettingRefusedError as exc:
            self.sig_refused.emit(exc.setting, str(exc))
            return str(exc)
        return None

    def _known_load(self, channel: int) -> str | None:
        s = self.state
        return s.output.load if s is not None and s.channel == channel else None

    def apply(self, channel: int, *, waveform: str, frequency_hz: float | None = None,
              amplitude_vpp: float | None = None, offset_v: float = 0.0,
              phase_deg: float = 0.0, load: str | None = None) -> str | None:
        """Send a basic wave (and the load, if given).  Returns the reason when it is
        refused before sending (and emits it as sig_failed); None when queued."""
        wave = BasicWave(waveform.upper(), frequency_hz, amplitude_vpp, offset_v, phase_deg)
        reason = self._precheck(channel, wave, load or self._known_load(channel))
        if reason:
            return reason

        def job(epoch):
            fg = self._require()
            # one call: the new wave is checked against the new load, and the driver
            # sends the load and the wave in the order that is safe in between
            sent = fg.configure(channel, waveform=wave.waveform, frequency_hz=frequency_hz,
                                amplitude_vpp=amplitude_vpp, offset_v=offset_v,
                                phase_deg=phase_deg, load=load)
            self._record("apply", {"channel": channel, "wave": asdict(sent), "load": load,
                                   "device_time": self._newest_device_time()})
            state = self._read_state(channel, motion_changed=True)
            self.sig_info.emit(f"applied: {state.text()}")
        self._jobs.submit("apply", job)
        return None

    def set_output(self, channel: int, on: bool) -> str | None:
        """Output on (refused at once if what the instrument last reported is outside the
        limits) or off (always).  The state shown afterwards is what the instrument reports."""
        if on:
            s = self.state
            if s is not None and s.channel == channel or self.fg is None or self.fg.closed:
                reason = self._precheck(channel, s.wave if s is not None else None,
                                        s.output.load if s is not None else None)
            else:
                reason = None                 # not read yet: the driver checks what it reads
            if reason:
                return reason

        def job(epoch):
            fg = self._require()
            if on:
                self._jobs.guard(epoch)
            before = self._newest_device_time()
            fg.set_output(channel, on)
            state = self._read_state(channel, before=before)
            self._record("output", {"channel": channel, "on": state.output.on,
                                    "device_time": before if not on else self._newest_device_time()})
        self._jobs.submit("output on" if on else "output off", job)
        return None

    def refresh(self, channel: int) -> None:
        """Read a channel back (the front panel may have changed it)."""
        self._jobs.submit("read back", lambda epoch: self._read_state(channel))

    def upload_profile(self, channel: int, profile: BaseMotionProfile,
                       name: str | None = None) -> str | None:
        """Upload a base-motion profile as the channel's arbitrary waveform and play it
        (ARB at 1/period); the output state is left as it is.  Returns the refusal
        reason, or None when queued."""
        arb_name = arb_name_for(name or profile.name)
        peak = max(abs(float(profile.volts.max())), abs(float(profile.volts.min())))
        wave = BasicWave("ARB", profile.frequency_hz, 2 * peak, 0.0, 0.0)
        reason = self._precheck(channel, wave, self._known_load(channel))
        if reason:
            return reason

        def job(epoch):
            fg = self._require()
            self._jobs.guard(epoch)
            up = fg.upload_arbitrary(channel, profile.volts, name=arb_name,
                                     frequency_hz=profile.frequency_hz)
            self.uploaded = UploadedProfile(channel, profile, up)
            # a run before this upload is not this profile's (if the output is on, the
            # read-back below starts the motion again: the waveform restarts on selection)
            self.motion_start_s = self.motion_end_s = None
            self.motion_plays_upload = False
            lo, hi = profile.psd.band_hz
            self._record("upload", {"channel": channel, "name": arb_name, "profile": profile.name,
                                    "psd_source": profile.psd.source,
                                    "duration_s": profile.duration_s, "seed": profile.seed,
                                    "target_rms_rad": profile.target_rms_rad,
                                    "precompensated": profile.precompensated,
                                    "band_hz": [lo, hi], "points": up.points,
                                    "frequency_hz": up.frequency_hz,
                                    "amplitude_vpp": up.amplitude_vpp,
                                    "device_time": self._newest_device_time()},
                         up.codes.astype("<i2").tobytes())
            self.sig_uploaded.emit(self.uploaded)
            self._read_state(channel, motion_changed=True)
            self.sig_info.emit(f"uploaded {arb_name}: {up.points} points at "
                               f"{up.frequency_hz:.6g} Hz, {up.amplitude_vpp:.3f} Vpp")
        self._jobs.submit("upload", job)
        return None

    # ------------------------------------------------------------------ abort and shutdown
    def abort(self) -> None:
        """Both outputs off, from any state, without waiting for anything queued.  Returns
        at once; the read-back arrives as sig_state."""
        channel = self.state.channel if self.state is not None else 1

        def job(epoch):
            fg = self.fg
            if fg is None or fg.closed:       # nothing to switch off: nothing to say
                log.debug("abort: no function generator open")
                return
            before = self._newest_device_time()
            try:
                fg.abort()
            except GroundStationError as exc:
                self.sig_failed.emit("abort", f"the outputs may still be ON: {exc}")
                return
            self._record("abort", {"device_time": before})
            state = self._read_state(channel, before=before)
            self.sig_info.emit(f"abort: outputs off ({state.text()})")
        self._jobs.preempt("abort", job)

    def shutdown(self, timeout: float = SHUTDOWN_TIMEOUT_S) -> None:
        """Outputs off and the session closed before returning (bounded by `timeout` and
        the VISA timeout).  For the window closing and the simulator stopping."""
        self.blockSignals(True)               # the widgets that would hear are going
        self._jobs.close("close", lambda epoch: self._close_now(), timeout)
        lister = self._lister
        if lister is not None:                # never leave a listing running into teardown
            lister.join(timeout)
        fg, self.fg = self.fg, None
        if fg is not None:                    # the worker never ran, or hung: do it here
            fg.close()

    def forget_simulator(self, timeout: float = SHUTDOWN_TIMEOUT_S) -> None:
        """The simulator is about to stop: if its generator is the one open, switch the
        outputs off and close it before returning (afterwards nothing would answer)."""
        sim = self.simulator_resource()
        if not sim or self.resource != sim or self.fg is None:
            return
        done = threading.Event()

        def job(epoch):
            try:
                self._close_now()
            finally:
                done.set()
        # nothing queued for it may run any more
        self._jobs.preempt("close", job, even_closing=True)
        if not done.wait(timeout):
            log.error("generator: closing %s did not finish within %g s", sim, timeout)

    # ------------------------------------------------------------------ verification
    def check_achieved(self, tolerance: float = DEFAULT_TOLERANCE,
                       periods: int = 1) -> CheckResult:
        """The base encoder's last whole period(s) of settled motion under the last
        uploaded profile (from the session's telemetry store) against its target.
        BaseMotionError says what is missing (no upload, output never on, not enough data)."""
        up = self.uploaded
        s = self.state
        result = check_uploaded_motion(self.session, up, self.motion_start_s, self.motion_end_s,
                                       self.motion_plays_upload, s is not None and s.output.on,
                                       tolerance, periods)
        check, window = result.check, result.window
        self._record("check", {"profile": up.profile.name, "target_rms_rad": check.target_rms_rad,
                               "achieved_rms_rad": check.achieved_rms_rad,
                               "window_s": [window.start_s, window.end_s],
                               "missing_frames": window.missing_frames, "ok": result.ok})
        return result


__all__ = ["GeneratorController"]
