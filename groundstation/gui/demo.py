"""The one-click demo for the simulated testbed: a closed-loop step response.

An idle simulated rig shows flat lines (nanoradians of sensor noise), so the first minute
of `make run` would show nothing working.  The demo does what an operator would do, with
the same panels and the same Session machinery:

1. the Parameters dock loads the controller design for the simulator's testbed and
   validates it against that testbed's closed loop (refused: the demo stops there);
2. the table is uploaded and verified (worker thread; read back, HOUSEKEEPING agrees);
3. the Profiles dock plays a smoothed 1 mrad step in RELATIVE mode (set, armed,
   played sample-exact, disarmed) with its progress and playhead;
4. the strip charts show the channels that move: reference and encoders, the angle
   error, the motor currents.

It is offered only on the simulated testbed (never on a rig: it uploads a controller
table and arms the drives) and only on a testbed whose design validates.  Abort / Esc
stops it like everything else: the window calls cancel() before the Session's abort,
so nothing further is started, and the Session's ABORT ends a playing profile.

No I/O here: the panels and the Session do it (the Session on its worker threads).
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

from PySide6.QtCore import QObject, QTimer, Signal

from ..core.kinds import SIMULATED_DEVICE, LinkState
from ..params import table as ptable
from ..params.upload import UploadRecord
from ..profiles.profile import WAVEFORMS_DIR
from ..plant.testbed import DEFAULT_TESTBED, PROFILES_DIR
from .charts.panel import StripChartPanel
from .panels.params import ParameterPanel
from .panels.profile import ProfilePanel
from .session.session import Session
from .session.events import PlayOutcome

DEMO_TITLE = "Demo: step response on the simulator"
CONTROLLERS_DIR = PROFILES_DIR / "controllers"
#: chart window for the demo: the whole 5 s step and its return in view
DEMO_WINDOW_S = 10.0
#: link states that end a running demo (every state but connecting and up)
LINK_DOWN = (LinkState.LOST, LinkState.FAILED, LinkState.CLOSED, LinkState.ENDED)


@dataclass(frozen=True)
class DemoPlan:
    design: Path                 # a controller design that validates on the testbed
    profile: Path                # the command profile played
    mode: str                    # the controller mode it plays in
    layout: tuple[tuple[str, ...], ...]   # the charts: the channels that move

    def describe(self) -> str:
        return (f"uploads {self.design.name} (validated against the simulator's testbed), "
                f"then plays {self.profile.stem} in {self.mode} mode: +1 mrad at 0.5 s, back "
                f"at 3 s, drives disarmed at the end. Esc stops it.")


_STEP = WAVEFORMS_DIR / "step_relative_1mrad.toml"

#: per testbed file name.  inertial_2dof has no plan: its designs are refused by
#: validation on the reference's own model (docs/controllers.md).
PLANS: dict[str, DemoPlan] = {
    "relative_2dof.toml": DemoPlan(
        CONTROLLERS_DIR / "relative_design2.toml", _STEP, "RELATIVE",
        (("HIGH_RATE.reference", "HIGH_RATE.encoder_inner", "HIGH_RATE.encoder_outer"),
         ("HIGH_RATE.error_angle",),
         ("HIGH_RATE.current_coarse", "HIGH_RATE.current_fine"))),
    "rigid_1dof.toml": DemoPlan(
        CONTROLLERS_DIR / "rigid_pid.toml", _STEP, "RELATIVE",
        (("HIGH_RATE.reference", "HIGH_RATE.encoder_inner"),
         ("HIGH_RATE.error_angle",),
         ("HIGH_RATE.current_coarse",))),
}


def plan_for(testbed: str | Path | None) -> DemoPlan | None:
    """The demo for a simulator's testbed file (None: the simulator's default), or None
    when none of the shipped designs validates on it."""
    name = Path(testbed).name if testbed else DEFAULT_TESTBED.name
    return PLANS.get(name)


class DemoController(QObject):
    """Runs the demo through the panels; states: idle, uploading, playing, then
    completed / aborted / failed (and again from there)."""

    #: (state, text for the operator)
    sig_state = Signal(str, str)
    #: (offered, why not): offered on the simulator, whether or not it can start now
    sig_available = Signal(bool, str)

    def __init__(self, session: Session, parameters: ParameterPanel, profiles: ProfilePanel,
                 charts: StripChartPanel, parent: QObject | None = None):
        super().__init__(parent)
        self.session = session
        self.parameters = parameters
        self.profiles = profiles
        self.charts = charts
        self.state = "idle"
        self.text = ""
        self.plan: DemoPlan | None = None
        self._crc: int | None = None
        #: an upload of ours is still on its worker thread (even after an abort): no new
        #: demo until it has ended, so two uploads never overlap
        self._upload_pending = False
        # the drives' armed flag comes with the telemetry, not with a signal: looked at ten
        # times a second, so the button is offered only once the device shows them disarmed
        # (right after a profile's DISARM is acknowledged, the newest frame may still say
        # armed - a click then would only be refused)
        self._armed_seen = False
        self._armed_poll = QTimer(self)
        self._armed_poll.setInterval(100)
        self._armed_poll.timeout.connect(self._poll_armed)
        self._armed_poll.start()
        session.sig_params_uploaded.connect(self._on_uploaded)
        session.sig_params_failed.connect(self._on_params_failed)
        session.profiles.sig_done.connect(self._on_profile_done)
        session.sig_link_state.connect(self._on_link)
        # an ABORT sent by another path during the upload stops the demo too (the window's
        # abort() cancels first; while playing, the profile's outcome tells)
        session.sig_command.connect(self._on_command)
        session.sig_source.connect(lambda *_: self.update_availability())
        session.campaign.sig_started.connect(lambda *_: self.update_availability())
        session.campaign.sig_finished.connect(lambda *_: self.update_availability())
        session.campaign.sig_failed.connect(lambda *_: self.update_availability())

    # ------------------------------------------------------------------ availability
    @property
    def running(self) -> bool:
        return self.state in ("uploading", "playing")

    def offered(self) -> bool:
        """Shown at all: not on a rig, not on a replay."""
        s = self.session
        return s.replay is None and s.address in ("", SIMULATED_DEVICE)

    def unavailable_reason(self) -> str:
        """Why the demo cannot start now ("" when it can)."""
        s = self.session
        if s.replay is not None:
            return "a log is being replayed: the demo runs on the simulated testbed"
        if s.address not in ("", SIMULATED_DEVICE):
            return (f"connected to {s.address}: the demo runs only on the simulated testbed "
                    "(it uploads a controller table and arms the drives)")
        client = s.client
        if client is None or client.link_state != LinkState.UP:
            return "connect to the simulated testbed first (Device ▸ Connect, F5)"
        if plan_for(s.testbed) is None:
            name = Path(s.testbed).name if s.testbed else DEFAULT_TESTBED.name
            return (f"no demo on {name}: none of the shipped controller designs validates on "
                    "it (see docs/controllers.md); choose relative_2dof or rigid_1dof")
        if self.running:
            return "the demo is running (Esc stops it)"
        if self._drives_armed():
            return "the drives are armed: disarm first (Ctrl+D); the table changes only disarmed"
        if self._upload_pending:
            return "the last parameter upload is still finishing"
        if s.profiles.playing:
            return "a profile is playing"
        if s.campaign.running:
            return "a campaign is running: it owns the device until it ends"
        return ""

    def _drives_armed(self) -> bool:
        ring = self.session.store.rings.get("HIGH_RATE")
        return bool(ring is not None and ring.latest("armed"))

    def _poll_armed(self) -> None:
        armed = self._drives_armed()
        if armed != self._armed_seen:
            self._armed_seen = armed
            self.update_availability()

    def update_availability(self) -> None:
        reason = self.unavailable_reason()
        self.sig_available.emit(not reason and self.offered(), reason)

    # ------------------------------------------------------------------ running
    def start(self) -> str | None:
        """Start the demo; returns why not (nothing sent), else None."""
        reason = self.unavailable_reason()
        if reason:
            self.sig_state.emit("refused", reason)
            return reason
        plan = plan_for(self.session.testbed)
        assert plan is not None
        self.plan = plan
        self.charts.set_layout([list(ids) for ids in plan.layout])
        self.charts.set_window_seconds(DEMO_WINDOW_S)
        self.charts.set_paused(False)
        self._set("uploading", f"validating and uploading {plan.design.name}…")
        p = self.parameters
        loaded = p.load_design(plan.design)
        if self.state != "uploading":
            # aborted (Esc) while the design was validated off the GUI thread: the window
            # kept serving events meanwhile, so nothing more may be started now
            return self.state
        if not loaded or p.report is None or not p.report.ok:
            return self._fail(f"{plan.design.name} does not validate: {p.result.text()}")
        self._crc = ptable.table_crc(ptable.pack(self.session.d, p.values))
        self._upload_pending = True
        if not p.upload(confirm=False):
            self._upload_pending = False
            return self._fail(f"upload not sent: {p.result.text()}")
        return None

    def cancel(self, reason: str = "aborted by the operator (Esc): ABORT sent, drives off") -> None:
        """Stop the demo before anything further is started.  The caller sends the ABORT
        (MainWindow.abort -> Session.abort), which also ends a playing profile."""
        if self.running:
            self._set("aborted", reason)

    def _on_command(self, name: str, _seq: str, _stage: str, _reason: str) -> None:
        if name == "ABORT" and self.state == "uploading":
            self.cancel("aborted: an ABORT was sent during the upload; nothing was played")

    def _upload_ended(self) -> bool:
        """Our upload has ended (verified or failed): True when the demo goes on."""
        if not self._upload_pending:
            return False
        self._upload_pending = False
        if self.state != "uploading":          # aborted meanwhile: nothing more is started
            self.update_availability()
            return False
        return True

    def _on_uploaded(self, record: UploadRecord) -> None:
        if not self._upload_ended():
            return
        if record.crc != self._crc:
            self._fail(f"the device took table {record.crc:08x}, not the demo's {self._crc:08x}")
        else:
            self._play()

    def _on_params_failed(self, text: str) -> None:
        if self._upload_ended():
            self._fail(f"upload failed: {text}")

    def _play(self) -> None:
        plan = self.plan
        assert plan is not None
        if not self.profiles.set_file(plan.profile):
            self._fail(f"cannot load {plan.profile.name}: {self.profiles.status.text()}")
            return
        self.profiles.mode.setCurrentText(plan.mode)
        # "playing" first: the profile's own signals may follow at once
        self._set("playing", f"playing {plan.profile.stem} in {plan.mode} (Esc stops it)…")
        reason = self.profiles.play(confirm=False)
        if reason:
            self._fail(f"not played: {reason}")

    def _on_profile_done(self, outcome: PlayOutcome) -> None:
        if self.state == "playing":
            state = {"completed": "completed", "aborted": "aborted"}.get(outcome.status, "failed")
            self._set(state, "step response done: the charts show it; run it again, or load "
                      "another design or profile in the docks" if state == "completed" else
                      f"{outcome.status}: {outcome.text}")
        else:
            self.update_availability()          # a profile of someone else's ended

    def _on_link(self, state: str, message: str) -> None:
        if state == LinkState.UP:
            self._upload_pending = False         # an old link's upload died with it
        elif state in LINK_DOWN and self.running:
            self._fail(f"link {state}{': ' + message if message else ''}")
            return
        self.update_availability()

    def _fail(self, text: str) -> str:
        self._set("failed", text)
        return text

    def _set(self, state: str, text: str) -> None:
        self.state, self.text = state, text
        self.sig_state.emit(state, text)
        self.update_availability()


__all__ = ["DEMO_TITLE", "DemoController", "DemoPlan", "PLANS", "plan_for"]
