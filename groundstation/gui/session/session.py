"""The GUI's session controller: owns the link (or the replay), the simulator child
process (with its function generator), the recorder, the function-generator controller
and the campaign controller (campaigns run on this session's link), and turns thread
callbacks into Qt signals.  Two jobs of their own are collaborators it owns, each built
with what it needs: `profiles` (ProfilePlayback: a profile played through the Station,
with its own sig_* signals) and `consoles` (Consoles: publishing this link for
read-only consoles, or watching one read-only).  No widgets here: this is the window's
model, the panels connect to its signals.

The parameter table and command profiles go through the Station verbs, exactly as the
CLI and scripts do: while the link is up a `Station` is attached to it (`self.station`,
`Station.attach`: it borrows the link, journals into this session's recording and keeps
the parameter history), and params_read / params_upload / params_rollback / play_profile
run its verbs on worker threads - the validation gate (a table goes only validated
against its design, or on the operator's stated reason) is the Station's, not the GUI's.

Widgets never touch a socket or a file: they call this object's methods, which run
anything that can block (connecting, commands, opening a log) on worker threads, and
they read the TelemetryStore / LimitMonitor on their own timers.  Results arrive as
typed signals, one per event (sig_params_active carries an ActiveTable, ...).
"""

from __future__ import annotations

import logging
import threading
from pathlib import Path
from typing import Any

from PySide6.QtCore import QObject, QTimer, Signal

from ...core.dictionary import Dictionary
from ...core.errors import GroundStationError
from ...core.kinds import SIMULATED_DEVICE, LinkState
from ...link import DeviceClient
from ...logs import Recorder, ReplaySource
from ...logs.live import attach_recorder
from ...logs.summary import event_markers
from .consoles import Consoles
from .profiles import ProfilePlayback
from .source import device_description
from ...live.limits import LimitMonitor
from ...params.upload import ParameterHistory
from ...station.recording import device_record
from ...station.keeper import RECONNECT_DELAYS_S
from ...station.rig import LocalSimulator, open_link, start_simulator
from ...station.station import Station
from ...live.display_buffers import TelemetryStore
from .campaign_runner import CampaignController
from ..generator.controller import GeneratorController
from .commands import CommandQueue
from ...profiles import Profile

log = logging.getLogger(__name__)

#: the telemetry reader's batches in the window: it draws at 30 Hz and only shows the
#: limits, so 25 ms batches lose nothing, and the reader thread costs a third less than
#: with the link's default 10 ms (bench_gui.py; arrival times stay the kernel's)
TELEMETRY_BATCH_S = 0.025


