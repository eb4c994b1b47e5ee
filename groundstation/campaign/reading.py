"""Reading a campaign file: its structure, the matrix expanded into steps with their
placeholders filled and files resolved, then every step's values checked by its
action's handler (`actions.ACTIONS`).  Nothing here connects or sends anything."""

from __future__ import annotations

import itertools
import math
import re
from pathlib import Path
from typing import Any

from ..core.errors import GroundStationError
from ..core.tomlfile import read_toml
from .actions import ACTIONS, PATH_KEYS, known_actions
from .checks import CampaignChecker, show
from .model import REFERENCE_METRICS, AnalysisSpec, Campaign, CampaignError, Step

#: the keys of the optional [analysis] table (campaign/metrics.py scores the logs with them)
ANALYSIS_KEYS = ("start_after_mark", "duration_s", "sensor", "integration_period_s", "group_by",
                 "compare", "baseline", "metrics", "max_excluded_fraction")


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
    unknown = set(doc) - {"campaign", "matrix", "setup", "run", "teardown", "analysis"}
    if unknown:
        raise CampaignError(f"{path}: unknown table(s) {sorted(unknown)} (known: campaign, matrix, "
                            f"setup, run, teardown, analysis)")
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
            if _skipped(item, matrix, variables, problems, f"{path.name}: "
                        f"{f'run {run}' if run else phase} step {position}"):
                continue
            step = _step(item, problems, len(steps), phase, run, position, variables, path, name)
            if step is not None:
                steps.append(step)
    add("setup", 0, raw["setup"], {})
    for run, combo in enumerate(combos, 1):
        if raw["run"]:
            add("run", run, raw["run"], combo)
    add("teardown", 0, raw["teardown"], {})
    runs = len(combos) if raw["run"] else 0
    analysis = read_analysis(doc.get("analysis"), path, name, matrix, combos[:runs], steps, problems)
    campaign = Campaign(path, name, str(head.get("description", "")), testbed, matrix, steps,
                        runs, policy, analysis)
    problems += check_campaign(campaign, dictionary)
    return campaign, problems


def read_analysis(table: Any, path: Path, name: str, matrix: dict[str, list[Any]],
                  combos: list[dict[str, Any]], steps: list[Step], problems: list[str]) -> AnalysisSpec:
    """The [analysis] table checked (problems appended, worded as the steps' are:
    "FILE: [analysis] duration_s = -5 - must be a finite number > 0"); the defaults where
    a value is absent or refused.  No table: the defaults, `given` False."""
    if table is None:
        return AnalysisSpec()
    head = f"{path.name}: [analysis]"
    if not isinstance(table, dict):
        problems.append(f"{head} must be a table ([analysis] with keys {', '.join(ANALYSIS_KEYS)})")
        return AnalysisSpec(given=True)
    check = _AnalysisTable(table, head, matrix)
    check.keys_known()
    check.numbers()
    check.sensor()
    check.grouping()
    check.baseline()
    check.metrics()
    check.start_after_mark(name, combos, steps)
    problems += check.found
    values = check.values
    if values.get("compare") and "baseline" not in values:
        values["baseline"] = matrix[values["compare"]][0]       # the first value, as the matrix lists it
    return AnalysisSpec(given=True, **values)


