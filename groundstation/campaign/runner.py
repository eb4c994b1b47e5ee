"""Running a checked campaign on an open Testbed, step by step: each step is done by its
action's handler (`actions.ACTIONS`); a failure, an abort or Ctrl-C ends the campaign
with the rig made safe, or - with on_run_failure = "next_run" - ends only that run.

Every recording the report lists carries the run it ended in ("run": 1, 2, ...; 0 in
setup or teardown) and that run's matrix values ("variables": each matrix key and, for
a text value, its KEY_stem), so that the logs' metrics can be grouped by them
(campaign/metrics.py) - recordings closed by a failure or Ctrl-C as well.  `on_recording`
is handed each one, so tagged, as soon as it ends (scoring_behind.py scores its logs
while the next run records)."""

from __future__ import annotations

import contextlib
import signal
import threading
import time
import traceback
from pathlib import Path
from typing import Any, Callable

from ..station.clock import ScriptAborted
from ..core.errors import GroundStationError
from .actions import ACTIONS, StepRun, known_actions
from .model import Campaign, Step
from .report import CampaignReport, StepResult


class CampaignRunner:
    """Runs a Campaign on a Testbed (already open), step by step."""

    def __init__(self, campaign: Campaign, testbed, *, max_step_seconds: float | None = None,
                 progress: Callable[[Step, float], None] | None = None,
                 on_recording: Callable[[dict[str, Any]], None] | None = None):
        self.campaign = campaign
        self.tb = testbed
        self.max_step_seconds = max_step_seconds
        self.progress = progress or (lambda step, fraction: None)
        self.on_recording = on_recording
        self._tags: dict[int, dict[str, Any]] = {}     # index in tb.recordings -> run, variables
        self._tagged = 0                                # tb.recordings[:_tagged] have their tags

    def run(self, resume: CampaignReport | None = None) -> CampaignReport:
        """Run the steps; returns the report whatever happens.  Ctrl-C (KeyboardInterrupt
        in the main thread) ends the campaign cleanly: status "interrupted", the rig made
        safe and the run's recording closed with that reason."""
        c = self.campaign
        report = CampaignReport(c.name, str(c.path), time.time())
        skip_runs = set(resume.completed_runs) if resume else set()
        if resume:
            report.completed_runs = sorted(skip_runs)
            report.recordings = list(resume.recordings)
        recordings_before = self._tagged = len(self.tb.recordings)
        self._prepare_writers()
        current_run, run_failed = 0, False
        step: Step | None = None
        try:
            for step in c.steps:
                if step.run and step.run in skip_runs:
                    report.steps.append(StepResult(step.index, step.label(), "skipped"))
                    continue
                if step.run != current_run:
                    if current_run and not run_failed:
                        report.completed_runs.append(current_run)
                    current_run, run_failed = step.run, False
                if run_failed:                      # the rest of a failed run (next_run policy)
                    report.steps.append(StepResult(step.index, step.label(), "skipped"))
                    continue
                t0 = time.monotonic()
                self.progress(step, 0.0)
                try:
                    self._do(step)
                except BaseException as exc:
                    interrupted = isinstance(exc, KeyboardInterrupt)
                    aborted = isinstance(exc, ScriptAborted)
                    status = "interrupted" if interrupted else "aborted" if aborted else "failed"
                    report.steps.append(StepResult(step.index, step.label(), status,
                                                   time.monotonic() - t0, _reason(exc)))
                    run_failed = True
                    self._tag(step)
                    if step.run and status == "failed" and c.on_run_failure == "next_run" \
                            and isinstance(exc, GroundStationError):
                        report.failed_runs[str(step.run)] = f"{step.label()}: {_reason(exc)}"
                        try:
                            self.tb.recover(f"run {step.run} failed: {_reason(exc)}")
                        finally:
                            self._tag(step)          # the run's recording, closed by recover
                        continue
                    report.status = status
                    report.failed_step, report.failed_run = step.index, step.run or None
                    report.reason = f"{step.label()}: {_reason(exc)}"
                    if not isinstance(exc, (GroundStationError, KeyboardInterrupt)):
                        report.reason += "\n" + traceback.format_exc()
                    break
                report.steps.append(StepResult(step.index, step.label(), "done", time.monotonic() - t0))
                self._tag(step)
                self.progress(step, 1.0)
            else:
                if current_run and not run_failed:
                    report.completed_runs.append(current_run)
                report.status = "completed_with_failures" if report.failed_runs else "completed"
        except KeyboardInterrupt:
            # Ctrl-C between two steps (or while a failed run was being recovered)
            report.status = "interrupted"
            if step is not None:
                report.failed_step, report.failed_run = step.index, step.run or None
                if step.run:
                    report.completed_runs = [r for r in report.completed_runs if r != step.run]
            report.reason = (f"{step.label()}: " if step is not None else "") + _reason(KeyboardInterrupt())
        finally:
            if report.status not in ("completed", "completed_with_failures"):
                if report.status == "running":      # an exception of our own: say so
                    report.status = "failed"
                with _interrupts_deferred():        # a second Ctrl-C must not cut this short
                    self.tb.make_safe(report.reason.splitlines()[0] if report.reason else "campaign stopped")
            self._tag(step)                         # what make_safe closed: the run it stopped in
            report.recordings += self._recordings(recordings_before)
            report.completed_runs = sorted(set(report.completed_runs))
            report.finished = time.time()
        return report

    def _prepare_writers(self) -> None:
        """More than one recording to come: each run's log writer is started ahead, during
        the run before it (logs/standby.py, through the station's RecordingSlot)."""
        if sum(s.action == "start_recording" for s in self.campaign.steps) > 1:
            recording = getattr(self.tb, "recording", None)
            if recording is not None:
                recording.prepare_ahead()

    def _tag(self, step: Step | None) -> None:
        """The recordings that ended since the last call belong to `step`'s run."""
        recordings = self.tb.recordings
        tags = run_tags(self.campaign, step)
        for i in range(self._tagged, len(recordings)):
            self._tags[i] = tags
            if self.on_recording is not None:
                self.on_recording(self._tagged_recording(i, recordings[i]))
        self._tagged = max(self._tagged, len(recordings))

    def _recordings(self, since: int) -> list[dict[str, Any]]:
        return [self._tagged_recording(i, rec)
                for i, rec in enumerate(list(self.tb.recordings[since:]), since)]

    def _tagged_recording(self, i: int, rec: dict[str, Any]) -> dict[str, Any]:
        """The station's entry `i` with its run and matrix values, as the report lists it."""
        tags = self._tags.get(i, {"run": 0, "variables": {}})
        return {**rec, "run": tags["run"], "variables": dict(tags["variables"])}

    def _do(self, step: Step) -> None:
        """Do one step with its action's handler (the GUI's runner wraps this)."""
        handler = ACTIONS.get(step.action)
        if handler is None:                         # load_campaign admits only registered actions
            raise GroundStationError(f"no handler for action {step.action!r} "
                                     f"(known: {known_actions()})")
        handler.run(StepRun(self.tb, step, self.max_step_seconds, self.progress))


