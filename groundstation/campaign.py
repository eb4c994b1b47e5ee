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

`load_campaign` checks every step of every run before anything runs - the structure,
then every value against the protocol dictionary, the testbed's limits and the 4053B
generator's, and that every referenced file loads - and raises CampaignError listing
every problem ("FILE: run 2 step 4 (dwell): seconds = -5 - must be a finite number > 0").

On any failure or an abort the session is made safe (ABORT, generator off, recording
closed) and the report says which step stopped and why.  `resume` re-runs the setup
steps (they build the state a run needs), skips the runs that completed, and starts the
failed run again from its first step - a run's mode, table and recording are made by
its own steps, so half a run cannot be continued.
"""

from __future__ import annotations

import contextlib
import itertools
import json
import math
import re
import signal
import threading
import time
import traceback
from dataclasses import asdict, dataclass, field
from pathlib import Path
from typing import Any, Callable

from .errors import GroundStationError
from .instruments import spec4050
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
    """A campaign file is malformed or asks for values the rig must not be given; every
    problem found names the file, the step and the field (`problems`, one per line of
    the message)."""

    def __init__(self, message: str, problems: list[str] | None = None):
        super().__init__(message)
        self.problems = list(problems) if problems else [message]


@dataclass
class Step:
    index: int                       # position in the whole campaign, 0-based
    phase: str                       # "setup", "run", "teardown"
    run: int                         # 1-based run number (0 in setup/teardown)
    action: str
    args: dict[str, Any]
    variables: dict[str, Any]
    position: int = 0                # 1-based position within its phase (within a run)

    def label(self) -> str:
        where = f"run {self.run}" if self.run else self.phase
        return f"step {self.index + 1} ({where}): {self.action}"

    def where(self) -> str:
        """'run 2 step 4 (dwell)', 'setup step 1 (connect)': how problems name a step."""
        head = f"run {self.run}" if self.run else self.phase
        return f"{head} step {self.position} ({self.action})"


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


def load_campaign(path: str | Path, dictionary=None) -> Campaign:
    """Read a campaign file and check every step of every run before anything runs:
    the file's structure, then every value against the protocol dictionary, the
    testbed's limits and the function generator's (`check_campaign`).  Raises
    CampaignError listing every problem found."""
    campaign, problems = read_campaign(path, dictionary)
    if problems:
        raise CampaignError(_problems_text(Path(path), problems), problems)
    return campaign


def read_campaign(path: str | Path, dictionary=None) -> tuple[Campaign | None, list[str]]:
    """The campaign and every problem found in it (an empty list: it may run).  The
    campaign is None when the file is too broken to list its steps."""
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
    problems: list[str] = []
    raw = {ph: doc.get(ph, []) for ph in ("setup", "run", "teardown")}
    for ph, items in raw.items():
        if not isinstance(items, list) or any(not isinstance(i, dict) for i in items):
            raise CampaignError(f"{path}: [[{ph}]] must be an array of tables")
    if not raw["run"] and not raw["setup"]:
        raise CampaignError(f"{path}: no steps ([[setup]] or [[run]])")
    policy = head.get("on_run_failure", "stop")
    if policy not in ("stop", "next_run"):
        raise CampaignError(f"{path}: [campaign] on_run_failure must be \"stop\" or \"next_run\", "
                            f"not {policy!r}")

    def add(phase: str, run: int, items: list[dict], variables: dict[str, Any]) -> None:
        for position, item in enumerate(items, 1):
            step = _step(item, problems, len(steps), phase, run, position, variables, path, name)
            if step is not None:
                steps.append(step)
    add("setup", 0, raw["setup"], {})
    for run, combo in enumerate(combos, 1):
        if raw["run"]:
            add("run", run, raw["run"], combo)
    add("teardown", 0, raw["teardown"], {})
    campaign = Campaign(path, name, str(head.get("description", "")), testbed, matrix, steps,
                        len(combos) if raw["run"] else 0, policy)
    problems += check_campaign(campaign, dictionary)
    return campaign, problems


def _problems_text(path: Path, problems: list[str]) -> str:
    if len(problems) == 1:
        return problems[0]
    return (f"{path.name}: {len(problems)} problems, nothing was run:\n  " + "\n  ".join(problems))


def _text_field(table: dict, key: str, path: Path, where: str) -> str:
    v = table.get(key)
    if not isinstance(v, str) or not v:
        raise CampaignError(f"{path}: {where} {key} must be a non-empty string")
    return v


_WHOLE_PLACEHOLDER = re.compile(r"^\{(\w+)\}$")


def _step(item: dict, problems: list[str], index: int, phase: str, run: int, position: int,
          variables: dict[str, Any], path: Path, campaign: str) -> Step | None:
    """One step with its placeholders filled and its files resolved, or None (the
    problems found appended to `problems`)."""
    action = item.get("action")
    head = f"{path.name}: {f'run {run}' if run else phase} step {position}"
    if action not in ACTIONS:
        problems.append(f"{head}: action {action!r} is not one of {', '.join(sorted(ACTIONS))}")
        return None
    where = f"{head} ({action})"
    required, optional = ACTIONS[action]
    keys = set(item) - {"action"}
    ok = True
    if required - keys:
        problems.append(f"{where}: missing {', '.join(sorted(required - keys))}")
        ok = False
    if keys - required - optional:
        problems.append(f"{where}: unknown key(s) {', '.join(sorted(keys - required - optional))}"
                        f" (allowed: {', '.join(sorted(required | optional)) or 'none'})")
        ok = False
    names = {"campaign": campaign, "run": run, **variables}
    for k, v in variables.items():
        if isinstance(v, str):
            names[f"{k}_stem"] = Path(v).stem
    args = {}
    for k, v in item.items():
        if k == "action":
            continue
        if isinstance(v, str):
            whole = _WHOLE_PLACEHOLDER.match(v)
            if whole and whole.group(1) in variables and not isinstance(variables[whole.group(1)], str):
                args[k] = variables[whole.group(1)]     # a number or flag from the matrix keeps its type
                continue
            try:
                v = v.format(**names)
            except (KeyError, IndexError, ValueError) as exc:
                problems.append(f"{where}: {k} = {v!r}: unknown or bad placeholder {exc} "
                                f"(known: {', '.join(sorted(names))})")
                ok = False
                continue
            if k in PATH_KEYS:
                resolved = (path.parent / v).resolve()
                if not resolved.is_file():
                    problems.append(f"{where}: {k}: no file {resolved}")
                    ok = False
                    continue
                v = str(resolved)
        elif k in PATH_KEYS:
            problems.append(f"{where}: {k} = {v!r} - must be the path of a file (text)")
            ok = False
            continue
        args[k] = v
    if not ok:
        return None
    return Step(index, phase, run, action, args, dict(variables), position)


# ---------------------------------------------------------------------------------- values
def check_campaign(campaign: Campaign, dictionary=None) -> list[str]:
    """Every value of every step (of every run) against what the rig accepts: the
    protocol dictionary's ranges and mode names, the testbed file's limits (travel,
    motor peak currents, the generator's [limits]), the 4053B generator's own limits;
    every referenced design, profile and PSD file must load.  Returns the problems,
    each naming file, step and field; nothing is sent anywhere."""
    from .dictionary import load_dictionary
    from .plant.testbed import load_testbed

    d = dictionary if dictionary is not None else load_dictionary()
    problems: list[str] = []
    try:
        testbed = load_testbed(campaign.testbed)
    except GroundStationError as exc:
        problems.append(f"{campaign.path.name}: [campaign] testbed: {exc}")
        testbed = None
    checker = _ValueChecker(campaign.path, d, testbed)
    for step in campaign.steps:
        problems += checker.check(step)
    return problems


class _ValueChecker:
    """Checks the steps' values; loads each referenced file once."""

    def __init__(self, path: Path, dictionary, testbed):
        self.path = path
        self.d = dictionary
        self.testbed = testbed
        self._loaded: dict[tuple, str | None] = {}       # (kind, args) -> problem or None
        self._base_motion: dict[tuple, Any] = {}

    # -- helpers
    def _arg(self, command: str, name: str):
        return next(i for i in self.d.command(command).args if i.name == name)

    def _modes(self) -> dict[str, int]:
        return dict(self._arg("SET_MODE", "mode").states)

    def _once(self, key: tuple, load: Callable[[], Any]) -> str | None:
        if key not in self._loaded:
            try:
                load()
                self._loaded[key] = None
            except GroundStationError as exc:
                self._loaded[key] = str(exc).strip() or type(exc).__name__
            except (OSError, ValueError) as exc:
                self._loaded[key] = f"{type(exc).__name__}: {exc}"
        return self._loaded[key]

    def check(self, step: Step) -> list[str]:
        out: list[str] = []
        head = f"{self.path.name}: {step.where()}"

        def bad(key: str, text: str) -> None:
            out.append(f"{head}: {key} = {_show(step.args.get(key))} - {text}")

        def number(key: str, *, lo: float | None = None, hi: float | None = None,
                   positive: bool = False, what: str = "") -> float | None:
            """The value as a finite number, or None after a problem (absent: None)."""
            if key not in step.args:
                return None
            v = step.args[key]
            if isinstance(v, bool) or not isinstance(v, (int, float)) or not math.isfinite(v):
                rule = "must be a finite number"
                if positive:
                    rule += " > 0"
                elif lo is not None and hi is not None:
                    rule += f" in [{lo:g}, {hi:g}]"
                bad(key, rule + (f" ({what})" if what else ""))
                return None
            if positive and not v > 0:
                bad(key, "must be a finite number > 0" + (f" ({what})" if what else ""))
                return None
            if (lo is not None and v < lo) or (hi is not None and v > hi):
                bad(key, f"outside [{'-inf' if lo is None else f'{lo:g}'}, "
                         f"{'inf' if hi is None else f'{hi:g}'}]" + (f" ({what})" if what else ""))
                return None
            return float(v)

        def text(key: str, *, empty_ok: bool = False) -> None:
            if key in step.args:
                v = step.args[key]
                if not isinstance(v, str) or (not empty_ok and not v.strip()):
                    bad(key, "must be text" + ("" if empty_ok else " (not empty)"))

        def flag(key: str) -> None:
            if key in step.args and not (isinstance(step.args[key], bool) or step.args[key] in (0, 1)):
                bad(key, "must be true or false")

        def mode(key: str) -> None:
            if key in step.args:
                modes = self._modes()
                if step.args[key] not in modes:
                    bad(key, f"not a mode of the protocol (SET_MODE: {', '.join(modes)})")

        def loads(key: str, kind: str, load: Callable[[], Any]) -> bool:
            problem = self._once((kind, step.args[key]), load)
            if problem:
                out.append(f"{head}: {key}: {problem}")
            return problem is None

        def channel() -> int | None:
            if "channel" not in step.args:
                return 1
            v = step.args["channel"]
            if isinstance(v, bool) or v not in spec4050.CHANNELS:
                bad("channel", f"must be one of the generator's channels "
                               f"{', '.join(map(str, spec4050.CHANNELS))}")
                return None
            return int(v)

        a, act, tb = step.args, step.action, self.testbed
        if act == "dwell":
            number("seconds", positive=True)
        elif act in ("set_mode", "play"):
            mode("mode")
            if act == "play":
                from .profiles.profile import load_profile
                loads("profile", "profile", lambda: load_profile(a["profile"], self.d))
        elif act == "friction_comp":
            flag("enabled")
        elif act == "set_reference":
            item = self._arg("SET_REFERENCE", "reference")
            lo, hi = item.value_range or (-math.inf, math.inf)
            v = number("angle_rad", lo=lo, hi=hi, what="SET_REFERENCE range in protocol/commands.toml")
            if v is not None and tb is not None and abs(v) > tb.mechanics["travel"]:
                bad("angle_rad", f"beyond the testbed's travel of +-{tb.mechanics['travel']:g} rad "
                                 f"({tb.path.name} [mechanics] travel)")
        elif act == "set_currents":
            for key, arg, motor in (("coarse_a", "current_coarse", "motor_coarse"),
                                    ("fine_a", "current_fine", "motor_fine")):
                lo, hi = self._arg("SET_CURRENTS", arg).value_range or (-math.inf, math.inf)
                v = number(key, lo=lo, hi=hi, what=f"SET_CURRENTS {arg} range in protocol/commands.toml")
                if v is not None and tb is not None:
                    m = getattr(tb, motor)
                    peak = m["peak_torque"] / m["torque_constant"]
                    if abs(v) > peak * (1 + 1e-6):
                        bad(key, f"beyond the motor's peak current {peak:.3g} A ({tb.path.name} "
                                 f"[{motor}] peak_torque / torque_constant)")
        elif act == "generator_set":
            self._check_generator(step, bad, number, flag, channel)
        elif act == "play_base_motion":
            self._check_base_motion(step, bad, number, channel, loads, out, head)
        elif act == "upload_design":
            from .params.design import load_design
            loads("design", "design", lambda: load_design(a["design"]))
            text("accept_risk")
        elif act == "start_recording":
            text("name")
            text("notes", empty_ok=True)
        elif act == "mark":
            text("text")
        elif act == "pause":
            text("prompt")
        return out

    def _check_generator(self, step: Step, bad, number, flag, channel) -> None:
        a = step.args
        channel()
        flag("output")
        wave = a.get("waveform")
        if not isinstance(wave, str) or wave.upper() not in spec4050.WAVEFORMS:
            bad("waveform", f"not a waveform the generator driver sets ({', '.join(spec4050.WAVEFORMS)})")
            return
        wave = wave.upper()
        needed = spec4050.WAVE_PARAMETERS[wave]
        model = f"{spec4050.MODEL} limit, groundstation/instruments/spec4050.py"
        if "FRQ" in needed:
            number("frequency_hz", lo=spec4050.FREQUENCY_MIN_HZ, hi=spec4050.FREQUENCY_MAX_HZ[wave],
                   what=f"{model}, {wave}")
        if "PHSE" in needed:
            number("phase_deg", lo=spec4050.PHASE_MIN_DEG, hi=spec4050.PHASE_MAX_DEG, what=model)
        # the stage's amplifier input is high impedance: the load the driver expects
        amp = number("amplitude_vpp", lo=spec4050.AMPLITUDE_MIN_VPP["HZ"],
                     hi=spec4050.AMPLITUDE_MAX_VPP["HZ"], what=f"{model}, high-impedance load") \
            if "AMP" in needed else None
        omax = spec4050.OFFSET_MAX_V["HZ"]
        ofst = number("offset_v", lo=-omax, hi=omax, what=f"{model}, high-impedance load")
        if amp is not None and ofst is not None and abs(ofst) + amp / 2 > spec4050.ENVELOPE_MAX_V["HZ"]:
            bad("amplitude_vpp", f"|offset| + amplitude/2 = {abs(ofst) + amp / 2:g} V is beyond "
                                 f"{spec4050.ENVELOPE_MAX_V['HZ']:g} V ({model})")
        tb = self.testbed
        if tb is None:
            return
        lim_amp, lim_ofst = tb.limits.get("fg_max_amplitude"), tb.limits.get("fg_max_offset")
        if amp is not None and lim_amp is not None and amp > lim_amp:
            bad("amplitude_vpp", f"above the testbed's limit of {lim_amp:g} Vpp "
                                 f"({tb.path.name} [limits] fg_max_amplitude)")
        if ofst is not None and lim_ofst is not None and abs(ofst) > lim_ofst:
            bad("offset_v", f"beyond the testbed's limit of +-{lim_ofst:g} V "
                            f"({tb.path.name} [limits] fg_max_offset)")

    def _check_base_motion(self, step: Step, bad, number, channel, loads, out, head) -> None:
        from .basemotion import load_profile, load_psd

        a = step.args
        channel()
        duration = number("duration_s", positive=True)
        rms = number("rms_mrad", positive=True)
        seed = a.get("seed", 0)
        if isinstance(seed, bool) or not isinstance(seed, int) or seed < 0:
            bad("seed", "must be an integer >= 0")
            return
        if not loads("psd", "psd", lambda: load_psd(a["psd"])):
            return
        if ("duration_s" in a and duration is None) or ("rms_mrad" in a and rms is None):
            return
        tb = self.testbed
        if tb is None:
            return
        key = (a["psd"], duration, seed, rms)
        if key not in self._base_motion:
            try:
                kwargs = {"seed": seed, "target_rms_rad": None if rms is None else rms * 1e-3}
                if duration is not None:
                    kwargs["duration_s"] = duration
                self._base_motion[key] = load_profile(a["psd"], tb, **kwargs)
            except GroundStationError as exc:
                self._base_motion[key] = str(exc)
        profile = self._base_motion[key]
        if isinstance(profile, str):
            out.append(f"{head}: psd: {profile}")
            return
        vpp = profile.amplitude_vpp
        model = f"{spec4050.MODEL} limit, groundstation/instruments/spec4050.py"
        if vpp > spec4050.AMPLITUDE_MAX_VPP["HZ"]:
            out.append(f"{head}: psd: the profile needs {vpp:.3g} Vpp, above the generator's "
                       f"{spec4050.AMPLITUDE_MAX_VPP['HZ']:g} Vpp ({model})")
        lim = tb.limits.get("fg_max_amplitude")
        if lim is not None and vpp > lim:
            out.append(f"{head}: psd: the profile needs {vpp:.3g} Vpp, above the testbed's limit "
                       f"of {lim:g} Vpp ({tb.path.name} [limits] fg_max_amplitude); lower rms_mrad")


def _show(v: Any) -> str:
    if isinstance(v, str):
        return repr(v)
    if isinstance(v, float) and v.is_integer():
        return f"{v:g}"
    return str(v)


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
    status: str = "running"           # "completed", "completed_with_failures", "failed", "aborted",
    #                                   "interrupted" (Ctrl-C)
    failed_step: int | None = None    # 0-based index
    failed_run: int | None = None
    reason: str = ""
    steps: list[StepResult] = field(default_factory=list)
    recordings: list[dict[str, Any]] = field(default_factory=list)
    completed_runs: list[int] = field(default_factory=list)
    failed_runs: dict[str, str] = field(default_factory=dict)     # run number -> reason
    report_file: str = ""             # where save() wrote it (named in the resume hint)

    def save(self, path: str | Path) -> Path:
        path = Path(path)
        self.report_file = str(path)
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
            if self.status == "interrupted":
                lines.append("interrupted by the operator (Ctrl-C): the rig was made safe (ABORT, "
                             "generator off) and the run's log closed with that reason")
            lines.append(f"resume with: groundstation campaign run {self.file} "
                         f"--resume {self.report_file or 'REPORT.json'}")
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
        """Run the steps; returns the report whatever happens.  Ctrl-C (KeyboardInterrupt
        in the main thread) ends the campaign cleanly: status "interrupted", the rig made
        safe and the run's recording closed with that reason."""
        c = self.campaign
        report = CampaignReport(c.name, str(c.path), time.time())
        skip_runs = set(resume.completed_runs) if resume else set()
        if resume:
            report.completed_runs = sorted(skip_runs)
            report.recordings = list(resume.recordings)
        recordings_before = len(self.tb.recordings)
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
                    aborted = type(exc).__name__ == "ScriptAborted"
                    status = "interrupted" if interrupted else "aborted" if aborted else "failed"
                    report.steps.append(StepResult(step.index, step.label(), status,
                                                   time.monotonic() - t0, _reason(exc)))
                    run_failed = True
                    if step.run and status == "failed" and c.on_run_failure == "next_run" \
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


def _reason(exc: BaseException) -> str:
    if isinstance(exc, KeyboardInterrupt):
        return "interrupted by the operator (Ctrl-C)"
    text = str(exc).strip()
    return text or type(exc).__name__