class _AnalysisTable:
    """The checks of one [analysis] table: what each accepts goes to `values`, what it
    refuses to `found`."""

    def __init__(self, table: dict, head: str, matrix: dict[str, list[Any]]) -> None:
        self.table, self.head, self.matrix = table, head, matrix
        self.found: list[str] = []
        self.values: dict[str, Any] = {}

    def bad(self, key: str, text: str) -> None:
        self.found.append(f"{self.head} {key} = {show(self.table[key])} - {text}")

    def keys_known(self) -> None:
        unknown = sorted(set(self.table) - set(ANALYSIS_KEYS))
        if unknown:
            self.found.append(f"{self.head}: unknown key(s) {', '.join(unknown)} "
                              f"(allowed: {', '.join(ANALYSIS_KEYS)})")

    def numbers(self) -> None:
        table, values = self.table, self.values
        for key in ("duration_s", "integration_period_s"):
            if key in table:
                v = table[key]
                if isinstance(v, bool) or not isinstance(v, (int, float)) or not math.isfinite(v) or v <= 0:
                    self.bad(key, "must be a finite number > 0 (seconds)")
                else:
                    values[key] = float(v)
        if "max_excluded_fraction" in table:
            v = table["max_excluded_fraction"]
            if isinstance(v, bool) or not isinstance(v, (int, float)) or not 0 <= v <= 1:
                self.bad("max_excluded_fraction", "must be a fraction from 0 to 1 (0.01: a window "
                                                  "with more than 1 % excluded is not valid)")
            else:
                values["max_excluded_fraction"] = float(v)

    def sensor(self) -> None:
        if "sensor" in self.table:
            from ..analysis.names import SENSORS      # the names alone: no numerics imported
            if self.table["sensor"] not in SENSORS:
                self.bad("sensor", f"not a scored sensor (one of {', '.join(SENSORS)})")
            else:
                self.values["sensor"] = self.table["sensor"]

    def grouping(self) -> None:
        """group_by and compare: keys of [matrix], and not the same one."""
        table, values, matrix = self.table, self.values, self.matrix
        keys = list(matrix)
        for key in ("group_by", "compare"):
            if key in table:
                v = table[key]
                if not isinstance(v, str) or v not in matrix:
                    self.bad(key, f"must name a key of [matrix] "
                                  f"({', '.join(keys) or 'the file has no matrix'})")
                else:
                    values[key] = v
        if values.get("group_by") and values.get("group_by") == values.get("compare"):
            self.bad("compare", "must be another matrix key than group_by (the groups hold the "
                                "values compared)")
            values.pop("compare")

    def baseline(self) -> None:
        """baseline: one value of the compared matrix key, as written or by file stem."""
        if "baseline" not in self.table:
            return
        compare = self.values.get("compare")
        if "compare" not in self.table:
            self.bad("baseline", "needs compare = MATRIX_KEY (the key whose values the baseline "
                                 "is one of)")
        elif compare:
            v = self.table["baseline"]
            hits = [x for x in self.matrix[compare]
                    if x == v or (isinstance(x, str) and isinstance(v, str) and Path(x).stem == v)]
            shown = ", ".join(show(x) for x in self.matrix[compare])
            if not hits:
                self.bad("baseline", f"not a value of [matrix] {compare} (as written, or a file's "
                                     f"name without its extension): {shown}")
            elif len(hits) > 1:
                self.bad("baseline", f"names {len(hits)} values of [matrix] {compare}: give the "
                                     f"path as written in [matrix]")
            else:
                self.values["baseline"] = hits[0]

    def metrics(self) -> None:
        if "metrics" in self.table:
            problem, names = _metrics_problem(self.table["metrics"])
            if problem:
                self.bad("metrics", problem)
            else:
                self.values["metrics"] = names

    def start_after_mark(self, name: str, combos: list[dict[str, Any]], steps: list[Step]) -> None:
        if "start_after_mark" not in self.table:
            return
        v = self.table["start_after_mark"]
        if not isinstance(v, str) or not v.strip():
            self.bad("start_after_mark", "must be text: the text (or the start of the text) of a "
                                         "mark step")
            return
        problem = _mark_problem(v, name, combos, steps)
        if problem:
            self.bad("start_after_mark", problem)
        else:
            self.values["start_after_mark"] = v


def _metrics_problem(value: Any) -> tuple[str, tuple[str, ...]]:
    """(why `metrics = value` is refused ('' : it is not), the names in order, once each)."""
    known = ", ".join(REFERENCE_METRICS)
    if not isinstance(value, list) or any(not isinstance(v, str) for v in value):
        return f"must be a list of metric names, e.g. [\"step\"] (known: {known})", ()
    always = [v for v in value if v in ("jitter", "energy")]
    if always:
        return (f"{', '.join(map(repr, always))}: jitter and control energy are scored for every "
                f"log anyway; list only the reference metrics ({known})"), ()
    unknown = [v for v in value if v not in REFERENCE_METRICS]
    if unknown:
        return (f"unknown metric{'s' if len(unknown) > 1 else ''} {', '.join(map(repr, unknown))} "
                f"(known: {known}, as `groundstation analyze --metrics` names them)"), ()
    return "", tuple(dict.fromkeys(value))


def _mark_problem(text: str, name: str, combos: list[dict[str, Any]], steps: list[Step]) -> str:
    """Why no mark of some run would start the window ('' : every run has one)."""
    marks: dict[int, list[str]] = {}
    for s in steps:
        if s.action == "mark" and isinstance(s.args.get("text"), str):
            marks.setdefault(s.run, []).append(s.args["text"])
    shared = marks.get(0, [])       # setup and teardown marks go into whatever log is recording then
    for run, combo in enumerate(combos or [{}], 1):
        try:
            target = text.format(**run_names(name, run if combos else 0, combo))
        except (KeyError, IndexError, ValueError) as exc:
            return (f"unknown or bad placeholder {exc} (known: "
                    f"{', '.join(sorted(run_names(name, run, combo)))})")
        texts = marks.get(run, []) + shared
        if not any(target in t for t in texts):
            where = f"run {run}" if combos else "the campaign"
            return (f"no mark step of {where} has this text" + (f" (its marks: {', '.join(map(repr, texts))})"
                                                                if texts else " (it has no mark step)"))
    return ""