@contextlib.contextmanager
def _interrupts_deferred():
    """While the rig is being made safe after a Ctrl-C, a second Ctrl-C is noted and
    ignored (only the main thread can change signal handling; elsewhere: no change)."""
    if threading.current_thread() is not threading.main_thread():
        yield
        return
    try:
        previous = signal.signal(signal.SIGINT, lambda signum, frame: None)
    except (ValueError, OSError):
        yield
        return
    try:
        yield
    finally:
        signal.signal(signal.SIGINT, previous)


def run_tags(campaign: Campaign, step: Step | None) -> dict[str, Any]:
    """{"run": N, "variables": {KEY: value, KEY_stem: stem}} of `step`'s run: the matrix
    keys only (0 and {} in setup and teardown)."""
    if step is None or not step.run:
        return {"run": 0, "variables": {}}
    variables: dict[str, Any] = {}
    for key in campaign.matrix:
        if key in step.variables:
            value = step.variables[key]
            variables[key] = value
            if isinstance(value, str):
                variables[f"{key}_stem"] = Path(value).stem
    return {"run": step.run, "variables": variables}


def _reason(exc: BaseException) -> str:
    if isinstance(exc, KeyboardInterrupt):
        return "interrupted by the operator (Ctrl-C)"
    text = str(exc).strip()
    return text or type(exc).__name__
