"""Campaigns: a test procedure as data, run step by step on a `Testbed`, with a report.

A campaign file (`profiles/campaigns/*.toml`):

    [campaign]
    name = "relative_steps"
    testbed = "../testbeds/relative_2dof.toml"      # relative to this file

    [matrix]                                        # one run per combination, first key outermost
    design = ["../controllers/relative_design1.toml", "../controllers/relative_design2.toml"]

    [[setup]]                                       # once, before the runs
    action = "set_mode"
    mode = "RELATIVE"

    [[run]]                                         # for every combination of the matrix
    action = "upload_design"
    design = "{design}"
    ...

    [[teardown]]                                    # once, after the runs

`[campaign] on_run_failure = "next_run"` makes a failed run (a fault, a refused upload)
a result instead of the end: the rig is made safe, the fault acknowledged, that run's
recording closed, and the next run starts.  The default, "stop", ends the campaign.

Text values may use {campaign}, {run} (1, 2, ...), every matrix key, and {KEY_stem}
(the file name of a path without its extension).  Values naming files (`design`,
`profile`, `psd`) are relative to the campaign file.

On any failure or an abort the session is made safe (ABORT, generator off, recording
closed) and the report says which step stopped and why.  `resume` re-runs the setup
steps (they build the state a run needs), skips the runs that completed, and starts the
failed run again from its first step - a run's mode, table and recording are made by
its own steps, so half a run cannot be continued.
"""

from __future__ import annotations

import itertools
import json
import time
import traceback
from dataclasses import asdict, dataclass, field
from pathlib import Path
from typing import Any, Callable

from .errors import GroundStationError
from .tomlfile import read_toml

#: action -> (required keys, optional keys); a step's other keys are refused
ACTIONS: dict[str, tuple[set[str], set[str]]] = {
    "connect": (set(), set()),
    "set_mode": ({"mode"}, set()),
    "arm": (set(), set()),
    "disarm": (set(), set()),
    "upload_design": ({"design"}, {"accept_risk"}),
    "friction_comp": ({"enabled"}, set()),
    "set_reference": ({"angle_rad"}, set()),
    "set_currents": (set(), {"coarse_a", "fine_a"}),
    "generator_set": ({"waveform"}, {"channel", "frequency_hz", "amplitude_vpp", "offset_v",
                                      "phase_deg", "output"}),
    "generator_off": (set(), set()),
    "play_base_motion": ({"psd"}, {"duration_s", "seed", "rms_mrad", "channel"}),
    "start_recording": ({"name"}, {"notes"}),
    "stop_recording": (set(), set()),
    "play": ({"profile"}, {"mode"}),
    "dwell": ({"seconds"}, set()),
    "mark": ({"text"}, set()),
    "pause": ({"prompt"}, set()),
}
PATH_KEYS = {"design", "profile", "psd"}
#: keys whose value is a time the run waits through (a test may cap them; a base-motion
#: profile keeps its period, the capped dwell then plays only its beginning)
DURATION_KEYS = {("dwell", "seconds")}


class CampaignError(GroundStationError):
    """A campaign file is malformed (names file, step and field)."""


@dataclass
class Step:
    index: int                       # position in the whole campaign, 0-based
    phase: str                       # "setup", "run", "teardown"
    run: int                         # 1-based run number (0 in setup/teardown)
    action: str
    args: dict[str, Any]
    variables: dict[str, Any]

    def label(self) -> str:
        where = f"run {self.run}" if self.run else self.phase
        return f"step {self.index + 1} ({where}): {self.action}"


@dataclass
class Campaign:
    path: Path
    name: str
    description: str
    testbed: Path
    matrix: dict[str, list[Any]]
    steps: list[Step]
    runs: int
    on_run_failure: str = "stop"


