"""`Testbed`: the campaign verbs for a script or a notebook.

    from groundstation import Testbed

    with Testbed("sim", testbed="profiles/testbeds/relative_2dof.toml", fast=True) as tb:
        tb.upload_design("profiles/controllers/relative_design2.toml")
        tb.set_mode("RELATIVE")
        tb.arm()
        tb.start_recording("step", notes="Design #2, 1 mrad step")
        tb.set_reference(1e-3)
        tb.dwell(2.0)
        tb.stop_recording()

Whatever happens inside the `with` block - an exception, Ctrl-C, a lost link - the exit
leaves the rig safe: ABORT (motors off, disarmed), the generator's outputs off, and the
recording closed with everything received so far.  Every verb raises a specific error
when it cannot do its job; none of them leaves a step half done without saying so.

`device="sim"` starts the simulated testbed: with `fast=True` in this process, its
clock driven by the script (a 60 s dwell takes about a second); without, as a real-time
child process, exactly as `make run` does.  Any other value is an address of a rig.
"""

from __future__ import annotations

import logging
import threading
import time
from pathlib import Path
from typing import Any, Callable

from .clock import ScriptAborted, SteppedClock, WallClock
from .dictionary import load_dictionary
from .errors import GroundStationError
from .link import open_client
from .logs import Recorder
from .logs.live import attach_recorder
from .params.upload import ParameterHistory, ParameterLoader
from .plant.testbed import load_testbed

log = logging.getLogger(__name__)


class ScriptError(GroundStationError):
    """A step of a script or campaign could not be done (the message says which and why)."""


class _Tracker:
    """The newest HIGH_RATE state the script needs (receiver thread writes, script reads)."""

    def __init__(self) -> None:
        self.mode = 0
        self.armed = False
        self.fault = False
        self.profile_active = False
        self.profile_index = 0
        self.tick = -1

    def __call__(self, block) -> None:
        if block.name != "HIGH_RATE" or not len(block):
            return
        self.mode = int(block["mode"][-1])
        self.armed = bool(block["armed"][-1])
        self.fault = bool(block["fault"][-1])
        self.profile_active = bool(block["profile_active"][-1])
        self.profile_index = int(block["profile_index"][-1])
        self.tick = int(block["tick"][-1])


