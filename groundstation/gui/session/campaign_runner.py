"""The GUI's campaign controller: runs a campaign on a worker thread against the device
the operator is connected to, and reports step by step as Qt signals.  No widgets here.

The campaign runs on the Session's own link (`Testbed.attach`): the charts, the status
panel and the event log show it live, and nothing has to be disconnected or reconnected
around it.  The Session keeps owning the link; the campaign's Testbed only borrows it
and never closes it.

The function generator.  A campaign that drives the base motion (or runs on an inertial
testbed, where the generator must be switched off when it stops) needs the generator:

* on the simulated testbed the campaign opens a VISA session of its own to the
  simulator's generator - its SCPI server serves any number of connections, one thread
  each, the generator state under one lock - so the Generator panel may stay connected
  (its read-back is refreshed when the campaign ends);
* on a rig, a real instrument may accept a single session (USB, most LAN sockets), so
  the campaign borrows the driver the Generator panel has open - the driver is safe to
  call from several threads, one transaction at a time - and leaves it open.  With no
  generator connected there, the generator steps fail and say so.

Abort (Esc, the Abort buttons, MainWindow.abort through Session.abort): the campaign's
Testbed.abort() - its next wait raises, and the rig is made safe now: the device's
ABORT, the generator's outputs off, the campaign's recording closed with a last event.
The report then says "aborted", names the step, and is saved beside the logs.
"""

from __future__ import annotations

import logging
import threading
import time
from dataclasses import dataclass
from pathlib import Path

from PySide6.QtCore import QObject, Signal

from ...campaign import ACTIONS, Campaign, CampaignReport, CampaignRunner, Step, StepResult
from ...campaign.scoring_behind import ScoringBehind
from ...core.contracts import BaseMotionInstrument
from ...station.clock import ScriptAborted
from ...core.errors import GroundStationError
from ...core.kinds import SIMULATED_DEVICE, LinkState
from ...station.station import Station as Testbed
from ...plant.testbed import DEFAULT_TESTBED, load_testbed

log = logging.getLogger(__name__)

#: actions that need a function generator in the session (each action says so itself)
GENERATOR_ACTIONS = frozenset(name for name, action in ACTIONS.items() if action.needs_generator)
#: how long shutdown waits for a running campaign to make the rig safe and stop
STOP_TIMEOUT_S = 20.0


@dataclass(frozen=True)
class CampaignOutcome:
    """What a finished campaign left: the report, where it and the logs were written."""

    report: CampaignReport
    report_path: Path | None
    log_folder: Path
    aborted_by_operator: bool


class _SignallingRunner(CampaignRunner):
    """The campaign runner, telling the GUI each step's result as it happens (the
    runner itself only hands back the whole report at the end)."""

    def __init__(self, campaign: Campaign, testbed, controller: "CampaignController", **kw):
        super().__init__(campaign, testbed, **kw)
        self.controller = controller
        self._last = -1

    def _do(self, step: Step) -> None:
        c = self.controller
        # steps the runner passed over without running (a resumed or failed run's rest)
        for index in range(self._last + 1, step.index):
            c.sig_step_result.emit(StepResult(index, self.campaign.steps[index].label(), "skipped"))
        self._last = step.index
        t0 = time.monotonic()
        try:
            super()._do(step)
        except BaseException as exc:
            aborted = c.abort_requested or isinstance(exc, ScriptAborted)
            c.sig_step_result.emit(StepResult(step.index, step.label(),
                                              "aborted" if aborted else "failed",
                                              time.monotonic() - t0, str(exc).strip()
                                              or type(exc).__name__))
            raise
        c.sig_step_result.emit(StepResult(step.index, step.label(), "done", time.monotonic() - t0))