def load_campaign(path: str | Path) -> Campaign:
    path = Path(path)
    doc, _text = read_toml(path, CampaignError, "campaign file not found (see profiles/campaigns/)")
    head = doc.get("campaign")
    if not isinstance(head, dict):
        raise CampaignError(f"{path}: needs a [campaign] table with name and testbed")
    name = _text_field(head, "name", path, "[campaign]")
    testbed = (path.parent / _text_field(head, "testbed", path, "[campaign]")).resolve()
    if not testbed.is_file():
        raise CampaignError(f"{path}: [campaign] testbed: no file {testbed}")
    unknown = set(doc) - {"campaign", "matrix", "setup", "run", "teardown"}
    if unknown:
        raise CampaignError(f"{path}: unknown table(s) {sorted(unknown)} (known: campaign, matrix, "
                            f"setup, run, teardown)")
    matrix = doc.get("matrix", {})
    if not isinstance(matrix, dict) or any(not isinstance(v, list) or not v for v in matrix.values()):
        raise CampaignError(f"{path}: [matrix] values must be non-empty lists")
    combos = [dict(zip(matrix, values)) for values in itertools.product(*matrix.values())] or [{}]
    steps: list[Step] = []
    raw = {ph: doc.get(ph, []) for ph in ("setup", "run", "teardown")}
    for ph, items in raw.items():
        if not isinstance(items, list) or any(not isinstance(i, dict) for i in items):
            raise CampaignError(f"{path}: [[{ph}]] must be an array of tables")
    if not raw["run"] and not raw["setup"]:
        raise CampaignError(f"{path}: no steps ([[setup]] or [[run]])")

    def add(phase: str, run: int, items: list[dict], variables: dict[str, Any]) -> None:
        for item in items:
            where = f"{path}: [[{phase}]] step {len([s for s in steps if s.phase == phase]) + 1}"
            steps.append(_step(item, where, len(steps), phase, run, variables, path, name))
    add("setup", 0, raw["setup"], {})
    for run, combo in enumerate(combos, 1):
        if raw["run"]:
            add("run", run, raw["run"], combo)
    add("teardown", 0, raw["teardown"], {})
    policy = head.get("on_run_failure", "stop")
    if policy not in ("stop", "next_run"):
        raise CampaignError(f"{path}: [campaign] on_run_failure must be \"stop\" or \"next_run\", "
                            f"not {policy!r}")
    return Campaign(path, name, str(head.get("description", "")), testbed, matrix, steps,
                    len(combos) if raw["run"] else 0, policy)


def _text_field(table: dict, key: str, path: Path, where: str) -> str:
    v = table.get(key)
    if not isinstance(v, str) or not v:
        raise CampaignError(f"{path}: {where} {key} must be a non-empty string")
    return v


def _step(item: dict, where: str, index: int, phase: str, run: int, variables: dict[str, Any],
          path: Path, campaign: str) -> Step:
    action = item.get("action")
    if action not in ACTIONS:
        raise CampaignError(f"{where}: action {action!r} is not one of {', '.join(sorted(ACTIONS))}")
    required, optional = ACTIONS[action]
    keys = set(item) - {"action"}
    if required - keys:
        raise CampaignError(f"{where} ({action}): missing {', '.join(sorted(required - keys))}")
    if keys - required - optional:
        raise CampaignError(f"{where} ({action}): unknown key(s) {', '.join(sorted(keys - required - optional))}"
                            f" (allowed: {', '.join(sorted(required | optional)) or 'none'})")
    names = {"campaign": campaign, "run": run, **variables}
    for k, v in variables.items():
        if isinstance(v, str):
            names[f"{k}_stem"] = Path(v).stem
    args = {}
    for k, v in item.items():
        if k == "action":
            continue
        if isinstance(v, str):
            try:
                v = v.format(**names)
            except (KeyError, IndexError, ValueError) as exc:
                raise CampaignError(f"{where} ({action}): {k} = {v!r}: unknown or bad placeholder "
                                    f"{exc} (known: {', '.join(sorted(names))})") from None
            if k in PATH_KEYS:
                resolved = (path.parent / v).resolve()
                if not resolved.is_file():
                    raise CampaignError(f"{where} ({action}): {k}: no file {resolved}")
                v = str(resolved)
        args[k] = v
    return Step(index, phase, run, action, args, dict(variables))