def run_names(campaign: str, run: int, variables: dict[str, Any]) -> dict[str, Any]:
    """The placeholders of a run's text values: {campaign}, {run}, every matrix key and
    {KEY_stem} of each text value."""
    names = {"campaign": campaign, "run": run, **variables}
    for k, v in variables.items():
        if isinstance(v, str):
            names[f"{k}_stem"] = Path(v).stem
    return names


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


def _skipped(item: dict, matrix: dict[str, list[Any]], variables: dict[str, Any],
             problems: list[str], head: str) -> bool:
    """True when the step's `skip_if` matches this run's matrix values, so the run has no
    such step.  `skip_if = {design = "open_loop"}` (a value as [matrix] writes it, or a
    list of them) leaves the step out of every run whose `design` is that value: e.g. no
    upload and no arming in an open-loop baseline run.  (_step ignores the key.)  A
    malformed skip_if is a problem, and the step is kept."""
    cond = item.get("skip_if")
    if cond is None:
        return False
    where = f"{head} ({item.get('action')})"
    if not isinstance(cond, dict) or not cond:
        problems.append(f"{where}: skip_if must be a table of matrix keys and values, e.g. "
                        f"skip_if = {{design = \"open_loop\"}}")
        return False
    hit = True
    for key, wanted in cond.items():
        values = wanted if isinstance(wanted, list) else [wanted]
        if key not in matrix:
            problems.append(f"{where}: skip_if names {key!r}, which is not a [matrix] key "
                            f"(known: {', '.join(sorted(matrix)) or 'none'})")
            return False
        stray = [v for v in values if v not in matrix[key]]
        if stray:
            problems.append(f"{where}: skip_if {key} = {stray!r}: not among the matrix's values "
                            f"{matrix[key]!r}")
            return False
        hit = hit and variables.get(key) in values
    return hit


def _step(item: dict, problems: list[str], index: int, phase: str, run: int, position: int,
          variables: dict[str, Any], path: Path, campaign: str) -> Step | None:
    """One step with its placeholders filled and its files resolved, or None (the
    problems found appended to `problems`)."""
    action = item.get("action")
    head = f"{path.name}: {f'run {run}' if run else phase} step {position}"
    handler = ACTIONS.get(action) if isinstance(action, str) else None
    if handler is None:
        problems.append(f"{head}: action {action!r} is not one of {known_actions()}")
        return None
    where = f"{head} ({action})"
    required, allowed = handler.required, handler.keys
    keys = set(item) - {"action", "skip_if"}
    ok = True
    if required - keys:
        problems.append(f"{where}: missing {', '.join(sorted(required - keys))}")
        ok = False
    if keys - allowed:
        problems.append(f"{where}: unknown key(s) {', '.join(sorted(keys - allowed))}"
                        f" (allowed: {', '.join(sorted(allowed)) or 'none'})")
        ok = False
    names = run_names(campaign, run, variables)
    args = {}
    for k, v in item.items():
        if k in ("action", "skip_if"):
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
            # any file key is resolved (and must exist), whatever the action: a file key
            # given to the wrong action is then refused for the file as well as the key
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


def check_campaign(campaign: Campaign, dictionary=None) -> list[str]:
    """Every value of every step (of every run) against what the rig accepts: the
    protocol dictionary's ranges and mode names, the testbed file's limits (travel,
    motor peak currents, the generator's [limits]), the 4053B generator's own limits;
    every referenced design, profile and PSD file must load.  Returns the problems,
    each naming file, step and field; nothing is sent anywhere."""
    from ..core.dictionary import load_dictionary
    from ..plant.testbed import load_testbed

    d = dictionary if dictionary is not None else load_dictionary()
    problems: list[str] = []
    try:
        testbed = load_testbed(campaign.testbed)
    except GroundStationError as exc:
        problems.append(f"{campaign.path.name}: [campaign] testbed: {exc}")
        testbed = None
    checker = CampaignChecker(campaign.path, d, testbed)
    for step in campaign.steps:
        handler = ACTIONS.get(step.action)
        if handler is None:                 # a Campaign built by hand, not read from a file
            problems.append(f"{campaign.path.name}: {step.where()}: action {step.action!r} "
                            f"is not one of {known_actions()}")
            continue
        check = checker.step(step)
        handler.check(check)
        problems += check.problems
    return problems