class CampaignController(QObject):
    sig_started = Signal(object, str)            # Campaign, log folder
    sig_progress = Signal(int, float)            # step index, fraction of the step
    sig_step_result = Signal(object)             # StepResult, as each step ends
    sig_log = Signal(str)                        # what the Testbed says (echo)
    sig_pause = Signal(str)                      # a pause step's prompt: answer() it
    sig_finished = Signal(object)                # CampaignOutcome
    sig_failed = Signal(str)                     # could not start (nothing was run)

    def __init__(self, session, parent: QObject | None = None):
        """`session`: the GUI Session (client, replay, address, testbed, fg_resource,
        generator, profiles, param_history)."""
        super().__init__(parent)
        self.session = session
        self.campaign: Campaign | None = None
        self.testbed: Testbed | None = None          # while running
        self.abort_requested = False
        self.last: CampaignOutcome | None = None
        self._thread: threading.Thread | None = None
        self._abort_thread: threading.Thread | None = None
        self._answer: bool | None = None
        self._answered = threading.Event()

    # ------------------------------------------------------------------ state
    @property
    def running(self) -> bool:
        return self._thread is not None and self._thread.is_alive()

    def session_testbed(self) -> Path:
        """The testbed the session's simulator runs (its default when none was chosen)."""
        return Path(self.session.testbed or DEFAULT_TESTBED).resolve()

    def readiness(self, campaign: Campaign) -> tuple[str | None, str]:
        """(why Run must be refused or None, a note for the operator)."""
        client = self.session.client
        if self.session.replay is not None:
            return "a log is being replayed: connect to the device first", ""
        if client is None or client.link_state != LinkState.UP:
            return "not connected: connect to the device (or the simulated testbed) first", ""
        if self.running:
            return "a campaign is already running", ""
        if self.session.profiles.playing:
            return "a profile is playing: wait for it to end or abort it", ""
        note = ""
        if self.session.address == SIMULATED_DEVICE:
            if self.session_testbed() != campaign.testbed.resolve():
                return (f"the simulator runs {self.session_testbed().name}, the campaign is "
                        f"written for {campaign.testbed.name}: connect the simulated testbed "
                        f"with {campaign.testbed.name} first"), ""
        else:
            note = (f"the campaign assumes the rig is a {campaign.testbed.name}; "
                    f"the device's configuration is not checked from here")
        if self._needs_generator(campaign) and self._generator() is None:
            note = (note + "; " if note else "") + ("no function generator: connect one in the "
                                                    "Generator panel, or the generator steps fail")
        return None, note

    def _needs_generator(self, campaign: Campaign) -> bool:
        if any(s.action in GENERATOR_ACTIONS for s in campaign.steps):
            return True
        try:
            return load_testbed(campaign.testbed).inertial
        except GroundStationError:
            return False

    def _generator(self):
        """What the campaign's Testbed uses as its generator (see the module docstring):
        the simulator's resource, the Generator panel's open driver, or None."""
        sim = self.session.fg_resource
        if sim and self.session.address == SIMULATED_DEVICE:
            return sim
        gen = self.session.generator
        if gen.is_open:
            return gen.fg
        return None

    # ------------------------------------------------------------------ run
    def run(self, campaign: Campaign, log_folder: str | Path,
            max_step_seconds: float | None = None) -> str | None:
        """Start the campaign on a worker thread; returns why not (and runs nothing)."""
        reason, _ = self.readiness(campaign)
        if reason:
            return reason
        self.campaign = campaign
        self.abort_requested = False
        self._abort_thread = None
        self._answered.clear()
        folder = Path(log_folder)
        generator = self._generator() if self._needs_generator(campaign) else None
        self._thread = threading.Thread(target=self._work, name="gs-campaign", daemon=True,
                                        args=(campaign, folder, max_step_seconds, generator))
        self.sig_started.emit(campaign, str(folder))
        self._thread.start()
        return None

    def _work(self, campaign: Campaign, folder: Path, cap: float | None,
              generator: str | BaseMotionInstrument | None) -> None:
        scoring = ScoringBehind(campaign)      # each log scored while the next run records
        try:
            self._run_and_report(campaign, folder, cap, generator, scoring)
        finally:
            scoring.close()

    def _run_and_report(self, campaign: Campaign, folder: Path, cap: float | None,
                        generator: str | BaseMotionInstrument | None, scoring: ScoringBehind) -> None:
        session = self.session
        report: CampaignReport | None = None
        tb: Testbed | None = None
        try:
            tb = Testbed.attach(session.client, testbed=campaign.testbed, generator=generator,
                                log_folder=folder, history=session.param_history,
                                operator=self._ask, echo=self._echo)
            self.testbed = tb
            if self.abort_requested:          # Esc while the generator was being opened
                tb.abort_event.set()
            runner = _SignallingRunner(campaign, tb, self, max_step_seconds=cap,
                                       progress=lambda step, f: self.sig_progress.emit(step.index, f),
                                       on_recording=scoring.submit)
            report = runner.run()
        except GroundStationError as exc:
            self.sig_failed.emit(f"the campaign could not start: {exc}")
        except Exception as exc:            # a bug must not leave the rig armed: said, made safe
            log.exception("campaign %s", campaign.name)
            self.sig_failed.emit(f"the campaign stopped on an internal error: {type(exc).__name__}: {exc}")
        finally:
            aborter = self._abort_thread
            if aborter is not None:               # its make_safe first, then ours
                aborter.join(STOP_TIMEOUT_S)
            if tb is not None:
                # as the CLI does at the end of every campaign: the rig safe, the
                # campaign's own recording and generator session closed; the link stays
                tb.make_safe("end of campaign" if report is not None and report.status.startswith(
                    "completed") else "campaign stopped")
                tb.close()
            self.testbed = None
        if report is None:
            return
        if self.abort_requested and report.status in ("failed", "aborted"):
            # the operator's abort, said so.  A step can also fail *because* of it (a
            # playing profile ends "aborted" on the device, and the play step raises as
            # a failure): that is the abort too, not a fault of the rig
            report.status = "aborted"
            last = report.steps[-1] if report.steps else None
            why = last.error.strip() if last is not None else ""
            text = "aborted by the operator" + (f" ({why})" if why and why != "aborted" else "")
            report.reason = f"{last.label}: {text}" if last is not None else text
            if last is not None and last.status in ("failed", "aborted"):
                last.status, last.error = "aborted", text
        path: Path | None = folder / "report.json"
        try:
            report.save(path)
        except OSError as exc:
            self._echo(f"the report could not be saved to {path}: {exc}")
            path = None
        if path is not None and report.recordings:
            self._write_metrics(report, path, campaign, scoring)
        outcome = CampaignOutcome(report, path, folder, self.abort_requested)
        self.last = outcome
        if session.generator.is_open:          # the panel shows what the instrument holds now
            state = session.generator.state
            session.generator.refresh(state.channel if state is not None else 1)
        self.sig_finished.emit(outcome)

    def _write_metrics(self, report: CampaignReport, path: Path, campaign: Campaign,
                       scoring: ScoringBehind) -> None:
        """The logs scored and compared, written beside the report as `campaign run`
        writes them (metrics CSV/JSON, charts, HTML); on this worker thread.  Each log
        was scored behind the runs as its recording ended (`scoring`)."""
        from ...campaign.metrics import campaign_metrics, write_metrics
        try:
            written = write_metrics(campaign_metrics(report, campaign, scored=scoring), report, path)
        except Exception as exc:              # the campaign's result stands without them
            log.exception("campaign metrics")
            self._echo(f"the metrics could not be written: {type(exc).__name__}: {exc}")
            return
        self._echo(f"metrics: {', '.join(p.name for p in written)}")

    # ------------------------------------------------------------------ the Testbed's callbacks
    def _echo(self, text: str) -> None:
        self.sig_log.emit(text)

    def _ask(self, prompt: str) -> bool:
        """A pause step (campaign thread): ask the operator through the panel and wait
        for answer() - or for an abort, which is a "no"."""
        self._answer = None
        self._answered.clear()
        self.sig_pause.emit(prompt)
        while not self._answered.wait(0.1):
            tb = self.testbed
            if self.abort_requested or (tb is not None and tb.abort_event.is_set()):
                return False
        return bool(self._answer)

    def answer(self, go_on: bool) -> None:
        self._answer = go_on
        self._answered.set()

    # ------------------------------------------------------------------ abort
    def abort(self) -> None:
        """From the GUI thread: stop the campaign at its next wait and make the rig safe.
        Returns at once; the report arrives as sig_finished."""
        if not self.running:
            return
        self.abort_requested = True
        self._answered.set()                       # a pause waiting for the operator: "no"
        tb = self.testbed
        if tb is None:
            return                                 # not attached yet: _work sees the flag
        tb.abort_event.set()                       # at once, whatever the thread below does
        # Testbed.abort makes safe - commands, VISA, closing a recording: not on this thread
        if self._abort_thread is None or not self._abort_thread.is_alive():
            self._abort_thread = threading.Thread(target=tb.abort, name="gs-campaign-abort",
                                                  daemon=True)
            self._abort_thread.start()

    def stop(self, timeout: float = STOP_TIMEOUT_S) -> None:
        """Abort and wait for the campaign thread (the window closes, the link goes)."""
        thread = self._thread
        if thread is None or not thread.is_alive():
            return
        self.abort()
        thread.join(timeout)
        if thread.is_alive():
            log.error("the campaign thread did not stop within %g s", timeout)


__all__ = ["CampaignController", "CampaignOutcome", "GENERATOR_ACTIONS"]