# ---------------------------------------------------------------------- running
@dataclass
class StepResult:
    index: int
    label: str
    status: str                       # "done", "failed", "skipped", "aborted"
    seconds: float = 0.0
    error: str = ""


@dataclass
class CampaignReport:
    campaign: str
    file: str
    started: float
    finished: float = 0.0
    status: str = "running"           # "completed", "completed_with_failures", "failed", "aborted"
    failed_step: int | None = None    # 0-based index
    failed_run: int | None = None
    reason: str = ""
    steps: list[StepResult] = field(default_factory=list)
    recordings: list[dict[str, Any]] = field(default_factory=list)
    completed_runs: list[int] = field(default_factory=list)
    failed_runs: dict[str, str] = field(default_factory=dict)     # run number -> reason

    def save(self, path: str | Path) -> Path:
        path = Path(path)
        path.parent.mkdir(parents=True, exist_ok=True)
        path.write_text(json.dumps(asdict(self), indent=2) + "\n")
        path.with_suffix(".txt").write_text(self.summary() + "\n")
        return path

    @classmethod
    def load(cls, path: str | Path) -> "CampaignReport":
        try:
            doc = json.loads(Path(path).read_text())
            doc["steps"] = [StepResult(**s) for s in doc.get("steps", [])]
            return cls(**doc)
        except (OSError, ValueError, TypeError) as exc:
            raise CampaignError(f"{path}: not a campaign report ({exc})") from None

    def summary(self) -> str:
        done = sum(1 for s in self.steps if s.status == "done")
        lines = [f"campaign {self.campaign}: {self.status.upper()} - {done} step(s) done, "
                 f"{len(self.completed_runs)} run(s) complete, {self.finished - self.started:.1f} s"]
        for run, why in sorted(self.failed_runs.items(), key=lambda kv: int(kv[0])):
            lines.append(f"run {run} failed: {why}")
        if self.failed_step is not None:
            lines.append(f"stopped at step {self.failed_step + 1}"
                         + (f" (run {self.failed_run})" if self.failed_run else "") + f": {self.reason}")
            lines.append(f"resume with: groundstation campaign run {self.file} --resume REPORT.json")
        for rec in self.recordings:
            lines.append(f"  log {', '.join(Path(f).name for f in rec.get('files', []))}: "
                         f"{rec.get('frames', 0)} frames, {rec.get('discarded_blocks', 0)} blocks discarded"
                         + (f", {rec['dropped']} frames dropped on the link" if rec.get("dropped") else ""))
        return "\n".join(lines)