class Session(QObject):
    sig_link_state = Signal(str, str)            # state, message
    sig_event = Signal(str, str, str)            # level, source, text
    sig_command = Signal(str, str, str, str)     # command, sequence (u32, as text), stage, reason
    sig_recording_started = Signal(str)          # the log file's path
    sig_recording_stopped = Signal(str)          # what was written ("N frames in a.h5, ...")
    sig_recording_failed = Signal(str)           # why the recording failed (or ended badly)
    sig_source = Signal(str, str)                # "live"/"replay"/"none", description
    # parameter table work (worker threads)
    sig_params_active = Signal(object)           # ActiveTable: after a read, upload, rollback
    sig_params_uploaded = Signal(object)         # UploadRecord: a table verified on the device
    sig_params_progress = Signal(str, float)     # step ("upload", "read back"), fraction done
    sig_params_failed = Signal(str)              # why a read, upload or rollback failed

    def __init__(self, dictionary: Dictionary, store_seconds: float = 600.0, parent=None,
                 param_history: str | Path | None = None):
        super().__init__(parent)
        self.d = dictionary
        self.param_history = ParameterHistory(param_history or ParameterHistory.default_folder())
        self.store = TelemetryStore(dictionary, store_seconds)
        self.store.on_restart = self._on_device_restart
        self.limits = LimitMonitor(dictionary)
        self.client: DeviceClient | None = None
        #: the Station verbs on the live link (attached when it comes up, closed with it)
        self.station: Station | None = None
        self.replay: ReplaySource | None = None
        self.sim: LocalSimulator | None = None
        self.recorder: Recorder | None = None
        self._detach_recorder = None           # undoes attach_recorder on the current link
        self.address: str = ""
        self.testbed: str | None = None
        #: what the connected device says it is (source.device_description), "" before
        self.device_description = ""
        self._sim_testbed: str | None = None       # the testbed the running simulator has
        #: the simulator's pace (control periods per 1/1200 s of wall time); tests raise it
        #: to play a base-motion period in less wall time, the device's clock is unchanged
        self.sim_speed = 1.0
        self.last_uploaded_crc: int | None = None
        self.replay_events: list[tuple[float, int, str]] = []
        self._want_connected = False
        self._closing = False
        self._workers: list[threading.Thread] = []
        #: which link is the session's: raised whenever one is closed or replaced, so the
        #: states a replaced link still reports are ignored
        self._link_generation = 0
        #: operator commands, sent one after another in the order given
        self._commands = CommandQueue(self._worker)
        self._attempt = 0
        self._reconnect = QTimer(self)
        self._reconnect.setSingleShot(True)
        self._reconnect.timeout.connect(self._try_reconnect)
        self.sig_link_state.connect(self._on_link_state)
        #: the base-motion function generator; Abort, disconnecting and closing switch its
        #: outputs off whatever the link to the device is doing
        self.generator = GeneratorController(self, journal=self._journal, parent=self)
        self.generator.sig_failed.connect(
            lambda action, text: self.sig_event.emit("ERROR", "generator", f"{action}: {text}"))
        self.generator.sig_refused.connect(
            lambda setting, text: self.sig_event.emit("WARNING", "generator", f"refused: {text}"))
        self.generator.sig_info.connect(lambda text: self.sig_event.emit("INFO", "generator", text))
        #: profile playback on this session's Station (its own sig_step ... sig_done)
        self.profiles = ProfilePlayback(self._worker, self.sig_event.emit, parent=self)
        #: the fan-out: this link published, or another station watched read-only (then a
        #: fanout.WatchClient is self.client, with no Station: the verbs say "not connected")
        self.consoles = Consoles(dictionary, self.sig_event.emit, self._worker)
        #: campaigns on this session's link (Abort, disconnecting and closing stop them)
        self.campaign = CampaignController(self, parent=self)
        self.campaign.sig_log.connect(lambda text: self.sig_event.emit("INFO", "campaign", text))
        self.campaign.sig_failed.connect(lambda text: self.sig_event.emit("ERROR", "campaign", text))
        self.campaign.sig_finished.connect(lambda outcome: self.sig_event.emit(
            "INFO" if outcome.report.status == "completed" else "WARNING", "campaign",
            outcome.report.summary().splitlines()[0]))

    # ------------------------------------------------------------------ sources
    @property
    def source(self):
        """What telemetry comes from: the live client or the replay (same interface)."""
        return self.replay if self.replay is not None else self.client

    def connect_sim(self, testbed: str | None = None) -> None:
        self.testbed = testbed
        self._start_link(SIMULATED_DEVICE)

    def connect_address(self, address: str) -> None:
        self._start_link(address)

    @property
    def fg_resource(self) -> str | None:
        """The simulator's function generator (a VISA resource), when it is running."""
        sim = self.sim
        return sim.fg_resource if sim is not None and not sim.gone() else None

    def _start_link(self, address: str) -> None:
        self.close_replay()
        self.disconnect_link()
        # leaving the simulator behind, or asking for another testbed than it runs
        if self.sim is not None and (address != SIMULATED_DEVICE or self._sim_testbed != self.testbed):
            self.generator.forget_simulator()          # its outputs off while it can answer
            self.sim.stop()
            self.sim = None
        self.address = address
        self._want_connected = True
        self._attempt = 0
        self.sig_link_state.emit(LinkState.CONNECTING, address)
        generation = self._link_generation
        self._worker(lambda: self._connect_worker(generation), "gs-connect")

    def _worker(self, target, name: str) -> None:
        """Run blocking work off the GUI thread; shutdown() waits for all of it."""
        self._workers = [t for t in self._workers if t.is_alive()]
        t = threading.Thread(target=target, name=name, daemon=True)
        self._workers.append(t)
        t.start()

    def _link_state_of(self, generation: int, state: str, message: str) -> None:
        """A link's state, from its client or its connect worker: passed on only while
        that link is the session's.  A client being closed after the operator chose
        another address (or a reconnect replaced it) may still say "lost"; that must not
        start a reconnect that takes over the new link."""
        if generation == self._link_generation:
            self.sig_link_state.emit(state, message)
        else:
            log.debug("link state %r of a replaced link ignored (%s)", state, message)

    def _connect_worker(self, generation: int) -> None:
        try:
            address = self.address
            if address == SIMULATED_DEVICE:
                if self.sim is None or self.sim.gone():
                    # with its function generator, so the GUI always has one to drive
                    sim = start_simulator(self.testbed, speed=self.sim_speed, generator=True)
                    self.sim, self._sim_testbed = sim, self.testbed
                address = self.sim.address
            client = open_link(self.d, address,
                               local=self.sim if self.address == SIMULATED_DEVICE else None)
            client.telemetry_batch_s = TELEMETRY_BATCH_S
            client.subscribe(self.store)
            client.subscribe(self.limits)
            client.subscribe(self._on_block)
            client.add_link_listener(lambda s, m: self._link_state_of(generation, s, m))
            client.add_command_listener(self._on_command_done)
            client.connect(take_over=True)
            description = device_description(client)
            if self._closing or not self._want_connected or generation != self._link_generation:
                client.close()                     # the operator gave up or went elsewhere meanwhile
                return
            try:
                station = Station.attach(client, testbed=self.testbed, history=self.param_history,
                                         journal=self._journal, echo=self._station_echo)
            except BaseException:
                client.close()
                raise
            self.client, self.station = client, station
            self.device_description = description
            self.consoles.link_up(client, address)
            if self.recorder is not None and self.recorder.state == "recording":
                self._detach_recorder = attach_recorder(client, self.recorder)   # a reconnect keeps recording
            self._attempt = 0
            self.sig_source.emit("live", address)
            self.sig_link_state.emit(LinkState.UP, address)
            self.sig_event.emit("INFO", "link", f"connected to {address}")
        except GroundStationError as exc:
            self._link_state_of(generation, LinkState.FAILED, str(exc))

    def disconnect_link(self) -> None:
        """Close the session (the device disarms), switch the generator's outputs off
        and stop the simulator child."""
        self.profiles.abort()
        self.campaign.abort()                       # its rig made safe while the link is up
        self.generator.abort()
        self._want_connected = False
        self._reconnect.stop()
        self._link_generation += 1                  # what the old link says from now on is ignored
        self._close_station()
        client, self.client = self.client, None
        self.device_description = ""
        self.consoles.link_down()
        if client is not None:
            self._worker(client.close, "gs-disconnect")
            self.sig_link_state.emit(LinkState.CLOSED, "")
            self.sig_source.emit("none", "")       # a rig or a watched station no longer
        if self.sim is not None and self.address != SIMULATED_DEVICE:
            self.generator.forget_simulator()
            self.sim.stop()
            self.sim = None

    def shutdown(self) -> None:
        """Everything off: generator outputs off and closed, recording closed, link
        closed, simulator stopped.  Signals are blocked first: the widgets they would
        reach are being torn down."""
        self.blockSignals(True)
        self.campaign.blockSignals(True)
        self.profiles.blockSignals(True)
        self._closing = True
        self.profiles.abort()
        # first: a campaign makes the rig safe (its generator session too) while the link
        # and the simulator still answer
        self.campaign.stop()
        self.generator.shutdown()                   # while the simulator still answers
        self.stop_recording()
        self._want_connected = False
        self._reconnect.stop()
        self._close_station()
        if self.client is not None:
            self.client.close()
            self.client = None
        for t in self._workers:
            t.join(timeout=10.0)
        self._close_station()                      # connected while we waited
        if self.client is not None:
            self.client.close()
            self.client = None
        if self.sim is not None:
            self.sim.stop()
            self.sim = None
        self.consoles.close()
        self.close_replay()

    def _on_link_state(self, state: str, message: str) -> None:
        if state == LinkState.LOST:
            self.sig_event.emit("ERROR", "link", f"link lost: {message}")
        if state == LinkState.ENDED:       # taken over: not reconnected, the operator decides
            self.sig_event.emit("ERROR", "link", message)
        if state in (LinkState.LOST, LinkState.FAILED) and self._want_connected and self.replay is None:
            delay = RECONNECT_DELAYS_S[min(self._attempt, len(RECONNECT_DELAYS_S) - 1)]
            self._attempt += 1
            self.sig_event.emit("WARNING", "link", f"reconnecting in {delay:g} s (attempt {self._attempt})")
            self._reconnect.start(int(delay * 1000))

    def _try_reconnect(self) -> None:
        if not self._want_connected:
            return
        self._close_station()
        self._link_generation += 1
        old, self.client = self.client, None
        if old is not None:
            self._worker(old.close, "gs-close-lost")
        if self.address == SIMULATED_DEVICE and self.sim is not None and self.sim.gone():
            self.generator.close()                # its generator went with it
            self.sim.stop()
            self.sim = None                       # start a fresh simulator
        self.sig_link_state.emit(LinkState.CONNECTING, self.address)
        generation = self._link_generation
        self._worker(lambda: self._connect_worker(generation), "gs-reconnect")

    # ------------------------------------------------------------------ read-only consoles
    def watch(self, endpoint: str, curve_keys: str | None = None, key_name: str = "viewer") -> None:
        """Become a read-only console on the station publishing at `endpoint`: the same
        charts, status, recording and analysis; commands refused but ABORT, which goes
        straight to the device (fanout/viewer.py).  ZeroMQ reconnects by itself: no
        back-off here."""
        self.close_replay()
        self.disconnect_link()
        try:
            viewer = self.consoles.open_watch(endpoint, curve_keys, key_name)
        except GroundStationError as exc:
            self.sig_link_state.emit(LinkState.FAILED, str(exc))
            self.sig_event.emit("ERROR", "watch", str(exc))
            return
        self.address = viewer.endpoint
        self.store.clear()
        for cb in (self.store, self.limits, self._on_block):
            viewer.subscribe(cb)
        viewer.add_link_listener(self.sig_link_state.emit)
        viewer.add_command_listener(self._on_command_done)
        self.client = viewer
        self.sig_source.emit("watch", viewer.endpoint)
        self.consoles.start_watch(viewer)

    def start_publishing(self, endpoint: str, curve_keys: str | None = None) -> bool:
        """Publish what this window's device link receives (now and after reconnects)
        for read-only consoles; False (and an ERROR event) when it cannot."""
        live = self.client if self.consoles.watching is None else None
        return self.consoles.start_publishing(endpoint, curve_keys, live, self.address)

    # ------------------------------------------------------------------ telemetry callbacks
    def _on_block(self, block) -> None:
        """Receiver thread: only EVENT packets go further (as signals, queued to the GUI)."""
        if block.name != "EVENT":
            return
        levels = {v: k for k, v in block.packet.item_by_name["level"].states.items()}
        for lvl, code, text in zip(block["level"], block["code"], block["text"]):
            self.sig_event.emit(levels.get(int(lvl), str(lvl)), "device",
                                f"{self.d.event_name(int(code))}: {text}")

    def _on_device_restart(self, packet: str, old_end_s: float, new_start_s: float) -> None:
        """Receiver thread: the device clock went back (a reboot or a fresh simulator)."""
        self.sig_event.emit("WARNING", "link",
                            f"device time restarted ({packet}: {old_end_s:.3f} s -> {new_start_s:.3f} s): "
                            "the device rebooted; the charts start again, the recording keeps everything")

    def _on_command_done(self, result) -> None:
        last = result.stages[-1] if result.stages else None
        if result.name == "HEARTBEAT" and last is not None and last.stage == "COMPLETED":
            return
        if last is not None:
            self.sig_command.emit(result.name, str(result.sequence), last.stage, last.reason)

    # ------------------------------------------------------------------ commands
    def command(self, name: str, **args: Any) -> None:
        """Send a command off the GUI thread; stages arrive as sig_command.

        Commands go out one after another in the order given (SET_MODE then ARM must not
        overtake each other on two threads).  ABORT overtakes them all: it is sent at
        once on its own thread, and what was still waiting is dropped (CANCELLED) - an
        ARM queued before an Esc must not follow the ABORT."""
        client = self.client
        if client is None:
            self.sig_command.emit(name, "", "REFUSED", "not connected")
            return

        def stage(rec):
            self.sig_command.emit(name, "", rec.stage, rec.reason)

        def work():
            try:
                client.command(name, on_stage=stage, **args)
            except GroundStationError as exc:
                self.sig_event.emit("ERROR", "command", str(exc))
        if name == "ABORT":
            for dropped in self._commands.drop_waiting():
                self.sig_command.emit(dropped, "", "CANCELLED", "ABORT sent before it")
            self._worker(work, "gs-cmd-ABORT")
        else:
            self._commands.submit(name, work)

    def abort(self) -> None:
        """ABORT now, whatever the state: the generator's outputs off (fail safe, even
        with no device connected) and the device's ABORT; reported as an event if the
        latter cannot be sent.  A running campaign stops at once (its Testbed.abort: the
        generator session it holds off, its recording closed); a playing profile's wait
        ends and reports "aborted"."""
        self.profiles.abort()
        self.campaign.abort()
        self.generator.abort()
        client = self.client
        if client is None:
            self.sig_event.emit("WARNING", "command", "ABORT: no device connected")
            return
        self.command("ABORT")

    # ------------------------------------------------------------------ the Station
    def _close_station(self) -> None:
        """Detach the Station from the link (the link itself is closed by the caller, or
        goes on).  A verb still running on its worker thread fails on the closed link
        and reports it as usual."""
        station, self.station = self.station, None
        if station is not None:
            station.close()

    def _station_echo(self, text: str) -> None:
        """What the Station says about its verbs: the Python log only.  The operator's
        event log gets the Session's own reports of the same work (with the table's
        version, an override as a WARNING; see _uploaded)."""
        log.info("station: %s", text)

    def _journal(self, kind: str, record: dict, blob: bytes = b"") -> None:
        """The Station's journal entries (uploads, profiles) go into this session's
        recording, when one runs."""
        rec = self.recorder
        if rec is not None:
            rec.record(kind, record, blob)

    # ------------------------------------------------------------------ parameter table
    def _param_work(self, name: str, work) -> None:
        """Run `work(station)` on a worker thread; a failure arrives as sig_params_failed
        (and an ERROR event)."""
        station = self.station
        if station is None or self.client is None:
            self.sig_params_failed.emit("not connected")
            return

        def run():
            try:
                work(station)
            except GroundStationError as exc:     # ScriptError too: refused, device fault
                self._params_failed(str(exc))
            except Exception as exc:              # a bug: said, so no panel waits forever
                log.exception("parameter table: %s", name)
                self._params_failed(f"{type(exc).__name__}: {exc}")
        self._worker(run, f"gs-params-{name}")

    def _params_failed(self, text: str) -> None:
        self.sig_params_failed.emit(text)
        self.sig_event.emit("ERROR", "parameters", text)

    def params_read(self) -> None:
        """Read the device's active table (worker thread); arrives as sig_params_active."""
        self._param_work("read", lambda station: self.sig_params_active.emit(
            station.read_params(self._param_progress)))

    def params_upload(self, values: dict, source: str, design=None,
                      accept_risk: str | None = None) -> None:
        """Validate (against `design`), upload and verify a table (worker thread,
        Station.upload_table): sig_params_uploaded, then sig_params_active.  Without a
        design, or refused by the validation, it is sent only with `accept_risk`, the
        operator's reason (recorded in the history, the recording and the record)."""
        def work(station: Station) -> None:
            record = station.upload_table(values, source, design=design, accept_risk=accept_risk,
                                          progress=self._param_progress)
            self._uploaded(record)
            self.sig_params_active.emit(station.read_params())
        self._param_work("upload", work)

    def params_rollback(self) -> None:
        """Re-activate the table that was active before the last upload
        (Station.rollback_params): sig_params_uploaded, then sig_params_active."""
        def work(station: Station) -> None:
            record = station.rollback_params(progress=self._param_progress)
            self._uploaded(record)
            self.sig_params_active.emit(station.read_params())
        self._param_work("rollback", work)

    def _uploaded(self, record) -> None:
        self.last_uploaded_crc = record.crc
        self.sig_params_uploaded.emit(record)
        text = (f"parameter table {record.crc:08x} (v{record.version}) verified on the "
                f"device: {record.source}")
        if record.validated:
            self.sig_event.emit("INFO", "parameters", text)
        elif record.accepted_risk == "marginal":
            self.sig_event.emit("WARNING", "parameters",
                                f"{text} - stable but marginal, margins accepted "
                                f"({'; '.join(record.validation_problems)})")
        else:
            self.sig_event.emit("WARNING", "parameters",
                                f"{text} - NOT validated ({'; '.join(record.validation_problems)})")

    def _param_progress(self, step: str, fraction: float) -> None:
        self.sig_params_progress.emit(step, fraction)

    # ------------------------------------------------------------------ profiles
    def play_profile(self, profile: Profile, mode: str | None = None) -> str | None:
        """Play `profile` on the device (self.profiles, through the Station) when this
        session's link can take it: live, up, and no campaign owning the device.  Returns
        why not (nothing sent), else None; progress and the outcome arrive as
        self.profiles' signals.  Abort ends it at once."""
        client, station = self.client, self.station
        if (self.replay is not None or client is None or station is None
                or client.link_state != LinkState.UP):
            return "not connected: connect to the device first"
        if self.campaign.running:
            return "a campaign is running: it owns the device until it ends"
        return self.profiles.play(station, profile, mode)

    # ------------------------------------------------------------------ recording
    def start_recording(self, folder: str, test_name: str, notes: str = "") -> Path | None:
        if self.recorder is not None and self.recorder.state == "recording":
            return self.recorder.path
        testbed_text = Path(self.testbed).read_text() if self.testbed else ""
        rec = Recorder(self.d, folder, test_name=test_name or "test", notes=notes,
                       testbed_text=testbed_text, testbed_path=self.testbed or "",
                       on_failure=self.sig_recording_failed.emit)
        try:
            path = rec.start()
        except GroundStationError as exc:
            self.sig_recording_failed.emit(str(exc))
            return None
        self.recorder = rec
        rec.record("testbed", device_record(self.address == SIMULATED_DEVICE, address=self.address,
                                            seed=self.sim.seed if self.sim else 0,
                                            speed=self.sim_speed))
        if self.client is not None:
            self._detach_recorder = attach_recorder(self.client, rec)
        if notes:
            rec.note(notes)
        self.sig_recording_started.emit(str(path))
        return path

    def stop_recording(self) -> None:
        rec = self.recorder
        if rec is None:
            return
        self.recorder = None
        detach, self._detach_recorder = self._detach_recorder, None
        if detach is not None:
            detach()
        status = rec.stop()
        if status.state == "stopped":
            self.sig_recording_stopped.emit(f"{status.frames} frames in "
                                            + ", ".join(p.name for p in status.files))
        else:
            self.sig_recording_failed.emit(status.error if status.state == "failed"
                                           else f"{status.state}: {status.error}")

    # ------------------------------------------------------------------ replay
    def open_log(self, path: str) -> None:
        """Switch the charts to a recorded log (the link, if any, is closed)."""
        self.stop_recording()
        self.disconnect_link()
        self.close_replay()
        try:
            src = ReplaySource(path, dictionary=None, speed=1.0)
        except GroundStationError as exc:
            self.sig_event.emit("ERROR", "replay", str(exc))
            return
        try:
            self.replay_events = event_markers(path)
        except GroundStationError as exc:
            log.warning("no event markers: %s", exc)
            self.replay_events = []
        self.store.clear()
        self.limits.acknowledge()
        src.subscribe(self.store)
        src.subscribe(self.limits)
        src.subscribe(self._on_block)
        src.add_link_listener(lambda s, m: self.sig_event.emit("INFO", "replay", f"replay {s} {m}".strip()))
        self.replay = src
        self.sig_source.emit("replay", str(path))
        src.play()

    def close_replay(self) -> None:
        src, self.replay = self.replay, None
        if src is not None:
            src.close()
            self.sig_source.emit("none", "")