class Testbed:
    """One session with a testbed (or its simulation); see the module docstring."""

    __test__ = False        # a name starting with "Test" that pytest must not collect

    def __init__(self, device: str = "sim", *, testbed: str | Path | None = None, fast: bool = False,
                 generator: str | None = "auto", log_folder: str | Path = "logs", seed: int = 0,
                 history: str | Path | None = None, take_over: bool = False,
                 operator: Callable[[str], bool] | None = None,
                 echo: Callable[[str], None] | None = None):
        self.device_spec = device
        self.testbed_path = Path(testbed) if testbed else None
        self.fast = fast
        self.generator_spec = generator
        self.log_folder = Path(log_folder)
        self.seed = seed
        self.history = ParameterHistory(history) if history else None
        self.take_over = take_over
        #: asked at a pause step; True goes on, False aborts (None: refuse pauses)
        self.operator = operator
        self.echo = echo or (lambda text: log.info("%s", text))
        self.d = load_dictionary()
        self.testbed = load_testbed(self.testbed_path)
        self.abort_event = threading.Event()
        self.state = _Tracker()
        self.client = None
        self.clock: WallClock | SteppedClock | None = None
        self.generator = None
        self.recorder: Recorder | None = None
        self.recordings: list[dict[str, Any]] = []
        self.last_upload = None
        self._device = None          # in-process SimulatedDevice (fast)
        self._drops_at_start = 0
        self._recording_t0 = 0.0
        self._detach_recorder: Callable[[], None] | None = None
        self._fg_server = None
        self._sim = None             # SimulatorProcess (real-time simulation)
        #: attach(): the client belongs to someone else (the GUI's session) - close() leaves
        #: it open; likewise a generator driver passed in is not ours to close
        self._attached = False
        self._owns_generator = True
        # abort() runs make_safe on the caller's thread while the script's own thread may
        # be making safe after its step failed: one at a time, or both would close the
        # same recording
        self._safe_lock = threading.RLock()

    # ------------------------------------------------------------------ session
    @classmethod
    def attach(cls, client, *, testbed: str | Path | None = None, generator=None,
               log_folder: str | Path = "logs", history=None,
               operator: Callable[[str], bool] | None = None,
               echo: Callable[[str], None] | None = None) -> "Testbed":
        """A session on a connection that is already open and owned by someone else (the
        GUI's, whose charts then show the script live).  `client` is a connected
        DeviceClient; time is wall time (a real-time device).  `generator` is None, a
        VISA resource (opened here, closed by close()) or an open FunctionGenerator4050
        (used, never closed here).  `history` a folder or a ParameterHistory.

        make_safe()/abort() act as always (ABORT on the shared link, generator outputs
        off, this session's recording closed); close() closes only what the session
        opened itself - the client stays open, with this session's subscriptions removed."""
        if client is None or client.link_state != "up":
            raise ScriptError("attach: the link is not up - connect to the device first")
        shared_history = isinstance(history, ParameterHistory)
        tb = cls("attached", testbed=testbed, generator=None, log_folder=log_folder,
                 history=None if shared_history else history, operator=operator, echo=echo)
        if shared_history:
            tb.history = history
        tb._attached = True
        tb.d = client.dictionary           # the link's own dictionary: the same protocol
        tb.client = client
        client.subscribe(tb.state)
        tb.clock = WallClock(client, tb.abort_event)
        if isinstance(generator, str):
            from .instruments.fg4050 import open_generator
            try:
                tb.generator = open_generator(generator, testbed=tb.testbed)
            except BaseException:
                client.unsubscribe(tb.state)
                raise
        elif generator is not None:
            tb.generator, tb._owns_generator = generator, False
        tb.echo("attached to the open link" + (f", generator {tb.generator.resource_name}"
                                                 if tb.generator is not None else ""))
        return tb

    @property
    def attached(self) -> bool:
        return self._attached

    def __enter__(self) -> "Testbed":
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
        resource = None
        want_fg = (self.generator_spec == "auto" and self.testbed.inertial) or self.generator_spec == "sim"
        if self.device_spec == "sim":
            if self.fast:
                from .sim.device import SimulatedDevice
                from .sim.firmware import Firmware

                fw = Firmware(self.d, seed=self.seed, testbed=self.testbed)
                self._device = SimulatedDevice(self.d, pacing="manual", firmware=fw).start()
                address = f"127.0.0.1:{self._device.tcp_port}"
                if want_fg:
                    from .sim.scpi_fg import attach_generator
                    self._fg_server = attach_generator(self._device)
                    resource = self._fg_server.resource
            else:
                from .sim.process import SimulatorProcess
                self._sim = SimulatorProcess(pacing="realtime", seed=self.seed,
                                             testbed=str(self.testbed.path),
                                             fg_port=0 if want_fg else None)
                address = self._sim.start()
                resource = self._sim.fg_resource
        else:
            address = self.device_spec
            if self.generator_spec not in (None, "auto", "none", "sim"):
                resource = self.generator_spec
        self.echo(f"device {address}" + (f", generator {resource}" if resource else ""))
        self.client = open_client(self.d, address)
        self.client.subscribe(self.state)
        self.client.connect(take_over=self.take_over)
        self.clock = (SteppedClock(self._device, self.client, self.abort_event) if self._device
                      else WallClock(self.client, self.abort_event))
        if resource:
            from .instruments.fg4050 import open_generator
            self.generator = open_generator(resource, testbed=self.testbed)

    def close(self) -> None:
        """Close everything this session opened (after make_safe)."""
        for step in (self._stop_recorder_quietly, self._close_generator, self._close_clock,
                     self._close_client, self._stop_sim):
            try:
                step()
            except Exception:                          # closing must reach every step
                log.exception("closing the test session: %s failed", step.__name__)

    def make_safe(self, reason: str = "") -> None:
        """ABORT the device, generator outputs off, recording closed.  Never raises."""
        with self._safe_lock:
            self._make_safe(reason)

    def _make_safe(self, reason: str) -> None:
        if self.client is not None and self.client.link_state == "up":
            try:
                self.client.command("ABORT")
            except GroundStationError as exc:
                log.error("ABORT failed: %s", exc)
        if self.generator is not None:
            try:
                self.generator.abort()
            except Exception as exc:                   # the driver logs and retries itself
                log.error("generator off failed: %s", exc)
        if self.recorder is not None:
            try:
                self.mark(f"stopped: {reason}" if reason else "stopped")
            except GroundStationError:
                pass
        self._stop_recorder_quietly(reason)

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

    def upload_design(self, path: str | Path, accept_risk: str | None = None):
        """Validate a controller design against this testbed's model and upload it,
        verified.  A design the validation refuses is not sent, unless `accept_risk`
        gives the reason an engineer accepts it (recorded in the history and the log);
        the device still applies its own checks."""
        from .params.design import load_design, table_values
        from .params.loop import validate

        self._check_running()
        design = load_design(path)
        loader = ParameterLoader(self.client, self.d, self.history, journal=self._journal)
        active = loader.read_active()
        values = table_values(design, base=active.values, dictionary=self.d)
        report = validate(design, values, self.d)
        source = str(path)
        if not report.ok:
            if not accept_risk:
                raise ScriptError(f"{path}: refused by validation, nothing sent: "
                                  + "; ".join(report.problems))
            source += f" (validation refused it; accepted: {accept_risk})"
            self.echo(f"WARNING: uploading {Path(path).name} although validation refused it "
                      f"({'; '.join(report.problems)}); reason given: {accept_risk}")
        self.last_upload = loader.upload(values, source=source)
        self.echo(f"parameter table {self.last_upload.crc:08x} verified ({design.name})")
        return self.last_upload

    def play(self, profile, mode: str | None = None, *, max_seconds: float | None = None,
             progress: Callable[[float], None] | None = None):
        """Play a command profile (a file or a Profile): upload it (verified), set the
        mode, arm, play it sample-exact to its end, disarm.  On the fast simulator the
        device clock runs flat out meanwhile.  `max_seconds` shortens a longer profile
        (trial runs, tests) with a smooth return to rest over its last 0.2 s.  Returns
        the PlaybackResult; raises when playback did not complete."""
        from .profiles.profile import Profile, load_profile
        from .profiles.upload import ProfilePlayer

        self._check_running()
        prof = profile if isinstance(profile, Profile) else load_profile(profile, self.d)
        if max_seconds is not None and prof.duration > max_seconds:
            prof = _shortened(prof, max_seconds)
        count = prof.sample_count
        player = ProfilePlayer(self.client, self.d, journal=self._journal)
        try:
            with self.clock.fast_forward():
                result = player.play(prof, mode, on_step=lambda text: self.echo(f"{prof.name}: {text}"),
                                     progress=(lambda done, total: progress(done / max(total, 1)))
                                     if progress else None)
        finally:
            player.close()
        if not result.completed:
            if self.abort_event.is_set():          # ended by our own abort: say so
                raise ScriptAborted(f"profile {prof.name}: aborted ({result.text()})")
            raise ScriptError(f"profile {prof.name}: {result.text()}")
        self.echo(f"profile {prof.name}: {count} samples played")
        return result

    # ------------------------------------------------------------------ time
    def dwell(self, seconds: float, progress: Callable[[float], None] | None = None) -> None:
        """Let `seconds` of device time pass (fast on the fast simulator)."""
        self._check_running()
        # a fault ends the wait at once: the log then ends near the fault, not a minute on
        self.clock.advance(seconds, progress, until=lambda: self.state.fault)
        self._check_running()

    def pause(self, prompt: str) -> None:
        """Wait for the operator; refused when nobody can answer (a non-interactive run)."""
        if self.operator is None:
            raise ScriptError(f"pause '{prompt}': no operator to answer in this run")
        self.echo(f"PAUSE: {prompt}")
        if not self.operator(prompt):
            raise ScriptAborted(f"the operator stopped at '{prompt}'")

    # ------------------------------------------------------------------ recording
    def start_recording(self, name: str, notes: str = "") -> Path:
        if self.recorder is not None:
            raise ScriptError(f"start_recording '{name}': '{self.recorder.test_name}' is still recording")
        tb = self.testbed
        rec = Recorder(self.d, self.log_folder, test_name=name, notes=notes,
                       testbed_text=tb.path.read_text(), testbed_name=tb.name,
                       testbed_path=str(tb.path))
        path = rec.start()
        try:
            self._detach_recorder = attach_recorder(self.client, rec)
        finally:
            # ours from here on, so that make_safe closes it with its reason even when a
            # Ctrl-C lands in the middle of this step
            self.recorder = rec
        self._drops_at_start = self._link_drops()
        self._recording_t0 = time.monotonic()
        # every log carries the table the device runs, whatever was uploaded before
        try:
            active = ParameterLoader(self.client, self.d).read_active()
            rec.record("parameter_table", {"source": "active at recording start", "crc": active.crc},
                       active.blob)
        except GroundStationError as exc:
            rec.note(f"could not read the active parameter table: {exc}")
        if notes:
            rec.note(notes)
        self.echo(f"recording {path}")
        return path

    def stop_recording(self) -> dict[str, Any]:
        rec = self.recorder
        if rec is None:
            raise ScriptError("stop_recording: nothing is recording")
        self.recorder = None
        self._detach()
        status = rec.stop()
        if status.state != "stopped":
            raise ScriptError(f"recording '{rec.test_name}' ended badly: {status.state} {status.error}")
        entry = {"name": rec.test_name, "files": [str(p) for p in status.files],
                 "frames": status.frames, "discarded_blocks": rec.discarded_blocks,
                 "dropped": self._link_drops() - self._drops_at_start,
                 "wall_seconds": round(time.monotonic() - self._recording_t0, 3)}
        self.recordings.append(entry)
        self.echo(f"recorded {status.frames} frames to {', '.join(p.name for p in status.files)}")
        return entry

    def mark(self, text: str) -> None:
        """An event in the current log (and the script's output)."""
        self.echo(f"mark: {text}")
        if self.recorder is not None:
            self.recorder.record("event", {"source": "script", "text": text})

    # ------------------------------------------------------------------ generator
    def _need_generator(self, what: str):
        if self.generator is None:
            raise ScriptError(f"{what}: no function generator in this session "
                              f"(give generator='sim' or a VISA resource)")
        return self.generator

    def generator_set(self, channel: int = 1, *, waveform: str = "SINE", frequency_hz: float | None = None,
                      amplitude_vpp: float | None = None, offset_v: float = 0.0,
                      phase_deg: float = 0.0, output: bool = True) -> None:
        gen = self._need_generator("generator_set")
        gen.configure(channel, waveform=waveform, frequency_hz=frequency_hz,
                      amplitude_vpp=amplitude_vpp, offset_v=offset_v, phase_deg=phase_deg)
        gen.set_output(channel, output)
        self.echo(f"generator: {gen.describe(channel)}")

    def generator_off(self) -> None:
        if self.generator is not None:
            self.generator.abort()

    def play_base_motion(self, psd_file: str | Path, *, duration_s: float = 60.0, seed: int = 0,
                         rms_rad: float | None = None, channel: int = 1):
        """Synthesise a base-motion profile from a PSD table, upload it to the generator
        and switch the output on; returns the profile (for the achieved-vs-target check)."""
        from .basemotion import load_profile

        gen = self._need_generator("play_base_motion")
        profile = load_profile(psd_file, self.testbed, duration_s=duration_s, seed=seed,
                               target_rms_rad=rms_rad)
        gen.upload_arbitrary(channel, profile.volts, name=Path(psd_file).stem[:8].upper(),
                             frequency_hz=1.0 / profile.duration_s)
        gen.set_output(channel, True)
        self.echo(f"base motion {profile.name}: {profile.amplitude_vpp:.3f} Vpp, "
                  f"{profile.duration_s:g} s period")
        if self.recorder is not None:
            self.recorder.record("event", {"source": "generator", "text": f"base motion {profile.name} on",
                                           "amplitude_vpp": profile.amplitude_vpp})
        return profile

    # ------------------------------------------------------------------ helpers
    def _link_drops(self) -> int:
        """Frames lost on the link so far (sequence gaps, every packet)."""
        if self.client is None:
            return 0
        return sum(ps.dropped for ps in self.client.stats.snapshot().packets.values())

    def _journal(self, kind: str, record: dict, blob: bytes) -> None:
        if self.recorder is not None:
            self.recorder.record(kind, record, blob)

    def _check_running(self) -> None:
        if self.abort_event.is_set():
            raise ScriptAborted("aborted")
        if self.client is None:
            raise ScriptError("the session is not open")
        if self.state.fault:
            raise ScriptError("the device reports a fault (see its EVENTs); it has disarmed")

    def _stop_recorder_quietly(self, reason: str = "") -> None:
        """Close the recording, its last journal entry saying why (`reason`): the log
        then explains its own end - an operator's Ctrl-C, a failed step, the end of the
        script."""
        rec, self.recorder = self.recorder, None
        if rec is not None:
            self._detach()
            why = reason or "end of the session"
            try:
                rec.note(f"recording closed: {why}")
            except Exception:                          # closing must go on regardless
                log.exception("could not note why the recording closes")
            status = _stop_with_reason(rec, why)
            self.recordings.append({"name": rec.test_name, "files": [str(p) for p in status.files],
                                    "frames": status.frames, "discarded_blocks": rec.discarded_blocks,
                                    "state": status.state, "stop_reason": why})

    def _detach(self) -> None:
        """The recorder off the link: telemetry, command and link listeners."""
        detach, self._detach_recorder = self._detach_recorder, None
        if detach is not None:
            detach()

    def _close_generator(self) -> None:
        gen, self.generator = self.generator, None
        if gen is not None and self._owns_generator:
            gen.close()
        server, self._fg_server = self._fg_server, None
        if server is not None:
            server.stop()

    def _close_clock(self) -> None:
        if self.clock is not None:
            self.clock.close()

    def _close_client(self) -> None:
        client, self.client = self.client, None
        if client is not None and self._attached:
            client.unsubscribe(self.state)     # the owner's link goes on without us
        elif client is not None:
            client.close()

    def _stop_sim(self) -> None:
        dev, self._device = self._device, None
        if dev is not None:
            dev.stop()
        sim, self._sim = self._sim, None
        if sim is not None:
            sim.stop()


def _stop_with_reason(rec, reason: str):
    """rec.stop() with the reason for the log's closing record, where the Recorder takes
    one (the note written before it says the same either way)."""
    import inspect

    try:
        takes_reason = "reason" in inspect.signature(rec.stop).parameters
    except (TypeError, ValueError):
        takes_reason = False
    return rec.stop(reason=reason) if takes_reason else rec.stop()


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