class CampaignRunner:
    """Runs a Campaign on a Testbed (already open), step by step."""

    def __init__(self, campaign: Campaign, testbed, *, max_step_seconds: float | None = None,
                 progress: Callable[[Step, float], None] | None = None):
        self.campaign = campaign
        self.tb = testbed
        self.max_step_seconds = max_step_seconds
        self.progress = progress or (lambda step, fraction: None)

    def run(self, resume: CampaignReport | None = None) -> CampaignReport:
        c = self.campaign
        report = CampaignReport(c.name, str(c.path), time.time())
        skip_runs = set(resume.completed_runs) if resume else set()
        if resume:
            report.completed_runs = sorted(skip_runs)
            report.recordings = list(resume.recordings)
        recordings_before = len(self.tb.recordings)
        current_run, run_failed = 0, False
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
                    aborted = isinstance(exc, KeyboardInterrupt) or type(exc).__name__ == "ScriptAborted"
                    status = "aborted" if aborted else "failed"
                    report.steps.append(StepResult(step.index, step.label(), status,
                                                   time.monotonic() - t0, _reason(exc)))
                    run_failed = True
                    if step.run and not aborted and c.on_run_failure == "next_run" \
                            and isinstance(exc, GroundStationError):
                        report.failed_runs[str(step.run)] = f"{step.label()}: {_reason(exc)}"
                        self.tb.recover(f"run {step.run} failed: {_reason(exc)}")
                        continue
                    report.status = status
                    report.failed_step, report.failed_run = step.index, step.run or None
                    report.reason = f"{step.label()}: {_reason(exc)}"
                    if not isinstance(exc, (GroundStationError, KeyboardInterrupt)):
                        report.reason += "\n" + traceback.format_exc()
                    break
                report.steps.append(StepResult(step.index, step.label(), "done", time.monotonic() - t0))
                self.progress(step, 1.0)
            else:
                if current_run and not run_failed:
                    report.completed_runs.append(current_run)
                report.status = "completed_with_failures" if report.failed_runs else "completed"
        finally:
            if report.status not in ("completed", "completed_with_failures"):
                self.tb.make_safe(report.reason.splitlines()[0] if report.reason else "campaign stopped")
            report.recordings += self._recordings(recordings_before)
            report.completed_runs = sorted(set(report.completed_runs))
            report.finished = time.time()
        return report

    def _recordings(self, since: int) -> list[dict[str, Any]]:
        out = []
        for rec in self.tb.recordings[since:]:
            out.append(dict(rec))
        return out

    def _capped(self, step: Step, key: str, value: float) -> float:
        if self.max_step_seconds is not None and (step.action, key) in DURATION_KEYS:
            return min(float(value), self.max_step_seconds)
        return float(value)

    def _do(self, step: Step) -> None:
        tb, a = self.tb, step.args
        act = step.action
        if act == "connect":
            if tb.client is None or tb.client.link_state != "up":
                raise GroundStationError("the link is not up")
        elif act == "set_mode":
            tb.set_mode(a["mode"])
        elif act == "arm":
            tb.arm()
        elif act == "disarm":
            tb.disarm()
        elif act == "upload_design":
            tb.upload_design(a["design"], accept_risk=a.get("accept_risk"))
        elif act == "friction_comp":
            tb.friction_comp(bool(a["enabled"]))
        elif act == "set_reference":
            tb.set_reference(float(a["angle_rad"]))
        elif act == "set_currents":
            tb.set_currents(float(a.get("coarse_a", 0.0)), float(a.get("fine_a", 0.0)))
        elif act == "generator_set":
            tb.generator_set(int(a.get("channel", 1)), waveform=a["waveform"],
                             frequency_hz=a.get("frequency_hz"), amplitude_vpp=a.get("amplitude_vpp"),
                             offset_v=float(a.get("offset_v", 0.0)), phase_deg=float(a.get("phase_deg", 0.0)),
                             output=bool(a.get("output", True)))
        elif act == "generator_off":
            tb.generator_off()
        elif act == "play_base_motion":
            rms = a.get("rms_mrad")
            tb.play_base_motion(a["psd"], duration_s=self._capped(step, "duration_s", a.get("duration_s", 60.0)),
                                seed=int(a.get("seed", 0)), rms_rad=None if rms is None else float(rms) * 1e-3,
                                channel=int(a.get("channel", 1)))
        elif act == "start_recording":
            tb.start_recording(a["name"], a.get("notes", ""))
        elif act == "stop_recording":
            tb.stop_recording()
        elif act == "play":
            tb.play(a["profile"], mode=a.get("mode"), max_seconds=self.max_step_seconds,
                    progress=lambda f: self.progress(step, f))
        elif act == "dwell":
            tb.dwell(self._capped(step, "seconds", a["seconds"]), progress=lambda f: self.progress(step, f))
        elif act == "mark":
            tb.mark(a["text"])
        elif act == "pause":
            tb.pause(a["prompt"])
        else:                                       # load_campaign admits only ACTIONS
            raise GroundStationError(f"no handler for action {act!r}")


def _reason(exc: BaseException) -> str:
    if isinstance(exc, KeyboardInterrupt):
        return "interrupted by the operator (Ctrl-C)"
    text = str(exc).strip()
    return text or type(exc).__name__
